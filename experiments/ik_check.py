"""
How often the goal check's inverse kinematics finds q* for goals that are known to be reachable.

For each arm, ``--cases`` seeded random joint configurations within the limits (a joint without
stops in [-pi, pi]) give the goals (their forward kinematics: exactly reachable), and as many
random configurations within the limits the measured starts. Each goal is solved as the
controller's worker solves it (``inverse_kinematics.goal_configuration``, joint-limit margin
``--margin``). Printed per arm: the fraction solved, the fraction of those at a regular
configuration (``sigma_min >= SINGULAR_SIGMA_MIN``), the largest residual of q* (position m and
orientation ``||e||``) and whether every q* lies within the limits, and the time per solve
(median and max: the process's CPU time, which other jobs on a shared host disturb less than
the wall time; the worker is niced, so its wall time is longer on a busy host).

With ``--compare-starts N`` each goal is solved again with N IK starts (the controller's
search stops after ``MAX_STARTS`` once it has a regular q* out of the bands), and a column
counts the goals where that q* is nearer by more than ``NEARER_S`` of travel (the slowest
joint's time at its velocity limit), with the CPU time of those searches.

The arms come from example-robot-data (``experiments/arms.py``; ``name`` or ``name:tip_link``)
and the package's own wrist (``wrist``: ``urdf/spherical_wrist.urdf``, orientation task)::

    PYTHONPATH=$PWD python -m experiments.ik_check
    PYTHONPATH=$PWD python -m experiments.ik_check --arms ur3 so100:gripper --cases 50
    PYTHONPATH=$PWD python -m experiments.ik_check --compare-starts 48
"""
import argparse
from pathlib import Path
import time
from typing import Optional

from experiments import arms
import numpy as np
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.inverse_kinematics import (goal_configuration, sampling_box, sigma_min,
                                                   travel_speeds)
from quat_jt_controller.model import RobotModel, SINGULAR_SIGMA_MIN

DEFAULT_ARMS = ('ur3', 'ur5', 'ur10', 'panda', 'so100:gripper', 'z1', 'xarm7', 'talos_left_arm',
                'wrist')
WRIST_URDF = Path(__file__).resolve().parent.parent / 'urdf' / 'spherical_wrist.urdf'
NEARER_S = 0.2  # --compare-starts: a q* nearer by more than this (s of travel) counts


def arm_model(spec: str) -> tuple[RobotModel, Task]:
    """Return the model and task of ``name`` or ``name:tip_link`` (``wrist``: orientation)."""
    name, _, tip = spec.partition(':')
    if name == 'wrist':
        urdf = WRIST_URDF.read_text()
        task = Task.ORIENTATION
    else:
        urdf = arms.example_robot_urdf(name).read_text()
        task = Task.POSE
    base, tip_link, joints = arms.arm_links(urdf, None, tip or None)
    return RobotModel(urdf, base, tip_link, joints), task


def travel_s(model: RobotModel, q_from: np.ndarray, q_to: np.ndarray) -> float:
    """
    Return the slowest joint's time from ``q_from`` to ``q_to`` at the velocity limits (s).

    At the goal check's travel speeds (``inverse_kinematics.travel_speeds``: a joint without a
    limit, or with a placeholder, at 2 pi rad/s).
    """
    return float(np.max(np.abs(np.asarray(q_to) - np.asarray(q_from)) / travel_speeds(model)))


def check_arm(model: RobotModel, task: Task, cases: int, seed: int, margin_rad: float,
              compare_starts: int = 0) -> dict:
    """
    Solve ``cases`` random reachable goals; return the figures of :func:`row`.

    With ``compare_starts`` > 0, each solved goal again with that many IK starts: how many
    of those q* are nearer (``NEARER_S``), and their CPU time.
    """
    rng = np.random.default_rng(seed)
    lo, hi = sampling_box(model)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    solved = regular = within = nearer = 0
    residual = 0.0
    times, compared_times = [], []
    for _ in range(cases):
        q_goal, q_start = rng.uniform(lo, hi), rng.uniform(lo, hi)
        p_d, R_d = model.forward_kinematics(q_goal.tolist())
        q_d = quat.from_rotation_matrix(R_d)
        t0 = time.process_time()
        q_star = goal_configuration(model, q_start, q_d, p_d, task, margin_rad)
        times.append(time.process_time() - t0)
        if q_star is None:
            continue
        solved += 1
        p, R = model.forward_kinematics(q_star.tolist())
        _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
        error = float(np.linalg.norm(e)) if task.has_orientation else 0.0
        if task.has_position:
            error = max(error, float(np.linalg.norm(np.subtract(p, p_d))))
        residual = max(residual, error)
        regular += bool(sigma_min(model, q_star, task) >= SINGULAR_SIGMA_MIN)
        within += bool(np.all(q_star >= lower) and np.all(q_star <= upper))
        if compare_starts > 0:
            t0 = time.process_time()
            other = goal_configuration(model, q_start, q_d, p_d, task, margin_rad,
                                       (compare_starts, compare_starts))
            compared_times.append(time.process_time() - t0)
            nearer += bool(other is not None and travel_s(model, q_start, other)
                           < travel_s(model, q_start, q_star) - NEARER_S)
    return {'cases': cases, 'solved': solved, 'regular': regular, 'within': within,
            'residual': residual, 'median_s': float(np.median(times)),
            'max_s': float(np.max(times)), 'nearer': nearer,
            'compared_median_s': (float(np.median(compared_times)) if compared_times
                                  else float('nan'))}


HEADER = ('| arm | task | joints | solved | of them regular | largest residual | '
          'within the limits | CPU time per solve: median / max s |\n'
          '|---|---|---|---|---|---|---|---|')


COMPARED = ' q* nearer with {n} starts / their median CPU time s |'


def row(spec: str, model: RobotModel, task: Task, f: dict, compare_starts: int = 0) -> str:
    """Return the markdown table row of one arm (``HEADER``'s columns, + ``COMPARED``)."""
    return (f"| {spec} | {task.value} | {model.n} | {f['solved']}/{f['cases']} "
            f"({100.0 * f['solved'] / f['cases']:.1f}%) | {f['regular']} | "
            f"{f['residual']:.1e} | {f['within']}/{f['solved']} | "
            f"{f['median_s']:.3f} / {f['max_s']:.3f} |"
            + (f" {f['nearer']} / {f['compared_median_s']:.3f} |" if compare_starts else ''))


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--arms', nargs='+', default=list(DEFAULT_ARMS),
                        help='example-robot-data names, name:tip_link, or wrist')
    parser.add_argument('--cases', type=int, default=200)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--margin', type=float, default=0.1,
                        help='joint-limit margin of q* (rad), as the design gives it')
    parser.add_argument('--compare-starts', type=int, default=0, metavar='N',
                        help='also solve each goal with N IK starts; count the nearer q*')
    args = parser.parse_args(argv)
    if args.cases < 1:
        parser.error(f'--cases must be at least 1, not {args.cases}')
    if args.compare_starts < 0:
        parser.error(f'--compare-starts must be at least 0, not {args.compare_starts}')
    header = HEADER
    if args.compare_starts:
        head, rule = HEADER.split('\n')
        header = (head + COMPARED.format(n=args.compare_starts) + '\n' + rule + '---|')
    print(header, flush=True)
    for spec in args.arms:
        try:
            model, task = arm_model(spec)
        except ValueError as exc:
            print(f'| {spec} | skipped: {exc} |', flush=True)
            continue
        print(row(spec, model, task, check_arm(model, task, args.cases, args.seed,
                                               args.margin, args.compare_starts),
                  args.compare_starts), flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

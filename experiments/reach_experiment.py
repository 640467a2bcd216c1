"""
Reach any reachable goal from any start: the figures, from the package's configs.

For random (start, goal) pairs, seeded, the regulator of ``config/wrist_controller.yaml``,
``config/xarm6_controller.yaml`` or ``config/panda_controller.yaml`` runs as the nodes run it:
on the PyBullet simulator core, with the friction of ``config/*_sim.yaml``, sampled at 1 kHz,
one tick of delay, clamped to the effort limits (``reference_sim.run_sampled``). The goal
configuration q* reaches the regulator 0.1 s after the goal, as from the node's goal-check
worker.

* wrist (orientation): start and goal joint angles within 90% of the URDF ranges, |q2| >= 0.3
  at the goal; reached if ||e|| < 0.005 over the last 0.1 s of 4 s;
* xArm6 (pose): start and goal within 80% of the ranges (about their middle), the goal away
  from singularities (sigma_min(J_G) >= 0.1); reached if ||p_d - p|| < 1 mm and ||e|| < 0.01
  over the last 0.1 s of 5 s.
* Panda (pose, 7 joints: a redundant arm; the fingers held): as the xArm6, with the goal's
  sigma_min(J_G) >= 0.05 (the issue's bound), then held 2 s more:
  over that last second the fastest joint speed (the self-motion drift) and, at the end,
  max_j |q_j - q*_j| (the elbow where the goal check put it).

A stop is touched if a joint comes within 1e-3 rad of a URDF limit. Failures are listed with
their likely cause (``stall.StallDetector.diagnose`` at the final state).

    python -m experiments.reach_experiment [--robot wrist xarm6 panda]
        [--potential tanh quadratic] [--cases N] [--seed S] [--dds K]
        [--without configuration|friction|limits] [--fraction F] [--duration T]
        [--sim-coulomb-scale S | --sim-coulomb-effort-fraction X] [--estimate-of-sim K]

The plant is never the model: ``--sim-coulomb-scale`` multiplies the simulator's Coulomb
friction of ``config/*_sim.yaml`` (the controller's estimate unchanged),
``--sim-coulomb-effort-fraction`` sets it to a fraction of each URDF effort limit, and
``--estimate-of-sim`` sets the controller's estimate to that multiple of the simulated
friction. The sign changes of each joint's control torque without gravity, ``tau - g(q)``, are
counted over the case's last second: more than one on a joint and the case ends in a limit
cycle.

``--dds K`` also runs the first K cases of each robot over DDS with the real nodes
(``local_ros``, lockstep paced at real time, so that the goal-check worker answers in the same
time as on a robot; the goal 2 s after the start): the verdict from the last joint state after
the case's duration.
"""
import argparse
import dataclasses
from dataclasses import dataclass
import math
import os
from pathlib import Path
import shutil
import sys
import tempfile
import time
from typing import Optional

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.controller_config import controller_from_package_config
from quat_jt_controller.goal_check import goal_configuration
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_controller.regulator import Regulator
from quat_jt_controller.stall import StallDetector
from quat_jt_runtime.resources import config_parameters, default_urdf_xml
import yaml

TOUCH_RAD = 1e-3  # closer than this to a URDF limit: the stop was touched
LIMIT_CYCLE_FLIPS_PER_S = 1.0  # more sign changes of tau - g(q) in the last second: a cycle
FLIP_FLOOR = 1e-3  # of the effort limit: smaller torques have no sign (numerical dither)
FINAL_WINDOW_S = 0.1
Q_STAR_AFTER_S = 0.1  # the goal-check worker's answer arrives after the goal (10-50 ms)
DDS_GOAL_AFTER_S = 2.0  # over DDS, the goal is sent this long after the start (simulated time)


@dataclass(frozen=True)
class Robot:
    """One robot of the experiment: its files, its case generator and its targets."""

    name: str
    controller_config: str
    sim_config: str
    task: cl.Task
    fraction: float  # of the half range around the middle, for starts and goals
    duration_s: float
    orientation_tol: float
    position_tol_m: float
    # held on after duration_s (reached is judged at duration_s): the drift, the distance to q*
    # and the limit cycles are measured over the last second of the hold
    hold_s: float = 0.0
    goal_sigma_min: float = 0.1  # pose task: the goal's sigma_min(J_G) at least this


ROBOTS = {
    'wrist': Robot('wrist', 'wrist_controller.yaml', 'wrist_sim.yaml',
                   cl.Task.ORIENTATION, 0.9, 4.0, 0.005, math.inf),
    'xarm6': Robot('xarm6', 'xarm6_controller.yaml', 'xarm6_sim.yaml',
                   cl.Task.POSE, 0.8, 5.0, 0.01, 1e-3),
    'panda': Robot('panda', 'panda_controller.yaml', 'panda_sim.yaml',
                   cl.Task.POSE, 0.8, 5.0, 0.01, 1e-3, hold_s=2.0, goal_sigma_min=0.05),
}


def robot_urdf(robot: Robot) -> str:
    """Return the URDF XML of ``robot`` (the xArm6's ships inside pybullet_data)."""
    if robot.name == 'wrist':
        return default_urdf_xml()
    import pybullet_data
    if robot.name == 'panda':
        return (Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf').read_text()
    return (Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf').read_text()


def load_controller(robot: Robot, potential: Optional[str] = None,
                    overrides: Optional[dict] = None):
    """Return ``(model, gains, shaping)`` of the robot's controller config (+ ``overrides``)."""
    regulator = controller_from_package_config(robot.controller_config, robot_urdf(robot),
                                               potential, overrides)
    return regulator.model, regulator.gains, regulator.shaping


def cases(model: RobotModel, robot: Robot, count: int, seed: int) -> list:
    """Return ``count`` seeded (start, goal) joint configurations, as the targets define them."""
    rng = np.random.default_rng(seed)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    lo, hi = mid - robot.fraction * half, mid + robot.fraction * half
    out = []
    while len(out) < count:
        q0, qg = rng.uniform(lo, hi), rng.uniform(lo, hi)
        if robot.task is cl.Task.ORIENTATION and abs(qg[1]) < 0.3:
            continue
        if robot.task is cl.Task.POSE:
            _, _, J = model.kinematics(qg.tolist())
            if np.linalg.svd(np.array(J), compute_uv=False)[-1] < robot.goal_sigma_min:
                continue
        out.append((q0, qg))
    return out


def quiet():
    """Silence PyBullet's C-level prints (connection banner, inertia warnings)."""
    from wrist_sim.quiet import c_output_silenced
    return c_output_silenced((1, 2))


@dataclass
class Outcome:
    """One case: reached?, the final errors, and what went wrong if anything."""

    index: int
    reached: bool
    touched: bool
    position_error_m: float
    orientation_error: float
    settled_s: float
    max_speed_rad_s: float
    saturated_ticks: int
    flips_per_s: float  # the most sign changes of tau_j - g_j(q) in the last second
    q_start: np.ndarray
    q_goal: np.ndarray
    q_final: np.ndarray
    final_speed_rad_s: float = math.nan  # the fastest joint over the run's last second
    from_q_star_rad: float = math.nan  # max_j |q_j - q*_j| at the end (nan: no q*)
    cause: str = ''


def run_case(robot: Robot, model: RobotModel, gains: cl.Gains, shaping: sh.Shaping,
             sim_params: dict, index: int, q0: np.ndarray, qg: np.ndarray,
             delay_ticks: int = 1, q_star_after_s: float = Q_STAR_AFTER_S) -> Outcome:
    """Run one case on the PyBullet core; classify it."""
    from wrist_sim.simulator import WristSimulator

    p_d, R_d = model.forward_kinematics(qg.tolist())
    q_d = quat.from_rotation_matrix(R_d)
    q_star = (goal_configuration(model, q0, q_d, p_d, robot.task,
                                 shaping.joint_limit_margin_rad,
                                 q_preferred=shaping.preferred_configuration_rad or None,
                                 posture_weight=shaping.posture_weight)
              if shaping.configuration_on else None)
    loop = ClosedLoop(model, gains, robot.task, q_d, p_d, shaping=shaping)
    with quiet():
        sim = WristSimulator(robot_urdf(robot), model.joint_names, initial_positions_rad=q0,
                             viscous_nm_s_per_rad=sim_params.get('viscous_friction'),
                             coulomb_nm=sim_params.get('coulomb_friction'),
                             enforce_velocity_limits=sim_params.get('enforce_velocity_limits',
                                                                    True))
    try:
        held = run_sampled(loop, sim, robot.duration_s + robot.hold_s, delay_ticks, q_star,
                           q_star_after_s)
    finally:
        sim.close()
    run = held.until(robot.duration_s)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    gap = float(np.minimum(held.q_rad - lower, upper - held.q_rad).min())
    position, orientation = run.final(FINAL_WINDOW_S)
    reached = (run.all_finite and orientation < robot.orientation_tol
               and position < robot.position_tol_m)
    dt_s = run.t_s[1] - run.t_s[0]
    speed = float(np.abs(np.diff(held.q_rad, axis=0)).max() / dt_s)
    settle_tol = (robot.position_tol_m if math.isfinite(robot.position_tol_m) else math.inf)
    settled_s = run.settled_at_s(settle_tol, robot.orientation_tol)
    last = held.q_rad[int(np.searchsorted(held.t_s, held.t_s[-1] - 1.0)):]
    outcome = Outcome(index, reached, gap < TOUCH_RAD, position, orientation, settled_s, speed,
                      held.saturated_ticks, torque_flips_per_s(model, held),
                      q0, qg, held.q_rad[-1].copy(),
                      final_speed_rad_s=float(np.abs(np.diff(last, axis=0)).max() / dt_s),
                      from_q_star_rad=(math.nan if q_star is None else
                                       float(np.abs(held.q_rad[-1] - q_star).max())))
    if not reached:
        outcome.cause = classify(model, loop, shaping, q_star, run)
    if outcome.flips_per_s > LIMIT_CYCLE_FLIPS_PER_S:
        outcome.cause = '; '.join(c for c in (outcome.cause, (
            f'LIMIT CYCLE: {outcome.flips_per_s:.0f} torque sign changes in the last second'))
            if c)
    return outcome


def torque_flips_per_s(model: RobotModel, run) -> float:
    """
    Return the most sign changes of a joint's ``tau - g(q)`` in the case's last second.

    More than ``LIMIT_CYCLE_FLIPS_PER_S`` there: the case ends in a limit cycle. Torques below
    ``FLIP_FLOOR`` of the effort limit carry no sign (numerical dither at rest).
    """
    k0 = int(np.searchsorted(run.t_s, float(run.t_s[-1]) - 1.0))
    q, tau = run.q_rad[k0:], run.tau_nm[k0:]
    g = np.array([model.gravity(qi.tolist()) for qi in q])
    floor = FLIP_FLOOR * np.array([v if math.isfinite(v) else 1.0 for v in model.effort_limits])
    most = 0
    for j in range(model.n):
        signs = np.sign(tau[:, j] - g[:, j])
        signs = signs[np.abs(tau[:, j] - g[:, j]) > floor[j]]
        most = max(most, int(np.count_nonzero(np.diff(signs))))
    return float(most)


def classify(model: RobotModel, loop: ClosedLoop, shaping: sh.Shaping, q_star,
             run) -> str:
    """Name the likely cause of a failed case, as the stall detector would."""
    causes = []
    if shaping.configuration_on and q_star is None:
        causes.append('no goal configuration found (IK)')
    speed = np.abs(np.diff(run.q_rad[-100:], axis=0)).max() / (run.t_s[1] - run.t_s[0])
    if speed > 0.02:
        causes.append(f'still moving at the end (up to {speed:.3f} rad/s): too slow')
    else:
        reg = Regulator(model, loop.task, loop.gains, None, loop.goal, shaping)
        out = reg.update(run.q_rad[-1].tolist(), [0.0] * model.n)
        found = StallDetector(reg).diagnose(run.q_rad[-1].tolist(), out)
        causes += ['stalled: ' + c for c in found]
    return '; '.join(causes)


def report(robot: Robot, potential: str, outcomes: list, elapsed_s: float) -> str:
    """Return the summary lines of one robot and potential."""
    n = len(outcomes)
    ok = sum(o.reached for o in outcomes)
    touched = sum(o.touched for o in outcomes)
    settled = np.array([o.settled_s for o in outcomes if o.reached])
    pos = np.array([o.position_error_m for o in outcomes])
    ori = np.array([o.orientation_error for o in outcomes])
    target = (f'||e|| < {robot.orientation_tol:g}' if robot.task is cl.Task.ORIENTATION
              else f'< {robot.position_tol_m * 1e3:g} mm and ||e|| < {robot.orientation_tol:g}')
    lines = [
        f'{robot.name}, {potential}: {ok}/{n} reached ({100.0 * ok / max(n, 1):.1f}%) '
        f'{target} within {robot.duration_s:g} s; stops touched in {touched} cases; '
        f'{sum(o.saturated_ticks > 0 for o in outcomes)} cases with saturated ticks',
    ]
    if settled.size:
        lines.append(f'  time to stay within tolerance: median {np.median(settled):.2f} s, '
                     f'90% {np.percentile(settled, 90):.2f} s, max {settled.max():.2f} s; '
                     f'fastest joint speed up to '
                     f'{max(o.max_speed_rad_s for o in outcomes):.2f} rad/s')
    flips = np.array([o.flips_per_s for o in outcomes])
    cycles = int(np.count_nonzero(flips > LIMIT_CYCLE_FLIPS_PER_S))
    lines.append(f'  torque sign changes in the last second (tau - g, worst joint): median '
                 f'{np.median(flips):.2f}, max {flips.max():.2f}; limit cycles (> '
                 f'{LIMIT_CYCLE_FLIPS_PER_S:g}) in {cycles} cases')
    if robot.hold_s > 0.0 and ok:  # after settling: the cases reached
        drift = np.array([o.final_speed_rad_s for o in outcomes if o.reached])
        away = np.array([o.from_q_star_rad for o in outcomes if o.reached])
        lines.append(f'  the {ok} reached, held {robot.hold_s:g} s more: fastest joint over the '
                     f'last second median {np.median(drift):.1e}, max {drift.max():.1e} rad/s; '
                     f'at the end, max_j |q_j - q*_j| median {np.nanmedian(away):.1e}, max '
                     f'{np.nanmax(away):.1e} rad (no q* in '
                     f'{int(np.count_nonzero(np.isnan(away)))})')
    lines.append(f'  final ||e||: median {np.median(ori):.2e}, max {ori.max():.2e}'
                 + (f'; final ||p_d - p||: median {np.median(pos) * 1e3:.3f} mm, max '
                    f'{pos.max() * 1e3:.3f} mm' if robot.task is cl.Task.POSE else '')
                 + f' ({elapsed_s:.0f} s)')
    for o in outcomes:
        if not o.reached or o.touched or o.flips_per_s > LIMIT_CYCLE_FLIPS_PER_S:
            lines.append(
                f'  case {o.index}: start {np.round(o.q_start, 2).tolist()} goal '
                f'{np.round(o.q_goal, 2).tolist()} end {np.round(o.q_final, 2).tolist()}: '
                f'||e|| {o.orientation_error:.3g}'
                + (f', {o.position_error_m * 1e3:.2f} mm' if robot.task is cl.Task.POSE
                   else '')
                + (', TOUCHED A STOP' if o.touched else '')
                + (f'; {o.cause}' if o.cause else ''))
    return '\n'.join(lines)


ABLATIONS = {  # --without: turn one extension off to see what it does
    'configuration': {'configuration_gain': ()},
    'friction': {'friction_compensation_nm': ()},
    'limits': {'joint_limit_gain': ()},
}


@dataclass(frozen=True)
class Plant:
    """How the simulated plant and the controller's friction estimate differ from the configs."""

    coulomb_scale: float = 1.0  # x the simulator config's Coulomb friction
    coulomb_effort_fraction: Optional[float] = None  # or this fraction of each effort limit
    estimate_of_sim: Optional[float] = None  # the estimate = this x the simulated friction

    def describe(self) -> str:
        """Return the plant's difference from the configs, for the report ('' if none)."""
        parts = []
        if self.coulomb_effort_fraction is not None:
            parts.append(f'simulated Coulomb friction {self.coulomb_effort_fraction:g} x the '
                         'effort limits')
        elif self.coulomb_scale != 1.0:
            parts.append(f'simulated Coulomb friction {self.coulomb_scale:g} x the configured one')
        if self.estimate_of_sim is not None:
            parts.append(f'estimate {self.estimate_of_sim:g} x the simulated friction')
        return ', '.join(parts)

    def apply(self, model: RobotModel, sim_params: dict, shaping: sh.Shaping):
        """Return ``(sim_params, shaping)`` for this plant."""
        coulomb = [self.coulomb_scale * f for f in sim_params['coulomb_friction']]
        if self.coulomb_effort_fraction is not None:
            coulomb = [self.coulomb_effort_fraction * e for e in model.effort_limits]
        sim_params = dict(sim_params, coulomb_friction=coulomb)
        if self.estimate_of_sim is not None:  # the learnable part keeps its ratio to it
            estimate = [self.estimate_of_sim * f for f in coulomb]
            old = shaping.friction_compensation_nm or (0.0,) * model.n
            ratio = [a / f if f > 0.0 else 0.0 for a, f in
                     zip(shaping.friction_learning_limit_nm or (0.0,) * model.n, old)]
            shaping = dataclasses.replace(
                shaping, friction_compensation_nm=tuple(estimate),
                friction_learning_limit_nm=tuple(r * e for r, e in zip(ratio, estimate)))
        return sim_params, shaping


def run_robot(robot: Robot, potential: str, count: int, seed: int, delay_ticks: int = 1,
              progress=print, without: Optional[str] = None,
              plant: Plant = Plant(), overrides: Optional[dict] = None) -> list:
    """Run ``count`` cases of ``robot`` with ``potential``; return their outcomes."""
    model, gains, shaping = load_controller(robot, potential, overrides)
    if without:
        shaping = dataclasses.replace(shaping, **ABLATIONS[without])
    sim_params, shaping = plant.apply(model, config_parameters(robot.sim_config), shaping)
    outcomes = []
    for i, (q0, qg) in enumerate(cases(model, robot, count, seed)):
        outcomes.append(run_case(robot, model, gains, shaping, sim_params, i, q0, qg,
                                 delay_ticks))
        if progress and (i + 1) % 25 == 0:
            done = sum(o.reached for o in outcomes)
            progress(f'  [{robot.name} {potential}] {i + 1}/{count} cases, {done} reached',
                     flush=True)
    return outcomes


def run_dds(robot: Robot, count: int, seed: int, progress=print) -> str:
    """Run the first ``count`` cases of ``robot`` over DDS (real nodes, lockstep); a report."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    from experiments import local_ros
    from experiments.probe import ProbeNode

    model, _, shaping = load_controller(robot)
    urdf = {} if robot.name == 'wrist' else {'robot_description': robot_urdf(robot)}
    lines = []
    for i, (q0, qg) in enumerate(cases(model, robot, count, seed)):
        p_d, R_d = model.forward_kinematics(qg.tolist())
        q_d = quat.from_rotation_matrix(R_d)
        work = Path(tempfile.mkdtemp(prefix='reach_dds_'))
        domain = 50 + (os.getpid() + i) % 40
        env = local_ros.isolated_env(work, domain)
        sim, ctrl = local_ros.spawn_wrist_pair(
            env, work, sim_params={'initial_positions': q0.tolist(), 'publish_clock': True,
                                   'max_real_time_factor': 1.0, **urdf},
            controller_params={'use_sim_time': True, **urdf},
            controller_config=f'config/{robot.controller_config}',
            sim_config=f'config/{robot.sim_config}')
        probe = ProbeNode('reach_probe', domain)
        states: list = []
        probe.node.create_subscription(JointState, '/joint_states', states.append, 100)
        pub = probe.node.create_publisher(PoseStamped, '/quat_jt_controller/target_pose', 10)

        def spin_until(condition, timeout_s: float) -> bool:
            deadline = time.monotonic() + timeout_s
            while not condition():
                if time.monotonic() > deadline or sim.poll() is not None or \
                        ctrl.poll() is not None:
                    return False
                probe.executor.spin_once(timeout_sec=0.05)
            return True

        def stamp_s() -> float:
            s = states[-1].header.stamp
            return s.sec + 1e-9 * s.nanosec
        try:
            # as a user would: the goal some time after the start, the goal-check worker up
            ok = spin_until(lambda: len(states) > 50 and stamp_s() >= DDS_GOAL_AFTER_S, 60.0)
            msg = PoseStamped()
            msg.header.frame_id = model.base_link
            o, p = msg.pose.orientation, msg.pose.position
            o.x, o.y, o.z, o.w = quat.to_xyzw(q_d)
            if robot.task is cl.Task.POSE:
                p.x, p.y, p.z = (float(v) for v in p_d)
            t0 = stamp_s()
            pub.publish(msg)
            ok = ok and spin_until(lambda: stamp_s() - t0 >= robot.duration_s, 240.0)
            q_end = [states[-1].position[states[-1].name.index(n)] for n in model.joint_names]
            p_end, R_end = model.forward_kinematics(q_end)
            _, e = quat.orientation_error(quat.from_rotation_matrix(R_end), q_d)
            err = math.sqrt(sum(c * c for c in e))
            position = math.dist(p_end, p_d) if robot.task is cl.Task.POSE else 0.0
            verdict = ('reached' if ok and err < robot.orientation_tol
                       and position < robot.position_tol_m else 'NOT reached')
            if verdict == 'reached':
                shutil.rmtree(work, ignore_errors=True)  # else keep the nodes' logs
            lines.append(f'  DDS case {i}: after {robot.duration_s:g} s (simulated) ||e|| = '
                         f'{err:.3g}'
                         + (f', ||p_d - p|| = {position * 1e3:.3f} mm'
                            if robot.task is cl.Task.POSE else '')
                         + f' -> {verdict}' + ('' if verdict == 'reached'
                                               else f' (logs in {work})'))
            progress(lines[-1], flush=True)
        finally:
            for proc in (sim, ctrl):
                local_ros.stop_node(proc)
            probe.close()
    return '\n'.join(lines)


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--robot', nargs='+', choices=list(ROBOTS), default=list(ROBOTS))
    parser.add_argument('--potential', nargs='+', choices=[p.value for p in cl.Potential],
                        default=['tanh', 'quadratic'])
    parser.add_argument('--cases', type=int, help='cases per robot and potential (default: '
                        '200 wrist, 100 xArm6)')
    parser.add_argument('--seed', type=int, default=10)
    parser.add_argument('--delay', type=int, default=1, help='ticks of delay')
    parser.add_argument('--dds', type=int, default=0,
                        help='also run the first this many cases of each robot over DDS (real '
                        'nodes, lockstep)')
    parser.add_argument('--without', choices=list(ABLATIONS),
                        help='turn this extension off (to see what it does)')
    parser.add_argument('--fraction', type=float,
                        help='draw starts and goals within this fraction of the half ranges '
                        '(default: 0.9 wrist, 0.8 xArm6)')
    parser.add_argument('--duration', type=float,
                        help='seconds per case (default: 4 wrist, 5 xArm6)')
    friction = parser.add_mutually_exclusive_group()
    friction.add_argument('--sim-coulomb-scale', type=float, default=1.0,
                          help="multiply the simulator config's Coulomb friction by this (the "
                          "controller's estimate unchanged)")
    friction.add_argument('--sim-coulomb-effort-fraction', type=float,
                          help='simulate a Coulomb friction of this fraction of each URDF '
                          'effort limit')
    parser.add_argument('--estimate-of-sim', type=float,
                        help="set the controller's friction estimate to this multiple of the "
                        'simulated Coulomb friction')
    parser.add_argument('--param', action='append', default=[], metavar='NAME:=VALUE',
                        help='override a controller parameter of the config, ros2-style '
                        "(VALUE in YAML, e.g. 'configuration_gain:=[0, 0, 0]')")
    args = parser.parse_args(argv)
    overrides = {}
    for item in args.param:
        name, sep, value = item.partition(':=')
        if not sep:
            parser.error(f'--param takes NAME:=VALUE, got {item!r}')
        overrides[name.strip()] = yaml.safe_load(value)
    plant = Plant(args.sim_coulomb_scale, args.sim_coulomb_effort_fraction,
                  args.estimate_of_sim)
    default_cases = {'wrist': 200, 'xarm6': 100, 'panda': 100}
    text = []
    for name in args.robot:
        robot = ROBOTS[name]
        if args.fraction is not None:
            robot = dataclasses.replace(robot, fraction=args.fraction)
        if args.duration is not None:
            robot = dataclasses.replace(robot, duration_s=args.duration)
        for potential in args.potential:
            t0 = time.monotonic()
            outcomes = run_robot(robot, potential, args.cases or default_cases[name],
                                 args.seed, args.delay, without=args.without, plant=plant,
                                 overrides=overrides)
            label = ', '.join(x for x in (
                potential, f'without {args.without}' if args.without else '',
                f'within {robot.fraction:g} of the ranges', plant.describe(),
                ', '.join(f'{k} {v}' for k, v in overrides.items())) if x)
            text.append(report(robot, label, outcomes, time.monotonic() - t0))
            print(text[-1], flush=True)
    for name in args.robot if args.dds else ():
        robot = ROBOTS[name]
        text.append(f'{name} over DDS (nodes in lockstep, tanh, config/'
                    f'{robot.controller_config}):\n' + run_dds(robot, args.dds, args.seed))
    print('\n' + '\n'.join(text))
    return 0


if __name__ == '__main__':
    sys.exit(main())

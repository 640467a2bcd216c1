"""
How long a design again takes (``gain_redesign``), and what the loop that asks for it feels.

For each product config, the node's ``DesignWorker`` (started before the loop, as the node
starts it) is asked to design the gains again with 0.1 kg m^2 more armature per joint while
this process runs a 1 kHz loop of sleeps, as the node's executor waits for states: at
SCHED_FIFO 50 where permitted (the node's default), else with normal scheduling. Printed: the
time ``submit`` takes on the loop's thread, the time to the answer (asked once the worker has
imported what a design needs, as it does while the node starts), and how late the loop's
wake-ups are, worst, over the design and over as long without one.

With an arm from its URDF (the arguments of ``experiments.reach_experiment``: ``--urdf`` or
``--example-robot``, ``--base-link``, ``--tip-link``, ...), that arm instead, its parameters
``design_gains``' on the URDF alone, asked for the armature a design again takes for 0.1 kg m^2
found per joint (``DESIGN_SHARE`` of it): the latency ``reach_experiment``'s
``REDESIGN_AFTER_S`` stands for. Every arm of the campaign:

    python -m experiments.redesign_time [--rounds 3]
    MODULE=experiments.redesign_time bash experiments/reach_campaign.sh OUT [--rounds 3]
"""
import argparse
import os
from pathlib import Path
import statistics
import sys
import time
from typing import Optional

from experiments import arms
from experiments import reach_experiment as rx
from quat_jt_controller import control_law as cl
from quat_jt_controller.redesign import DESIGN_SHARE, DesignWorker
from quat_jt_runtime.resources import config_parameters

PERIOD_S = 1e-3
FOUND_KG_M2 = 0.1  # an arm's design again: for this rotor inertia found per joint


def loop(seconds: float, each_tick=None) -> float:
    """Run a 1 kHz loop of sleeps for ``seconds``; return its worst lateness (s)."""
    worst = 0.0
    next_s = time.perf_counter()
    end_s = next_s + seconds
    while next_s < end_s:
        next_s += PERIOD_S
        wait_s = next_s - time.perf_counter()
        if wait_s > 0.0:
            time.sleep(wait_s)
        worst = max(worst, time.perf_counter() - next_s)
        if each_tick is not None and each_tick():
            break
    return worst


def loop_scheduling() -> str:
    """Put this process at SCHED_FIFO 50, the node's default, if permitted; say which."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
        return 'SCHED_FIFO 50'
    except (AttributeError, OSError):
        return 'normal scheduling (SCHED_FIFO not permitted)'


def time_design(urdf_xml: str, values: dict, armature: list, rounds: int) -> dict:
    """Return per round: submit (s), the time to the answer (s), the worst lateness (s)."""
    out = {'submit': [], 'answer': [], 'late': [], 'late_idle': []}
    worker = DesignWorker(urdf_xml)
    try:
        deadline = time.monotonic() + 60.0  # started with the node, it is ready long before
        while not worker.ready and time.monotonic() < deadline:  # its first design
            time.sleep(0.01)
        for _ in range(rounds):
            t0 = time.perf_counter()
            worker.submit(values, armature)
            out['submit'].append(time.perf_counter() - t0)
            answers = []

            def answered() -> bool:
                answers.append(worker.poll())
                return answers[-1] is not None
            out['late'].append(loop(60.0, answered))
            out['answer'].append(time.perf_counter() - t0)
            if 'error' in answers[-1]:
                raise RuntimeError(answers[-1]['error'])
            out['late_idle'].append(loop(out['answer'][-1]))
    finally:
        worker.close()
    return out


def product_cases() -> list:
    """Return (row label, URDF, parameters, armature) for each product config."""
    out = []
    for name in ('wrist', 'xarm6', 'panda'):
        robot = rx.ROBOTS[name]
        values = config_parameters(robot.controller_config)
        armature = [a + 0.1 for a in values.get('armature') or [0.0] * len(values['joints'])]
        out.append((robot.controller_config, rx.robot_urdf(robot), values, armature))
    return out


def arm_case(args) -> tuple:
    """Return (row label, URDF, parameters, armature) for the arm the arguments name."""
    path = args.urdf or arms.example_robot_urdf(args.example_robot)
    robot = rx.arm_robot(args.name or args.example_robot or Path(path).stem, str(path),
                         args.base_link, args.tip_link, cl.Task(args.task))
    model, design = rx.arm_design(robot, 0.0, 1000.0)
    values = {**design.structure(), **design.parameters(args.potential)}
    return (robot.name, rx.robot_urdf(robot), values, [DESIGN_SHARE * FOUND_KG_M2] * model.n)


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rounds', type=int, default=3, help='designs per config')
    arm = parser.add_argument_group('an arm from its URDF (as experiments.reach_experiment)')
    arm.add_argument('--urdf', help='the URDF file')
    arm.add_argument('--example-robot', help='a URDF of example-robot-data, by name')
    arm.add_argument('--name', help="the row label (default: the robot's name)")
    arm.add_argument('--base-link', help="default: the URDF's root link")
    arm.add_argument('--tip-link', help='default: the end of the longest chain')
    arm.add_argument('--task', default='pose', choices=[t.value for t in cl.Task])
    arm.add_argument('--potential', default='tanh', choices=[p.value for p in cl.Potential])
    args = parser.parse_args(argv)
    try:
        cases = [arm_case(args)] if args.urdf or args.example_robot else product_cases()
    except (ValueError, OSError) as exc:
        parser.error(str(exc))
    print(f'the loop at {loop_scheduling()}; {args.rounds} designs per config, median / worst')
    print(f'| {"arm" if args.urdf or args.example_robot else "config"} | submit on the loop, '
          'ms | to the answer, s | loop late during it, ms | loop late without, ms |')
    print('|---|---|---|---|---|')
    for label, urdf_xml, values, armature in cases:
        try:
            t = time_design(urdf_xml, values, armature, args.rounds)
        except RuntimeError as exc:
            print(f'{label}: the design failed: {exc}', file=sys.stderr)
            return 1
        cells = [f'{statistics.median(v) * k:.2f} / {max(v) * k:.2f}' for v, k in (
            (t['submit'], 1e3), (t['answer'], 1.0), (t['late'], 1e3), (t['late_idle'], 1e3))]
        print(f'| {label} | ' + ' | '.join(cells) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())

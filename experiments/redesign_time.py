"""
How long a design again takes (``gain_redesign``), and what the loop that asks for it feels.

For each product config, the node's ``DesignWorker`` (started before the loop, as the node
starts it) is asked to design the gains again with 0.1 kg m^2 more armature per joint while
this process runs a 1 kHz loop of sleeps, as the node's executor waits for states: at
SCHED_FIFO 50 where permitted (the node's default), else with normal scheduling. Printed: the
time ``submit`` takes on the loop's thread, the time to the answer (the worker's first design
imports Pinocchio), and how late the loop's wake-ups are, worst, over the design and over as
long without one.

    python -m experiments.redesign_time [--rounds 3]
"""
import argparse
import os
import statistics
import sys
import time
from typing import Optional

from experiments import reach_experiment as rx
from quat_jt_controller.redesign import DesignWorker
from quat_jt_runtime.resources import config_parameters

PERIOD_S = 1e-3


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


def time_design(robot: rx.Robot, rounds: int) -> dict:
    """Return per round: submit (s), the time to the answer (s), the worst lateness (s)."""
    values = config_parameters(robot.controller_config)
    armature = [a + 0.1 for a in values.get('armature') or [0.0] * len(values['joints'])]
    out = {'submit': [], 'answer': [], 'late': [], 'late_idle': []}
    worker = DesignWorker(rx.robot_urdf(robot))
    try:
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
                raise RuntimeError(f'{robot.name}: {answers[-1]["error"]}')
            out['late_idle'].append(loop(out['answer'][-1]))
    finally:
        worker.close()
    return out


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rounds', type=int, default=3, help='designs per config')
    args = parser.parse_args(argv)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
        scheduling = 'SCHED_FIFO 50'
    except (AttributeError, OSError):
        scheduling = 'normal scheduling (SCHED_FIFO not permitted)'
    print(f'the loop at {scheduling}; {args.rounds} designs per config, median / worst')
    print('| config | submit on the loop, ms | to the answer, s | loop late during it, ms '
          '| loop late without, ms |')
    print('|---|---|---|---|---|')
    for name in ('wrist', 'xarm6', 'panda'):
        robot = rx.ROBOTS[name]
        t = time_design(robot, args.rounds)
        cells = [f'{statistics.median(v) * k:.2f} / {max(v) * k:.2f}' for v, k in (
            (t['submit'], 1e3), (t['answer'], 1.0), (t['late'], 1e3), (t['late_idle'], 1e3))]
        print(f'| {robot.controller_config} | ' + ' | '.join(cells) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())

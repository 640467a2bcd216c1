"""
Every URDF of example-robot-data, as it comes: each tool takes it, or says why not.

For each URDF file under example-robot-data's ``robots`` directory (``pip install
example-robot-data``): ``design_gains --urdf FILE --task pose`` with every other argument
left to its default, run as a user runs it (a subprocess; its exit status and the last line
of its stderr), and the simulator built on it with each engine, all movable joints driven,
stepped 10 times with zero torque. Each outcome is one of: taken; refused, with the one-line
reason the tool gives (a URDF that is not an arm, a joint without an effort limit, ...);
crashed (a traceback, or an exception that is not the tool's own error: a fault of ours).

    python -m experiments.urdf_sweep [--only SUBSTRING] [--timeout S]

docs/reach.md ("Every URDF of example-robot-data") has the table it printed.
"""
import argparse
from pathlib import Path
import subprocess
import sys

from experiments.arms import example_robot_roots
import numpy as np
from wrist_sim.engine import SimulatorError
from wrist_sim.quiet import c_output_silenced
from wrist_sim.simulator import ENGINES, RobotSimulator

REASON_CHARS = 110  # of a refusal's message, in the table


def design_outcome(urdf: Path, timeout_s: float) -> tuple[str, str]:
    """Return ('taken' | 'refused' | 'crashed', what it said) for design_gains on ``urdf``."""
    try:
        run = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design', '--urdf',
                              str(urdf), '--task', 'pose', '--out', '/dev/null'],
                             capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return 'crashed', f'no answer within {timeout_s:g} s'
    lines = [ln for ln in run.stderr.splitlines() if ln.strip()]
    if 'Traceback' in run.stderr:
        return 'crashed', lines[-1] if lines else 'a traceback'
    if run.returncode == 0:
        return 'taken', ''
    return 'refused', lines[-1].replace('design_gains: error: ', '') if lines else '?'


def simulator_outcome(urdf: Path, engine: str) -> tuple[str, str]:
    """Return ('taken' | 'refused' | 'crashed', what it said) for the simulator on ``urdf``."""
    try:
        with c_output_silenced((1, 2)):  # PyBullet and MuJoCo print as they load
            with RobotSimulator(urdf.read_text(), None, engine=engine,
                                search_dirs=[urdf.parent]) as sim:
                for _ in range(10):
                    sim.step(np.zeros(sim.n))
                if not np.all(np.isfinite(sim.q_rad)):
                    return 'crashed', 'positions not finite after 10 steps'
        return 'taken', ''
    except SimulatorError as exc:
        return 'refused', str(exc).splitlines()[0]
    except Exception as exc:  # noqa: B902 - anything else is a fault to report
        return 'crashed', f'{type(exc).__name__}: {exc}'


def cell(outcome: tuple[str, str]) -> str:
    """One table cell: the outcome, and for a refusal or a crash, what was said (shortened)."""
    kind, text = outcome
    text = text.replace('|', '/')
    if len(text) > REASON_CHARS:
        text = text[:REASON_CHARS - 3] + '...'
    return kind if not text else f'{kind}: {text}'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', default='', help='only the URDFs whose path contains this')
    parser.add_argument('--timeout', type=float, default=120.0,
                        help='s for design_gains on one URDF (default 120)')
    args = parser.parse_args(argv)
    roots = example_robot_roots()
    if not roots:
        parser.error('example-robot-data is not installed: pip install example-robot-data')
    urdfs = sorted(p for p in roots[0].rglob('*.urdf') if args.only in str(p))
    print(f'| URDF | design_gains --task pose | {" | ".join(ENGINES)} |')
    print('|---|---|' + '---|' * len(ENGINES))
    counts: dict[str, dict[str, int]] = {}
    for urdf in urdfs:
        outcomes = [('design_gains', design_outcome(urdf, args.timeout))]
        outcomes += [(engine, simulator_outcome(urdf, engine)) for engine in ENGINES]
        for tool, (kind, _) in outcomes:
            counts.setdefault(tool, {}).setdefault(kind, 0)
            counts[tool][kind] += 1
        print(f'| {urdf.relative_to(roots[0])} | '
              + ' | '.join(cell(o) for _, o in outcomes) + ' |', flush=True)
    print(f'\n{len(urdfs)} URDFs.')
    for tool, kinds in counts.items():
        print(f'{tool}: ' + ', '.join(f'{n} {kind}' for kind, n in sorted(kinds.items())))
    crashed = sum(kinds.get('crashed', 0) for kinds in counts.values())
    return 1 if crashed else 0


if __name__ == '__main__':
    sys.exit(main())

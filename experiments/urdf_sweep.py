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

docs/reach.md ("Every URDF of example-robot-data") has the table it printed. With
``--mutate FILE`` it runs ``design_gains`` on faulty copies of one URDF instead (``MUTATIONS``:
what a CAD export, a typo or a xacro not expanded leaves in a URDF), and prints what it said
of each: its refusal, or the warnings it wrote.
"""
import argparse
from pathlib import Path
import re
import subprocess
import sys
import tempfile
from typing import Callable, Optional

from experiments.arms import example_robot_roots
import numpy as np
from quat_jt_runtime.joints import default_links
from wrist_sim.engine import SimulatorError
from wrist_sim.quiet import c_output_silenced
from wrist_sim.simulator import ENGINES, RobotSimulator

REASON_CHARS = 110  # of a refusal's message, in the table


def design_outcome(urdf: Path, timeout_s: float,
                   warnings: Optional[list] = None) -> tuple[str, str]:
    """
    Return ('taken' | 'refused' | 'crashed', what it said) for design_gains on ``urdf``.

    ``warnings``, if given, receives the lines of its WARNINGs.
    """
    try:
        run = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design', '--urdf',
                              str(urdf), '--task', 'pose', '--out', '/dev/null'],
                             capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return 'crashed', f'no answer within {timeout_s:g} s'
    lines = [ln for ln in run.stderr.splitlines() if ln.strip()]
    if warnings is not None:
        warnings.extend(ln for ln in lines if 'WARNING: ' in ln)
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


def _on_link(link: str, pattern: str, repl: str) -> Callable[[str], str]:
    """Return a mutation: ``pattern`` replaced once inside ``<link name="link">``."""
    def mutate(xml: str) -> str:
        start = xml.index(f'<link name="{link}"')
        end = xml.index('</link>', start)
        return xml[:start] + re.sub(pattern, repl, xml[start:end], count=1) + xml[end:]
    return mutate


def mutations(urdf_xml: str) -> dict[str, Callable[[str], str]]:
    """Return the faults of ``--mutate`` by name; a link's are the default chain's tip's."""
    tip = default_links(urdf_xml)[1]
    return {
        'no velocity in any <limit>': lambda x: re.sub(r'\s+velocity="[^"]*"', '', x),
        'no effort in any <limit>': lambda x: re.sub(r'\s+effort="[^"]*"', '', x),
        'no <limit> at all': lambda x: re.sub(r'<limit\b[^>]*/>', '', x),
        'velocity="0" everywhere': lambda x: re.sub(r'velocity="[^"]*"', 'velocity="0"', x),
        'a ${...} a xacro left': lambda x: re.sub(r'velocity="[^"]*"', 'velocity="${v}"', x,
                                                  count=1),
        f'mass nan on {tip}': _on_link(tip, r'<mass value="[^"]*"', '<mass value="nan"'),
        f'mass -1 on {tip}': _on_link(tip, r'<mass value="[^"]*"', '<mass value="-1"'),
        f'mass abc on {tip}': _on_link(tip, r'<mass value="[^"]*"', '<mass value="abc"'),
        f'ixx -0.5 on {tip}': _on_link(tip, r'ixx="[^"]*"', 'ixx="-0.5"'),
    }


def mutation_table(urdf: Path, timeout_s: float) -> int:
    """Print what design_gains says of each faulty copy of ``urdf``; 1 if any crashed."""
    xml = urdf.read_text()
    print(f'| fault in {urdf.name} | design_gains --task pose |')
    print('|---|---|')
    crashed = 0
    rows = [('none (the URDF as it comes)', None), *mutations(xml).items()]
    with tempfile.TemporaryDirectory() as tmp:
        for name, mutate in rows:
            faulty = xml if mutate is None else mutate(xml)
            path = Path(tmp) / urdf.name  # its own name: design_gains' output names it
            path.write_text(faulty)
            warned: list[str] = []
            if mutate is not None and faulty == xml:
                kind, text = 'not applied', 'the URDF has nothing to change'
            else:
                kind, text = design_outcome(path, timeout_s, warned)
            if kind == 'taken':  # each warning's head, up to its first colon
                text = 'warns: ' + ('; '.join(
                    line.split('WARNING: ', 1)[1].split(':')[0] for line in warned)
                    or 'nothing')
            crashed += kind == 'crashed'
            print(f'| {name} | {cell((kind, text), 2 * REASON_CHARS)} |', flush=True)
    return 1 if crashed else 0


def cell(outcome: tuple[str, str], chars: int = REASON_CHARS) -> str:
    """One table cell: the outcome, and for a refusal or a crash, what was said (shortened)."""
    kind, text = outcome
    text = text.replace('|', '/')
    if len(text) > chars:
        text = text[:chars - 3] + '...'
    return kind if not text else f'{kind}: {text}'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', default='', help='only the URDFs whose path contains this')
    parser.add_argument('--timeout', type=float, default=120.0,
                        help='s for design_gains on one URDF (default 120)')
    parser.add_argument('--mutate', type=Path, default=None,
                        help='instead, design_gains on faulty copies of this URDF')
    args = parser.parse_args(argv)
    if args.mutate is not None:
        return mutation_table(args.mutate, args.timeout)
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

"""
Ctrl-C as a terminal sends it, many times: exit codes and tracebacks, counted.

For ``--rounds`` rounds, starts the two nodes (``wrist_sim_node`` and ``controller_node``, the
product configs) or the ``composed`` process on a private loopback graph, waits a random time
of up to ``--within`` seconds (so start-up, the first states and steady running are all hit),
then sends SIGINT to each process group, as a terminal's Ctrl-C does; in half of the rounds a
second SIGINT follows within 0.3 s, as ``ros2 launch`` sends one when another process exits
(``on_exit=Shutdown``). It counts the processes that exit with status 0, and those whose log has
a traceback. Target (streamed-goals issue): 0 and no traceback, every time.

    python -m experiments.ctrl_c [--rounds 20] [--within 3]
"""
import argparse
from pathlib import Path
import random
import sys
import tempfile
import time
from typing import Optional

from experiments import local_ros
from quat_jt_runtime.resources import share_path


def one_round(mode: str, within_s: float, work_dir: Path, rng: random.Random) -> list[dict]:
    """Start ``mode`` ('pair' or 'composed'), Ctrl-C it; return one record per process."""
    env = local_ros.isolated_env(work_dir, rng.randint(101, 200))
    if mode == 'composed':
        procs = {'composed': local_ros.spawn_node(
            'composed', env, work_dir, params_files=(
                share_path('config/wrist_sim.yaml'),
                share_path(local_ros.PRODUCT_CONTROLLER_CONFIG)))}
    else:
        sim, ctrl = local_ros.spawn_wrist_pair(
            env, work_dir, controller_config=local_ros.PRODUCT_CONTROLLER_CONFIG)
        procs = {'controller_node': ctrl, 'wrist_sim_node': sim}
    delay_s = rng.uniform(0.0, within_s)
    time.sleep(delay_s)  # the point of the test: a Ctrl-C at any moment
    second = rng.random() < 0.5
    for proc in procs.values():
        local_ros.interrupt_group(proc)
    if second:
        time.sleep(rng.uniform(0.0, 0.3))
        for proc in procs.values():
            local_ros.interrupt_group(proc)
    records = []
    for name, proc in procs.items():
        code = local_ros.stop_node(proc, timeout=30.0)  # already interrupted: waits, or kills
        log = (work_dir / f'{name}.log').read_text(errors='replace')
        records.append({'process': name, 'delay_s': delay_s, 'second_sigint': second,
                        'exit_code': code, 'traceback': 'Traceback' in log,
                        'log': str(work_dir / f'{name}.log')})
    return records


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rounds', type=int, default=20, help='rounds per mode')
    parser.add_argument('--within', type=float, default=3.0,
                        help='the Ctrl-C comes at a random time up to this many seconds')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--out', type=Path, default=None, help='folder for the logs')
    args = parser.parse_args(argv)
    rng = random.Random(args.seed)
    out = args.out or Path(tempfile.mkdtemp(prefix='qjt_ctrl_c_'))
    bad = []
    counts: dict = {}
    for mode in ('pair', 'composed'):
        for k in range(args.rounds):
            work_dir = out / f'{mode}_{k}'
            work_dir.mkdir(parents=True, exist_ok=True)
            for r in one_round(mode, args.within, work_dir, rng):
                ok = r['exit_code'] == 0 and not r['traceback']
                c = counts.setdefault(r['process'], [0, 0])
                c[0] += ok
                c[1] += 1
                if not ok:
                    bad.append(r)
    for process, (ok, total) in counts.items():
        print(f'{process}: exit 0 without a traceback {ok} of {total}')
    for r in bad:
        print(f'  {r["process"]}: exit {r["exit_code"]}, traceback {r["traceback"]}, Ctrl-C at '
              f'{r["delay_s"]:.2f} s, second SIGINT {r["second_sigint"]}: {r["log"]}')
    print(f'logs in {out}')
    return 0 if not bad else 1


if __name__ == '__main__':
    sys.exit(main())

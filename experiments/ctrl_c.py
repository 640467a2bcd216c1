"""
Ctrl-C as a terminal sends it, many times: exit codes and tracebacks, counted.

For ``--rounds`` rounds, starts the two nodes (``wrist_sim_node`` and ``controller_node``, the
product configs) or the ``composed`` process on a private loopback graph, waits a random time
of up to ``--within`` seconds (so start-up, the first states and steady running are all hit),
then sends SIGINT to each process group, as a terminal's Ctrl-C does; in half of the rounds a
second SIGINT follows within 0.3 s, as ``ros2 launch --noninteractive`` sends its own after the
terminal's. It counts the processes that exit with status 0, and those whose log has a
traceback. Target (streamed-goals issue): 0 and no traceback, every time.

It also times each exit from the first SIGINT, and counts what ``ros2 launch`` (not on PyPI,
so not run here) would log as an ERROR for the same process by its rules (launch's
``ExecuteLocal``): an exit status other than 0 ("process has died"), or a process still running
``LAUNCH_SIGTERM_TIMEOUT_S`` after the SIGINT (launch then sends SIGTERM, "failed to terminate").
Under launch the nodes share its process group, so the terminal's Ctrl-C reaches each at once,
as here; launch's own ``on_exit=Shutdown`` adds nothing once a shutdown is under way.

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

LAUNCH_SIGTERM_TIMEOUT_S = 5.0  # ros2 launch's sigterm_timeout default: SIGTERM and an ERROR


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
    t_sigint = time.monotonic()
    for proc in procs.values():
        local_ros.interrupt_group(proc)
    exit_s: dict[str, float] = {}

    def note_exits() -> None:
        for name, proc in procs.items():
            if name not in exit_s and proc.poll() is not None:
                exit_s[name] = time.monotonic() - t_sigint
    if second:
        second_at = time.monotonic() + rng.uniform(0.0, 0.3)
        while time.monotonic() < second_at:
            note_exits()
            time.sleep(0.005)
        for proc in procs.values():
            local_ros.interrupt_group(proc)
    while len(exit_s) < len(procs) and time.monotonic() < t_sigint + 30.0:
        note_exits()
        time.sleep(0.005)
    records = []
    for name, proc in procs.items():
        code = local_ros.stop_node(proc, timeout=1.0)  # exited, or 30 s past the SIGINT: killed
        log = (work_dir / f'{name}.log').read_text(errors='replace')
        records.append({'process': name, 'delay_s': delay_s, 'second_sigint': second,
                        'exit_code': code, 'traceback': 'Traceback' in log,
                        'exit_s': exit_s.get(name, float('inf')),
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
                launch_error = r['exit_code'] != 0 or r['exit_s'] > LAUNCH_SIGTERM_TIMEOUT_S
                c = counts.setdefault(r['process'], [0, 0, 0, 0.0])
                c[0] += ok
                c[1] += 1
                c[2] += launch_error
                c[3] = max(c[3], r['exit_s'])
                if not ok or launch_error:
                    bad.append(r)
    for process, (ok, total, launch_errors, slowest_s) in counts.items():
        print(f'{process}: exit 0 without a traceback {ok} of {total}; slowest exit '
              f'{slowest_s:.2f} s after the SIGINT; ERROR lines ros2 launch would log by its '
              f'rules (exit status, SIGTERM after {LAUNCH_SIGTERM_TIMEOUT_S:g} s): '
              f'{launch_errors}')
    for r in bad:
        print(f'  {r["process"]}: exit {r["exit_code"]} after {r["exit_s"]:.2f} s, traceback '
              f'{r["traceback"]}, Ctrl-C at {r["delay_s"]:.2f} s, second SIGINT '
              f'{r["second_sigint"]}: {r["log"]}')
    print(f'logs in {out}')
    return 0 if not bad else 1


if __name__ == '__main__':
    sys.exit(main())

"""
Worker processes of a node: slow model work (a goal check, a gain design) off its loop.

:func:`start_worker` starts ``python -m <module>`` as the node's goal-check and design workers
are started, and :func:`quiet_worker` is the first thing such a worker does. ROS-free.
"""
import json
import os
import signal
import subprocess
import sys
from typing import Any, Callable, Iterable

from quat_jt_runtime.realtime import start_at_normal_scheduling

WORKER_NICE = 10  # advice only: leave the CPU to the 1 kHz nodes


def start_worker(module: str) -> subprocess.Popen:
    """
    Start ``python -m module`` with text pipes on its stdin and stdout (stderr the node's).

    SIGINT is blocked from its first instruction (a blocked mask survives exec) until it
    ignores it (:func:`quiet_worker`), and it runs out of the terminal's process group: Ctrl-C
    is the node's, which then closes its stdin. Here a SIGINT only waits until the mask is
    restored. Started from a real-time thread (a restart, from the tick's executor), it still
    begins with normal scheduling: it must never compete with the loop.
    """
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return start_at_normal_scheduling(lambda: subprocess.Popen(
            [sys.executable, '-m', module], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=None, text=True, bufsize=1, start_new_session=True))
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def quiet_worker() -> None:
    """In a worker :func:`start_worker` started: ignore SIGINT, unblock it, lower priority."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node stops it (closes its stdin)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked since its start
    try:
        os.nice(WORKER_NICE)
    except OSError:
        pass


def read_json_lines(lines: Iterable[str], put: Callable[[Any], None]) -> None:
    """Give ``put`` each JSON line of a worker's output until it ends; skip what is not JSON."""
    for line in lines:
        try:
            put(json.loads(line))
        except ValueError:
            pass

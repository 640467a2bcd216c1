"""
Worker processes of a node: slow model work (a goal check, a gain design) off its loop.

:func:`start_worker` starts ``python -m <module>`` as the node's goal-check and design workers
are started, and :func:`quiet_worker` is the first thing such a worker does; a
:class:`LineWriter` writes to its input, :func:`read_json_lines` reads its output. ROS-free.
"""
import json
import os
import queue
import signal
import subprocess
import sys
import threading
from typing import Any, Callable, IO, Iterable, Optional

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


class LineWriter:
    """
    Lines to a worker's input, written by a thread of their own: the caller never waits.

    A pipe holds 64 KiB. A longer line (the URDF of a whole robot is 100 to 200 KiB) is
    written only as fast as the worker reads it, and a niced worker on a busy host reads it
    late: written on the control thread, it held the loop for tens of milliseconds
    (docs/benchmark.md, "A design again"). :meth:`put` queues a line; the thread writes the
    lines in order, and :meth:`close` closes the input after the lines queued before it (a
    worker ends when its input closes). A write that fails (the worker is gone) ends the
    thread: the worker's output closing says so to its reader.
    """

    def __init__(self, stream: IO[str], name: str) -> None:
        self._stream = stream
        self._lines: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._write, name=name, daemon=True)
        self._thread.start()

    def put(self, line: str) -> None:
        """Queue ``line`` (one JSON text, without its newline) for the worker."""
        self._lines.put(line)

    def close(self) -> None:
        """Close the worker's input once the lines queued before are written."""
        self._lines.put(None)

    def join(self, timeout_s: Optional[float] = None) -> bool:
        """Wait for the thread to end (the input closed, or a write failed); say if it has."""
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def _write(self) -> None:
        stream = self._stream
        try:
            while (line := self._lines.get()) is not None:
                stream.write(line + '\n')
                stream.flush()
        except (OSError, ValueError):  # the worker is gone, or its input closed
            pass
        try:
            stream.close()
        except (OSError, ValueError):  # BrokenPipeError on the flush of what is left
            pass

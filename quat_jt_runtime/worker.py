"""
Worker processes of a node: slow model work (a goal check, a gain design) off its loop.

:func:`start_worker` starts ``python -m <module>`` as the node's goal-check and design workers
are started, and :func:`quiet_worker` is the first thing such a worker does; a
:class:`LineWriter` writes to its input, :func:`read_json_lines` reads its output. A worker
started again while the node runs is started by a :class:`Launcher`, a process of the node's
started with it (``python -m quat_jt_runtime.worker``). ROS-free.
"""
import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
from typing import Any, Callable, IO, Iterable, Optional, Sequence

from quat_jt_runtime.realtime import start_at_normal_scheduling

WORKER_NICE = 10  # advice only: leave the CPU to the 1 kHz nodes
# a worker (or the launcher) not gone this long after its input closes is killed
WORKER_CLOSE_WAIT_S = 2.0


def start_worker(module: str) -> subprocess.Popen:
    """
    Start ``python -m module`` with text pipes on its stdin and stdout (stderr the node's).

    SIGINT is blocked from its first instruction (a blocked mask survives exec) until it
    ignores it (:func:`quiet_worker`), and it runs out of the terminal's process group: Ctrl-C
    is the node's, which then closes its stdin. Here a SIGINT only waits until the mask is
    restored. Started from a real-time thread (a restart, from the tick's executor), it still
    begins with normal scheduling: it must never compete with the loop.
    """
    return _start(['-m', module], subprocess.PIPE, subprocess.PIPE)


def _start(args: list, stdin: Any, stdout: Any) -> subprocess.Popen:
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return start_at_normal_scheduling(lambda: subprocess.Popen(
            [sys.executable, *args], stdin=stdin, stdout=stdout, stderr=None, text=True,
            bufsize=1, start_new_session=True))
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

    def __init__(self, stream: IO[str], name: str,
                 lines: Optional[queue.SimpleQueue] = None) -> None:
        self._stream = stream
        # lines queued before the worker was there (a worker started by a Launcher) go first
        self._lines: queue.SimpleQueue = queue.SimpleQueue() if lines is None else lines
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


LAUNCH_MESSAGE_BYTES = 4096  # a launcher message: a module name, a pid, an exit code


class LaunchedProcess:
    """
    A worker the :class:`Launcher` started: what the node uses of a ``Popen``.

    ``pid``, ``stdin`` (text, line-buffered) and ``stdout`` (text) are the worker's;
    ``poll``, ``wait`` and ``kill`` go through the launcher, its parent, which reports its exit
    (the code as ``Popen.returncode`` gives it: ``-9`` for SIGKILL).
    """

    def __init__(self, launcher: 'Launcher', pid: int, stdin_fd: int, stdout_fd: int) -> None:
        self.pid = pid
        self.stdin = os.fdopen(stdin_fd, 'w', buffering=1)
        self.stdout = os.fdopen(stdout_fd, 'r')
        self.returncode: Optional[int] = None
        self._launcher = launcher
        self._exited = threading.Event()

    def poll(self) -> Optional[int]:
        """Return the exit code, or None while the worker runs (as far as it is known)."""
        return self.returncode

    def wait(self, timeout: Optional[float] = None) -> int:
        """Wait for the exit; raise ``subprocess.TimeoutExpired`` after ``timeout`` s."""
        if not self._exited.wait(timeout):
            raise subprocess.TimeoutExpired(f'worker {self.pid}', timeout)
        return self.returncode

    def kill(self) -> None:
        """Ask the launcher to kill the worker (SIGKILL)."""
        self._launcher.send({'kill': self.pid})

    def exited(self, code: Optional[int]) -> None:
        """Take the exit code the launcher reported (None: the launcher itself is gone)."""
        self.returncode = code
        self._exited.set()


class Launcher:
    """
    A process that starts a node's workers for it: the node never starts one while it runs.

    Starting a process from a running node holds Python's lock for milliseconds, which its
    loop then waits for (docs/benchmark.md, "A worker started again"). The launcher
    (``python -m quat_jt_runtime.worker``, started as :func:`start_worker` starts a worker,
    with the node, before its loop runs, a Unix socket its input) starts each worker asked for
    and hands its pipes over through that socket. :meth:`start` sends one short message and
    returns; the launcher's reader thread, a thread of the node started with the launcher,
    calls ``on_started`` with the :class:`LaunchedProcess` (or None and the reason), and
    reports each exit to it. Call :meth:`close` at the end (after the workers' input is
    closed).
    """

    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self._proc = _start(['-m', 'quat_jt_runtime.worker'], stdin=theirs.fileno(),
                                stdout=None)
        finally:
            theirs.close()
        self._sock = ours
        self._lock = threading.Lock()
        self._next_id = 0
        self._waiting: dict[int, Callable[[Optional[LaunchedProcess], str], None]] = {}
        self._running: dict[int, LaunchedProcess] = {}
        self._gone = ''  # why the launcher is gone ('' while it runs)
        self._reader = threading.Thread(target=self._read, name='launcher_reader', daemon=True)
        self._reader.start()

    @property
    def pid(self) -> int:
        """Return the launcher process's id."""
        return self._proc.pid

    def send(self, message: dict) -> bool:
        """Send one message to the launcher (never waits on it); False if it is gone."""
        with self._lock:
            try:
                self._sock.send(json.dumps(message).encode(), socket.MSG_DONTWAIT)
                return True
            except OSError:
                return False

    def start(self, module: str,
              on_started: Callable[[Optional[LaunchedProcess], str], None]) -> None:
        """
        Ask for ``python -m module``, started as :func:`start_worker` starts it.

        ``on_started(process, '')``, or ``on_started(None, reason)``, is called later, on the
        launcher's reader thread, not the caller's: the threads that serve the worker may be
        started there, off the loop.
        """
        with self._lock:
            self._next_id += 1
            key = self._next_id
            self._waiting[key] = on_started
        if self._gone or not self.send({'start': module, 'id': key}):
            with self._lock:  # unless the reader, ending, has told it already
                told = self._waiting.pop(key, None) is None
            if not told:
                on_started(None, self._gone or 'the worker launcher is gone')

    def _read(self) -> None:
        sock = self._sock
        while True:
            try:
                data, fds, _, _ = socket.recv_fds(sock, LAUNCH_MESSAGE_BYTES, 2)
            except OSError:
                data, fds = b'', []
            if not data:
                break
            message = json.loads(data)
            if 'exited' in message:
                proc = self._running.pop(message['exited'], None)
                if proc is not None:
                    proc.exited(message['code'])
                continue
            with self._lock:
                on_started = self._waiting.pop(message.get('id'), None)
            if 'pid' in message and len(fds) == 2:
                proc = LaunchedProcess(self, int(message['pid']), fds[0], fds[1])
                self._running[proc.pid] = proc
                if on_started is not None:
                    on_started(proc, '')
                continue
            for fd in fds:
                os.close(fd)
            if on_started is not None:
                on_started(None, str(message.get('error', 'the worker launcher failed')))
        self._gone = f'the worker launcher exited (status {self._proc.wait()})'
        with self._lock:
            waiting, self._waiting = self._waiting, {}
        for on_started in waiting.values():
            on_started(None, self._gone)
        for proc in list(self._running.values()):  # their exits can no longer be told
            proc.exited(None)

    def close(self) -> None:
        """End the launcher (its socket closes); the workers end when their input closes."""
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        try:
            self._proc.wait(timeout=WORKER_CLOSE_WAIT_S)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._reader.join(WORKER_CLOSE_WAIT_S)
        self._sock.close()


def _serve_launcher() -> None:
    """
    Serve as the launcher process (:class:`Launcher`): start workers, hand their pipes over.

    Its input is a socket to the node (one JSON message a request): ``{'start': module,
    'id': k}`` is answered ``{'id': k, 'pid': pid}`` with the worker's input and output pipes
    attached (or ``{'id': k, 'error': text}``), and ``{'exited': pid, 'code': code}`` when that
    worker ends; ``{'kill': pid}`` kills it. It runs with normal scheduling, not niced (its
    workers nice themselves); it ends when the node closes the socket, and its workers when
    the node closes their input.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node ends it (closes the socket)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    sock = socket.socket(fileno=sys.stdin.fileno())
    lock = threading.Lock()  # one message at a time: answers here, exits on the watchers
    children: dict[int, subprocess.Popen] = {}

    def send(message: dict, fds: Sequence[int] = ()) -> None:
        with lock:
            try:
                socket.send_fds(sock, [json.dumps(message).encode()], list(fds))
            except OSError:  # the node is gone: nobody to tell
                pass

    def watch(proc: subprocess.Popen) -> None:
        send({'exited': proc.pid, 'code': proc.wait()})

    while True:
        try:
            data, _, _, _ = socket.recv_fds(sock, LAUNCH_MESSAGE_BYTES, 0)
        except OSError:
            break
        if not data:  # the node closed its end, or died
            break
        request = json.loads(data)
        if 'start' in request:
            try:
                proc = start_worker(str(request['start']))
            except OSError as exc:
                send({'id': request['id'], 'error': f'{type(exc).__name__}: {exc}'})
                continue
            children[proc.pid] = proc
            send({'id': request['id'], 'pid': proc.pid},
                 (proc.stdin.fileno(), proc.stdout.fileno()))
            proc.stdin.close()  # the node holds them now
            proc.stdout.close()
            threading.Thread(target=watch, args=(proc,), daemon=True).start()
        elif 'kill' in request:
            proc = children.get(request['kill'])
            if proc is not None and proc.poll() is None:
                proc.kill()


if __name__ == '__main__':
    _serve_launcher()

"""
Worker processes of a node: slow model work (a goal check, a gain design) off its loop.

A node's goal-check and design workers are each a :class:`SupervisedWorker`: ``python -m
<module>``, started by a :class:`Launcher` (a process of the node's started with it, ``python
-m quat_jt_runtime.worker``, so that the node never starts a process while its loop runs), and
started again after a back-off when it dies. :func:`start_worker` is how the launcher starts
one, and :func:`quiet_worker` the first thing such a worker does; a :class:`LineWriter` writes
to its input, :func:`read_json_lines` reads its output, and the worker writes it with
:func:`answer`. ROS-free.
"""
import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Any, Callable, IO, Iterable, Optional, Sequence

from quat_jt_runtime.realtime import start_at_normal_scheduling

# advice only: leave the CPU to the 1 kHz nodes. On simulated time a node's launcher is told 0
# (controller_node): there the loop keeps no deadlines, and a niced worker on a busy host would
# answer seconds of simulated time late, as the loop steps on without it.
WORKER_NICE = 10
# a worker (or the launcher) not gone this long after its input closes is killed
WORKER_CLOSE_WAIT_S = 2.0
RESTART_BACKOFF_S = (1.0, 2.0, 4.0, 8.0, 16.0, 30.0)  # after the 1st, 2nd, ... death in a row


def start_worker(module: str, nice: int = WORKER_NICE) -> subprocess.Popen:
    """
    Start ``python -m module`` with text pipes on its stdin and stdout (stderr the node's).

    The worker runs ``nice`` more niced than this process, set as soon as it runs (advice:
    where it cannot be set, it runs as it is).

    SIGINT is blocked from its first instruction (a blocked mask survives exec) until it
    ignores it (:func:`quiet_worker`), and it runs out of the terminal's process group: Ctrl-C
    is the node's, which then closes its stdin. Here a SIGINT only waits until the mask is
    restored. Started from a real-time thread (a restart, from the tick's executor), it still
    begins with normal scheduling: it must never compete with the loop.
    """
    proc = _start(['-m', module], subprocess.PIPE, subprocess.PIPE)
    if nice > 0:
        try:
            os.setpriority(os.PRIO_PROCESS, proc.pid,
                           os.getpriority(os.PRIO_PROCESS, 0) + nice)
        except OSError:  # gone already, or not permitted: it runs as it is
            pass
    return proc


def _start(args: list, stdin: Any, stdout: Any) -> subprocess.Popen:
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return start_at_normal_scheduling(lambda: subprocess.Popen(
            [sys.executable, *args], stdin=stdin, stdout=stdout, stderr=None, text=True,
            bufsize=1, start_new_session=True))
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def quiet_worker() -> None:
    """In a worker :func:`start_worker` started (and niced): ignore SIGINT, unblock it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node stops it (closes its stdin)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked since its start


def answer(message: Any) -> bool:
    """
    In a worker: write ``message`` as a JSON line to the node; False if the node reads no more.

    The node gone (or a worker it never took, the launcher's copy closed), the write fails:
    stdout then goes to /dev/null, so that Python's flush at exit is quiet too.
    """
    try:
        sys.stdout.write(json.dumps(message) + '\n')
        sys.stdout.flush()
        return True
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return False


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
    closed). Each worker runs ``worker_nice`` more niced than the launcher (0: as niced).
    """

    def __init__(self, worker_nice: int = WORKER_NICE) -> None:
        if not 0 <= worker_nice <= 19:
            raise ValueError(f'worker_nice must be 0 to 19, got {worker_nice}')
        self._worker_nice = worker_nice
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
        if self._gone or not self.send({'start': module, 'id': key,
                                        'nice': self._worker_nice}):
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


class SupervisedWorker:
    """
    One worker process at a time, started by a :class:`Launcher`, started again when it dies.

    ``python -m module`` reads ``first_line`` first (each new worker does), then the lines
    :meth:`send` queues, and answers with JSON lines. Its ``{'ready': true}`` line sets
    :attr:`ready` (on its reader thread); :meth:`poll` returns the other lines, in order, and
    says whether the worker died since the last call. Then :meth:`take_failure` says so once
    (and what is ``unavailable`` until it is back), :attr:`available` is False, and a
    :meth:`poll` after the back-off (``RESTART_BACKOFF_S``, longer after each death in a row,
    reset by an answer) asks the launcher for a new worker. Lines sent before a worker is
    there wait for it; lines sent while none is available are dropped: the owner holds or
    refuses its work.

    No method but :meth:`close` waits or starts a process: they run on the node's loop. The
    launcher is ``launcher`` (the node's, shared by its workers) or one of its own, closed
    with it.
    """

    def __init__(self, module: str, first_line: str, label: str, unavailable: str,
                 launcher: Optional[Launcher] = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.label = label  # 'the goal-check worker'
        self.restarts = 0
        self.last_exit = ''  # how the last worker ended ('' before any death)
        self._module = module
        self._first_line = first_line
        self._unavailable = unavailable
        self._clock = clock
        self._events: queue.SimpleQueue = queue.SimpleQueue()  # from the launcher and readers
        self._owns_launcher = launcher is None
        self._launcher = Launcher() if launcher is None else launcher
        self._proc: Optional[LaunchedProcess] = None  # None until a poll took it
        self._current: Optional[LaunchedProcess] = None  # ... until the launcher started it
        self._writer: Optional[LineWriter] = None
        self._lines: queue.SimpleQueue = queue.SimpleQueue()
        self._ready = False
        self._deaths_in_a_row = 0
        self._restart_at: Optional[float] = None
        self._failure: Optional[str] = None
        self._closed = False
        self._start_process()

    @property
    def available(self) -> bool:
        """Tell whether a worker is up or starting (False from a death until its restart)."""
        return self._restart_at is None and not self._closed

    @property
    def ready(self) -> bool:
        """Tell whether the worker said it is ready to answer at once (no poll needed)."""
        return self._ready and self.available

    @property
    def pid(self) -> Optional[int]:
        """Return the worker process's id (None while the launcher starts it); needs no poll."""
        current = self._current
        return None if current is None else current.pid

    @property
    def unavailable_reason(self) -> str:
        """Say why the worker is unavailable, and when it restarts ('' if available)."""
        if self._closed:
            return f'{self.label} was closed'
        if self._restart_at is None:
            return ''
        wait_s = max(0.0, self._restart_at - self._clock())
        return f'{self.last_exit}; restarting in {wait_s:.1f} s'

    def send(self, line: str) -> None:
        """Queue ``line`` (one JSON text) for the worker; never waits."""
        self._lines.put(line)  # a worker gone: its reader reports the exit

    def poll(self) -> tuple[list, bool]:
        """Return the worker's answers since the last call and whether it died after them."""
        answers, died = [], False
        while not self._events.empty():
            kind, value, writer = self._events.get()
            if kind == 'started':
                self._proc, self._writer = value, writer
            elif kind == 'not started':
                if self._proc is None and not self._closed:
                    self._on_exit(value)
                    died = True
            elif kind == 'exited':
                if value is self._proc and not self._closed:
                    self._on_exit()
                    died = True
            else:
                self._deaths_in_a_row = 0  # the worker works
                answers.append(value)
        if self._restart_at is not None and self._clock() >= self._restart_at:
            self._restart_at = None
            self.restarts += 1
            self._start_process()
        return answers, died

    def take_failure(self) -> Optional[str]:
        """Return (once) what happened to the worker since the last call, or None."""
        failure, self._failure = self._failure, None
        return failure

    def close(self, wait_s: float = WORKER_CLOSE_WAIT_S) -> None:
        """End the worker (its input closes; killed after ``wait_s``); idempotent."""
        self._closed = True
        self._restart_at = None
        self._lines.put(None)  # a worker still to come ends as soon as it starts
        while not self._events.empty():  # one started since the last poll
            kind, value, writer = self._events.get()
            if kind == 'started':
                self._proc, self._writer = value, writer
        proc = self._proc
        if proc is not None and proc.poll() is None:
            try:
                proc.wait(timeout=wait_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                try:
                    proc.wait(timeout=WORKER_CLOSE_WAIT_S)
                except subprocess.TimeoutExpired:
                    pass
        if self._owns_launcher:
            self._launcher.close()

    def _start_process(self) -> None:
        """Ask the launcher for a worker: one short message (on the loop's thread, too)."""
        self._ready = False  # until the new worker says it is
        self._proc = self._current = self._writer = None
        lines: queue.SimpleQueue = queue.SimpleQueue()  # the worker's input, until it is there
        lines.put(self._first_line)
        self._lines = lines
        self._launcher.start(self._module,
                             lambda proc, error: self._on_started(proc, error, lines))

    def _on_started(self, proc: Optional[LaunchedProcess], error: str,
                    lines: queue.SimpleQueue) -> None:
        """On the launcher's reader thread: serve the worker, or report why there is none."""
        if proc is None:
            self._events.put(('not started', error, None))
            return
        self._current = proc
        name = self._module.rsplit('.', 1)[-1]
        writer = LineWriter(proc.stdin, f'{name}_writer', lines)
        self._events.put(('started', proc, writer))  # before its reader's lines
        threading.Thread(target=self._read, args=(proc,), name=f'{name}_reader',
                         daemon=True).start()

    def _read(self, proc: LaunchedProcess) -> None:
        def take(line: Any) -> None:
            if isinstance(line, dict) and line.get('ready'):
                self._ready = True  # said at once, without a poll: this is the current worker
            else:
                self._events.put(('line', line, None))
        read_json_lines(proc.stdout, take)
        try:  # its output closed: the launcher tells its exit code a moment later
            proc.wait(timeout=WORKER_CLOSE_WAIT_S)
        except subprocess.TimeoutExpired:  # told as an exit all the same: it answers no more
            pass
        self._events.put(('exited', proc, None))

    def _on_exit(self, not_started: str = '') -> None:
        """Schedule the restart after the back-off, and say what happened."""
        if not_started:
            code = None
        else:
            code = self._proc.poll()  # the reader waited for it (None: not told)
            self._writer.close()  # its writer thread ends
        self._ready = False
        backoff_s = RESTART_BACKOFF_S[min(self._deaths_in_a_row, len(RESTART_BACKOFF_S) - 1)]
        self._deaths_in_a_row += 1
        self._restart_at = self._clock() + backoff_s
        self.last_exit = (f'{self.label} could not be started: {not_started}' if not_started
                          else f'{self.label} exited'
                          + ('' if code is None else f' (exit code {code})'))
        self._failure = f'{self.last_exit}: {self._unavailable}; restarting it in {backoff_s:g} s'


class WorkerOwner:
    """
    What a node's worker object (the goal check's, the design's) tells of its process.

    A base for an object that runs its work on ``self._worker``, a :class:`SupervisedWorker`:
    whether it is up, ready, why not, its pid and restarts, and its failures, said once.
    """

    _worker: SupervisedWorker

    @property
    def available(self) -> bool:
        """Tell whether a worker process is up (False from its death until its restart)."""
        return self._worker.available

    @property
    def ready(self) -> bool:
        """Tell whether the worker is ready: it answers at once (no poll needed)."""
        return self._worker.ready

    @property
    def unavailable_reason(self) -> str:
        """Say why the worker is unavailable, and when it restarts ('' if available)."""
        return self._worker.unavailable_reason

    @property
    def pid(self) -> Optional[int]:
        """Return the worker process's id (None while the launcher starts it)."""
        return self._worker.pid

    @property
    def restarts(self) -> int:
        """Return how many times a worker was started again."""
        return self._worker.restarts

    def take_failure(self) -> Optional[str]:
        """Return (once) what happened to the worker since the last call, or None."""
        return self._worker.take_failure()


def _serve_launcher() -> None:
    """
    Serve as the launcher process (:class:`Launcher`): start workers, hand their pipes over.

    Its input is a socket to the node (one JSON message a request): ``{'start': module,
    'id': k, 'nice': n}`` is answered ``{'id': k, 'pid': pid}`` with the worker's input and
    output pipes attached (or ``{'id': k, 'error': text}``), and ``{'exited': pid, 'code':
    code}`` when that worker ends; ``{'kill': pid}`` kills it. It runs with normal scheduling,
    not niced (each worker ``n`` more, :func:`start_worker`); it ends when the node closes the
    socket, and its workers when the node closes their input.
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
                proc = start_worker(str(request['start']),
                                    int(request.get('nice', WORKER_NICE)))
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

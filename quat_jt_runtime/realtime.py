"""
The real-time side of a 1 kHz loop: CPU affinity, timer slack, and the loop's waiting rules.

ROS-free (an executor is any object with ``spin_once(timeout_sec)``). The settings are what a
real-time deployment of a 1 kHz loop sets (ros2_control's controller_manager has a
``cpu_affinity`` parameter for the same reason):

* **CPU affinity.** A node pinned to a CPU of its own keeps its caches warm between ticks;
  on a machine with few cores it can also miss more ticks than not pinning, so it is off by
  default (measured both ways in docs/benchmark.md). Every thread of the process is pinned
  (the DDS threads too); threads started later inherit it. Child processes started before
  (the controller's goal-check worker) are not.
* **Thread priority.** Every thread of a node's process (the DDS threads too) runs in
  ``SCHED_FIFO`` at the node's ``thread_priority`` (50 by default, as ros2_control's
  controller_manager), so no ordinary process can preempt the loop or a DDS thread that holds
  a lock the loop needs (the soaks beside other processes: docs/benchmark.md). A child process
  started through :func:`start_at_normal_scheduling` (the goal-check worker) starts with
  normal scheduling, so it never competes with the loop.
* **Timer slack.** Linux lets a sleeping thread wake up to 50 us late (the default slack) so
  that wake-ups can be merged. The simulator's real-time loop sleeps until just before each
  tick and busy-waits the rest; with 1 ns of slack its sleeps end closer to the tick, so the
  busy-wait, which costs a core while it lasts, can be short.
* **Waiting for an answer** (:func:`answer_deadline`, :func:`await_answer`): the simulator's
  rules, shared with the benchmark's minimal pair so that the two compare one to one.
* **Prewarm** (:class:`Prewarm`): the controller runs a throwaway tick shortly before each
  state is due, so that the real tick finds its code and data in the caches and its CPU awake,
  for one more wake-up per state (what it buys and costs, measured with the benchmark's
  ``--prewarm-pairs``: docs/ros.md, 'Prewarm', and docs/benchmark.md).
* :class:`RunCheck`: the nodes' "keep running?" check, cheap enough to ask after every event.
"""
import ctypes
import os
import sys
import threading
import time
from typing import Any, Callable, Iterable, Optional, TypeVar

T = TypeVar('T')
PR_SET_TIMERSLACK = 29  # <linux/prctl.h>
PR_GET_TIMERSLACK = 30
# The real-time loop sleeps (timer slack 1 ns) until this long before a tick, then busy-waits
# (experiments/tick_profile.py: such a sleep wakes ~50 us late p50).
BUSY_WAIT_S = 1.0e-4
# Step with the last command (a stale tick) if no answer came this long before the tick. A
# step that runs past the tick only delays that state's publication; a stale tick applies an
# old command, so the answer gets as long as the step leaves...
STEP_LEAD_S = 1.0e-4
# ... but at least this fraction of a period after its state went out: a state published late
# (this process descheduled at its tick) still gets its answer, and the lateness is absorbed
# by the next tick's wait instead of costing a stale step.
MIN_ANSWER_FRACTION = 0.5
# At the deadline, events that arrived while this process was descheduled are still taken, up to
# this many (composed: the state to the controller, then its command back).
DRAIN_EVENTS = 4
CONTEXT_CHECK_S = 0.01  # an external shutdown is noticed within this (wall s)
# The controller's throwaway tick runs this long before the next state is due (its timer wakes
# 50-80 us late, so about 0.2 ms before). In A/B runs, 0.2 ms did as well; 0.4 ms cost more CPU
# for no faster tick; with 0.1 ms the timer mostly fired after the state had come.
DEFAULT_PREWARM_LEAD_S = 3.0e-4
PERIOD_SMOOTHING = 16  # the state period estimate moves 1/16 of the way to each new interval


def allowed_cpus() -> set[int]:
    """Return the CPUs this process may run on (its cpuset, e.g. from taskset or a container)."""
    if not hasattr(os, 'sched_getaffinity'):
        return set(range(os.cpu_count() or 1))
    return set(os.sched_getaffinity(0))


def check_cpus(cpus: Iterable[int]) -> tuple[int, ...]:
    """
    Return ``cpus`` sorted, or raise ValueError saying why they cannot be used.

    Empty means no pinning. Each entry must be a CPU this process may run on.
    """
    wanted = tuple(sorted({int(c) for c in cpus}))
    if not wanted:
        return ()
    if not hasattr(os, 'sched_setaffinity'):
        raise ValueError(f'cpu_affinity {list(wanted)}: this platform ({sys.platform}) cannot '
                         'pin threads; leave it empty')
    allowed = allowed_cpus()
    outside = [c for c in wanted if c not in allowed]
    if outside:
        raise ValueError(f'cpu_affinity {list(wanted)}: CPUs {outside} are not available to '
                         f'this process (it may use {sorted(allowed)})')
    return wanted


def _every_thread(apply: Callable[[int], None]) -> None:
    """Call ``apply(tid)`` for every thread of this process, and for any started meanwhile."""
    done: set[int] = set()
    for _ in range(10):  # again, until no thread started while applying was missed
        try:
            threads = {int(t) for t in os.listdir('/proc/self/task')}
        except OSError:  # no /proc: the calling thread only
            threads = {0}
        if threads <= done:
            break
        for tid in threads - done:
            try:
                apply(tid)
            except ProcessLookupError:  # the thread ended meanwhile
                pass
        done |= threads


def pin_process(cpus: Iterable[int]) -> tuple[int, ...]:
    """
    Pin every thread of this process to ``cpus`` (checked by :func:`check_cpus`).

    Returns the CPUs pinned to; empty ``cpus`` changes nothing and returns ().
    """
    wanted = check_cpus(cpus)
    if wanted:
        _every_thread(lambda tid: os.sched_setaffinity(tid, wanted))
    return wanted


# ros2_control's controller_manager runs its loop at this SCHED_FIFO priority by default
DEFAULT_THREAD_PRIORITY = 50


def set_thread_priority(priority: int) -> str:
    """
    Run every thread of this process in ``SCHED_FIFO`` at ``priority``; return '' or why not.

    0 changes nothing. Threads started later inherit it, and so do child processes, unless
    started through :func:`start_at_normal_scheduling`. Refused without the right to
    (``CAP_SYS_NICE``, or an ``rtprio`` limit of at least ``priority``): then nothing changes
    and the reason says how to allow it.
    """
    priority = int(priority)
    if priority <= 0:
        return ''
    if not hasattr(os, 'sched_setscheduler'):
        return f'this platform ({sys.platform}) has no SCHED_FIFO'
    param = os.sched_param(priority)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, param)  # this thread first: a refusal, no harm
    except PermissionError:
        return ('not permitted (it needs CAP_SYS_NICE, or an rtprio limit of at least '
                f'{priority}: `ulimit -r`, /etc/security/limits.conf; in a container with '
                'real-time group scheduling, a cpu.rt_runtime_us above 0 too)')
    except OSError as exc:
        return f'SCHED_FIFO refused: {exc.strerror or exc}'
    try:
        _every_thread(lambda tid: os.sched_setscheduler(tid, os.SCHED_FIFO, param))
    except OSError as exc:  # this thread has it, another refused: say so
        return f'SCHED_FIFO refused for a thread of this process: {exc.strerror or exc}'
    return ''


def start_at_normal_scheduling(start: Callable[[], T]) -> T:
    """
    Return ``start()``, run so that a process it starts begins with normal scheduling.

    From a real-time thread (``SCHED_FIFO``, :func:`set_thread_priority`), ``start`` runs in a
    short-lived thread of its own flagged ``SCHED_RESET_ON_FORK``: its child starts as
    ``SCHED_OTHER``, nice 0. That thread ends with the flag, since only a privileged thread may
    clear it (an ``rtprio`` limit suffices to set it), and a thread the flagged one started
    would lose the priority too. The helper starts with the caller's signal mask. An exception
    of ``start`` is raised here. From any other thread, ``start()`` is called as is.
    """
    flag = getattr(os, 'SCHED_RESET_ON_FORK', 0)
    policy = os.sched_getscheduler(0) if flag else None
    if policy is None or policy & ~flag not in (os.SCHED_FIFO, os.SCHED_RR):
        return start()
    outcome: list = []

    def run() -> None:
        try:
            os.sched_setscheduler(0, policy | flag, os.sched_getparam(0))
            outcome.append((True, start()))
        except BaseException as exc:  # noqa: B902 - re-raised in the caller's thread
            outcome.append((False, exc))
    helper = threading.Thread(target=run, name='start_at_normal_scheduling')
    helper.start()
    helper.join()
    ok, value = outcome[0]
    if not ok:
        raise value
    return value


def _prctl(option: int, value: int = 0) -> int:
    """Call prctl(2); -1 where there is none (not Linux) or it fails."""
    if not sys.platform.startswith('linux'):
        return -1
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(option, ctypes.c_ulong(value), 0, 0, 0))
    except (OSError, AttributeError):
        return -1


def set_timer_slack(slack_ns: int = 1) -> bool:
    """Set the calling thread's timer slack in ns (Linux); return whether it was set."""
    return _prctl(PR_SET_TIMERSLACK, int(slack_ns)) == 0


def timer_slack_ns() -> int:
    """Return the calling thread's timer slack in ns (-1 if it cannot be read)."""
    return _prctl(PR_GET_TIMERSLACK)


# ---------------------------------------- the pieces of a 1 kHz loop (ROS-free)
def answer_deadline(next_tick_s: float, published_s: float, period_s: float) -> float:
    """
    Return when to stop waiting for the answer to the state published at ``published_s``.

    ``STEP_LEAD_S`` before the next tick, but at least ``MIN_ANSWER_FRACTION`` of a period
    after the state went out. Times from ``time.perf_counter``, in s.
    """
    return max(next_tick_s - STEP_LEAD_S, published_s + MIN_ANSWER_FRACTION * period_s)


def await_answer(executor: Any, answered: Callable[[], bool], deadline_s: float,
                 ok: Callable[[], bool]) -> bool:
    """
    Spin ``executor`` until ``answered()`` or ``deadline_s`` (perf_counter s); return answered().

    At the deadline, what has already arrived is taken (up to ``DRAIN_EVENTS`` queued events):
    a command that came while this process was descheduled is in the queue, as it would be in
    a driver's command buffer, and is not a missed tick.
    """
    clock = time.perf_counter
    while not answered():
        if not ok():
            return False
        remaining = deadline_s - clock()
        if remaining <= 0.0:
            for _ in range(DRAIN_EVENTS):
                executor.spin_once(timeout_sec=0.0)
                if answered():
                    return True
            return False
        executor.spin_once(timeout_sec=remaining)
    return True


def wait_for_tick(executor: Any, tick_s: float) -> float:
    """
    Spin ``executor`` until ``BUSY_WAIT_S`` before ``tick_s``, then busy-wait to it.

    Times from ``time.perf_counter``, in s; returns the time reached (``tick_s`` or later).
    """
    clock = time.perf_counter
    remaining = tick_s - clock()
    while remaining > BUSY_WAIT_S:
        executor.spin_once(timeout_sec=remaining - BUSY_WAIT_S)
        remaining = tick_s - clock()
    now = clock()
    while now < tick_s:
        now = clock()
    return now


def ticks_to_skip(next_tick_s: float, period_s: float, now_s: float) -> int:
    """Return the whole ticks a loop stalled past ``next_tick_s`` cannot make up (0 if none)."""
    behind = now_s - next_tick_s
    return int(behind / period_s) if behind > period_s else 0


class RunCheck:
    """
    ``keep_running() and context_ok()``, with the context asked at most every CONTEXT_CHECK_S.

    The nodes' loops ask after every event; rclpy's ``Context.ok`` takes a lock and calls into C
    (it was 6% of a lockstep step). The context only ends on an external shutdown, which is noticed
    within CONTEXT_CHECK_S; Ctrl-C and SIGTERM set ``keep_running``, checked every time.
    """

    __slots__ = ('_keep_running', '_context_ok', '_alive', '_next_check_s', '_clock')

    def __init__(self, keep_running: Callable[[], bool], context_ok: Callable[[], bool],
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self._keep_running = keep_running
        self._context_ok = context_ok
        self._clock = clock
        self._alive = True
        self._next_check_s = -float('inf')

    def __call__(self) -> bool:
        """Return True while the loop should go on."""
        if not self._keep_running():
            return False
        now = self._clock()
        if now >= self._next_check_s:
            self._next_check_s = now + CONTEXT_CHECK_S
            self._alive = self._context_ok()
        return self._alive


class Prewarm:
    """
    When to run the controller's throwaway tick: ``lead_ns`` before the next state is due.

    The state period is estimated from the arrival times (``time.perf_counter_ns``) of the
    states: a running mean that moves ``1/PERIOD_SMOOTHING`` of the way to each new interval
    (at least 1 ns), the interval first clipped to between half and twice the estimate. So a
    late state and the one right after it (a long interval, then a short one), or a pause in the
    states, move the estimate by a few percent only, while a lasting change of rate is followed
    within a few dozen states. :meth:`arrived` gives how long from now the throwaway tick is
    due; :meth:`take` says whether a timer that fired now should run it.
    """

    __slots__ = ('lead_ns', 'period_ns', 'due_ns', '_last_ns')

    def __init__(self, lead_ns: int) -> None:
        if lead_ns <= 0:
            raise ValueError(f'the prewarm lead must be > 0 ns, got {lead_ns}')
        self.lead_ns = int(lead_ns)
        self.period_ns = 0  # 0 until two states have arrived
        self.due_ns = 0  # when the throwaway tick is due; 0: none
        self._last_ns: Optional[int] = None

    def arrived(self, arrival_ns: int, now_ns: int) -> Optional[int]:
        """
        Take a state's arrival time; return the delay from ``now_ns`` to the throwaway tick.

        None (and nothing due) while the period is unknown or under twice the lead: lockstep,
        where states come as fast as they are answered, has no idle time to use.
        """
        last_ns, self._last_ns = self._last_ns, arrival_ns
        self.due_ns = 0
        if last_ns is None or arrival_ns <= last_ns:
            return None
        interval_ns = arrival_ns - last_ns
        period_ns = self.period_ns
        if period_ns <= 0:
            period_ns = interval_ns
        else:
            target_ns = min(max(interval_ns, period_ns >> 1), period_ns << 1)
            step_ns = (target_ns - period_ns) // PERIOD_SMOOTHING
            if step_ns == 0 and target_ns != period_ns:
                step_ns = 1 if target_ns > period_ns else -1
            period_ns += step_ns
        self.period_ns = period_ns
        if period_ns < 2 * self.lead_ns:
            return None
        self.due_ns = arrival_ns + period_ns - self.lead_ns
        return max(self.due_ns - now_ns, 0)

    def take(self, now_ns: int) -> Optional[bool]:
        """
        Return True to run the throwaway tick now, False to drop it, None if it is not yet due.

        A timer that fires over half the lead early fired for an earlier arrival (the state came
        while its callback was queued): not yet, None. One that fires over half the lead late
        would hold up the state about to arrive, and one with nothing due has nothing to do:
        False. After True or False nothing is due until the next arrival.
        """
        due_ns = self.due_ns
        if due_ns and now_ns < due_ns - (self.lead_ns >> 1):
            return None
        self.due_ns = 0
        return bool(due_ns) and now_ns <= due_ns + (self.lead_ns >> 1)

"""
Real-time pieces of the loop, without ROS (``realtime.py``).

CPU pinning and timer slack, the simulator's answer deadline (shared with the minimal pair),
and the nodes' run check. The nodes' ``cpu_affinity`` parameter: ``test_realtime_nodes.py``.
"""
import json
import os
import subprocess
import sys
import threading
import time

from cpus import linux_only, thread_cpus, thread_policies, thread_policy, two_cpus
import pytest
from quat_jt_runtime import realtime
from quat_jt_runtime.realtime import answer_deadline, await_answer, DRAIN_EVENTS
from quat_jt_runtime.realtime import MIN_ANSWER_FRACTION, STEP_LEAD_S

pytestmark = pytest.mark.unit


def test_check_cpus_accepts_available_cpus_and_names_the_others():
    allowed = sorted(realtime.allowed_cpus())
    assert realtime.check_cpus([]) == ()
    assert realtime.check_cpus([allowed[-1], allowed[0], allowed[0]]) == tuple(
        sorted({allowed[0], allowed[-1]}))
    missing = max(allowed) + 1000
    with pytest.raises(ValueError) as exc:
        realtime.check_cpus([allowed[0], missing])
    assert f'CPUs [{missing}] are not available' in str(exc.value)
    assert str(allowed) in str(exc.value)


@linux_only
@two_cpus
def test_pin_process_pins_every_thread_and_later_threads_inherit_it():
    cpu = max(realtime.allowed_cpus())
    script = (
        'import threading, time, json, os\n'
        'from quat_jt_runtime import realtime\n'
        'stop = threading.Event()\n'
        'before = [threading.Thread(target=stop.wait) for _ in range(3)]\n'
        'for t in before: t.start()\n'
        f'print(json.dumps(realtime.pin_process([{cpu}])))\n'
        'after = threading.Thread(target=stop.wait); after.start()\n'
        'print(json.dumps(sorted(int(t) for t in os.listdir("/proc/self/task"))), flush=True)\n'
        'input()\n'
        'stop.set()\n')
    proc = subprocess.Popen([sys.executable, '-c', script], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == f'[{cpu}]'
        threads = proc.stdout.readline()
        cpus = thread_cpus(proc.pid)
        assert len(cpus) >= 5, (threads, cpus)  # main, 3 before, 1 after
        assert set(cpus.values()) == {str(cpu)}, cpus
    finally:
        proc.communicate('\n', timeout=10)


def test_pin_process_with_nothing_asked_changes_nothing():
    before = os.sched_getaffinity(0) if hasattr(os, 'sched_getaffinity') else None
    assert realtime.pin_process([]) == ()
    if before is not None:
        assert os.sched_getaffinity(0) == before


def _rtprio_limit_possible() -> bool:
    """Tell whether a process here may have an rtprio limit of 7 (its hard limit allows it)."""
    import resource
    return resource.getrlimit(resource.RLIMIT_RTPRIO)[1] >= 7


@linux_only
@pytest.mark.parametrize('who', ['this user', 'an unprivileged user with an rtprio limit'])
def test_thread_priority_reaches_every_thread_but_not_a_worker_process(who):
    """
    SCHED_FIFO for the threads there and to come; a worker process starts with normal ones.

    Without CAP_SYS_NICE (an rtprio limit, as docs/ros.md advises), a thread may set
    SCHED_RESET_ON_FORK but not clear it: the thread that starts the worker must not be one
    that goes on (it would keep the flag, and its later threads would lose the priority).
    """
    if who != 'this user' and not _rtprio_limit_possible():
        pytest.skip('the hard rtprio limit here is under 7: no unprivileged user may try it')
    drop = ('import resource\n'
            'resource.setrlimit(resource.RLIMIT_RTPRIO, (7, resource.getrlimit('
            'resource.RLIMIT_RTPRIO)[1]))\n'
            'if os.geteuid() == 0:  # without CAP_SYS_NICE from here on\n'
            '    os.setgid(65534); os.setuid(65534)\n') if who != 'this user' else ''
    script = (
        'import json, os, subprocess, sys, threading\n'
        'from quat_jt_runtime import realtime\n' + drop
        + 'stop = threading.Event()\n'
        'before = threading.Thread(target=stop.wait, daemon=True); before.start()\n'
        'refused = realtime.set_thread_priority(7)\n'
        'after = threading.Thread(target=stop.wait, daemon=True); after.start()\n'
        'worker = realtime.start_at_normal_scheduling(lambda: subprocess.Popen(["sleep", "60"]))\n'
        'late = threading.Thread(target=stop.wait, daemon=True); late.start()\n'
        'print(json.dumps([refused, worker.pid]), flush=True)\n'
        'input()\n'
        'worker.kill()\n'
        'stop.set()\n')
    proc = subprocess.Popen([sys.executable, '-c', script], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        refused, worker = json.loads(proc.stdout.readline())
        policies = thread_policies(proc.pid)
        assert len(policies) >= 4, policies  # main, before, after, late
        if refused:  # no right to it here: nothing changed, and the reason says how to allow it
            assert who == 'this user', refused  # the limit given above must suffice
            assert 'rtprio' in refused and set(policies.values()) == {('other', 0)}, refused
        else:
            assert set(policies.values()) == {('fifo', 7)}, policies
        assert thread_policy(worker) == ('other', 0)  # never at the loop's priority
    finally:
        proc.communicate('\n', timeout=10)


def test_starting_a_worker_from_an_ordinary_thread_calls_it_as_is():
    """No real-time thread: ``start`` runs here, and its exception comes through."""
    assert realtime.start_at_normal_scheduling(threading.get_ident) == threading.get_ident()
    with pytest.raises(ValueError, match='bad start'):
        realtime.start_at_normal_scheduling(lambda: int('bad start'))


@linux_only
def test_thread_priority_zero_changes_nothing_and_a_refusal_says_why(monkeypatch):
    before = thread_policy()
    assert realtime.set_thread_priority(0) == '' and thread_policy() == before

    def refuse(*_args) -> None:
        raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    reason = realtime.set_thread_priority(50)
    assert 'CAP_SYS_NICE' in reason and 'at least 50' in reason, reason
    assert thread_policy() == before


@linux_only
def test_timer_slack_is_set_for_the_calling_thread_only():
    seen = []

    def worker() -> None:
        seen.append((realtime.set_timer_slack(12345), realtime.timer_slack_ns()))

    main_slack = realtime.timer_slack_ns()
    assert main_slack != 12345
    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == [(True, 12345)]
    assert realtime.timer_slack_ns() == main_slack


def test_answer_deadline_gives_a_late_state_at_least_the_minimum_window():
    period = 1e-3
    # On time: the answer may come until STEP_LEAD_S before the next tick.
    assert answer_deadline(2.0, 1.0, period) == pytest.approx(2.0 - STEP_LEAD_S)
    # Published 0.9 ms late: the answer still gets MIN_ANSWER_FRACTION of a period.
    published = 2.0 - period + 0.9e-3
    assert answer_deadline(2.0, published, period) == pytest.approx(
        published + MIN_ANSWER_FRACTION * period)
    assert answer_deadline(2.0, published, period) > 2.0


class _QueueExecutor:
    """An executor whose queue holds callbacks that are already due; spin_once runs one."""

    def __init__(self, queued) -> None:
        self.queued = list(queued)
        self.spins = []

    def spin_once(self, timeout_sec: float) -> None:
        self.spins.append(timeout_sec)
        if self.queued:
            self.queued.pop(0)()


def test_at_the_deadline_an_answer_already_queued_is_taken():
    """A process stalled past its deadline still takes the command waiting in its queue."""
    got = []
    # The deadline has passed; the state's callback, then the command, are queued.
    executor = _QueueExecutor([lambda: None, lambda: got.append('command')])
    assert await_answer(executor, lambda: bool(got), deadline_s=0.0, ok=lambda: True)
    assert executor.spins == [0.0, 0.0]  # no waiting past the deadline, just the queue


def test_with_nothing_queued_the_deadline_gives_a_stale_tick_after_a_bounded_look():
    executor = _QueueExecutor([])
    assert not await_answer(executor, lambda: False, deadline_s=0.0, ok=lambda: True)
    assert executor.spins == [0.0] * DRAIN_EVENTS


def test_before_the_deadline_the_wait_is_bounded_by_it():
    got = []
    executor = _QueueExecutor([lambda: got.append('command')])
    deadline = time.perf_counter() + 10.0
    assert await_answer(executor, lambda: bool(got), deadline_s=deadline, ok=lambda: True)
    assert len(executor.spins) == 1 and 0.0 < executor.spins[0] <= 10.0


def test_run_check_asks_the_context_at_most_every_period_and_the_flag_every_time():
    from quat_jt_runtime.realtime import CONTEXT_CHECK_S, RunCheck
    now, asked, running, alive = [100.0], [], [True], [True]

    def context_ok() -> bool:
        asked.append(now[0])
        return alive[0]
    check = RunCheck(lambda: running[0], context_ok, clock=lambda: now[0])
    assert check() and check() and asked == [100.0]  # asked once in the period
    alive[0] = False  # an external shutdown
    assert check()  # not seen yet...
    now[0] += CONTEXT_CHECK_S
    assert not check() and len(asked) == 2  # ... seen within one period
    running[0] = False  # Ctrl-C: seen at once
    alive[0] = True
    assert not check()


class _IdleExecutor:
    """An executor with nothing queued: spin_once records its timeout and returns."""

    def __init__(self) -> None:
        self.timeouts = []

    def spin_once(self, timeout_sec: float) -> None:
        self.timeouts.append(timeout_sec)


def test_wait_for_tick_sleeps_in_the_executor_then_busy_waits_to_the_tick():
    executor = _IdleExecutor()
    tick = time.perf_counter() + 2e-3
    reached = realtime.wait_for_tick(executor, tick)
    assert reached >= tick
    assert executor.timeouts and all(0.0 < t <= 2e-3 - realtime.BUSY_WAIT_S
                                     for t in executor.timeouts)


def test_ticks_to_skip_counts_whole_periods_beyond_one():
    assert realtime.ticks_to_skip(10.0, 1e-3, 10.0005) == 0  # late, but catches up
    assert realtime.ticks_to_skip(10.0, 1e-3, 10.0035) == 3


def _arrivals(prewarm: realtime.Prewarm, start_ns: int, intervals_ns) -> tuple[int, list]:
    """Feed arrivals spaced by ``intervals_ns``; return the last time and the delays given."""
    delays, now = [], start_ns
    for interval in intervals_ns:
        now += interval
        delays.append(prewarm.arrived(now, now))
    return now, delays


def test_prewarm_is_due_the_lead_before_the_next_state():
    prewarm = realtime.Prewarm(300_000)
    assert prewarm.arrived(5_000_000, 5_000_000) is None  # one state: no period yet
    now, delays = _arrivals(prewarm, 5_000_000, [1_000_000] * 50)
    assert delays[0] == delays[-1] == 700_000
    assert prewarm.period_ns == 1_000_000 and prewarm.due_ns == now + 700_000
    # Armed 40 us after the arrival (the tick's own time): the delay is counted from then.
    assert prewarm.arrived(now + 1_000_000, now + 1_040_000) == 660_000
    with pytest.raises(ValueError):
        realtime.Prewarm(0)


def test_prewarm_estimate_shrugs_off_a_late_state_and_a_pause_and_follows_a_new_rate():
    prewarm = realtime.Prewarm(300_000)
    now, _ = _arrivals(prewarm, 0, [1_000_000] * 50)
    # A late state and the one right after it: the estimate moves by a few percent only.
    now, delays = _arrivals(prewarm, now, [1_900_000, 100_000])
    assert all(abs(d - 700_000) < 0.1 * 1_000_000 for d in delays)
    now, _ = _arrivals(prewarm, now, [1_000_000] * 100)
    assert abs(prewarm.period_ns - 1_000_000) < 5_000
    # The states pause for a second: one interval, clipped to twice the period.
    now, delays = _arrivals(prewarm, now, [1_000_000_000])
    assert prewarm.period_ns <= 1_000_000 * (1 + 1 / realtime.PERIOD_SMOOTHING) + 5_000
    # The rate halves for good (500 Hz): followed within a few dozen states.
    now, delays = _arrivals(prewarm, now, [2_000_000] * 80)
    assert abs(prewarm.period_ns - 2_000_000) < 0.05 * 2_000_000
    assert abs(delays[-1] - 1_700_000) < 0.05 * 2_000_000


def test_prewarm_recovers_from_a_burst_at_start_up_however_short():
    """A queue of states delivered at once seeds a tiny period; it grows back, never sticks."""
    for seed_ns in (1, 10, 30_000):
        prewarm = realtime.Prewarm(300_000)
        now, _ = _arrivals(prewarm, 0, [seed_ns])
        now, delays = _arrivals(prewarm, now, [0] + [1_000_000] * 400)  # 0: same instant
        assert abs(prewarm.period_ns - 1_000_000) < 0.05 * 1_000_000, seed_ns
        assert delays[-1] is not None and abs(delays[-1] - 700_000) < 50_000, seed_ns


def test_prewarm_has_no_time_to_use_when_states_come_faster_than_twice_the_lead():
    """Lockstep answers each state at once: after the first period, no throwaway tick."""
    prewarm = realtime.Prewarm(300_000)
    _, delays = _arrivals(prewarm, 0, [1_000_000_000] * 2 + [150_000] * 300)
    # A start-up pause is taken as the period at first...
    assert delays[0] is None and delays[1] is not None
    assert delays[-1] is None and prewarm.period_ns < 600_000  # ... not for long
    assert prewarm.due_ns == 0 and prewarm.take(10**12) is False  # nothing due


def test_prewarm_runs_only_near_its_time():
    prewarm = realtime.Prewarm(300_000)
    now, _ = _arrivals(prewarm, 0, [1_000_000] * 20)
    due = prewarm.due_ns
    assert prewarm.take(due - 200_000) is None  # a fire for an earlier state: not yet
    assert prewarm.due_ns == due  # still due
    assert prewarm.take(due + 100_000) is True  # on time, within half the lead
    assert prewarm.take(due + 100_000) is False  # once
    _arrivals(prewarm, now, [1_000_000])
    assert prewarm.take(prewarm.due_ns + 200_000) is False  # late: the state is near

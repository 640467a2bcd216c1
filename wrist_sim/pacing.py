"""
The simulator's two stepping loops, ROS-free: real-time deadlines, or lockstep with /clock.

Both spin an executor (anything with ``spin_once(timeout_sec=...)``; the node passes its
EventsExecutor) between steps, so the command that answers a state is taken in the loop's own
thread. What a step is comes from the node as a :class:`Stepper`.
"""
import time
from typing import Any, Callable, Optional, Protocol

from quat_jt_runtime import realtime
from quat_jt_runtime.loop_stats import LoopStats
from wrist_sim.config import SimConfig

LOG_PERIOD_S = 1.0


class Stepper(Protocol):
    """What the loops drive: the simulator node."""

    stats: LoopStats

    def answered(self) -> bool:
        """Tell whether a command has come for the last published state."""

    def published_at(self) -> float:
        """Return when (``time.perf_counter``) the last state was published."""

    def advance(self) -> None:
        """Apply the command to apply (or hold) and step the physics once."""

    def publish_state(self) -> None:
        """Publish the state of the current step (and /clock)."""

    def config(self) -> SimConfig:
        """Return the live settings in force."""

    def every_second(self, line: str) -> None:
        """Take the loop's once-a-second figures (and do the node's periodic checks)."""


class _Periodic:
    """Once a second: the steps per second, missed deadlines, fresh and rejected commands."""

    def __init__(self, stats: LoopStats, start_s: float) -> None:
        self._stats = stats
        self._last_s, self._last_steps = start_s, 0

    def due(self, now_s: float) -> Optional[str]:
        if now_s - self._last_s < LOG_PERIOD_S:
            return None
        s = self._stats
        line = (f'{(s.steps - self._last_steps) / (now_s - self._last_s):.1f} steps/s, missed '
                f'{s.missed_deadlines}, fresh {s.fresh_steps}/{s.steps}, rejected '
                f'{s.rejected_commands}')
        self._last_s, self._last_steps = now_s, s.steps
        return line


def run_real_time(stepper: Stepper, executor: Any, period_s: float,
                  ok: Callable[[], bool]) -> None:
    """
    Deadline loop: publish each state exactly on its tick, step as soon as its answer is in.

    The state of step k is published at its tick t_k (the executor sleeps, with 1 ns of timer
    slack, until shortly before, then a busy-wait). The controller answers that state; its
    command is applied the moment it arrives, stepping the physics to k + 1, whose state then
    waits for t_k+1. If no answer has come ``realtime.STEP_LEAD_S`` before t_k+1, and at least
    ``realtime.MIN_ANSWER_FRACTION`` of a period after the state went out, the last command is
    applied again (a stale tick; ``realtime.answer_deadline``, ``await_answer``). So the
    controller has nearly the whole period to answer, even for a state published late, and
    the publication never waits for the physics. After a stall the ticks resynchronise.
    """
    realtime.set_timer_slack(1)  # wake-ups on time, so the busy-wait can be short
    clock, stats = time.perf_counter, stepper.stats
    next_t = clock() + period_s
    periodic = _Periodic(stats, clock())
    while ok():
        realtime.await_answer(executor, stepper.answered, realtime.answer_deadline(
            next_t, stepper.published_at(), period_s), ok)
        fresh = stepper.answered()
        t0 = clock()
        stepper.advance()
        step_s = clock() - t0
        now = realtime.wait_for_tick(executor, next_t)
        if not ok():
            break
        late = now - next_t
        if late > 0.5 * period_s:
            stats.missed_deadlines += 1
        stepper.publish_state()
        stats.record_step(now, step_s + clock() - now, late, fresh)
        next_t += period_s
        skipped = realtime.ticks_to_skip(next_t, period_s, clock())  # stalled: resync
        stats.missed_deadlines += skipped
        next_t += skipped * period_s
        line = periodic.due(now)
        if line is not None:
            stepper.every_second(line)


def run_lockstep(stepper: Stepper, executor: Any, dt_s: float, ok: Callable[[], bool]) -> None:
    """
    Lockstep: step as soon as the last state is answered (or ``lockstep_timeout`` passed).

    At most ``max_real_time_factor`` times faster than real time, if that is set (> 0).
    """
    clock, stats = time.perf_counter, stepper.stats
    last_step = clock()
    periodic = _Periodic(stats, last_step)
    while ok():
        config = stepper.config()
        deadline = last_step + config.lockstep_timeout_s
        while not stepper.answered():
            remaining = deadline - clock()
            if remaining <= 0.0:
                stats.lockstep_timeouts += 1
                break
            executor.spin_once(timeout_sec=remaining)
            if not ok():
                return
        rtf = config.max_real_time_factor
        if rtf > 0.0:
            earliest = last_step + dt_s / rtf
            while (remaining := earliest - clock()) > 0.0 and ok():
                executor.spin_once(timeout_sec=remaining)
        last_step = clock()
        fresh = stepper.answered()
        stepper.advance()
        stepper.publish_state()
        stats.record_step(last_step, clock() - last_step, 0.0, fresh)
        line = periodic.due(last_step)
        if line is not None:
            stepper.every_second(line)

"""
The controller's throwaway tick on a node's timer (``realtime.Prewarm`` decides when).

Armed by each state's arrival, on the steady clock (as the arrival times): it fires
``prewarm_lead`` before the next state is due and runs ``run`` once, so that the real tick finds
its code and data in the CPU caches. ROS marshalling around the ROS-free ``realtime.Prewarm``.
"""
import time
from typing import Callable, Optional

from quat_jt_runtime.realtime import Prewarm
from rclpy.clock import Clock, ClockType
from rclpy.node import Node


def prewarm_off_reason(lead_s: float, composed: bool, simulated_time: bool) -> str:
    """Return why the throwaway tick is off ('' if it is on)."""
    return ('prewarm_lead is 0' if lead_s <= 0.0 else 'composed' if composed else
            'simulated time' if simulated_time else '')


def describe_prewarm(lead_s: float, off: str) -> str:
    """Describe the throwaway tick for the start-up log (``off``: why it is off, or '')."""
    return (f'prewarm: off ({off})' if off else
            f'prewarm: a throwaway tick {lead_s * 1e3:g} ms before each state is due (while '
            f'states come at least {2e3 * lead_s:g} ms apart)')


class PrewarmTimer:
    """A one-shot steady-clock timer, re-armed by every state, that runs ``run`` once."""

    def __init__(self, node: Node, lead_s: float, run: Callable[[], None]) -> None:
        self._prewarm = Prewarm(int(lead_s * 1e9))
        self._run = run
        self._delay_ns = 0
        self._timer = node.create_timer(1e-3, self._fire, autostart=False,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    def arrived(self, arrival_ns: int, now_ns: int) -> None:
        """Set the throwaway tick to run ``prewarm_lead`` before the next state is due."""
        timer = self._timer
        delay_ns: Optional[int] = self._prewarm.arrived(arrival_ns, now_ns)
        if delay_ns is None:
            timer.cancel()
            return
        if abs(delay_ns - self._delay_ns) > delay_ns >> 5:  # moved > 3%: reprogram
            self._delay_ns = timer.timer_period_ns = max(delay_ns, 1)
        timer.reset()

    def _fire(self) -> None:
        """Run the throwaway tick once per state (a timer that fired early stays armed)."""
        run = self._prewarm.take(time.perf_counter_ns())
        if run is None:  # fired for an earlier state: the timer stays armed for this one
            return
        self._timer.cancel()  # once per state: no wake-ups while states are away
        if run:
            self._run()

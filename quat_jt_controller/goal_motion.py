"""
The velocity of a streamed goal, estimated from its stamps (docs/lyapunov.md, section 7).

A teleoperation device, a visual-servoing loop or a planner streams goals at 30 to 1000 Hz, each
stamped when it was made. The regulator damps the joint velocity towards the goal's own (the
goal-check worker maps this task velocity to the joints at q*,
``inverse_kinematics.configuration_velocity``), so it needs that velocity: the motion between the
newest goal and the newest one at least ``min_span_s`` older, divided by the difference of their
stamps (not of their arrival times, which the network jitters). The span smooths the difference
of nearly equal goals at high rates.

A goal that is not stamped, not newer than the last, or more than ``max_gap_s`` after it starts
a new stream: a fixed goal until a later one gives a span. Past :meth:`hold_s` after the last
goal of a stream, its velocity is no longer in force (the caller makes it a fixed goal again).
ROS-free and numpy-free: it runs on every goal, on the control thread.
"""
from collections import deque
from typing import Optional, Sequence

from quat_jt_controller import quaternion as quat

MIN_SPAN_S = 0.02  # the velocity is the motion over at least this much stamp time
MAX_GAP_S = 0.25  # a goal this long after the last starts a new stream
HOLD_PERIODS = 3.0  # the velocity stays in force this many stream periods after the last goal
MIN_HOLD_S = 0.05  # and at least this long: a fast stream's publisher jitters by milliseconds


class GoalVelocityEstimator:
    """
    The task velocity of a stream of goals: ``[v; omega]``, ``omega`` or ``v``, per task.

    ``[v; omega]`` for the pose task, ``omega`` for the orientation task (``with_position``
    False), ``v`` for the position task (``with_orientation`` False).
    ``omega`` is the angular velocity in the base frame (rad/s) of ``q_d``, ``v`` the velocity
    of ``p_d`` (m/s); in the task's rows, as ``J qdot`` gives them.
    """

    def __init__(self, with_position: bool, min_span_s: float = MIN_SPAN_S,
                 max_gap_s: float = MAX_GAP_S, with_orientation: bool = True) -> None:
        self._with_position = with_position
        self._with_orientation = with_orientation
        self._min_span_s = min_span_s
        self._max_gap_s = max_gap_s
        # (stamp s, quaternion, position): the newest, and older ones back to the span
        self._samples: deque[tuple[float, quat.Quaternion, Sequence[float]]] = deque()
        self._period_s = 0.0

    def reset(self) -> None:
        """Forget the stream: the next goal is a fixed goal."""
        self._samples.clear()
        self._period_s = 0.0

    def update(self, stamp_s: float, q_desired: quat.Quaternion,
               p_desired: Sequence[float]) -> Optional[tuple[float, ...]]:
        """Take the next goal of the stream; return its task velocity, or None (fixed)."""
        samples = self._samples
        if stamp_s <= 0.0 or (samples and not 0.0 < stamp_s - samples[-1][0] <= self._max_gap_s):
            self.reset()
        if samples:
            self._period_s = stamp_s - samples[-1][0]
        samples.append((stamp_s, q_desired, p_desired))
        # keep the newest sample at least the span older than this one, and those after it
        while len(samples) > 2 and stamp_s - samples[1][0] >= self._min_span_s:
            samples.popleft()
        t_ref, q_ref, p_ref = samples[0]
        span = stamp_s - t_ref
        if span < self._min_span_s:
            return None
        v = ((p_desired[0] - p_ref[0]) / span, (p_desired[1] - p_ref[1]) / span,
             (p_desired[2] - p_ref[2]) / span)
        if not self._with_orientation:
            return v
        w = quat.rotation_vector(*quat.orientation_error(q_ref, q_desired))
        omega = (w[0] / span, w[1] / span, w[2] / span)
        if not self._with_position:
            return omega
        return v + omega

    def hold_s(self) -> float:
        """Return how long after the last goal its velocity stays in force (s)."""
        return min(self._max_gap_s, max(MIN_HOLD_S, HOLD_PERIODS * self._period_s))

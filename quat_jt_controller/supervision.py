"""
What the controller decides around the law, ROS-free: the node only marshals.

:class:`Supervisor` owns the decisions the controller node used to make inline, so that unit
tests drive them with plain numbers:

- until the first goal, hold the pose of the first valid joint state;
- a stream of stamped goals: its velocity (``goal_motion``), which stops when the stream does;
- a goal equal to the one in force is not a new goal (no log, no new check);
- the state watchdog: after ``state_timeout`` without a valid state, zero the command once;
- no valid state at all since start: a warning after ``NO_STATE_WARN_NS``, then one every
  ``NO_STATE_REPEAT_NS`` while it lasts (a topic remapped wrong looks like a working node);
- feedback every ``publish_rate_divider``-th tick, its quaternion kept in one hemisphere;
- ``/diagnostics``: right after the next command while states flow, else at once;
- the goal check (a worker process, ``goal_check.GoalCheckWorker``): what to ask it for a new
  goal, and its answers applied to the goal still in force, the warnings to log said once.

Times are integers of nanoseconds on one monotonic clock, given by the caller.
"""
from dataclasses import dataclass
from typing import Any, Optional, Sequence

from quat_jt_controller import quaternion as quat
from quat_jt_controller.goal_check import Posture
from quat_jt_controller.goal_motion import GoalVelocityEstimator
from quat_jt_controller.regulator import Goal, Regulator

# /diagnostics wait for the next tick while states come at least this often (else: at once)
DIAGNOSTICS_WAIT_NS = 20_000_000
# No valid state since start: the first warning after this long (within 2 s, on the watchdog
# timer), then one every NO_STATE_REPEAT_NS
NO_STATE_WARN_NS = 1_800_000_000
NO_STATE_REPEAT_NS = 10_000_000_000


@dataclass(frozen=True)
class GoalTaken:
    """What :meth:`Supervisor.on_goal` did with a goal."""

    new: bool  # differs from the goal it replaced: log it, check it
    nu_desired_base: Optional[tuple[float, ...]]  # the stream's task velocity, or None


class Supervisor:
    """The controller's decisions around :class:`Regulator`; one per node."""

    def __init__(self, regulator: Regulator, state_timeout_s: float,
                 publish_rate_divider: int, checker: Optional[Any] = None,
                 started_ns: int = 0) -> None:
        """
        ``checker``: the goal-check worker (``submit``, ``poll``, ``take_*``), None for none.

        ``started_ns``: when the node started, for :meth:`no_state_yet`.
        """
        self.regulator = regulator
        self.checker = checker
        self.goal_warning = ''  # the goal check's warning for the goal in force ('' = none)
        self.state_timeout_ns = int(state_timeout_s * 1e9)
        self.publish_rate_divider = publish_rate_divider
        self.goal_source = 'none'  # 'none' | 'hold' (initial pose) | 'target_pose'
        self.stopped = False  # commanding zeros after a state timeout
        self.last_state_ns = 0  # the last valid state; 0: none yet
        self._motion = GoalVelocityEstimator(regulator.task.has_position,
                                             with_orientation=regulator.task.has_orientation)
        self._goal_velocity_until_ns = 0  # 0: not a stream (a fixed goal)
        self._decimation = 0
        self._published_q: quat.Quaternion = (1.0, 0.0, 0.0, 0.0)
        self.diagnostics_due = False
        self._last_stamp_ns = 0
        self.started_ns = started_ns
        self._no_state_warn_ns = started_ns + NO_STATE_WARN_NS  # the next warning, if none yet

    def tick_interval_s(self, stamp_ns: int) -> float:
        """
        Return the time since the last state's stamp (s), the tick's time step; 0 if unknown.

        0 for the first state, an unstamped one, or one not newer than the last: a tick of
        zero length re-evaluates the law without advancing its slow state (the friction
        learned at rest). The regulator caps long gaps.
        """
        last, self._last_stamp_ns = self._last_stamp_ns, stamp_ns
        if last <= 0 or stamp_ns <= last:
            return 0.0
        return (stamp_ns - last) * 1e-9

    # -- states ---------------------------------------------------------------------------
    def before_tick(self, q: Sequence[float], now_ns: int) -> Optional[Goal]:
        """
        Prepare the tick of a valid state at ``q``: return the held pose on the first state.

        Until a goal arrives the regulator holds the pose measured here (q* = q). A stream
        whose last goal is older than its hold becomes a fixed goal again.
        """
        if self.regulator.goal is None:
            self.goal_source = 'hold'
            return self.regulator.hold(q)
        if self._goal_velocity_until_ns and now_ns > self._goal_velocity_until_ns:
            self._goal_velocity_until_ns = 0  # the stream stopped: a fixed goal again
            self.regulator.set_goal_joint_velocity(None)
        return None

    def after_tick(self, now_ns: int) -> tuple[bool, bool, bool]:
        """
        Close a tick: return (states are back after a stop, feedback due, diagnostics due).

        Feedback is due every ``publish_rate_divider``-th tick; owed diagnostics now, with the
        command out and the next state about a period away.
        """
        self.last_state_ns = now_ns
        resumed, self.stopped = self.stopped, False
        self._decimation += 1
        feedback = self._decimation >= self.publish_rate_divider
        if feedback:
            self._decimation = 0
        diagnostics, self.diagnostics_due = self.diagnostics_due, False
        return resumed, feedback, diagnostics

    def on_silence(self, now_ns: int) -> Optional[float]:
        """Return the seconds without a valid state once they pass the timeout (once), or None."""
        if self.stopped or not self.last_state_ns:
            return None
        silent_ns = now_ns - self.last_state_ns
        if silent_ns <= self.state_timeout_ns:
            return None
        self.stopped = True
        return silent_ns * 1e-9

    def no_state_yet(self, now_ns: int) -> Optional[float]:
        """
        Return the seconds since start when no valid state has come and a warning is due.

        The first after ``NO_STATE_WARN_NS``, then one every ``NO_STATE_REPEAT_NS`` while no
        valid state comes; None otherwise, and for good once one has.
        """
        if self.last_state_ns or now_ns < self._no_state_warn_ns:
            return None
        self._no_state_warn_ns = now_ns + NO_STATE_REPEAT_NS
        return (now_ns - self.started_ns) * 1e-9

    def on_diagnostics_timer(self, now_ns: int) -> bool:
        """At 1 Hz: return True to publish now; else they go out after the next command."""
        flowing = self.last_state_ns and now_ns - self.last_state_ns < DIAGNOSTICS_WAIT_NS
        if flowing and not self.diagnostics_due:
            self.diagnostics_due = True
            return False
        self.diagnostics_due = False
        return True

    def published_quaternion(self, R_tip_base: Sequence[Sequence[float]]) -> quat.Quaternion:
        """Return the measured orientation in the hemisphere of the last one published."""
        q = quat.same_hemisphere(quat.from_rotation_matrix(R_tip_base), self._published_q)
        self._published_q = q
        return q

    # -- goals ----------------------------------------------------------------------------
    def on_goal(self, goal: Goal, stamp_s: float, now_ns: int) -> GoalTaken:
        """Put a valid goal in force; estimate the stream's velocity from its stamp."""
        previous = self.regulator.goal
        self.regulator.set_goal(goal)
        self.goal_source = 'target_pose'
        nu_desired = self._motion.update(stamp_s, goal.q_desired_base, goal.p_desired_base)
        if nu_desired is None:  # a fixed goal, or the first of a stream
            self._goal_velocity_until_ns = 0
            self.regulator.set_goal_joint_velocity(None)
        else:  # a stream: its joint velocity comes from the worker, until the stream stops
            self._goal_velocity_until_ns = now_ns + int(self._motion.hold_s() * 1e9)
        return GoalTaken(goal != previous, nu_desired)

    @property
    def streaming(self) -> bool:
        """Tell whether a stream of goals is in force (its velocity may be given)."""
        return self._goal_velocity_until_ns != 0

    def on_goal_velocity(self, qdot_desired: Sequence[float]) -> bool:
        """Give the stream's joint velocity (from the worker) if the stream goes on."""
        if not self.streaming:
            return False
        self.regulator.set_goal_joint_velocity(qdot_desired)
        return True

    # -- the goal check --------------------------------------------------------------------
    def check_goal(self, goal: Goal, nu_desired: Optional[Sequence[float]],
                   q_measured: Optional[Sequence[float]]) -> None:
        """
        Ask the worker about a new goal: A1/A2, q* (when a term uses it), and a stream's qdot*.

        q* is searched from the measured joints, within the band margin when the
        goal-configuration term or goal tracking needs it, near the preferred posture.
        """
        shaping = self.regulator.shaping
        tracking = shaping.goal_velocity_gain > 0.0 and nu_desired is not None
        self.goal_warning = ''
        if self.checker is None:
            return
        self.checker.submit(
            goal, q_measured, goal.q_desired_base, goal.p_desired_base,
            shaping.joint_limit_margin_rad if shaping.configuration_on or tracking else None,
            nu_desired if tracking else None,
            Posture(shaping.preferred_configuration_rad or None, shaping.posture_weight))

    def take_checks(self) -> tuple[Optional[str], list[str]]:
        """
        Apply the worker's answers; return (the worker's failure, the warnings to log).

        q* and qdot* go to the regulator for the goal they answer (the regulator ignores a
        goal no longer in force). A verdict counts only for the goal still in force, and a
        warning is logged once per change. The failure is given once per death (the worker
        restarts by itself); a verdict without a goal (the worker exited) is skipped.
        """
        checker = self.checker
        if checker is None:
            return None, []
        verdicts = checker.poll()
        failure = checker.take_failure()
        warnings = []
        for goal, verdict in verdicts:
            if goal is None:
                continue
            q_star = checker.take_configuration(goal)
            if q_star is not None:  # the goal-configuration term pulls towards it
                self.regulator.set_goal_configuration(goal, q_star)
            qdot_star = checker.take_configuration_velocity(goal)
            if qdot_star is not None:  # taken while the stream goes on
                self.on_goal_velocity(qdot_star)
            if goal is self.regulator.goal and verdict != self.goal_warning:
                self.goal_warning = verdict
                if verdict:
                    warnings.append(f'goal {goal.describe(False)} accepted with a warning: '
                                    f'{verdict}')
        return failure, warnings

"""
The controller around the law, ROS-free: a joint state in, a command out; a goal in, its log.

:class:`Controller` owns the goal and every decision around :meth:`Regulator.update
<quat_jt_controller.regulator.Regulator.update>`, the one control tick, so that the node only
reads a message, calls :meth:`Controller.on_state` and publishes the :class:`Command` (as
ros2_controllers' read, update, write):

- the state check: the controlled joints by name, the stamp's age, velocities estimated when
  a driver sends none (``quat_jt_runtime.joints.StateCheck``);
- until the first goal, hold the pose of the first valid joint state (q* = q);
- goals given in any link of the URDF, placed in the base (``goal_frames``); a goal equal to
  the one in force is not a new goal (no log, no new check);
- a stream of stamped goals: its velocity (``goal_motion``), which stops when the stream does;
- the goal check (a worker process, ``goal_check.GoalCheckWorker``): what to ask it for a new
  goal, and its answers (A1/A2, q*, the stream's qdot*) applied to the goal still in force,
  each warning said once;
- the state watchdog: after ``state_timeout`` without a valid state, zero the command once;
- no valid state at all since start: a warning after ``NO_STATE_WARN_NS``, then one every
  ``NO_STATE_REPEAT_NS`` while it lasts (a topic remapped wrong looks like a working node);
- feedback every ``publish_rate_divider``-th tick, its quaternion kept in one hemisphere;
- ``/diagnostics``: right after the next command while states flow, else at once; their
  content (``diagnostics.py``) and the stall detection (``stall.py``);
- the log lines to emit, with their severity, rate-limited per cause.

Two clocks, both read by the caller, once per call: ``now_ns``, the clock of the states'
stamps (ROS time), only to check a stamp's age; ``steady_ns``, a monotonic clock in ns, for
everything the controller times (the watchdog, streams, decimation of diagnostics, the stall,
the log throttles).
"""
from enum import IntEnum
from typing import Any, Callable, Mapping, NamedTuple, Optional, Sequence

from quat_jt_controller import diagnostics
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Gains
from quat_jt_controller.goal_check import Posture
from quat_jt_controller.goal_frames import GoalFrames
from quat_jt_controller.goal_motion import GoalVelocityEstimator
from quat_jt_controller.redesign import DESIGN_SHARE, InertiaWatch
from quat_jt_controller.regulator import Goal, Regulator, TickOutput
from quat_jt_controller.stall import identify_payload, StallDetector
from quat_jt_runtime.joints import (DEFAULT_STATE_RATE_HZ, ForeignState, StaleState,
                                    StateCheck)
from quat_jt_runtime.joints import VELOCITY_WINDOW_STATES
from quat_jt_runtime.payload import Payload
from quat_jt_runtime.throttle import cause, Throttle

# /diagnostics wait for the next tick while states come at least this often (else: at once)
DIAGNOSTICS_WAIT_NS = 20_000_000
# No valid state since start: the first warning after this long (within 2 s, on the node's
# timer), then one every NO_STATE_REPEAT_NS
NO_STATE_WARN_NS = 1_800_000_000
NO_STATE_REPEAT_NS = 10_000_000_000
THROTTLE_S = 1.0  # rejected goals and states, non-finite torques: one line a second and cause
GOAL_LOG_PERIOD_S = 0.2  # accepted distinct goals: one line each, at most 5 a second


class Severity(IntEnum):
    """The severity of a log line (the values of rclpy's ``LoggingSeverity``)."""

    INFO = 20
    WARN = 30
    ERROR = 40


def _values(told: Sequence[float], found: Sequence[float] = ()) -> str:
    """Return the armature told plus the one found, as design_gains --armature takes it."""
    return ' '.join(f'{a + e:.3g}' for a, e in zip(told, found or [0.0] * len(told)))


class LogLine(NamedTuple):
    """A line for the node's log."""

    severity: Severity
    text: str


NO_LOGS: tuple[LogLine, ...] = ()


class Command(NamedTuple):
    """
    What :meth:`Controller.on_state` (or the watchdog) decided: publish ``tau_nm``, then the rest.

    ``tau_nm`` is None when the state was refused (nothing to publish). ``feedback`` is the
    measured orientation (scalar first, in the hemisphere of the last one published) when a
    feedback sample is due, with ``out`` the tick's pose and errors; ``diagnostics`` says that
    ``/diagnostics`` are due now (:meth:`Controller.statuses`).
    """

    tau_nm: Optional[list[float]]
    out: Optional[TickOutput] = None
    feedback: Optional[quat.Quaternion] = None
    diagnostics: bool = False
    logs: tuple[LogLine, ...] = NO_LOGS


class GoalRequest(NamedTuple):
    """A goal as it came, in plain values: its frame, orientation, position and stamp."""

    frame_id: str
    xyzw: tuple[float, float, float, float]  # ROS order
    position_m: tuple[float, float, float]
    stamp_s: float = 0.0  # 0: not stamped (a fixed goal)


class GoalReply(NamedTuple):
    """What :meth:`Controller.on_goal` did with a goal request."""

    accepted: bool
    new: bool  # accepted and different from the goal it replaced: logged and checked
    nu_desired_base: Optional[tuple[float, ...]]  # the stream's task velocity, or None
    logs: tuple[LogLine, ...] = NO_LOGS


class Controller:
    """
    The goal and the decisions around one :class:`Regulator`; one per controller node.

    :param regulator: the law; the controller is the only one to set its goal, q* and qdot*.
    :param state_timeout_s: the watchdog: no valid state for longer, and the command is zero.
    :param publish_rate_divider: a feedback sample every this many ticks.
    :param max_state_age_s: a state older than this (or from the future) is refused; 0: off.
    :param state_rate_hz: the states' expected rate (the velocity estimate's time constant).
    :param checker: the goal-check worker (``submit``, ``poll``, ``take_*``), or None.
    :param started_ns: when the node started (``steady_ns``), for :meth:`no_state_yet`.
    :param position_resolution: a count of each joint's position in the states (0: exact),
        for the velocity estimate of states without velocities.
    :param designer: the design worker (``redesign.DesignWorker``: ``submit``, ``poll``,
        ``take_failure``, ``busy``, ``ready``, ``unavailable_reason``), or None: the gains are
        never designed again.
    :param parameter_values: the parameters in force by ROS name, read when a design starts.
    """

    def __init__(self, regulator: Regulator, state_timeout_s: float,
                 publish_rate_divider: int, max_state_age_s: float = 0.0,
                 state_rate_hz: float = DEFAULT_STATE_RATE_HZ, checker: Optional[Any] = None,
                 started_ns: int = 0,
                 position_resolution: Optional[Sequence[float]] = None,
                 designer: Optional[Any] = None,
                 parameter_values: Optional[Callable[[], Mapping[str, Any]]] = None) -> None:
        self.regulator = regulator
        model = regulator.model
        self.checker = checker
        self.has_position = regulator.task.has_position  # the goal's parts the task reads
        self.has_orientation = regulator.task.has_orientation
        self.state_timeout_s = state_timeout_s
        self.state_timeout_ns = int(state_timeout_s * 1e9)
        self.state_rate_hz = state_rate_hz
        self.publish_rate_divider = publish_rate_divider
        self.started_ns = started_ns
        self.counters = diagnostics.Counters()
        self.stall = StallDetector(regulator)
        self._frames = GoalFrames(model, regulator.task)  # the base and every link
        self._check_state = StateCheck(model.joint_names, max_state_age_s, state_rate_hz,
                                       model.continuous, position_resolution)
        self.position_resolution = tuple(position_resolution or ())
        self._zero = [0.0] * regulator.n
        # the goal
        self.goal_source = 'none'  # 'none' | 'hold' (initial pose) | 'target_pose'
        self.goal_warning = ''  # the goal check's warning for the goal in force ('' = none)
        self.goal_anchor: Optional[Sequence[float]] = None  # the tip when the goal took force
        self._motion = GoalVelocityEstimator(self.has_position,
                                             with_orientation=self.has_orientation)
        self._goal_velocity_until_ns = 0  # 0: not a stream (a fixed goal)
        # the states
        self.last: Optional[TickOutput] = None  # the last tick's output, q and qdot
        self.last_q: Optional[list[float]] = None
        self.last_qdot: Optional[list[float]] = None
        self.last_state_ns = 0  # the last valid state (steady_ns); 0: none yet
        self.stopped = False  # commanding zeros after a state timeout
        self.command_refusal = ''  # why no command is published, if one is not (refuse_commands)
        self._tick_clock = 0  # the clock of the last state's time: 1 its stamp, 2 its arrival
        self._tick_ns = 0  # ... and that time (ns)
        self._said_estimating = False
        self._armature_said: set[int] = set()  # joints whose rotor inertia found was said
        # ... when it has settled, and when the gains are due a design again (its armature)
        self._inertia = InertiaWatch(model.armature, started_ns * 1e-9)
        self.designer = designer
        self._parameter_values = parameter_values
        self._no_state_warn_ns = started_ns + NO_STATE_WARN_NS  # the next warning, if none yet
        # what goes out
        self._decimation = 0
        self._published_q: quat.Quaternion = (1.0, 0.0, 0.0, 0.0)
        self._diagnostics_due = False
        self._steady_ns = started_ns  # the throttles' clock: the last time given
        clock = self._clock_s
        self._reject_log = Throttle(THROTTLE_S, clock)  # per cause (the reason without numbers)
        self._nonfinite_log = Throttle(THROTTLE_S, clock)
        self._goal_log = Throttle(GOAL_LOG_PERIOD_S, clock)

    def _clock_s(self) -> float:
        return self._steady_ns * 1e-9

    @property
    def gains(self) -> Gains:
        """Return the gains in force (immutable)."""
        return self.regulator.gains

    @property
    def goal(self) -> Optional[Goal]:
        """Return the goal in force (immutable), or None before the first state or goal."""
        return self.regulator.goal

    @property
    def has_state(self) -> bool:
        """Tell whether a valid joint state has come since start."""
        return self.last_state_ns != 0

    @property
    def streaming(self) -> bool:
        """Tell whether a stream of goals is in force (its velocity may be given)."""
        return self._goal_velocity_until_ns != 0

    # -- states ---------------------------------------------------------------------------
    def on_state(self, names: Sequence[str], positions: Sequence[float],
                 velocities: Sequence[float], stamp_ns: int, now_ns: int,
                 steady_ns: int) -> Command:
        """
        One control tick: check the state, keep the goal, run the law, say what goes out.

        ``stamp_ns``: the state's stamp (0: unstamped) and ``now_ns`` the time on its clock;
        ``steady_ns``: the monotonic clock. A refused state gives no torque and its reason
        (rate-limited per cause); the watchdog goes on counting from the last valid state.
        """
        self._steady_ns = steady_ns
        try:
            q, qdot = self._check_state(names, positions, velocities, stamp_ns, now_ns)
        except ForeignState as exc:  # another publisher's (a gripper's): ignored, said once
            self.counters.foreign_states += 1
            if self.counters.foreign_states > 1:
                return Command(None)
            return Command(None, logs=(LogLine(Severity.INFO, (
                f'joint_states from another publisher: it {exc}; such states are ignored '
                '(counted as foreign_states_total on /diagnostics)')),))
        except ValueError as exc:
            self.counters.rejected_states += 1
            self.counters.stale_states += isinstance(exc, StaleState)
            return Command(None, logs=self._rejection('joint_states', str(exc)))
        logs = NO_LOGS
        if self._check_state.estimating and not self._said_estimating:
            self._said_estimating = True
            logs += (LogLine(Severity.WARN, self._estimating(stamp_ns)),)
        regulator = self.regulator
        if regulator.goal is None:  # until a goal arrives, hold the pose measured here
            self.goal_source = 'hold'
            held = regulator.hold(q)
            self.goal_anchor = held.p_desired_base
            logs += (LogLine(Severity.INFO, (
                f'first joint state, {(steady_ns - self.started_ns) * 1e-9:.2f} s after '
                f'start: holding the measured pose, '
                f'{held.describe(self.has_position, self.has_orientation)}')),)
        elif self._goal_velocity_until_ns and steady_ns > self._goal_velocity_until_ns:
            self._goal_velocity_until_ns = 0  # the stream stopped: a fixed goal again
            regulator.set_goal_joint_velocity(None)
        out = regulator.update(q, qdot, self._tick_interval_s(stamp_ns, steady_ns))
        self.last, self.last_q, self.last_qdot = out, q, qdot
        self.stall.feed(steady_ns * 1e-9, q, qdot, out)
        if not out.finite:
            self.counters.nonfinite_torques += 1
            if self._nonfinite_log('nonfinite') is not None:
                logs += (LogLine(Severity.ERROR, (
                    f'the law gave a non-finite torque at q = {q} (gains {self.gains}): '
                    'published zero torque')),)
        self.last_state_ns = steady_ns
        if self.stopped:
            self.stopped = False
            logs += (LogLine(Severity.INFO, 'joint_states are back: commanding torque again'),)
        self._decimation += 1
        feedback = None
        if self._decimation >= self.publish_rate_divider:
            self._decimation = 0
            feedback = self._published_quaternion(out.R_tip_base)
        due, self._diagnostics_due = self._diagnostics_due, False
        if self.command_refusal:  # nothing of ours reaches the plant
            regulator.torque_withheld()
            return Command(None, out, feedback, due, logs)
        return Command(out.tau_nm, out, feedback, due, logs)

    def _estimating(self, stamp_ns: int) -> str:
        rate = self.state_rate_hz
        if any(r > 0.0 for r in self.position_resolution):
            how = (f'on the longest window of up to {VELOCITY_WINDOW_STATES} states that '
                   'position_resolution allows, 0 while a joint stays within one count')
        else:
            how = (f'finite differences, low-pass of time constant {1e3 / rate:g} ms = one '
                   f'period at state_rate {rate:g} Hz; from an encoder, give its count as '
                   'position_resolution')
        unmeasured = self._check_state.unmeasured
        what = (f"joint_states carry NaN velocities for {list(unmeasured)} (ros2_control's "
                'joint_state_broadcaster publishes NaN where the hardware has no velocity '
                'state interface): estimating them' if unmeasured else
                'joint_states carry no velocities: estimating them')
        return (what + ' from the positions and '
                + ('their stamps' if stamp_ns else 'their arrival times (no stamps)')
                + f' ({how}); a driver that publishes velocities gives better damping')

    def _tick_interval_s(self, stamp_ns: int, steady_ns: int) -> float:
        """
        Return the time since the last state (s), the tick's time step; 0 if unknown.

        From the states' stamps; for unstamped ones (a driver that sends none, with
        ``max_state_age`` 0) from their arrival times, as the velocity estimate does. 0 for
        the first state, one not newer than the last, or one on the other clock than the last:
        a tick of zero length re-evaluates the law without advancing its slow state (the
        friction learned at rest, the goal-configuration term's fade-in). The regulator caps
        long gaps.
        """
        if stamp_ns > 0:
            clock, now_ns = 1, stamp_ns
        else:
            clock, now_ns = 2, steady_ns
        last_clock, last_ns = self._tick_clock, self._tick_ns
        self._tick_clock, self._tick_ns = clock, now_ns
        if clock != last_clock or last_ns <= 0 or now_ns <= last_ns:
            return 0.0
        return (now_ns - last_ns) * 1e-9

    def _published_quaternion(self, R_tip_base: Sequence[Sequence[float]]) -> quat.Quaternion:
        """Return the measured orientation in the hemisphere of the last one published."""
        q = quat.same_hemisphere(quat.from_rotation_matrix(R_tip_base), self._published_q)
        self._published_q = q
        return q

    def prewarm(self) -> None:
        """Run the last state's law again, its output dropped (the caches stay warm)."""
        if self.last_q is None:
            return
        self.regulator.update(self.last_q, self.last_qdot)
        self.counters.prewarm_passes += 1

    # -- timers ---------------------------------------------------------------------------
    def on_watchdog(self, steady_ns: int) -> Optional[Command]:
        """
        Return a zero command, once, when valid states stopped for longer than the timeout.

        None otherwise, and before the first state (nothing was commanded yet).
        """
        if self.stopped or not self.last_state_ns:
            return None
        silent_ns = steady_ns - self.last_state_ns
        if silent_ns <= self.state_timeout_ns:
            return None
        self.stopped = True
        return Command(list(self._zero), logs=(LogLine(Severity.ERROR, (
            f'no valid joint_states for {silent_ns * 1e-9:.3f} s (> state_timeout '
            f'{self.state_timeout_s} s): published zero torque, waiting for states')),))

    def identify_payload(self) -> tuple[Optional[Payload], str]:
        """
        Return the payload the tip carries as the torque held at rest shows it, and why.

        ``stall.identify_payload`` at the last state and the last tick's torque. None, with the
        reason, before any state, or while no torque of ours holds the arm (the states timed
        out, the commands are refused, the last torque was not finite).
        """
        if self.last is None or self.last_q is None or self.last_qdot is None:
            return None, 'no joint state yet: identify the payload with the arm at rest'
        if self.stopped or self.command_refusal or not self.last.finite:
            return None, ('no torque of ours holds the arm now (the states timed out, the '
                          'commands are refused, or the last one was not finite): nothing '
                          'to fit')
        return identify_payload(self.regulator, self.last_q, self.last_qdot, self.last.tau_nm)

    def refuse_commands(self, reason: str) -> Optional[Command]:
        """
        Stop commanding torque for ``reason`` (a receiver that would misapply it).

        Returns a zero command, once, with an ERROR: a receiver that holds its last command
        (ros2_control's JointGroupEffortController has no timeout) holds zero. The ticks go
        on (feedback, /diagnostics, the watchdog) but publish nothing until
        :meth:`allow_commands`. A new reason is logged again, with no second zero.
        """
        if reason == self.command_refusal:
            return None
        first = not self.command_refusal
        self.command_refusal = reason
        return Command(list(self._zero) if first else None,
                       logs=(LogLine(Severity.ERROR, reason),))

    def allow_commands(self) -> tuple[LogLine, ...]:
        """Command torque again after :meth:`refuse_commands`; say so (nothing if not refused)."""
        if not self.command_refusal:
            return NO_LOGS
        self.command_refusal = ''
        return (LogLine(Severity.INFO, 'the command receivers now take the joints in this '
                        "controller's order: commanding torque again"),)

    def no_state_yet(self, steady_ns: int) -> Optional[float]:
        """
        Return the seconds since start when no valid state has come and a warning is due.

        The first after ``NO_STATE_WARN_NS``, then one every ``NO_STATE_REPEAT_NS`` while no
        valid state comes; None otherwise, and for good once one has.
        """
        if self.last_state_ns or steady_ns < self._no_state_warn_ns:
            return None
        self._no_state_warn_ns = steady_ns + NO_STATE_REPEAT_NS
        return (steady_ns - self.started_ns) * 1e-9

    def on_diagnostics_timer(self, steady_ns: int) -> bool:
        """At 1 Hz: return True to publish now; else they are due after the next command."""
        last = self.last_state_ns
        flowing = last and steady_ns - last < DIAGNOSTICS_WAIT_NS
        if flowing and not self._diagnostics_due:
            self._diagnostics_due = True
            return False
        self._diagnostics_due = False
        return True

    # -- goals ----------------------------------------------------------------------------
    def on_goal(self, request: GoalRequest, steady_ns: int) -> GoalReply:
        """
        Validate a goal and put it in force, or refuse it with its reason (the last stays).

        A goal in a link of the robot is placed in the base with the last measured joints.
        A stamped stream gets its velocity; a new goal is logged (at most 5 lines a second)
        and given to the goal check.
        """
        self._steady_ns = steady_ns
        try:
            goal = self._frames.goal(request.frame_id, request.xyzw, request.position_m,
                                     self.last_q)
        except ValueError as exc:
            self.counters.rejected_goals += 1
            return GoalReply(False, False, None, self._rejection(
                'target_pose', f'previous goal stays in force: {exc}'))
        self.counters.accepted_goals += 1
        regulator = self.regulator
        previous = regulator.goal
        same = previous is not None and goal == previous
        if same:  # a repeated goal (a latched or periodic publisher) keeps its q* and check
            goal = previous
        else:
            regulator.set_goal(goal)
        self.goal_source = 'target_pose'
        nu_desired = self._motion.update(request.stamp_s, goal.q_desired_base,
                                         goal.p_desired_base)
        if nu_desired is None:  # a fixed goal, or the first of a stream
            self._goal_velocity_until_ns = 0
            regulator.set_goal_joint_velocity(None)
        else:  # a stream: its joint velocity comes from the worker, until the stream stops
            self._goal_velocity_until_ns = steady_ns + int(self._motion.hold_s() * 1e9)
        if same:
            return GoalReply(True, False, nu_desired)
        self.goal_anchor = None if self.last is None else self.last.p_tip_base
        self._check_goal(goal, nu_desired)
        frame, base = request.frame_id, self._frames.base_link
        placed = ('' if frame in ('', base) else
                  f' (given in {frame}, placed in {base} at the measured joints)')
        parts = (self.has_position, self.has_orientation)
        line = self._goal_log.line(  # one line per distinct goal, at most 5 a second
            'goal', lambda: f'new goal: {goal.describe(*parts)}{placed}',
            ' ({} more distinct goals since the last line)')
        return GoalReply(True, True, nu_desired,
                         NO_LOGS if line is None else (LogLine(Severity.INFO, line),))

    def _check_goal(self, goal: Goal, nu_desired: Optional[Sequence[float]]) -> None:
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
            goal, self.last_q, goal.q_desired_base, goal.p_desired_base,
            shaping.joint_limit_margin_rad if shaping.configuration_on or tracking else None,
            nu_desired if tracking else None,
            Posture(shaping.preferred_configuration_rad or None, shaping.posture_weight),
            self.regulator.model.payload)

    def take_goal_checks(self) -> tuple[LogLine, ...]:
        """
        Apply the worker's answers (never waits); return the lines to log.

        q* and qdot* go to the regulator for the goal they answer (the regulator ignores a
        goal no longer in force; qdot* only while the stream goes on). A verdict counts only
        for the goal still in force, and a warning is logged once per change. The worker's
        death is said once (it restarts by itself); a verdict without a goal is skipped.
        """
        checker = self.checker
        if checker is None:
            return NO_LOGS
        verdicts = checker.poll()
        failure = checker.take_failure()
        logs = NO_LOGS
        if failure is not None:
            logs += (LogLine(Severity.ERROR, f'{failure}; regulation goes on'),)
        regulator = self.regulator
        for goal, verdict in verdicts:
            if goal is None:
                continue
            q_star = checker.take_configuration(goal)
            if q_star is not None:  # the goal-configuration term pulls towards it
                regulator.set_goal_configuration(goal, q_star)
            qdot_star = checker.take_configuration_velocity(goal)
            if qdot_star is not None and self.streaming:
                regulator.set_goal_joint_velocity(qdot_star)
            if goal is regulator.goal and verdict != self.goal_warning:
                self.goal_warning = verdict
                if verdict:
                    said = goal.describe(self.has_position, self.has_orientation)
                    logs += (LogLine(Severity.WARN,
                                     f'goal {said} accepted with a warning: {verdict}'),)
        return logs

    def take_model_notes(self) -> tuple[LogLine, ...]:
        """
        Say once per joint that it moves as if it were more than twice as heavy as its model.

        The regulator's ``armature_estimate``, the rotor inertia the motion shows beyond the
        armature told, above the joint's own inertia in the model at the last state, and
        settled (``redesign.InertiaWatch``). The gains were sized for a joint that light: with
        ``gain_redesign`` and a designer, a design again is started at a look when one is due,
        the estimate settled or not (its answer: :meth:`take_design`). One M(q) a look.
        """
        found = self.regulator.armature_estimate  # a copy: read once
        q = self.last_q
        if q is None or not any(e > 0.0 for e in found):
            return NO_LOGS
        settled = self._inertia.settled(self._steady_ns * 1e-9, found)
        if settled is None:  # not a look
            return NO_LOGS
        regulator = self.regulator
        model = regulator.model
        own = model.own_inertias(q)
        logs = self._start_design(found, own)
        heavy = [(j, found[j], own[j] - found[j]) for j in settled
                 if found[j] > own[j] - found[j] and j not in self._armature_said]
        if not heavy:
            return logs
        self._armature_said.update(j for j, _, _ in heavy)
        limits = regulator.shaping.armature_estimation_limit_kg_m2
        joints = ', '.join(f'{model.joint_names[j]} {e:.3g} kg m^2 (its model {m:.3g}'
                           + ('; at its limit, armature_estimation_limit' if e >= limits[j]
                              else '') + ')' for j, e, m in heavy)
        then = ('the gains are being designed again for them (gain_redesign)'
                if self._redesigning else
                'the gains were sized without it. For gains sized for these joints, design '
                f'again with --armature {_values(model.armature, found)}')
        return (LogLine(Severity.WARN, (
            f'rotor inertia the model lacks, found from the motion: {joints}. The damping, the '
            'speed guard and the friction learning use it now (armature_estimate on '
            f'/diagnostics); {then}')),) + logs

    @property
    def _redesigning(self) -> bool:
        """Tell whether the gains are designed again when due (``gain_redesign``, a designer)."""
        return (self.designer is not None and self._parameter_values is not None
                and self.regulator.shaping.gain_redesign)

    def _start_design(self, found: Sequence[float],
                      own: Sequence[float]) -> tuple[LogLine, ...]:
        """Start a design again if one is due and allowed (``gain_redesign``, a designer)."""
        designer = self.designer
        if not self._redesigning or designer.busy:
            return NO_LOGS
        armature = self._inertia.due(found, own)
        if armature is None:
            return NO_LOGS
        self._inertia.designed_with(armature)  # tried once: not again for the same
        designer.submit(self._parameter_values(), armature)
        names = self.regulator.model.joint_names
        return (LogLine(Severity.INFO, (
            'designing the gains again for the rotor inertia found (gain_redesign): armature '
            + _values(armature) + f' kg m^2 per joint ({", ".join(names)}), '
            f'the armature told and {DESIGN_SHARE:g} x the estimate found')),)

    def take_design(self) -> tuple[Optional[dict], tuple[LogLine, ...]]:
        """
        Return the parameters of a design again that finished (or None), and its log.

        The caller sets them as one atomic change (the node: its own parameters, checked and
        logged as any ``ros2 param set``) and says how that went with :meth:`design_set`.
        A design that failed leaves the gains as they are (a WARN); a worker that died is said
        once (an ERROR: it starts again by itself).
        """
        designer = self.designer
        if designer is None:
            return None, NO_LOGS
        answer = designer.poll()
        failure = designer.take_failure()
        logs = NO_LOGS if failure is None else (
            LogLine(Severity.ERROR, f'{failure}; regulation goes on'),)
        if answer is None:
            return None, logs
        if 'error' in answer:
            return None, logs + (LogLine(Severity.WARN, (
                f'the gains could not be designed again with armature '
                f'[{_values(self._inertia.designed)}]: '
                f'{answer["error"]}; they stay as they are')),)
        return dict(answer['parameters']), logs

    def design_set(self, parameters: Mapping[str, Any], error: str = '') -> tuple[LogLine, ...]:
        """Say that the parameters of a design again are in force (or why they are not)."""
        told, armature = self._inertia.told, self._inertia.designed
        if error:
            return (LogLine(Severity.WARN, (
                f'the gains designed again with armature [{_values(armature)}] were not set: '
                f'{error}; they stay as they are')),)
        return (LogLine(Severity.INFO, (
            f'gains designed again for armature [{_values(armature)}] kg m^2 (told '
            f'[{_values(told)}]): set {", ".join(sorted(parameters)) or "nothing (no change)"}. '
            f'To start with them next time, design_gains --armature {_values(armature)} '
            '(gain_redesign false keeps the gains as set)')),)

    # -- reports --------------------------------------------------------------------------
    def statuses(self, figures: dict, graph_warnings: Sequence[str] = ()
                 ) -> list[tuple[str, int, str, list[tuple[str, str]]]]:
        """
        Return the ``/diagnostics`` statuses: the control loop, the goal and the stall.

        ``figures``: the loop's window (``TickStats.window``); ``graph_warnings``: what the
        node found in the ROS graph (a second commander, a second node of its name).
        """
        regulator, checker = self.regulator, self.checker
        unavailable = 'no goal-check worker' if checker is None else checker.unavailable_reason
        ready = checker is not None and checker.ready
        designer = self.designer
        designs = ((designer.ready, designer.unavailable_reason) if self._redesigning
                   else None)
        return [
            ('control loop', *diagnostics.loop_status(
                figures, not self.last_state_ns, self.stopped, self.counters, graph_warnings,
                self.command_refusal, () if self.last_q is None else
                diagnostics.gravity_beyond_effort(regulator, self.last_q))),
            ('goal', *diagnostics.goal_status(
                self.goal_source, regulator.goal, self.goal_warning, self.last, self.last_qdot,
                self.has_position, self.counters, unavailable, ready,
                diagnostics.configuration_state(regulator), designs)),
            ('stall', *self.stall.status())]

    def _rejection(self, topic: str, reason: str) -> tuple[LogLine, ...]:
        """Warn once per cause and second; held-back repeats are counted in the next line."""
        line = self._reject_log.line((topic, cause(reason)), f'{topic} rejected, {reason}')
        return NO_LOGS if line is None else (LogLine(Severity.WARN, line),)

"""
The regulator as a ROS 2 node: marshalling around ``regulator.Regulator`` (Eq. 22 + g(q)).

Each valid ``joint_states`` message is one tick: the command computed from it is published at
once on ``effort_controller/commands``. What to do around the law (hold the first pose, a
stream's velocity, the state watchdog, when feedback and diagnostics are due) is decided by the
ROS-free ``supervision.Supervisor``; this node marshals. ``~/target_pose`` goals are validated
like tf2 and in force at once; the A1/A2 advice comes later from a worker process. Feedback
(``~/current_pose``, ``~/orientation_error``, ``~/position_error``) is decimated;
``/diagnostics`` at 1 Hz. The gains are live parameters, applied as one immutable Gains
(``parameters.py``).
"""
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from quat_jt_controller import diagnostics
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Gains, GainsError, Task
from quat_jt_controller.goal_check import GoalCheckWorker, ModelSpec, Posture
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_controller.parameters import declare_gains, declare_shaping, declare_structural
from quat_jt_controller.parameters import describe_gains, GAIN_PARAMETERS, SHAPING_PARAMETERS
from quat_jt_controller.regulator import Goal, Regulator, TickOutput
from quat_jt_controller.shaping import describe as describe_shaping
from quat_jt_controller.stall import StallDetector
from quat_jt_controller.supervision import Supervisor
from quat_jt_runtime import lifecycle
from quat_jt_runtime import realtime
from quat_jt_runtime.joints import stamp_problem, StateLayout
from quat_jt_runtime.loop_stats import TickStats
from quat_jt_runtime.params import ChangeLog, declare_cpu_affinity, history_qos
from quat_jt_runtime.resources import bundled_urdf_hint
from quat_jt_runtime.throttle import cause, Throttle
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

NODE_NAME = 'quat_jt_controller'
THROTTLE_S = 1.0  # rejected goals and states: at most one log line per second and cause
GOAL_LOG_PERIOD_S = 0.2  # accepted distinct goals: one line each, at most 5 a second


class QuatJtController(Node):
    """Transpose-Jacobian regulator with unit-quaternion orientation error, Eq. (22)."""

    def __init__(self, prewarm: bool = True, **kwargs) -> None:
        """Build the node; ``prewarm=False``: never a throwaway tick (the composed mode)."""
        super().__init__(NODE_NAME, **kwargs)
        cfg = self.config = declare_structural(self)
        self.cpu_affinity = declare_cpu_affinity(self)  # pinned by lifecycle.run_node
        try:
            model = RobotModel(cfg.robot_description, cfg.base_link, cfg.tip_link, cfg.joints)
        except ModelError as exc:
            raise ModelError(f'{exc}{bundled_urdf_hint(cfg.given_robot_description)}') from None
        gains = declare_gains(self, cfg, model.effort_limits, on_apply=self._apply_gains)
        self.regulator = Regulator(model, cfg.task, gains.current)
        self._layout = StateLayout(cfg.joints)
        self._use_sim_time = bool(self.get_parameter('use_sim_time').value)
        self._max_age_ns = int(cfg.max_state_age_s * 1e9)
        self._goal_checker = GoalCheckWorker(ModelSpec(
            cfg.robot_description, cfg.base_link, cfg.tip_link, cfg.joints, cfg.task))
        # The extensions (live, whole) and stall detection for /diagnostics.
        self.shaping = declare_shaping(self, cfg, check=self.regulator.check_shaping,
                                       on_apply=self._apply_shaping,
                                       preferred_configuration=model.middle_of_ranges())
        self.regulator.set_shaping(self.shaping.current)
        self.stall = StallDetector(self.regulator)
        self._change_log = ChangeLog(self, (
            (GAIN_PARAMETERS, lambda: describe_gains(self.regulator.gains)),
            (SHAPING_PARAMETERS,
             lambda: f'extensions: {describe_shaping(self.regulator.shaping)}')))
        self.get_logger().info(f'extensions: {describe_shaping(self.shaping.current)}')

        self.supervisor = Supervisor(self.regulator, cfg.state_timeout_s,
                                     cfg.publish_rate_divider)
        self._goal_warning = ''
        self._reject_log = Throttle(THROTTLE_S)  # per cause (the reason without numbers)
        self._goal_log = Throttle(GOAL_LOG_PERIOD_S)
        self._graph_log = Throttle(10.0)
        self.counters = diagnostics.Counters()
        self.stats = TickStats()
        self._last: Optional[TickOutput] = None
        self._last_q: Optional[list[float]] = None
        self._last_qdot: Optional[list[float]] = None
        self._window_start_ns = time.monotonic_ns()

        self._cmd_msg = Float64MultiArray(data=[0.0] * model.n)
        self._pose_msg, self._eo_msg, self._ep_msg = (
            PoseStamped(), Vector3Stamped(), Vector3Stamped())
        for msg in (self._pose_msg, self._eo_msg, self._ep_msg):
            msg.header.frame_id = cfg.base_link
        self._cmd_pub = self.create_publisher(
            Float64MultiArray, 'effort_controller/commands', history_qos(self._use_sim_time))
        self._pose_pub = self.create_publisher(PoseStamped, '~/current_pose', 10)
        self._eo_pub = self.create_publisher(Vector3Stamped, '~/orientation_error', 10)
        self._ep_pub = (self.create_publisher(Vector3Stamped, '~/position_error', 10)
                        if cfg.task is Task.POSE else None)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, 'joint_states', self._on_joint_state, 10)
        self.create_subscription(PoseStamped, '~/target_pose', self._on_target_pose, 10)
        self.create_timer(min(0.05, cfg.state_timeout_s / 4.0), self._on_watchdog)
        self.create_timer(0.05, self._on_goal_checks)
        self.create_timer(1.0, self._on_diagnostics_timer)
        self._prewarm, self._prewarm_timer, self._prewarm_delay_ns = None, None, 0
        lead_ns = int(cfg.prewarm_lead_s * 1e9)
        off = ('prewarm_lead is 0' if lead_ns <= 0 else 'composed' if not prewarm else
               'simulated time' if self._use_sim_time else '')
        if not off:  # armed by each state, on the steady clock (as the arrival times)
            self._prewarm = realtime.Prewarm(lead_ns)
            self._prewarm_timer = self.create_timer(
                1e-3, self._on_prewarm, clock=Clock(clock_type=ClockType.STEADY_TIME),
                autostart=False)
        # /diagnostics is one topic for the whole graph: statuses carry the full node name.
        self._diag_name = self.get_fully_qualified_name().lstrip('/')
        g = self.regulator.gains
        self.get_logger().info(
            f'{cfg.task.value} task, joints {list(cfg.joints)}, {cfg.base_link} -> '
            f'{cfg.tip_link}, potential {g.potential.value}, kp {list(g.kp)}, kv {list(g.kv)}, '
            f'lambda {list(g.lam)}, effort limits {self.regulator.effort_limits_nm} N m; '
            'holding the first measured pose until a goal arrives on ~/target_pose')
        self.get_logger().info(
            f'prewarm: off ({off})' if off else
            f'prewarm: a throwaway tick {cfg.prewarm_lead_s * 1e3:g} ms before each state is due '
            f'(while states come at least {2e3 * cfg.prewarm_lead_s:g} ms apart)')

    @property
    def gains(self) -> Gains:
        """Return the gains in force (immutable)."""
        return self.regulator.gains

    def _apply_gains(self, gains: Gains) -> None:
        self.regulator.set_gains(gains)  # logged once per request by the ChangeLog

    def _apply_shaping(self, shaping) -> None:
        self.regulator.set_shaping(shaping)

    # ---------------------------------------------------------------------------------- tick
    def _on_joint_state(self, msg: JointState) -> None:
        """One control tick: the regulator's torque for this state, published at once."""
        t0 = time.perf_counter_ns()
        try:
            q, qdot = self._layout.extract(msg.name, msg.position, msg.velocity)
        except ValueError as exc:
            self.counters.rejected_states += 1
            self._log_rejection('joint_states', str(exc))
            return
        stamp = msg.header.stamp
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = self.get_clock().now().nanoseconds if self._use_sim_time else time.time_ns()
        problem = stamp_problem(stamp_ns, now_ns, self._max_age_ns)
        if problem:
            self.counters.rejected_states += 1
            self.counters.stale_states += 1
            self._log_rejection('joint_states', problem)
            return
        now_mono_ns = time.monotonic_ns()
        held = self.supervisor.before_tick(q, now_mono_ns)
        if held is not None:
            self.get_logger().info(
                f'first joint state: holding the measured pose, {held.describe()}')
        out = self.regulator.update(q, qdot, self.supervisor.tick_interval_s(stamp_ns))
        self._cmd_msg.data = out.tau_nm
        t1 = time.perf_counter_ns()
        self._cmd_pub.publish(self._cmd_msg)
        t2 = time.perf_counter_ns()
        self.stats.record(t0, t1, t2, (now_ns - stamp_ns) * 1e-3 if stamp_ns else float('nan'),
                          out.saturated)
        self._last, self._last_q, self._last_qdot = out, q, qdot
        if self._prewarm is not None:
            self._arm_prewarm(t0, t2)
        self.stall.feed(t0 * 1e-9, q, qdot, out)
        if not out.finite:
            self.counters.nonfinite_torques += 1
            self.get_logger().error(
                f'the law gave a non-finite torque at q = {q} (gains {self.gains}): published '
                'zero torque', throttle_duration_sec=THROTTLE_S)
        resumed, feedback, diagnostics_due = self.supervisor.after_tick(now_mono_ns)
        if resumed:
            self.get_logger().info('joint_states are back: commanding torque again')
        if feedback:
            self._publish_feedback(stamp, out)
        if diagnostics_due:  # now: the command is out, the next state ~1 period away
            self._publish_diagnostics()

    def _arm_prewarm(self, arrival_ns: int, now_ns: int) -> None:
        """Set the throwaway tick to run ``prewarm_lead`` before the next state is due."""
        timer = self._prewarm_timer
        delay_ns = self._prewarm.arrived(arrival_ns, now_ns)
        if delay_ns is None:
            timer.cancel()
            return
        if abs(delay_ns - self._prewarm_delay_ns) > delay_ns >> 5:  # moved > 3%: reprogram
            self._prewarm_delay_ns = timer.timer_period_ns = max(delay_ns, 1)
        timer.reset()

    def _on_prewarm(self) -> None:
        """Run the throwaway tick: the last state's law again, output dropped (caches warm)."""
        run = self._prewarm.take(time.perf_counter_ns())
        if run is None:  # fired for an earlier state: the timer stays armed for this one
            return
        self._prewarm_timer.cancel()  # once per state: no wake-ups while states are away
        if run:
            self.regulator.update(self._last_q, self._last_qdot)
            self.counters.prewarm_passes += 1

    def _publish_feedback(self, stamp, out: TickOutput) -> None:
        pose = self._pose_msg
        pose.header.stamp = stamp
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = out.p_tip_base
        o = pose.pose.orientation  # in the last one's hemisphere: no sign flip between samples
        o.x, o.y, o.z, o.w = quat.to_xyzw(self.supervisor.published_quaternion(out.R_tip_base))
        self._pose_pub.publish(pose)
        self._eo_msg.header.stamp = stamp
        self._eo_msg.vector.x, self._eo_msg.vector.y, self._eo_msg.vector.z = out.y_tilde[-3:]
        self._eo_pub.publish(self._eo_msg)
        if self._ep_pub is not None:
            self._ep_msg.header.stamp = stamp
            v = self._ep_msg.vector
            v.x, v.y, v.z = out.y_tilde[0], out.y_tilde[1], out.y_tilde[2]
            self._ep_pub.publish(self._ep_msg)

    def _on_watchdog(self) -> None:
        """Zero the command once when valid joint states stop for longer than state_timeout."""
        silent_s = self.supervisor.on_silence(time.monotonic_ns())
        if silent_s is not None:
            self._cmd_msg.data = [0.0] * self.regulator.n
            self._cmd_pub.publish(self._cmd_msg)
            self.get_logger().error(
                f'no valid joint_states for {silent_s:.3f} s (> state_timeout '
                f'{self.config.state_timeout_s} s): published zero torque, waiting for states')

    # ---------------------------------------------------------------------------------- goal
    def _on_target_pose(self, msg: PoseStamped) -> None:
        """Validate a goal (frame, tf2-style unit quaternion, finite position) and swap it in."""
        o, p = msg.pose.orientation, msg.pose.position
        try:
            goal = Goal.from_request(msg.header.frame_id, self.config.base_link,
                                     (o.x, o.y, o.z, o.w), (p.x, p.y, p.z), self.config.task)
        except ValueError as exc:
            self.counters.rejected_goals += 1
            self._log_rejection('target_pose', f'previous goal stays in force: {exc}')
            return
        self.counters.accepted_goals += 1
        stamp = msg.header.stamp
        taken = self.supervisor.on_goal(goal, stamp.sec + 1e-9 * stamp.nanosec,
                                        time.monotonic_ns())
        if not taken.new:
            return
        nu_desired = taken.nu_desired_base
        self._goal_warning = ''
        shaping = self.regulator.shaping
        tracking = shaping.goal_velocity_gain > 0.0 and nu_desired is not None
        self._goal_checker.submit(goal, self._last_q, goal.q_desired_base, goal.p_desired_base,
                                  shaping.joint_limit_margin_rad
                                  if shaping.configuration_on or tracking else None,
                                  nu_desired if tracking else None,
                                  Posture(shaping.preferred_configuration_rad or None,
                                          shaping.posture_weight))
        self._log_goal(goal)

    def _log_goal(self, goal: Goal) -> None:
        """One line per distinct goal, at most one per GOAL_LOG_PERIOD_S (the rest counted)."""
        held = self._goal_log('goal')
        if held is not None:
            self.get_logger().info(
                f'new goal: {goal.describe(self.config.task is Task.POSE)}'
                + (f' ({held} more distinct goals since the last line)' if held else ''))

    def _log_rejection(self, topic: str, reason: str) -> None:
        """Warn once per cause and second; held-back repeats are counted in the next line."""
        held = self._reject_log((topic, cause(reason)))
        if held is not None:
            self.get_logger().warn(f'{topic} rejected, {reason}' +
                                   (f' (and {held} more like it)' if held else ''))

    def _on_goal_checks(self) -> None:
        """Take the A1/A2 verdicts of the worker; only the goal still in force counts."""
        checker = self._goal_checker
        verdicts = checker.poll()
        failure = checker.take_failure()
        if failure is not None:  # once per death; the worker restarts by itself
            self.get_logger().error(f'{failure}; regulation goes on')
        for goal, verdict in verdicts:
            if goal is None:
                continue
            q_star = checker.take_configuration(goal)
            if q_star is not None:  # the goal-configuration term pulls towards it
                self.regulator.set_goal_configuration(goal, q_star)
            qdot_star = checker.take_configuration_velocity(goal)
            if qdot_star is not None:  # taken while the stream goes on
                self.supervisor.on_goal_velocity(qdot_star)
            if goal is self.regulator.goal and verdict != self._goal_warning:
                self._goal_warning = verdict
                if verdict:
                    self.get_logger().warn(f'goal {goal.describe(False)} accepted with a '
                                           f'warning: {verdict}')

    # --------------------------------------------------------------------------- diagnostics
    def _on_diagnostics_timer(self) -> None:
        """
        1 Hz: publish /diagnostics right after the next command, or now if states have stopped.

        Building them takes tens of us (more in the loop): done just after a command goes out,
        the next state is a period away. (Composed, the simulator takes that command after
        this, within its answer window.) A timer could instead fire just as a state arrives.
        If the last second's are still owed (no valid tick since), they go out now.
        """
        if self.supervisor.on_diagnostics_timer(time.monotonic_ns()):
            self._publish_diagnostics()

    def _configuration_state(self) -> diagnostics.ConfigurationState:
        reg = self.regulator
        names = reg.model.joint_names
        return diagnostics.ConfigurationState(
            reg.shaping.configuration_on, reg.goal_configuration,
            [names[j] for j in reg.goal_in_band()],
            reg.learned_friction_nm if reg.shaping.learning_on else ())

    def _publish_diagnostics(self) -> None:
        """Publish the loop's figures and the goal's state, from the ROS-free builders."""
        now = time.monotonic_ns()
        figures = self.stats.window((now - self._window_start_ns) * 1e-9)
        self._window_start_ns = now
        statuses = (
            ('control loop', diagnostics.loop_status(
                figures, self.supervisor.last_state_ns == 0, self.supervisor.stopped,
                self.counters,
                self._graph_warnings())),
            ('goal', diagnostics.goal_status(
                self.supervisor.goal_source, self.regulator.goal, self._goal_warning, self._last,
                self._last_qdot, self.config.task is Task.POSE, self.counters,
                self._goal_checker.unavailable_reason, self._goal_checker.ready,
                self._configuration_state())),
            ('stall', self.stall.status()),
        )
        arr = DiagnosticArray(status=[
            DiagnosticStatus(name=f'{self._diag_name}: {name}', hardware_id=self.config.tip_link,
                             level=bytes([level]), message=message,
                             values=[KeyValue(key=k, value=v) for k, v in values])
            for name, (level, message, values) in statuses])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)

    def _graph_warnings(self) -> list[str]:
        """Warn (every 10 s while it lasts) of a second commander or a second node named so."""
        me = (self.get_name(), self.get_namespace())
        warnings = diagnostics.graph_warnings(
            self._cmd_pub.topic_name, self.count_publishers(self._cmd_pub.topic_name),
            self.get_fully_qualified_name(),
            sum(1 for node in self.get_node_names_and_namespaces() if tuple(node) == me))
        for warning in warnings:
            if self._graph_log(cause(warning)) is not None:
                self.get_logger().warn(warning)
        return warnings

    def destroy_node(self) -> None:
        """Stop the goal-check worker, then destroy the node."""
        self._goal_checker.close()
        super().destroy_node()


def main(args=None) -> None:
    """``ros2 run quat_jt_controller controller_node``."""
    lifecycle.run_node(QuatJtController, NODE_NAME, (ModelError, GainsError, ValueError),
                       lambda node, executor, keep_running: lifecycle.spin(
                           executor, node.context, keep_running), args)


if __name__ == '__main__':
    main()

"""
The regulator as a ROS 2 node: marshalling around ``regulator.Regulator`` (Eq. 22 + g(q)).

Each valid ``joint_states`` message is one tick, its command published at once on
``effort_controller/commands``. The decisions around the law are the ROS-free
``supervision.Supervisor``'s; ``reports.py`` publishes the feedback and ``/diagnostics``; the
parameters are the table of ``parameters.py``, applied as immutable snapshots.
"""
import time
from typing import Optional

from geometry_msgs.msg import PoseStamped
from quat_jt_controller import diagnostics
from quat_jt_controller import parameters
from quat_jt_controller.control_law import Gains, GainsError
from quat_jt_controller.goal_check import GoalCheckWorker, ModelSpec
from quat_jt_controller.goal_frames import GoalFrames
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_controller.regulator import Regulator, TickOutput
from quat_jt_controller.reports import Diagnostics, Feedback, GoalPose
from quat_jt_controller.stall import StallDetector
from quat_jt_controller.supervision import Supervisor
from quat_jt_runtime import lifecycle
from quat_jt_runtime.joints import StaleState, StateCheck
from quat_jt_runtime.loop_stats import TickStats
from quat_jt_runtime.params import declare_realtime, history_qos
from quat_jt_runtime.prewarm_timer import describe_prewarm, prewarm_off_reason, PrewarmTimer
from quat_jt_runtime.resources import bundled_urdf_hint
from quat_jt_runtime.throttle import cause, Throttle
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

NODE_NAME = 'quat_jt_controller'
THROTTLE_S = 1.0  # rejected goals and states: at most one log line per second and cause
GOAL_LOG_PERIOD_S = 0.2  # accepted distinct goals: one line each, at most 5 a second
NO_STATE_CHECK_S = 0.3  # until the first state: is a no-state warning due (Supervisor)?


class QuatJtController(Node):
    """Transpose-Jacobian regulator with unit-quaternion orientation error, Eq. (22)."""

    def __init__(self, prewarm: bool = True, **kwargs) -> None:
        """Build the node; ``prewarm=False``: never a throwaway tick (the composed mode)."""
        super().__init__(NODE_NAME, **kwargs)
        cfg = self.config = parameters.declare_structural(self)
        self._use_sim_time = bool(self.get_parameter('use_sim_time').value)
        # applied by lifecycle.run_node; on simulated time there are no deadlines to keep
        self.realtime = declare_realtime(self, 'simulated time' if self._use_sim_time else '')
        try:
            model = RobotModel(cfg.robot_description, cfg.base_link, cfg.tip_link, cfg.joints,
                               cfg.armature)
        except ModelError as exc:
            raise ModelError(f'{exc}{bundled_urdf_hint(cfg.given_robot_description)}') from None
        gains = parameters.declare_gains(  # each change logged once by the ChangeLog
            self, cfg, model.effort_limits, on_apply=lambda new: self.regulator.set_gains(new))
        reg = self.regulator = Regulator(model, cfg.task, gains.current)
        self.shaping = parameters.declare_shaping(
            self, cfg, check=reg.check_shaping, on_apply=reg.set_shaping,
            preferred_configuration=model.middle_of_ranges())
        reg.set_shaping(self.shaping.current)
        self._change_log = parameters.change_log(self, reg)
        self._frames = GoalFrames(model, cfg.task)  # the base and every link of the URDF
        self._goal_parts = (cfg.task.has_position, cfg.task.has_orientation)  # for the log
        self._check_state = StateCheck(cfg.joints, cfg.max_state_age_s, cfg.state_rate_hz,
                                       model.continuous)
        self._said_estimating = False
        self._goal_checker = GoalCheckWorker(ModelSpec(
            cfg.robot_description, cfg.base_link, cfg.tip_link, cfg.joints, cfg.task))
        self.supervisor = Supervisor(reg, cfg.state_timeout_s, cfg.publish_rate_divider,
                                     self._goal_checker, started_ns=time.monotonic_ns())
        self.stall = StallDetector(reg)
        self._reject_log = Throttle(THROTTLE_S)  # per cause (the reason without numbers)
        self._goal_log = Throttle(GOAL_LOG_PERIOD_S)
        self.counters = diagnostics.Counters()
        self.stats = TickStats()
        self._last: Optional[TickOutput] = None  # the last tick's output, q and qdot
        self._last_q = self._last_qdot = None
        self._goal_anchor = None  # the tip's position when the goal took force (~/goal_pose)
        self._cmd_msg = Float64MultiArray(data=[0.0] * model.n)
        self._cmd_pub = self.create_publisher(
            Float64MultiArray, 'effort_controller/commands', history_qos(self._use_sim_time))
        self._feedback = Feedback(self, cfg.base_link, cfg.task.has_position)
        self._goal_pose = GoalPose(self, cfg.base_link, cfg.task.has_position)
        self._diagnostics = Diagnostics(
            self, cfg.tip_link, self._cmd_pub.topic_name, self.supervisor, self.stats,
            self.counters, self._goal_checker, self.stall, lambda: (self._last, self._last_qdot))
        self._state_sub = self.create_subscription(
            JointState, 'joint_states', self._on_joint_state, 10)
        self.create_subscription(PoseStamped, '~/target_pose', self._on_target_pose, 10)
        self.create_timer(min(0.05, cfg.state_timeout_s / 4.0), self._on_watchdog)
        self._no_state_timer = self.create_timer(
            NO_STATE_CHECK_S, self._on_no_state_yet, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_timer(0.05, self._on_goal_checks)
        self.create_timer(1.0, lambda: (  # /diagnostics after the next command, or now
            self.supervisor.on_diagnostics_timer(time.monotonic_ns())
            and self._diagnostics.publish()))
        off = prewarm_off_reason(cfg.prewarm_lead_s, not prewarm, self._use_sim_time)
        self._prewarm = None if off else PrewarmTimer(self, cfg.prewarm_lead_s, self._prewarm_tick)
        for line in parameters.describe_start(cfg, reg, self._state_sub.topic_name) + [
                describe_prewarm(
                cfg.prewarm_lead_s, off)]:
            self.get_logger().info(line)

    @property
    def gains(self) -> Gains:
        """Return the gains in force (immutable)."""
        return self.regulator.gains

    def _on_joint_state(self, msg: JointState) -> None:
        """One control tick: the regulator's torque for this state, published at once."""
        t0 = time.perf_counter_ns()
        stamp = msg.header.stamp
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = self.get_clock().now().nanoseconds if self._use_sim_time else time.time_ns()
        try:
            q, qdot = self._check_state(msg.name, msg.position, msg.velocity, stamp_ns, now_ns)
        except ValueError as exc:
            self.counters.rejected_states += 1
            self.counters.stale_states += isinstance(exc, StaleState)
            return self._log_rejection('joint_states', str(exc))
        if self._check_state.estimating and not self._said_estimating:
            self._said_estimating = True
            self.get_logger().warn(
                'joint_states carry no velocities: estimating them from the positions and '
                + ('their stamps' if stamp_ns else 'their arrival times (no stamps)')
                + f' (finite differences, low-pass of time constant '
                f'{1e3 / self.config.state_rate_hz:g} ms = one period at state_rate '
                f'{self.config.state_rate_hz:g} Hz); a driver that publishes velocities '
                'gives better damping')
        sup, now_mono_ns = self.supervisor, time.monotonic_ns()
        held = sup.before_tick(q, now_mono_ns)
        if held is not None:
            self._goal_anchor = held.p_desired_base
            self.get_logger().info(
                f'first joint state, {(now_mono_ns - sup.started_ns) * 1e-9:.2f} s after start: '
                f'holding the measured pose, {held.describe()}')
        out = self.regulator.update(q, qdot, sup.tick_interval_s(stamp_ns))
        self._cmd_msg.data = out.tau_nm
        t1 = time.perf_counter_ns()
        self._cmd_pub.publish(self._cmd_msg)
        t2 = time.perf_counter_ns()
        self.stats.record(t0, t1, t2, (now_ns - stamp_ns) * 1e-3 if stamp_ns else float('nan'),
                          out.saturated)
        self._last, self._last_q, self._last_qdot = out, q, qdot
        if self._prewarm is not None:
            self._prewarm.arrived(t0, t2)
        self.stall.feed(t0 * 1e-9, q, qdot, out)
        if not out.finite:
            self.counters.nonfinite_torques += 1
            self.get_logger().error(
                f'the law gave a non-finite torque at q = {q} (gains {self.gains}): published '
                'zero torque', throttle_duration_sec=THROTTLE_S)
        resumed, feedback, diagnostics_due = sup.after_tick(now_mono_ns)
        if resumed:
            self.get_logger().info('joint_states are back: commanding torque again')
        if feedback:
            self._feedback.publish(stamp, out, sup.published_quaternion(out.R_tip_base))
        if diagnostics_due:  # now: the command is out, the next state ~1 period away
            self._diagnostics.publish()

    def _prewarm_tick(self) -> None:
        """Run the last state's law again, its output dropped (the caches stay warm)."""
        self.regulator.update(self._last_q, self._last_qdot)
        self.counters.prewarm_passes += 1

    def _on_no_state_yet(self) -> None:
        """
        Before the first valid state, warn (slowly throttled) with the publishers on the topic.

        On a steady-clock timer (simulated time does not run without a simulator), which the
        first state cancels: the graph is read here, only while no state has come.
        """
        if self.supervisor.last_state_ns:
            self._no_state_timer.cancel()
            return
        waited_s = self.supervisor.no_state_yet(time.monotonic_ns())
        if waited_s is not None:
            topic = self._state_sub.topic_name
            self.get_logger().warn(diagnostics.no_state_warning(
                topic, waited_s, self.count_publishers(topic), self.counters.rejected_states))

    def _on_watchdog(self) -> None:
        """Zero the command once when valid joint states stop for longer than state_timeout."""
        silent_s = self.supervisor.on_silence(time.monotonic_ns())
        if silent_s is not None:
            self._cmd_msg.data = [0.0] * self.regulator.n
            self._cmd_pub.publish(self._cmd_msg)
            self.get_logger().error(
                f'no valid joint_states for {silent_s:.3f} s (> state_timeout '
                f'{self.config.state_timeout_s} s): published zero torque, waiting for states')

    def _on_target_pose(self, msg: PoseStamped) -> None:
        """
        Validate a goal (frame, tf2-style unit quaternion, finite position) and swap it in.

        A goal in a link of the robot is placed in the base frame here, with the last measured
        joints (``GoalFrames``), and held there.
        """
        o, p, stamp = msg.pose.orientation, msg.pose.position, msg.header.stamp
        frame = msg.header.frame_id
        try:
            goal = self._frames.goal(frame, (o.x, o.y, o.z, o.w), (p.x, p.y, p.z), self._last_q)
        except ValueError as exc:
            self.counters.rejected_goals += 1
            return self._log_rejection('target_pose', f'previous goal stays in force: {exc}')
        self.counters.accepted_goals += 1
        taken = self.supervisor.on_goal(goal, stamp.sec + 1e-9 * stamp.nanosec,
                                        time.monotonic_ns())
        if taken.new:
            self._goal_anchor = None if self._last is None else self._last.p_tip_base
            self.supervisor.check_goal(goal, taken.nu_desired_base, self._last_q)
            placed = ('' if frame in ('', self.config.base_link) else
                      f' (given in {frame}, placed in {self.config.base_link} at the measured '
                      'joints)')
            line = self._goal_log.line(  # one line per distinct goal, at most 5 a second
                'goal', lambda: f'new goal: {goal.describe(*self._goal_parts)}'
                f'{placed}', ' ({} more distinct goals since the last line)')
            if line is not None:
                self.get_logger().info(line)

    def _log_rejection(self, topic: str, reason: str) -> None:
        """Warn once per cause and second; held-back repeats are counted in the next line."""
        line = self._reject_log.line((topic, cause(reason)), f'{topic} rejected, {reason}')
        if line is not None:
            self.get_logger().warn(line)

    def _on_goal_checks(self) -> None:
        """Take the worker's answers (the Supervisor applies them); log; publish a new goal."""
        self._goal_pose.update(self.regulator.goal, self._goal_anchor)
        failure, warnings = self.supervisor.take_checks()
        if failure is not None:  # once per death; the worker restarts by itself
            self.get_logger().error(f'{failure}; regulation goes on')
        for warning in warnings:
            self.get_logger().warn(warning)

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

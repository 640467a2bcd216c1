"""
The regulator as a ROS 2 node: marshalling around ``controller.Controller`` (Eq. 22 + g(q)).

Each ``joint_states`` message is read into plain values, given to the ROS-free
:meth:`Controller.on_state <quat_jt_controller.controller.Controller.on_state>` (the one tick,
``Regulator.update``, with the decisions around it), and its command published at once on
``effort_controller/commands``, then its feedback, ``/diagnostics`` and log lines. Goals go to
:meth:`Controller.on_goal` the same way. ``reports.py`` publishes the feedback and
``/diagnostics``; the parameters are the table of ``parameter_table.py``, declared by
``parameters.py`` and applied as immutable snapshots. The ROS graph is read on timers only,
never in the state callback.
"""
import time
from typing import Iterable

from geometry_msgs.msg import PoseStamped
from quat_jt_controller import diagnostics
from quat_jt_controller import parameters
from quat_jt_controller.control_law import Gains, GainsError
from quat_jt_controller.controller import Command, Controller, GoalRequest, LogLine, Severity
from quat_jt_controller.goal_check import GoalCheckWorker, ModelSpec
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_controller.redesign import DesignWorker
from quat_jt_controller.regulator import Regulator
from quat_jt_controller.reports import CommandReceivers, Diagnostics, Feedback, GoalPose
from quat_jt_runtime import lifecycle
from quat_jt_runtime.loop_stats import TickStats
from quat_jt_runtime.params import declare_realtime, history_qos
from quat_jt_runtime.payload import Payload
from quat_jt_runtime.prewarm_timer import describe_prewarm, prewarm_off_reason, PrewarmTimer
from quat_jt_runtime.resources import bundled_urdf_hint
from quat_jt_runtime.worker import Launcher, WORKER_NICE
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

NODE_NAME = 'quat_jt_controller'
NO_STATE_CHECK_S = 0.3  # until the first state: is a no-state warning due (Controller)?
# The node's one steady clock (ns), given to the Controller and the loop statistics alike
steady_ns = time.perf_counter_ns


class QuatJtController(Node):
    """Transpose-Jacobian regulator with unit-quaternion orientation error, Eq. (22)."""

    def __init__(self, prewarm: bool = True, **kwargs) -> None:
        """Build the node; ``prewarm=False``: never a throwaway tick (the composed mode)."""
        super().__init__(NODE_NAME, **kwargs)
        try:
            self._start(prewarm)
        except BaseException:
            # A node that cannot start gives its handles back at once (its /rosout logger
            # too, which a later node of the same name in this process would not get).
            self._close_workers()
            Node.destroy_node(self)
            raise

    def _start(self, prewarm: bool) -> None:
        cfg = self.config = parameters.declare_structural(self)
        self._use_sim_time = bool(self.get_parameter('use_sim_time').value)
        # applied by lifecycle.run_node; on simulated time there are no deadlines to keep
        self.realtime = declare_realtime(self, 'simulated time' if self._use_sim_time else '')
        try:
            model = RobotModel(cfg.urdf_xml, cfg.base_link, cfg.tip_link, cfg.joints,
                               cfg.armature)
        except ModelError as exc:
            raise ModelError(f'{exc}{bundled_urdf_hint(cfg.given_urdf)}') from None
        gains = parameters.declare_gains(  # each change logged once by the ChangeLog
            self, cfg, model.effort_limits, on_apply=lambda new: self.regulator.set_gains(new))
        reg = self.regulator = Regulator(model, cfg.task, gains.current)
        self.shaping = parameters.declare_shaping(
            self, cfg, check=reg.check_shaping, on_apply=reg.set_shaping,
            preferred_configuration=model.middle_of_ranges())
        reg.set_shaping(self.shaping.current)
        self.payload = parameters.declare_payload(  # held up where the arm last was
            self, check=self._check_payload, on_apply=reg.set_payload)
        reg.set_payload(self.payload.current)
        self._change_log = parameters.change_log(self, reg)
        # the workers' launcher: a process started now, before the loop, that starts each
        # worker (again, after a death) so that the node never starts one while it runs;
        # niced, but not on simulated time, where the loop steps on without them
        self._launcher = Launcher(0 if self._use_sim_time else WORKER_NICE)
        self._goal_checker = GoalCheckWorker(ModelSpec(
            cfg.urdf_xml, cfg.base_link, cfg.tip_link, cfg.joints, cfg.task),
            launcher=self._launcher)
        self._designer = DesignWorker(cfg.urdf_xml, launcher=self._launcher)
        ctl = self.controller = Controller(
            reg, cfg.state_timeout_s, cfg.publish_rate_divider, cfg.max_state_age_s,
            cfg.state_rate_hz, self._goal_checker, started_ns=steady_ns(),
            position_resolution=cfg.position_resolution, designer=self._designer,
            parameter_values=lambda: parameters.design_inputs(self))
        self.counters = ctl.counters
        self.stats = TickStats()
        self._cmd_msg = Float64MultiArray(data=[0.0] * model.n)
        self._cmd_pub = self.create_publisher(
            Float64MultiArray, 'effort_controller/commands', history_qos(self._use_sim_time))
        self._feedback = Feedback(self, cfg.base_link, cfg.task.has_position)
        self._goal_pose = GoalPose(self, cfg.base_link, cfg.task.has_position)
        self._diagnostics = Diagnostics(self, cfg.tip_link, self._cmd_pub.topic_name, ctl,
                                        self.stats)
        self._receivers = CommandReceivers(self, self._cmd_pub.topic_name, model.joint_names,
                                           self._on_receivers)
        self._state_sub = self.create_subscription(
            JointState, 'joint_states', self._on_joint_state, 10)
        self.create_subscription(PoseStamped, '~/target_pose', self._on_target_pose, 10)
        self.create_service(Trigger, '~/identify_payload', self._on_identify_payload)
        self.create_timer(min(0.05, cfg.state_timeout_s / 4.0), self._on_watchdog)
        self._no_state_timer = self.create_timer(
            NO_STATE_CHECK_S, self._on_no_state_yet, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_timer(0.05, self._on_goal_checks)
        # the graph is read on this timer, once a second, never in the state callback
        self.create_timer(1.0, self._on_diagnostics_timer)
        off = prewarm_off_reason(cfg.prewarm_lead_s, not prewarm, self._use_sim_time)
        self._prewarm = None if off else PrewarmTimer(self, cfg.prewarm_lead_s, ctl.prewarm)
        for line in parameters.describe_start(cfg, reg, self._state_sub.topic_name) + [
                describe_prewarm(cfg.prewarm_lead_s, off)]:
            self.get_logger().info(line)
        for line in diagnostics.start_warnings(reg):
            self.get_logger().warn(line)

    def _on_identify_payload(self, request: Trigger.Request, response: Trigger.Response
                             ) -> Trigger.Response:
        """Set payload_mass and payload_com to what the arm at rest holds (Controller)."""
        payload, message = self.controller.identify_payload()
        if payload is not None:  # through the parameters: validated, logged, then in force
            result = self.set_parameters_atomically([
                Parameter('payload_mass', value=payload.mass_kg),
                Parameter('payload_com', value=list(payload.com_m))])
            if not result.successful:
                payload, message = None, f'{message}; not set: {result.reason}'
        response.success, response.message = payload is not None, message
        if payload is not None:  # one call site per severity, as rclpy's logger wants
            self.get_logger().info(f'~/identify_payload: {message}')
        else:
            self.get_logger().warning(f'~/identify_payload: {message}')
        return response

    def _check_payload(self, payload: Payload) -> Payload:
        """Refuse a payload the arm cannot hold up where it was last measured (if it was)."""
        ctl = getattr(self, 'controller', None)
        if ctl is None or ctl.last_q is None:  # no pose yet: only the values are checked
            return payload
        return self.regulator.check_payload(payload, ctl.last_q)

    @property
    def gains(self) -> Gains:
        """Return the gains in force (immutable)."""
        return self.regulator.gains

    def _on_joint_state(self, msg: JointState) -> None:
        """One control tick: read, ``Controller.on_state``, publish the command at once."""
        t0 = steady_ns()
        stamp = msg.header.stamp
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = self.get_clock().now().nanoseconds if self._use_sim_time else time.time_ns()
        cmd = self.controller.on_state(msg.name, msg.position, msg.velocity, stamp_ns, now_ns,
                                       t0)
        if cmd.tau_nm is not None:
            self._cmd_msg.data = cmd.tau_nm
            t1 = steady_ns()
            self._cmd_pub.publish(self._cmd_msg)
            t2 = steady_ns()
            self.stats.record(t0, t1, t2,
                              (now_ns - stamp_ns) * 1e-3 if stamp_ns else float('nan'),
                              cmd.out.saturated)
            if self._prewarm is not None:
                self._prewarm.arrived(t0, t2)
        self._log(cmd.logs)
        if cmd.feedback is not None:
            self._feedback.publish(stamp, cmd.out, cmd.feedback)
        if cmd.diagnostics:  # now: the command is out, the next state ~1 period away
            self._diagnostics.publish()

    def _log(self, lines: Iterable[LogLine]) -> None:
        """Log the controller's lines (one call site per severity, as rclpy's logger wants)."""
        logger = self.get_logger()
        for severity, text in lines:
            if severity >= Severity.ERROR:
                logger.error(text)
            elif severity >= Severity.WARN:
                logger.warning(text)
            else:
                logger.info(text)

    def _publish(self, cmd: Command) -> None:
        """Publish a command that does not come from a state (the watchdog's zeros)."""
        self._cmd_msg.data = cmd.tau_nm
        self._cmd_pub.publish(self._cmd_msg)
        self._log(cmd.logs)

    def _on_no_state_yet(self) -> None:
        """
        Before the first valid state, warn (slowly throttled) with the publishers on the topic.

        On a steady-clock timer (simulated time does not run without a simulator), which the
        first state cancels: the graph is read here, only while no state has come.
        """
        if self.controller.has_state:
            self._no_state_timer.cancel()
            return
        waited_s = self.controller.no_state_yet(steady_ns())
        if waited_s is not None:
            topic = self._state_sub.topic_name
            self.get_logger().warn(diagnostics.no_state_warning(
                topic, waited_s, self.count_publishers(topic), self.counters.rejected_states,
                self.counters.foreign_states))

    def _on_watchdog(self) -> None:
        """Zero the command once when valid joint states stop for longer than state_timeout."""
        cmd = self.controller.on_watchdog(steady_ns())
        if cmd is not None:
            self._publish(cmd)

    def _on_receivers(self, problems: list) -> None:
        """Stop commanding while a receiver would apply torques to the wrong joints."""
        if problems:
            cmd = self.controller.refuse_commands('; '.join(problems))
            if cmd is not None:
                if cmd.tau_nm is not None:
                    self._publish(cmd)
                else:
                    self._log(cmd.logs)
        else:
            self._log(self.controller.allow_commands())

    def _on_diagnostics_timer(self) -> None:
        """Read the graph (and the command receivers' joints); publish /diagnostics."""
        self._diagnostics.check_graph()
        self._receivers.check()
        if self.controller.on_diagnostics_timer(steady_ns()):
            self._diagnostics.publish()

    def _on_target_pose(self, msg: PoseStamped) -> None:
        """
        Give a goal to the controller: validated (frame, tf2-style unit quaternion, finite).

        A goal in a link of the robot is placed in the base frame with the last measured
        joints (``GoalFrames``), and held there.
        """
        o, p, stamp = msg.pose.orientation, msg.pose.position, msg.header.stamp
        reply = self.controller.on_goal(GoalRequest(
            msg.header.frame_id, (o.x, o.y, o.z, o.w), (p.x, p.y, p.z),
            stamp.sec + 1e-9 * stamp.nanosec), steady_ns())
        self._log(reply.logs)

    def _on_goal_checks(self) -> None:
        """
        Take the worker's answers (the controller applies them); log; publish a new goal.

        And say what the controller found of the model (the rotor inertia the motion shows).
        """
        ctl = self.controller
        self._goal_pose.update(ctl.goal, ctl.goal_anchor)
        logs = ctl.take_goal_checks() + ctl.take_model_notes()
        designed, said = ctl.take_design()
        self._log(logs + said)
        if designed is not None:  # through the parameters: checked, logged, then in force
            self._log(ctl.design_set(designed, parameters.set_live(self, designed)))

    def _close_workers(self) -> None:
        """Stop the goal-check and design workers, then their launcher (any started)."""
        for name in ('_goal_checker', '_designer', '_launcher'):
            if getattr(self, name, None) is not None:
                getattr(self, name).close()

    def destroy_node(self) -> None:
        """Stop the goal-check and design workers and their launcher, then destroy the node."""
        self._close_workers()
        super().destroy_node()


def main(args=None) -> None:
    """``ros2 run quat_jt_controller controller_node``."""
    lifecycle.run_node(QuatJtController, NODE_NAME, (ModelError, GainsError, ValueError),
                       lambda node, executor, keep_running: lifecycle.spin(
                           executor, node.context, keep_running), args)


if __name__ == '__main__':
    main()

"""
``wrist_sim_node``: the simulated wrist (or any fixed-base serial URDF) as a ROS 2 node.

A thin rclpy layer, with the interface of a ros2_control robot driven by a
JointGroupEffortController, over the ROS-free parts: the physics
(:class:`wrist_sim.simulator.RobotSimulator`, in PyBullet or MuJoCo: ``engine``), the command path
(:class:`wrist_sim.command_gate.CommandGate`: validation, watchdog, hold until the first
command, the reset gate) and the stepping loops (``wrist_sim.pacing``: real-time deadlines, or
lockstep with ``/clock``). It publishes ``joint_states`` after every step (effort = the motor
torque applied, clamped to the URDF limits, friction not included), takes
``effort_controller/commands`` (one torque in N m per joint, in ``joints`` order; bad ones are
refused with a throttled warning and the last good one stays), and serves ``~/reset`` (back to
``initial_positions`` at rest). It publishes the URDF in use on ``robot_description``
(transient local, ``publish_robot_description``), so RViz and robot_state_publisher's users
see the robot. Timing figures are kept in ``node.stats``, logged at shutdown
and written as JSON to ``stats_file`` if set. The parameters are the table of
``wrist_sim/parameters.py``; docs/ros.md tells the rest.
"""
import json
import time
from typing import Any, Callable, Optional

from quat_jt_runtime import lifecycle
from quat_jt_runtime import realtime
from quat_jt_runtime.description import publish_description
from quat_jt_runtime.loop_stats import LoopStats, write_summary
from quat_jt_runtime.params import history_qos
from quat_jt_runtime.resources import bundled_urdf_hint
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from wrist_sim import pacing
from wrist_sim.command_gate import CommandGate, RESUMED, TRIPPED
from wrist_sim.config import SimConfig
from wrist_sim.parameters import armature_note, change_log, declare_live, declare_structure
from wrist_sim.simulator import at_limit, missing_meshes_note, NoDisplayError, SimulatorError
from wrist_sim.simulator import repaired_inertia_note, RobotSimulator, zero_inertia_note

NODE_NAME = 'wrist_sim'
THROTTLE_S = 1.0
# No command since start: a warning after this long, then one every NO_COMMAND_REPEAT_S. Later
# than the controller's (a simulator waiting for its controller to start is normal at first).
NO_COMMAND_WARN_S = 5.0
NO_COMMAND_REPEAT_S = 10.0


class WristSimNode(Node):
    """The simulated robot; build it, then call :meth:`run` with an executor."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        try:
            self._start()
        except BaseException:
            # A node that cannot start gives its handles back at once (its /rosout logger
            # too, which a later node of the same name in this process would not get).
            Node.destroy_node(self)
            raise

    def _start(self) -> None:
        p = self.structure = declare_structure(self)
        self.realtime = p.realtime  # applied by lifecycle.run_node
        self.live = declare_live(self, len(p.joints), on_apply=self._apply_config)
        self._change_log = change_log(self, self.live)
        c = self.live.current
        self.dt_ns = p.dt_ns
        try:
            self.sim = RobotSimulator(
                p.plant_xml, p.joints, dt_s=self.dt_ns * 1e-9, use_gui=p.use_gui,
                viscous_nm_s_per_rad=c.viscous_nm_s_per_rad, coulomb_nm=c.coulomb_nm,
                initial_positions_rad=c.initial_positions_rad,
                enforce_velocity_limits=p.enforce_velocity_limits, engine=p.engine,
                armature=p.armature)
        except NoDisplayError:  # nothing to do with the robot: no advice on its URDF
            raise
        except SimulatorError as exc:
            raise SimulatorError(f'{exc}{bundled_urdf_hint(p.given_urdf)}') from None
        if self.sim.missing_meshes:
            self.get_logger().warning(missing_meshes_note(self.sim.missing_meshes))
        if self.sim.zero_inertia_links:
            self.get_logger().warning(zero_inertia_note(self.sim.zero_inertia_links))
        if self.sim.repaired_inertia_links:
            self.get_logger().warning(repaired_inertia_note(self.sim.repaired_inertia_links))
        unsimulated = armature_note(p, self.sim.supports_armature)
        if unsimulated:
            self.get_logger().warning(unsimulated)
        self._effort_limits = self.sim.effort_limits_nm.tolist()
        self._velocity_limits = self.sim.velocity_limits_rad_s.tolist()
        self._at_velocity_limit = [0.999 * v for v in self._velocity_limits]
        self.publish_clock = p.publish_clock
        self._clock_divider = p.clock_divider
        self.stats = LoopStats(capacity=p.stats_window_steps)
        # Without use_sim_time the node's ROS clock is the system clock: stamp from it directly
        # (time.time_ns) rather than through rclpy's Clock object on every tick.
        self._system_clock = not self.get_parameter('use_sim_time').value
        # The command path (touched only from the executor thread, which is also the loop's).
        self.gate = CommandGate(self._effort_limits, self.dt_ns, p.hold_until_first_command)
        self._publish_wall_s = time.perf_counter()
        self._last_stamp_ns = -1
        self._js = JointState()
        self._js.name = list(self.sim.joint_names)
        self._clock_msg = Clock()
        self.js_pub = self.create_publisher(JointState, 'joint_states',
                                            history_qos(self.publish_clock))
        self.clock_pub = (self.create_publisher(Clock, '/clock', QoSProfile(depth=1))
                          if self.publish_clock else None)
        # Publishers on the command topic, from matched events: no graph query (which blocks for
        # milliseconds while DDS discovers a new process) on the stepping thread.
        self._command_publishers = 0
        self.cmd_sub = self.create_subscription(
            Float64MultiArray, 'effort_controller/commands', self._on_command, 10,
            event_callbacks=SubscriptionEventCallbacks(matched=self._on_command_matched))
        self.reset_srv = self.create_service(Trigger, '~/reset', self._on_reset)
        self._hold = p.hold_until_first_command
        self._no_command_warn_s = float('inf')  # set when the loop starts (run)
        # the URDF for RViz, robot_state_publisher's users and a controller that reads the topic
        self.description_pub = (publish_description(self, p.urdf_xml)
                                if p.publish_robot_description else None)
        self.get_logger().info(
            f'simulating joints {list(self.sim.joint_names)} in {self.sim.engine} at '
            f'{p.rate_hz} Hz, armature {list(p.armature)} kg m^2, '
            + (f'{p.payload.describe(p.payload_link)}, ' if p.payload.mass_kg > 0.0 else '')
            + f'effort limits {self.sim.effort_limits_nm.tolist()} N m, '
            + ('lockstep with /clock' if self.publish_clock else 'real time')
            + f'; {self._before_first_command()} until the first command on '
            f'{self.cmd_sub.topic_name}'
            + f'; URDF from {p.description.describe()}'
            + (f', published on {self.description_pub.topic_name}'
               if self.description_pub is not None else ''))

    def _before_first_command(self) -> str:
        return 'joints held at rest' if self._hold else 'zero torque'

    def _apply_config(self, config: SimConfig) -> None:  # its friction, if it changed
        friction = [list(config.viscous_nm_s_per_rad), list(config.coulomb_nm)]
        if friction != [a.tolist() for a in self.sim.friction]:
            self.sim.set_friction(*friction)

    # -- callbacks -----------------------------------------------------------------------
    def _on_command_matched(self, info: Any) -> None:  # for the twin-controller warning
        self._command_publishers = info.current_count

    def _on_command(self, msg: Float64MultiArray) -> None:
        data = msg.data
        offer = self.gate.offer(data, self.sim.step_count)
        if offer.reason:  # one log line per cause and second (throttled per call site)
            self.stats.rejected_commands += 1
            if offer.nonfinite:
                self.get_logger().warning(f'rejected command with {offer.reason}',
                                          throttle_duration_sec=THROTTLE_S)
            else:
                self.get_logger().warning(
                    f'rejected command: {offer.reason} {list(self.sim.joint_names)}',
                    throttle_duration_sec=THROTTLE_S)
            return
        if not offer.applied:  # it answers a state from before ~/reset
            return
        if offer.clamped:
            self.stats.clamped_commands += 1
            self.get_logger().warning(
                f'command {list(data)} N m exceeds the effort limits {self._effort_limits} N m: '
                f'applied clamped ({self.stats.clamped_commands} clamped commands so far)',
                throttle_duration_sec=THROTTLE_S)
        if offer.first_since_state:
            self.stats.record_latency(time.perf_counter() - self._publish_wall_s)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        try:
            self.sim.reset(self.live.current.initial_positions_rad)
        except SimulatorError as exc:
            response.success, response.message = False, str(exc)
            return response
        self.gate.reset()
        response.success = True
        response.message = f'reset to {list(self.live.current.initial_positions_rad)} at rest'
        self.get_logger().info(response.message)
        return response

    # -- the step ------------------------------------------------------------------------
    def advance(self) -> None:
        """
        Step the physics with the command to apply, or hold the joints until the first one.

        Until the first valid command after start-up or ``~/reset`` (with
        ``hold_until_first_command``) the joints are held at rest, like a drive whose brakes
        release when its controller connects; only time advances. The command watchdog
        (``command_timeout``) is the gate's (:class:`wrist_sim.command_gate.CommandGate`).
        """
        config = self.live.current
        tau, event = self.gate.torque(self.sim.step_count, config.command_timeout_ns)
        if event == RESUMED:
            self.get_logger().info('commands are back: applying them again')
        elif event == TRIPPED:
            self.stats.watchdog_trips += 1
            self.get_logger().warning(
                f'no command for {self.gate.silence_s(self.sim.step_count):.3f} s (> '
                f'command_timeout {config.command_timeout_s} s): torque set to zero')
        if tau is None:
            self.sim.hold()
        else:
            self.sim.step(tau)

    # -- pacing.Stepper, for the loops ---------------------------------------------------
    def answered(self) -> bool:
        """Tell whether a command has come for the last published state."""
        return self.gate.answered

    def published_at(self) -> float:
        """Return when (``time.perf_counter``) the last state was published."""
        return self._publish_wall_s

    def config(self) -> SimConfig:
        """Return the live settings in force."""
        return self.live.current

    def every_second(self, line: str) -> None:
        """
        Log the loop's figures (debug); warn of a second controller on the command topic.

        Warn, slowly throttled, while no command has come since start, with the publishers
        matched on the command topic (counted from matched events, not the graph).
        """
        self.get_logger().debug(line)
        now_s = time.perf_counter()
        if not self.gate.commanded and now_s >= self._no_command_warn_s:
            self._no_command_warn_s = now_s + NO_COMMAND_REPEAT_S
            n = self._command_publishers
            self.get_logger().warning(
                f'no command on {self.cmd_sub.topic_name} {now_s - self.stats.start_s:.1f} s '
                f'after start ({n} publisher{"" if n == 1 else "s"} matched; is a controller '
                f'running and publishing there?): {self._before_first_command()} until one '
                'arrives')
        if self._command_publishers > 1:
            self.get_logger().warning(
                f'{self._command_publishers} publishers on {self.cmd_sub.topic_name}: more than '
                'one controller commands this robot, and they fight; stop all but one',
                throttle_duration_sec=10.0)

    def publish_state(self) -> None:
        """Publish joint_states (and /clock) for the current simulator state."""
        if self.publish_clock:
            stamp_ns = self.sim.step_count * self.dt_ns
        else:
            stamp_ns = time.time_ns() if self._system_clock else self.get_clock().now().nanoseconds
        if stamp_ns <= self._last_stamp_ns:  # strictly monotonic stamps
            stamp_ns = self._last_stamp_ns + 1
        self._last_stamp_ns = stamp_ns
        sec, nsec = divmod(stamp_ns, 1_000_000_000)
        js = self._js
        js.header.stamp.sec = sec
        js.header.stamp.nanosec = nsec
        js.position = self.sim.q_rad.tolist()
        js.velocity = velocity = self.sim.qdot_rad_s.tolist()
        if at_limit(velocity, self._at_velocity_limit):
            self.get_logger().warning(
                f'joint speeds {velocity} rad/s: a joint runs at (or past) its URDF velocity '
                f'limit ({self._velocity_limits} rad/s)' + (
                    ', where the simulator holds it' if self.sim.enforces_velocity_limits
                    else ' (enforce_velocity_limits is off)'), throttle_duration_sec=THROTTLE_S)
        js.effort = self.sim.tau_applied_nm.tolist()
        if self.clock_pub is not None and self.sim.step_count % self._clock_divider == 0:
            self._clock_msg.clock.sec = sec
            self._clock_msg.clock.nanosec = nsec
            self.clock_pub.publish(self._clock_msg)
        self.gate.published()
        self._publish_wall_s = time.perf_counter()
        self.js_pub.publish(js)

    # -- loops ---------------------------------------------------------------------------
    def run(self, executor: Any, keep_running: Callable[[], bool] = lambda: True) -> None:
        """Step until ``keep_running()`` is false or the context shuts down."""
        ok = realtime.RunCheck(keep_running, self.context.ok)
        self.publish_state()  # the initial state, so a controller can answer it
        self.stats.start_s = time.perf_counter()
        self._no_command_warn_s = self.stats.start_s + NO_COMMAND_WARN_S
        if self.publish_clock:
            pacing.run_lockstep(self, executor, self.dt_ns * 1e-9, ok)
        else:
            pacing.run_real_time(self, executor, self.dt_ns * 1e-9, ok)

    # -- shutdown ------------------------------------------------------------------------
    def destroy_node(self) -> None:
        """Log (and write) the timing statistics, close the simulator, destroy the node."""
        summary = self.stats.summary()
        self.get_logger().info('stats ' + json.dumps(summary, sort_keys=True))
        problem = write_summary(summary, self.structure.stats_file)
        if problem:
            self.get_logger().error(problem)
        self.sim.close()
        super().destroy_node()


def main(args: Optional[list[str]] = None) -> None:
    """Entry point of ``wrist_sim_node``."""
    lifecycle.run_node(WristSimNode, NODE_NAME, (SimulatorError, FileNotFoundError),
                       lambda node, executor, keep_running: node.run(executor, keep_running),
                       args)


if __name__ == '__main__':
    main()

"""
``wrist_sim_node``: the simulated wrist (or any fixed-base serial URDF) as a ROS 2 node.

A thin rclpy layer over :class:`wrist_sim.simulator.WristSimulator` and the command path of
:class:`wrist_sim.command_gate.CommandGate` (validation, watchdog, hold, reset gate; ROS-free),
with the interface of a ros2_control robot driven by a JointGroupEffortController:

- publishes ``joint_states`` (sensor_msgs/JointState) after every step: name, position,
  velocity and effort = the motor torque applied in that step (clamped to the URDF effort
  limits, friction not included);
- subscribes ``effort_controller/commands`` (std_msgs/Float64MultiArray, one torque in N m per
  joint, in the order of the ``joints`` parameter); bad commands (wrong length, NaN/Inf) are
  rejected with a throttled warning and the last good command (or zero) stays applied;
- command watchdog: no valid command for ``command_timeout`` seconds of simulated time (= wall
  time when pacing in real time) -> zero torque, logged once, recovers when commands return;
- ``~/reset`` (std_srvs/Trigger): back to ``initial_positions`` at rest, held command zeroed;
  commands that arrive before the reset state is published answer older states and are not
  applied, so the reset state is always published;
- real-time pacing at ``rate_hz`` (dt = 1 / rate_hz), or with ``publish_clock:=true`` lockstep
  with the controller: ``/clock`` is published with the simulation time and a step is taken
  as soon as a command has arrived for the last published state (or after
  ``lockstep_timeout`` s of wall time), so it can run faster than real time.

Loop (real time): a deadline loop spinning an EventsExecutor. Each state is published on its
tick (the executor sleeps, with 1 ns of timer slack, until just before it, then a short
busy-wait); the command that answers it is applied as soon as it arrives, stepping the
simulation, and the new state waits for the next tick. The answer is awaited until shortly
before that tick, and at least half a period after a state published late (see
``_run_real_time``; ``realtime.answer_deadline``, ``realtime.await_answer``).

Until the first valid command after start-up or ``~/reset``, the joints are held at rest
(``hold_until_first_command``). Timing figures (rate, missed deadlines, step compute time,
command freshness and latency) are kept in ``node.stats`` (:class:`loop_stats.LoopStats`, over
the last ``stats_window_steps`` steps), logged at shutdown and written as JSON to
``stats_file`` if set. ``cpu_affinity`` pins the process (``realtime.py``).
"""
import json
from pathlib import Path
import time
from typing import Any, Callable, Optional

from quat_jt_runtime import lifecycle
from quat_jt_runtime import realtime
from quat_jt_runtime.loop_stats import LoopStats
from quat_jt_runtime.params import ChangeLog, history_qos
from quat_jt_runtime.resources import bundled_urdf_hint
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from wrist_sim.command_gate import CommandGate, RESUMED, TRIPPED
from wrist_sim.config import SimConfig
from wrist_sim.parameters import declare_live, declare_structure, describe_config
from wrist_sim.parameters import LIVE_PARAMETERS
from wrist_sim.simulator import SimulatorError, WristSimulator

NODE_NAME = 'wrist_sim'
LOG_PERIOD_S = 1.0
THROTTLE_S = 1.0


class WristSimNode(Node):
    """The simulated robot; build it, then call :meth:`run` with an executor."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        p = self.structure = declare_structure(self)
        self.cpu_affinity = p.cpu_affinity  # pinned by lifecycle.run_node
        self.live = declare_live(self, len(p.joints), on_apply=self._apply_config)
        self._change_log = ChangeLog(self, ((LIVE_PARAMETERS,
                                             lambda: describe_config(self.live.current)),))
        c = self.live.current
        self.rate_hz = p.rate_hz
        self.dt_ns = p.dt_ns
        try:
            self.sim = WristSimulator(
                p.urdf_xml, p.joints, dt_s=self.dt_ns * 1e-9, use_gui=p.use_gui,
                viscous_nm_s_per_rad=c.viscous_nm_s_per_rad, coulomb_nm=c.coulomb_nm,
                initial_positions_rad=c.initial_positions_rad,
                enforce_velocity_limits=p.enforce_velocity_limits)
        except SimulatorError as exc:
            raise SimulatorError(f'{exc}{bundled_urdf_hint(p.given_urdf)}') from None
        if self.sim.missing_meshes:
            self.get_logger().warning(
                f'{len(self.sim.missing_meshes)} mesh file(s) of robot_description not found, '
                f'simulated without those shapes (the dynamics need only the inertias): '
                f'{", ".join(self.sim.missing_meshes)}. package:// URIs are looked for in the '
                'sourced workspaces (AMENT_PREFIX_PATH) and in pybullet_data; relative paths '
                'in pybullet_data')
        self.n = self.sim.n
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
        self.get_logger().info(
            f'simulating joints {list(self.sim.joint_names)} at {self.rate_hz} Hz, '
            f'effort limits {self.sim.effort_limits_nm.tolist()} N m, '
            + ('lockstep with /clock' if self.publish_clock else 'real time'))

    # -- parameters (wrist_sim/parameters.py) ------------------------------------------

    def _apply_config(self, config: SimConfig) -> None:
        """Take a new live config: push its friction to the simulator."""
        friction = (list(config.viscous_nm_s_per_rad), list(config.coulomb_nm))
        if friction != [a.tolist() for a in self.sim.friction]:
            self.sim.set_friction(*friction)

    # -- callbacks -----------------------------------------------------------------------

    def _on_command_matched(self, info: Any) -> None:
        """Count the controllers connected to the command topic (for the twin warning)."""
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
            response.success = False
            response.message = str(exc)
            return response
        self.gate.reset()
        response.success = True
        response.message = f'reset to {list(self.live.current.initial_positions_rad)} at rest'
        self.get_logger().info(response.message)
        return response

    # -- the step ------------------------------------------------------------------------

    def _advance_simulation(self) -> None:
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

    def tick(self, late_s: float = 0.0) -> None:
        """Apply the latest command, step once, publish the new state (and /clock)."""
        t0 = time.perf_counter()
        fresh = self.gate.answered
        self._advance_simulation()
        self.publish_state()
        self.stats.record_step(t0, time.perf_counter() - t0, late_s, fresh)

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
        for v, limit in zip(velocity, self._at_velocity_limit):
            if v >= limit or v <= -limit:
                self.get_logger().warning(
                    f'joint speeds {velocity} rad/s: a joint runs at (or past) its URDF velocity '
                    f'limit ({self._velocity_limits} rad/s)'
                    + (', where the simulator holds it' if self.sim.enforces_velocity_limits
                       else ' (enforce_velocity_limits is off)'),
                    throttle_duration_sec=THROTTLE_S)
                break
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
        self._ok = realtime.RunCheck(keep_running, self.context.ok)
        self.publish_state()  # the initial state, so a controller can answer it
        self.stats.start_s = time.perf_counter()
        if self.publish_clock:
            self._run_lockstep(executor)
        else:
            self._run_real_time(executor)

    def _periodic_log(self, now: float, last: list) -> None:
        if now - last[0] < LOG_PERIOD_S:
            return
        steps = self.stats.steps - last[1]
        self.get_logger().debug(
            f'{steps / (now - last[0]):.1f} steps/s, missed {self.stats.missed_deadlines}, '
            f'fresh {self.stats.fresh_steps}/{self.stats.steps}, '
            f'rejected {self.stats.rejected_commands}')
        last[0], last[1] = now, self.stats.steps
        publishers = self._command_publishers
        if publishers > 1:
            self.get_logger().warning(
                f'{publishers} publishers on {self.cmd_sub.topic_name}: more than one '
                'controller commands this robot, and they fight; stop all but one',
                throttle_duration_sec=10.0)

    def _run_real_time(self, executor: Any) -> None:
        """
        Deadline loop: publish each state exactly on its tick, step as soon as its answer is in.

        The state of step k is published at its tick t_k (the executor sleeps until shortly
        before, then a busy-wait). The controller answers that state; its command is applied
        the moment it arrives, stepping the physics to k + 1, whose state then waits for
        t_k+1. If no answer has come ``realtime.STEP_LEAD_S`` before t_k+1, and at least
        ``realtime.MIN_ANSWER_FRACTION`` of a period after the state went out, the last command
        is applied again (a stale tick; ``realtime.answer_deadline``, ``await_answer``). So the
        controller has nearly the whole period to answer, even for a state published late, and
        the publication never waits for the physics.
        """
        period = self.dt_ns * 1e-9
        realtime.set_timer_slack(1)  # wake-ups on time, so the busy-wait can be short
        clock = time.perf_counter
        next_t = clock() + period
        last_log = [clock(), 0]
        ok = self._ok
        gate = self.gate
        while ok():
            realtime.await_answer(
                executor, lambda: gate.answered, realtime.answer_deadline(
                    next_t, self._publish_wall_s, period), ok)
            fresh = gate.answered
            t0 = clock()
            self._advance_simulation()
            step_s = clock() - t0
            now = realtime.wait_for_tick(executor, next_t)
            if not ok():
                break
            late = now - next_t
            if late > 0.5 * period:
                self.stats.missed_deadlines += 1
            self.publish_state()
            self.stats.record_step(now, step_s + clock() - now, late, fresh)
            next_t += period
            skipped = realtime.ticks_to_skip(next_t, period, clock())  # stalled: resync
            self.stats.missed_deadlines += skipped
            next_t += skipped * period
            self._periodic_log(now, last_log)

    def _run_lockstep(self, executor: Any) -> None:
        clock = time.perf_counter
        last_step = clock()
        last_log = [last_step, 0]
        ok = self._ok
        while ok():
            config = self.live.current
            deadline = last_step + config.lockstep_timeout_s
            while not self.gate.answered:
                remaining = deadline - clock()
                if remaining <= 0.0:
                    self.stats.lockstep_timeouts += 1
                    break
                executor.spin_once(timeout_sec=remaining)
                if not ok():
                    return
            rtf = config.max_real_time_factor
            if rtf > 0.0:
                earliest = last_step + self.dt_ns * 1e-9 / rtf
                while (remaining := earliest - clock()) > 0.0 and ok():
                    executor.spin_once(timeout_sec=remaining)
            last_step = clock()
            self.tick()
            self._periodic_log(last_step, last_log)

    # -- shutdown ------------------------------------------------------------------------

    def destroy_node(self) -> None:
        """Log (and write) the timing statistics, close the simulator, destroy the node."""
        summary = self.stats.summary()
        self.get_logger().info('stats ' + json.dumps(summary, sort_keys=True))
        path = self.structure.stats_file
        if path:
            try:
                Path(path).write_text(json.dumps(summary, indent=1, sort_keys=True))
            except OSError as exc:
                self.get_logger().error(f'cannot write stats_file {path}: {exc}')
        self.sim.close()
        super().destroy_node()


def main(args: Optional[list[str]] = None) -> None:
    """Entry point of ``wrist_sim_node``."""
    lifecycle.run_node(WristSimNode, NODE_NAME, (SimulatorError, FileNotFoundError),
                       lambda node, executor, keep_running: node.run(executor, keep_running),
                       args)


if __name__ == '__main__':
    main()

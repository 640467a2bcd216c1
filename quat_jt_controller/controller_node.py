"""
The transpose-Jacobian unit-quaternion regulator as a ROS 2 node (Campa and Kelly).

    tau = J^T Q(eta_e, e)^T grad U_a(y_tilde) - K_v qdot + g(q),  clamped to the effort limits

with grad U_a = K_p y (Eq. 24, orientation task Eq. 37) or K_p tanh(Lambda y) (Eq. 32 / 38).

Node ``quat_jt_controller``:

* subscribes ``joint_states`` (sensor_msgs/JointState): every valid message is one control tick
  (event driven: the command is computed from that state and published at once);
* subscribes ``~/target_pose`` (geometry_msgs/PoseStamped): the goal, validated like tf2;
* publishes ``effort_controller/commands`` (std_msgs/Float64MultiArray, ``joints`` order),
  ``~/current_pose`` (PoseStamped), ``~/orientation_error`` (Vector3Stamped, ``e`` of Eq. 10),
  ``~/position_error`` (Vector3Stamped, pose task only; p_d - p of Eq. 9), decimated by
  ``publish_rate_divider``, and ``/diagnostics`` at 1 Hz.

The tick reads two immutable references, ``self._gains`` (a Gains) and ``self._goal`` (a
``(q_desired_base, p_desired_base)`` tuple); parameter and goal callbacks build new objects and
swap the reference, so the loop never sees half an update. The node runs on one thread
(EventsExecutor), so callbacks never interleave.
"""
import gc
from math import isfinite, sqrt
import time
from typing import Optional, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import control_torque, GainsError, output_error, saturate
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_check import check_goal
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_controller.parameters import declare_gains, declare_structural, GAIN_PARAMETERS
from quat_jt_controller.parameters import gains_update
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

NODE_NAME = 'quat_jt_controller'
# Ring buffers of per-tick timings, summarised by the 1 Hz diagnostics.
STATS_WINDOW = 2048
# |eta_e| below this means the error is within ~11.5 degrees of 180 degrees, where
# Q(eta_e, e)^T K_p e can vanish (ERRATA note 6): reported as a warning.
NEAR_180_ETA_E = 0.1
# Saturated ticks above this fraction of a diagnostics window give a warning.
SATURATION_WARN_FRACTION = 0.05
NS = 1e-9
# DiagnosticStatus levels as ints (the message constants are bytes).
OK, WARN, ERROR = 0, 1, 2


def _percentile(sorted_values: Sequence[float], fraction: float) -> float:
    if not sorted_values:
        return float('nan')
    i = min(len(sorted_values) - 1, max(0, int(round(fraction * (len(sorted_values) - 1)))))
    return sorted_values[i]


class QuatJtController(Node):
    """Transpose-Jacobian regulator with unit-quaternion orientation error, Eq. (22)."""

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._config = declare_structural(self)
        cfg = self._config
        self._model = RobotModel(cfg.robot_description, cfg.base_link, cfg.tip_link,
                                 cfg.joints)
        self._task = cfg.task
        self._n = self._model.n
        self._joint_names = list(cfg.joints)
        self._gains = declare_gains(self, cfg)
        self._gain_values = {name: self.get_parameter(name).value for name in GAIN_PARAMETERS}
        self._pending_gains = None
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        # Effort limits from the URDF; a missing/zero limit means 'no clamp'.
        self._effort_limits_nm = [lim if isfinite(lim) and lim > 0.0 else float('inf')
                                  for lim in self._model.effort_limits]
        self._use_sim_time = bool(self.get_parameter('use_sim_time').value)

        # Goal: (q_desired_base scalar-first, p_desired_base) or None until the first state.
        self._goal: Optional[tuple[quat.Quaternion, tuple[float, float, float]]] = None
        self._goal_source = 'none'  # 'none' | 'hold' (initial pose) | 'target_pose'
        self._goal_warning = ''

        # Joint-state layout cache: the last name list and its index map, plus a dict of all
        # layouts seen (keyed by name tuple) so alternating orders do not rebuild.
        self._last_names: Optional[list[str]] = None
        self._last_index: Optional[list[int]] = None
        self._layouts: dict[tuple[str, ...], Optional[list[int]]] = {}

        # Preallocated messages.
        self._cmd_msg = Float64MultiArray()
        self._cmd_msg.data = [0.0] * self._n
        self._pose_msg = PoseStamped()
        self._pose_msg.header.frame_id = cfg.base_link
        self._eo_msg = Vector3Stamped()
        self._eo_msg.header.frame_id = cfg.base_link
        self._ep_msg = Vector3Stamped()
        self._ep_msg.header.frame_id = cfg.base_link

        # Running state the tick updates cheaply; the diagnostics timer reads and resets it.
        self._compute_us = [0.0] * STATS_WINDOW
        self._publish_us = [0.0] * STATS_WINDOW
        self._period_us = [0.0] * STATS_WINDOW
        self._age_us = [0.0] * STATS_WINDOW
        self._n_ticks = 0  # ticks in the current diagnostics window
        self._n_saturated = 0
        self._n_rejected_states = 0
        self._n_rejected_goals = 0
        self._total_ticks = 0
        self._last_tick_ns = 0
        self._last_valid_state_ns = 0  # time.monotonic_ns of the last valid state
        self._window_start_ns = time.monotonic_ns()
        self._stopped = False  # commanding zeros after a state timeout
        self._last_error_norm = float('nan')
        self._last_eta_e = float('nan')
        self._last_q: Optional[list[float]] = None
        self._last_qdot: Optional[list[float]] = None
        self._decimation = 0
        self._published_q: Optional[quat.Quaternion] = None  # last ~/current_pose quaternion

        self._cmd_pub = self.create_publisher(Float64MultiArray, 'effort_controller/commands', 10)
        self._pose_pub = self.create_publisher(PoseStamped, '~/current_pose', 10)
        self._eo_pub = self.create_publisher(Vector3Stamped, '~/orientation_error', 10)
        self._ep_pub = (self.create_publisher(Vector3Stamped, '~/position_error', 10)
                        if self._task is Task.POSE else None)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, 'joint_states', self._on_joint_state, 10)
        self.create_subscription(PoseStamped, '~/target_pose', self._on_target_pose, 10)
        self._watchdog = self.create_timer(min(0.05, cfg.state_timeout_s / 4.0),
                                           self._on_watchdog)
        self._diag_timer = self.create_timer(1.0, self._on_diagnostics)
        # Statuses are named after the fully qualified node name: /diagnostics is one topic for
        # every node on the graph, and a namespace tells two controllers apart.
        self._diag_name = self.get_fully_qualified_name().lstrip('/')
        self.get_logger().info(
            f'{self._task.value} task, joints {self._joint_names}, {cfg.base_link} -> '
            f'{cfg.tip_link}, potential {self._gains.potential.value}, kp {list(self._gains.kp)}, '
            f'kv {list(self._gains.kv)}, lambda {list(self._gains.lam)}, effort limits '
            f'{self._effort_limits_nm} N m; holding the first measured pose until a goal '
            'arrives on ~/target_pose')

    # ----------------------------------------------------------------------------- parameters
    def _validate_parameters(self, params) -> SetParametersResult:
        """On-set callback: build the new Gains from current + incoming values, or reject."""
        gains, reason = gains_update(self._gain_values, params, self._config)
        if reason:
            self.get_logger().warn(f'parameter set {[p.name for p in params]} {reason}')
            return SetParametersResult(successful=False, reason=reason)
        self._pending_gains = gains
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params) -> None:
        """Post-set callback: the values are stored; swap the one Gains reference."""
        for p in params:
            if p.name in GAIN_PARAMETERS:
                self._gain_values[p.name] = p.value
        if self._pending_gains is not None:
            self._gains = self._pending_gains  # the tick reads this reference once per tick
            self._pending_gains = None
            g = self._gains
            self.get_logger().info(
                f'gains updated: potential {g.potential.value}, kp {list(g.kp)}, '
                f'kv {list(g.kv)}, lambda {list(g.lam)}, gravity_compensation '
                f'{g.gravity_compensation}')

    # ---------------------------------------------------------------------------------- tick
    def _layout(self, names: list[str]) -> Optional[list[int]]:
        """Map a JointState's name list to the controlled joints' indices (None if missing)."""
        if names == self._last_names:
            return self._last_index
        key = tuple(names)
        index = self._layouts.get(key, False)
        if index is False:
            where = {name: i for i, name in enumerate(names)}
            index = ([where[j] for j in self._joint_names]
                     if all(j in where for j in self._joint_names) else None)
            if len(self._layouts) < 64:
                self._layouts[key] = index
        self._last_names = list(names)
        self._last_index = index
        return index

    def _reject_state(self, why: str) -> None:
        self._n_rejected_states += 1
        self.get_logger().warn(f'joint_states rejected: {why}', throttle_duration_sec=1.0)

    def _on_joint_state(self, msg: JointState) -> None:
        """One control tick: Eq. (37)/(38) (orientation) or (24)/(32) (pose) + g(q), clamped."""
        t0 = time.perf_counter_ns()
        index = self._layout(msg.name)
        if index is None:
            self._reject_state(f'missing controlled joint(s): have {list(msg.name)}, '
                               f'need {self._joint_names}')
            return
        pos = msg.position
        vel = msg.velocity
        n_names = len(msg.name)
        if len(pos) != n_names or len(vel) != n_names:
            self._reject_state(f'{n_names} names but {len(pos)} positions and {len(vel)} '
                               'velocities (positions and velocities are required)')
            return
        q = [pos[i] for i in index]
        qdot = [vel[i] for i in index]
        for x in q:
            if not isfinite(x):
                self._reject_state(f'non-finite position {q}')
                return
        for x in qdot:
            if not isfinite(x):
                self._reject_state(f'non-finite velocity {qdot}')
                return

        gains = self._gains  # one read: an update lands at the next tick, whole
        p, R, J = self._model.kinematics(q)
        goal = self._goal
        if goal is None:
            goal = self._hold_current(p, R)
        q_desired_base, p_desired_base = goal
        y_tilde, eta_e = output_error(p, R, p_desired_base, q_desired_base, self._task)
        gravity = self._model.gravity(q) if gains.gravity_compensation else None
        tau_nm = control_torque(J[3:] if self._task is Task.ORIENTATION else J,
                                y_tilde, eta_e, qdot, gravity, gains)
        if saturate(tau_nm, self._effort_limits_nm):
            self._n_saturated += 1
        self._cmd_msg.data = tau_nm
        t1 = time.perf_counter_ns()
        self._cmd_pub.publish(self._cmd_msg)
        t2 = time.perf_counter_ns()

        # Bookkeeping (cheap): timings, watchdog, last error.
        now_mono = time.monotonic_ns()
        k = self._n_ticks % STATS_WINDOW
        self._compute_us[k] = (t1 - t0) * 1e-3
        self._publish_us[k] = (t2 - t1) * 1e-3
        if self._last_tick_ns:
            self._period_us[k] = (now_mono - self._last_tick_ns) * 1e-3
        else:
            self._period_us[k] = float('nan')
        self._last_tick_ns = now_mono
        stamp = msg.header.stamp
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = (self.get_clock().now().nanoseconds if self._use_sim_time
                  else time.time_ns())
        self._age_us[k] = (now_ns - stamp_ns) * 1e-3 if stamp_ns else float('nan')
        self._n_ticks += 1
        self._total_ticks += 1
        self._last_valid_state_ns = now_mono
        if self._stopped:
            self._stopped = False
            self.get_logger().info('joint_states are back: commanding torque again')
        e = y_tilde[-3:]
        self._last_error_norm = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        self._last_eta_e = eta_e
        self._last_q = q
        self._last_qdot = qdot

        self._decimation += 1
        if self._decimation >= self._config.publish_rate_divider:
            self._decimation = 0
            self._publish_feedback(msg.header.stamp, p, R, y_tilde)

    def _hold_current(self, p: Sequence[float], R: quat.Matrix3):
        """Until the first goal: hold the pose measured on the first joint state."""
        goal = (quat.from_rotation_matrix(R), (p[0], p[1], p[2]))
        self._goal = goal
        self._goal_source = 'hold'
        self.get_logger().info(
            f'first joint state: holding the measured pose, quaternion (x, y, z, w) '
            f'{tuple(round(c, 4) for c in quat.to_xyzw(goal[0]))}, position '
            f'{tuple(round(c, 4) for c in goal[1])} m')
        return goal

    def _publish_feedback(self, stamp, p, R, y_tilde) -> None:
        pose = self._pose_msg
        pose.header.stamp = stamp
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = p
        q = quat.from_rotation_matrix(R)
        prev = self._published_q
        if prev is not None and sum(a * b for a, b in zip(q, prev)) < 0.0:
            q = (-q[0], -q[1], -q[2], -q[3])  # the same rotation, no sign flip between samples
        self._published_q = q
        x, y, z, w = quat.to_xyzw(q)
        o = pose.pose.orientation
        o.x, o.y, o.z, o.w = x, y, z, w
        self._pose_pub.publish(pose)
        eo = self._eo_msg
        eo.header.stamp = stamp
        eo.vector.x, eo.vector.y, eo.vector.z = y_tilde[-3:]
        self._eo_pub.publish(eo)
        if self._ep_pub is not None:
            ep = self._ep_msg
            ep.header.stamp = stamp
            ep.vector.x, ep.vector.y, ep.vector.z = y_tilde[0], y_tilde[1], y_tilde[2]
            self._ep_pub.publish(ep)

    # ------------------------------------------------------------------------------ watchdog
    def _on_watchdog(self) -> None:
        """Zero the command once when valid joint states stop for longer than state_timeout."""
        if self._stopped or not self._last_valid_state_ns:
            return
        silent_s = (time.monotonic_ns() - self._last_valid_state_ns) * NS
        if silent_s > self._config.state_timeout_s:
            self._stopped = True
            self._cmd_msg.data = [0.0] * self._n
            self._cmd_pub.publish(self._cmd_msg)
            self.get_logger().error(
                f'no valid joint_states for {silent_s:.3f} s (> state_timeout '
                f'{self._config.state_timeout_s} s): published zero torque, waiting for states')

    # ---------------------------------------------------------------------------------- goal
    def _reject_goal(self, why: str) -> None:
        self._n_rejected_goals += 1
        self.get_logger().warn(f'target_pose rejected, previous goal stays in force: {why}')

    def _on_target_pose(self, msg: PoseStamped) -> None:
        """Validate a goal (frame, tf2-style unit quaternion, finite position) and swap it in."""
        frame = msg.header.frame_id.lstrip('/')
        if frame and frame != self._config.base_link:
            self._reject_goal(f"header.frame_id is '{msg.header.frame_id}', expected "
                              f"'{self._config.base_link}' (or empty)")
            return
        o = msg.pose.orientation
        try:
            q_desired_base = quat.validate_unit(quat.from_xyzw(o.x, o.y, o.z, o.w))
        except ValueError as exc:
            self._reject_goal(str(exc))
            return
        pos = msg.pose.position
        p_desired_base = (pos.x, pos.y, pos.z)
        if self._task is Task.POSE:
            if not all(isfinite(c) for c in p_desired_base):
                self._reject_goal(f'non-finite position {p_desired_base}')
                return
        else:
            p_desired_base = (0.0, 0.0, 0.0)  # ignored by the orientation task
        self._goal = (q_desired_base, p_desired_base)
        self._goal_source = 'target_pose'
        warning = check_goal(self._model, self._last_q, q_desired_base, p_desired_base,
                             self._task)
        self._goal_warning = warning
        text = (f'new goal: quaternion (x, y, z, w) '
                f'{tuple(round(c, 4) for c in quat.to_xyzw(q_desired_base))}')
        if self._task is Task.POSE:
            text += f', position {tuple(round(c, 4) for c in p_desired_base)} m'
        if warning:
            self.get_logger().warn(f'{text}; accepted with a warning: {warning}')
        else:
            self.get_logger().info(text)

    # --------------------------------------------------------------------------- diagnostics
    def _on_diagnostics(self) -> None:
        """1 Hz: achieved rate, period jitter, compute time, state age, saturation, error."""
        now = time.monotonic_ns()
        window_s = max((now - self._window_start_ns) * NS, 1e-9)
        n = self._n_ticks
        m = min(n, STATS_WINDOW)
        compute = sorted(self._compute_us[:m])
        publish = sorted(self._publish_us[:m])
        periods = sorted(x for x in self._period_us[:m] if x == x)
        ages = sorted(x for x in self._age_us[:m] if x == x)
        saturated = self._n_saturated
        self._n_ticks = 0
        self._n_saturated = 0
        self._window_start_ns = now
        rate_hz = n / window_s
        if periods:
            mean_p = sum(periods) / len(periods)
            jitter_std = sqrt(sum((x - mean_p) ** 2 for x in periods) / len(periods))
        else:
            mean_p = jitter_std = float('nan')

        loop = DiagnosticStatus(name=f'{self._diag_name}: control loop',
                                hardware_id=self._config.tip_link)
        loop_msgs = []
        level = OK
        if self._last_valid_state_ns == 0:
            level, loop_msgs = WARN, ['waiting for joint_states']
        elif self._stopped:
            level = ERROR
            loop_msgs.append('joint_states timed out: commanding zero torque')
        if n and saturated > SATURATION_WARN_FRACTION * n:
            level = max(level, WARN)
            loop_msgs.append(f'torque saturated in {saturated}/{n} ticks')
        loop.level = bytes([level])
        loop.message = '; '.join(loop_msgs) or f'running at {rate_hz:.0f} Hz'
        kv = [
            ('control_rate_hz', f'{rate_hz:.1f}'),
            ('ticks_in_window', str(n)),
            ('period_mean_us', f'{mean_p:.1f}'),
            ('period_jitter_std_us', f'{jitter_std:.1f}'),
            ('period_p99_us', f'{_percentile(periods, 0.99):.1f}'),
            ('period_max_us', f'{periods[-1] if periods else float("nan"):.1f}'),
            ('compute_us_p50', f'{_percentile(compute, 0.5):.1f}'),
            ('compute_us_p99', f'{_percentile(compute, 0.99):.1f}'),
            ('compute_us_max', f'{compute[-1] if compute else float("nan"):.1f}'),
            ('publish_us_p50', f'{_percentile(publish, 0.5):.1f}'),
            ('publish_us_p99', f'{_percentile(publish, 0.99):.1f}'),
            ('state_age_us_p50', f'{_percentile(ages, 0.5):.1f}'),
            ('state_age_us_max', f'{ages[-1] if ages else float("nan"):.1f}'),
            ('saturated_ticks', str(saturated)),
            ('rejected_states_total', str(self._n_rejected_states)),
            ('state_timeout', str(self._stopped)),
            ('total_ticks', str(self._total_ticks)),
        ]
        loop.values = [KeyValue(key=k, value=v) for k, v in kv]

        goal = DiagnosticStatus(name=f'{self._diag_name}: goal',
                                hardware_id=self._config.tip_link)
        glevel = OK
        gmsgs = []
        if self._goal_source == 'none':
            gmsgs.append('no goal (no joint state yet)')
        elif self._goal_source == 'hold':
            gmsgs.append('holding the initial pose (no goal received)')
        else:
            gmsgs.append('regulating to target_pose')
        if self._goal_warning:
            glevel = WARN
            gmsgs.append(self._goal_warning)
        eta_e = self._last_eta_e
        if eta_e == eta_e and abs(eta_e) < NEAR_180_ETA_E:
            glevel = WARN
            gmsgs.append(f'orientation error near 180 degrees (eta_e = {eta_e:.3f}): the '
                         'orientation torque can vanish there; give an intermediate goal')
        goal.level = bytes([glevel])
        goal.message = '; '.join(gmsgs)
        qd = self._goal[0] if self._goal is not None else None
        gkv = [
            ('error_norm', f'{self._last_error_norm:.6g}'),
            ('eta_e', f'{eta_e:.6g}'),
            ('max_joint_speed_rad_s',
             f'{max(abs(x) for x in self._last_qdot):.4g}' if self._last_qdot else 'nan'),
            ('goal_source', self._goal_source),
            ('goal_xyzw', str([round(c, 6) for c in quat.to_xyzw(qd)]) if qd else ''),
            ('rejected_goals_total', str(self._n_rejected_goals)),
        ]
        goal.values = [KeyValue(key=k, value=v) for k, v in gkv]
        arr = DiagnosticArray(status=[loop, goal])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)


def main(args=None) -> None:
    """``ros2 run quat_jt_controller controller_node``."""
    from rclpy.experimental import EventsExecutor

    rclpy.init(args=args)
    node = None
    try:
        try:
            node = QuatJtController()
        except (ModelError, GainsError, ValueError) as exc:
            rclpy.logging.get_logger(NODE_NAME).fatal(f'cannot start: {exc}')
            raise SystemExit(1) from None
        executor = EventsExecutor()
        executor.add_node(node)
        # The objects built so far (rclpy, Pinocchio, the model) live as long as the node: keep
        # the cyclic garbage collector from rescanning them during the 1 kHz loop.
        gc.collect()
        gc.freeze()
        # spin_once with a timeout in a loop: returns promptly on SIGINT (rclpy.ok() turns
        # false); EventsExecutor.spin() did not process events when measured here.
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()

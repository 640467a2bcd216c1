"""
The 7-DOF Panda over real DDS: the same two nodes, its configs, its URDF as robot_description.

``wrist_sim_node`` and ``controller_node`` in their own processes (``local_ros``) with
``config/panda_sim.yaml`` and ``config/panda_controller.yaml``, as launch/panda_demo.launch.py
starts them, in lockstep with the simulated clock paced at real time (so the checks hold on a
slow host: every wait is in simulated time, with a generous wall-clock deadline). The goal of
the launch file is reached, the arm comes to rest (no self-motion drift) and it rests at the
goal configuration q* that the controller reports on /diagnostics.
"""
import os
import time

from diagnostic_msgs.msg import DiagnosticArray
from experiments import local_ros
from experiments.probe import ProbeNode
from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from robots import PANDA_JOINTS, PANDA_URDF
from sensor_msgs.msg import JointState

pytestmark = pytest.mark.dds

# launch/panda_demo.launch.py's goal: the flange's pose at this configuration
Q_GOAL = (0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.9)
GOAL_AFTER_S = 2.0  # simulated: the goal-check worker is up, as when a user sends a goal
REACH_WITHIN_S = 5.0  # the bound, simulated
REST_WINDOW_S = 0.5


def test_the_panda_reaches_the_goal_and_rests_at_its_goal_configuration(tmp_path):
    urdf = PANDA_URDF.read_text()
    model = RobotModel(urdf, 'panda_link0', 'panda_link8', PANDA_JOINTS)
    p_d, R_d = model.forward_kinematics(list(Q_GOAL))
    q_d = quat.from_rotation_matrix(R_d)
    domain = int(os.environ['ROS_DOMAIN_ID'])
    env = local_ros.isolated_env(tmp_path, domain)
    sim, ctrl = local_ros.spawn_wrist_pair(
        env, tmp_path, sim_params={'robot_description': urdf, 'publish_clock': True,
                                   'max_real_time_factor': 1.0},
        controller_params={'robot_description': urdf, 'use_sim_time': True},
        controller_config='config/panda_controller.yaml', sim_config='config/panda_sim.yaml')
    probe = ProbeNode('panda_probe', domain)
    states: list = []
    goal_status: list = []
    probe.node.create_subscription(JointState, '/joint_states', states.append, 1000)

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name.endswith(': goal'):
                goal_status.append({kv.key: kv.value for kv in s.values})
    probe.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    pub = probe.node.create_publisher(PoseStamped, '/quat_jt_controller/target_pose', 10)

    def stamp_s() -> float:
        s = states[-1].header.stamp
        return s.sec + 1e-9 * s.nanosec

    def spin_until(condition, what: str, timeout_s: float = 240.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            for proc in (sim, ctrl):
                assert proc.poll() is None, f'a node exited while waiting for {what}'
            assert time.monotonic() < deadline, f'timed out waiting for {what}'
            probe.executor.spin_once(timeout_sec=0.05)
    try:
        spin_until(lambda: states and stamp_s() >= GOAL_AFTER_S, 'the nodes to run')
        assert tuple(states[-1].name) == PANDA_JOINTS  # the fingers are held, not published
        spin_until(lambda: pub.get_subscription_count() > 0, 'the goal subscription')
        msg = PoseStamped()
        msg.header.frame_id = 'panda_link0'
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p_d
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = quat.to_xyzw(q_d)
        t0 = stamp_s()
        pub.publish(msg)
        spin_until(lambda: stamp_s() >= t0 + REACH_WITHIN_S + REST_WINDOW_S, 'the motion')
        spin_until(lambda: goal_status and goal_status[-1].get('goal_configuration_rad'),
                   'q* on /diagnostics')
    finally:
        local_ros.stop_nodes((sim, ctrl))
        probe.close()
    last = [s for s in states if s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec
            >= t0 + REACH_WITHIN_S]
    q_end = np.array(last[-1].position)
    p, R = model.forward_kinematics(q_end.tolist())
    _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
    assert np.linalg.norm(np.subtract(p, p_d)) < 1e-3
    assert np.linalg.norm(e) < 0.01
    speed = max(np.abs(s.velocity).max() for s in last)
    assert speed < 1e-3, f'the arm still moves at {speed} rad/s: the self-motion drifts'
    q_star = np.array([float(x) for x in
                       goal_status[-1]['goal_configuration_rad'].strip('[]').split(',')])
    assert np.abs(q_end - q_star).max() < 0.05  # the elbow where the goal check put it

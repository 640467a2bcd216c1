"""
The 3D replay topics of an MCAP, read back with the standard ROS 2 MCAP decoder.

Every channel decodes, and the decoded transforms compose to the model's forward kinematics of
the tip link.
"""
from experiments.mcap_log import (cdr_joint_state, LATCHED_QOS_YAML, McapLog,
                                  message_definition, SEPARATOR)
from experiments.robot_tf import UrdfTfTree, write_robot_replay
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from robots import small_arm_urdf, wrist_model, xarm6_model, XARM6_URDF

pytestmark = pytest.mark.unit


def test_tf_message_schema_is_the_rosbag2_concatenated_definition():
    text = message_definition('tf2_msgs/msg/TFMessage')
    parts = text.split(SEPARATOR + '\n')
    assert parts[0].strip() == 'geometry_msgs/TransformStamped[] transforms'
    names = [p.split('\n', 1)[0] for p in parts[1:]]
    assert sorted(names) == sorted(
        f'MSG: {n}' for n in ('geometry_msgs/TransformStamped', 'std_msgs/Header',
                              'builtin_interfaces/Time', 'geometry_msgs/Transform',
                              'geometry_msgs/Vector3', 'geometry_msgs/Quaternion'))
    transform = parts[1 + names.index('MSG: geometry_msgs/Transform')]
    assert 'Vector3 translation' in transform and 'Quaternion rotation' in transform


def _compose(transforms: dict, base: str, link: str) -> np.ndarray:
    """Chain child -> parent transforms from ``link`` up to ``base``: T_base_link (4 x 4)."""
    T = np.eye(4)
    while link != base:
        parent, t = transforms[link]
        step = np.eye(4)
        step[:3, :3] = quat.to_rotation_matrix(quat.from_xyzw(
            t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w))
        step[:3, 3] = (t.translation.x, t.translation.y, t.translation.z)
        T = step @ T
        link = parent
    return T


@pytest.mark.parametrize('robot', ['wrist', 'xarm6'])
def test_replay_decodes_and_composes_to_the_forward_kinematics(tmp_path, robot):
    if robot == 'wrist':
        urdf, model, tip = default_urdf_xml(), wrist_model(), 'tool0'
        p_goal, _ = model.forward_kinematics(paper.Q_JOINT_DESIRED_RAD)
        goal_xyzw = quat.to_xyzw(paper.Q_DESIRED)
    else:
        urdf, model, tip = XARM6_URDF.read_text(), xarm6_model(), 'link6'
        p_goal, goal_xyzw = (0.36, 0.09, 0.52), (0.0, 1.0, 0.0, 0.0)
    rng = np.random.default_rng(7)
    n_samples = 250  # 0.25 s at 1 kHz
    stamps_ns = 1_700_000_000_000_000_000 + np.arange(n_samples) * 1_000_000
    log_ns = stamps_ns + 300_000  # received 0.3 ms after the stamp
    q = np.cumsum(rng.normal(0.0, 0.02, (n_samples, model.n)), axis=0)
    path = tmp_path / 'replay.mcap'
    log = McapLog(path)
    js = log.channel('/joint_states', 'sensor_msgs/msg/JointState')
    for k in range(n_samples):
        log.write(js, cdr_joint_state(int(stamps_ns[k]), model.joint_names, q[k]),
                  int(log_ns[k]))
    counts = write_robot_replay(log, urdf, model.joint_names, log_ns, stamps_ns, q,
                                goal=(model.base_link, p_goal, goal_xyzw))
    log.close()
    assert counts == {'/robot_description': 1, '/tf_static': 1, '/tf': 25}  # 100 Hz

    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        decoded = list(reader.iter_decoded_messages())
    # Every channel of the file is read back by the standard decoder, in log-time order.
    topics = {ch.topic: ch for ch in summary.channels.values()}
    assert set(topics) == {'/joint_states', '/robot_description', '/tf_static', '/tf'}
    assert {ch.topic for _, ch, _, _ in decoded} == set(topics)
    assert len(decoded) == n_samples + 27
    assert [m.log_time for _, _, m, _ in decoded] == sorted(m.log_time for _, _, m, _ in decoded)
    for latched in ('/robot_description', '/tf_static'):
        assert topics[latched].metadata['offered_qos_profiles'] == LATCHED_QOS_YAML
    by_topic: dict[str, list] = {}
    for _, ch, _, msg in decoded:
        by_topic.setdefault(ch.topic, []).append(msg)
    assert by_topic['/robot_description'][0].data == urdf
    static = by_topic['/tf_static'][0].transforms
    assert ('goal', model.base_link) in {(t.child_frame_id, t.header.frame_id) for t in static}
    state_at = {s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec: s
                for s in by_topic['/joint_states']}

    tree = {t.child_frame_id: (t.header.frame_id, t.transform) for t in static}
    worst_m = worst_rad = 0.0
    for msg in by_topic['/tf']:
        assert len(msg.transforms) == model.n
        stamp = {t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec
                 for t in msg.transforms}
        assert len(stamp) == 1
        state = state_at[stamp.pop()]
        tree.update({t.child_frame_id: (t.header.frame_id, t.transform)
                     for t in msg.transforms})
        T = _compose(tree, model.base_link, tip)
        p, R = model.forward_kinematics(state.position)
        worst_m = max(worst_m, float(np.abs(T[:3, 3] - p).max()))
        worst_rad = max(worst_rad, float(np.linalg.norm(T[:3, :3].T @ np.array(R) - np.eye(3))))
    assert worst_m < 1e-9 and worst_rad < 1e-9, (worst_m, worst_rad)
    # The goal frame composes to the goal given.
    T_goal = _compose(tree, model.base_link, 'goal')
    np.testing.assert_allclose(T_goal[:3, 3], p_goal, atol=1e-12)
    np.testing.assert_allclose(quat.from_rotation_matrix(T_goal[:3, :3]),
                               quat.normalized(quat.from_xyzw(*goal_xyzw)), atol=1e-9)


def test_continuous_joints_compose_to_the_forward_kinematics():
    urdf = small_arm_urdf()
    names = ['joint1', 'joint2', 'joint3', 'joint4', 'tool']
    model = RobotModel(urdf, 'base_link', 'tool', joint_names=names)
    tree = UrdfTfTree(urdf, names)
    q_rad = [2.5, -0.7, 1.1, -3.0, 0.4]  # joint1 and joint4 are continuous
    by_child = {child: (parent, _transform(xyz, xyzw))
                for parent, child, xyz, xyzw in tree.static_transforms()
                + tree.moving_transforms(q_rad)}
    T = _compose(by_child, 'base_link', 'tool')
    p_m, R = model.forward_kinematics(q_rad)
    np.testing.assert_allclose(T[:3, 3], p_m, atol=1e-12)
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-12)


def _transform(xyz, xyzw):
    """Return a decoded-message stand-in for :func:`_compose` (``translation``, ``rotation``)."""
    from types import SimpleNamespace as NS
    return NS(translation=NS(x=xyz[0], y=xyz[1], z=xyz[2]),
              rotation=NS(x=xyzw[0], y=xyzw[1], z=xyzw[2], w=xyzw[3]))

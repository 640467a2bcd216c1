"""MCAP files written from raw CDR decode with the standard ROS 2 MCAP reader."""
from experiments.mcap_log import McapLog, message_definition
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

pytestmark = pytest.mark.unit


def test_definition_carries_dependencies_in_rosbag2_form():
    text = message_definition('sensor_msgs/msg/JointState')
    assert 'float64[] effort' in text.split('=' * 80)[0]
    assert '\nMSG: std_msgs/Header\n' in text and '\nMSG: builtin_interfaces/Time\n' in text


def test_raw_messages_round_trip(tmp_path):
    path = tmp_path / 'run.mcap'
    log = McapLog(path)
    js_ch = log.channel('/joint_states', 'sensor_msgs/msg/JointState')
    cmd_ch = log.channel('/effort_controller/commands', 'std_msgs/msg/Float64MultiArray')
    for k in range(5):
        js = JointState(name=['joint1', 'joint2'], position=[0.1 * k, -0.2], velocity=[0.0, 1.0])
        js.header.stamp.sec, js.header.stamp.nanosec = 7, 1000 * k
        log.write(js_ch, serialize_message(js), log_time_ns=1_000_000 * k)
        log.write(cmd_ch, serialize_message(Float64MultiArray(data=[float(k), 2.0])),
                  log_time_ns=1_000_000 * k + 10)
    log.close()

    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        decoded = list(reader.iter_decoded_messages())
    states = [m for _, ch, _, m in decoded if ch.topic == '/joint_states']
    commands = [m for _, ch, _, m in decoded if ch.topic == '/effort_controller/commands']
    assert [s.position[0] for s in states] == [0.1 * k for k in range(5)]
    assert states[3].name == ['joint1', 'joint2'] and states[3].header.stamp.nanosec == 3000
    assert [c.data[0] for c in commands] == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_own_cdr_matches_rclpy():
    """
    The messages the tools serialise without rclpy match rclpy's serialisation.

    Byte for byte where CDR has no padding (String); elsewhere rclpy reads ours back to the same
    message (rclpy leaves its padding bytes uninitialised and pads the end to 8 bytes).
    """
    from experiments.mcap_log import cdr_joint_state, cdr_string
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String
    for text in ('', 'a', '<robot name="x"/>\n' * 3):
        assert cdr_string(text) == serialize_message(String(data=text))
    for names, position, velocity, effort in (
            (['joint1', 'j2', 'joint_three'], [0.1, -2.0, 3.5], [1.0, 2.0, 3.0], []),
            ([], [], [], []), (['a'], [1e-300], [], [7.0])):
        js = JointState(name=names, position=position, velocity=velocity, effort=effort)
        js.header.stamp.sec, js.header.stamp.nanosec = 1_700_000_001, 999_999_999
        js.header.frame_id = 'base'
        ours = cdr_joint_state(1_700_000_001_999_999_999, names, position, velocity, effort,
                               frame_id='base')
        assert deserialize_message(ours, JointState) == js, names

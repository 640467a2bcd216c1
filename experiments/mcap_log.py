"""
Write ROS 2 messages, as received serialised (CDR), to an MCAP file that rosbag2 can read.

The schema of each channel is the message definition in ROS 2's ``ros2msg`` form, the .msg text
followed by the definitions it depends on, as ``ros2 bag record`` writes it. ROS-free: works
on the raw bytes of an ``rclpy`` subscription created with ``raw=True``, and serialises the few
messages the tools write themselves (:class:`CdrWriter`: ``std_msgs/String``,
``tf2_msgs/TFMessage``, ``sensor_msgs/JointState``) without rclpy.
"""
import os
from pathlib import Path
import struct
import sys
from typing import BinaryIO, Optional, Sequence

from mcap.writer import CompressionType, Writer

PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
              'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}
SEPARATOR = '=' * 80
# Definitions of messages whose package is not on PyPI (used only where it is not installed).
# tf2_msgs/msg/TFMessage.msg in ROS 2 Jazzy is this one field.
BUNDLED_DEFINITIONS = {
    'tf2_msgs/msg/TFMessage': 'geometry_msgs/TransformStamped[] transforms\n',
}
# The QoS a latched publisher offers (robot_state_publisher's /robot_description, /tf_static),
# as rosbag2 (Jazzy, metadata version 9) writes it in a channel's 'offered_qos_profiles': the
# player then republishes the topic transient-local, so late subscribers (RViz) still get it.
_INFINITE = '\n    sec: 9223372036\n    nsec: 854775807'
LATCHED_QOS_YAML = (
    '- history: keep_last\n  depth: 1\n  reliability: reliable\n'
    '  durability: transient_local\n'
    f'  deadline:{_INFINITE}\n  lifespan:{_INFINITE}\n  liveliness: automatic\n'
    f'  liveliness_lease_duration:{_INFINITE}\n  avoid_ros_namespace_conventions: false\n')


def _share_dirs() -> list[Path]:
    dirs = [Path(p) / 'share' for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
            if p]
    return dirs + [Path(sys.prefix) / 'share']


def _msg_text(full_name: str) -> str:
    package, _, name = full_name.partition('/msg/')
    for share in _share_dirs():
        path = share / package / 'msg' / f'{name}.msg'
        if path.is_file():
            return path.read_text()
    if full_name in BUNDLED_DEFINITIONS:
        return BUNDLED_DEFINITIONS[full_name]
    raise FileNotFoundError(f'no definition of {full_name} under {_share_dirs()}')


def _dependencies(package: str, text: str) -> list[str]:
    deps = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        field_type = line.split()[0].split('[', 1)[0].split('<=', 1)[0]
        if field_type in PRIMITIVES:  # constants are always of primitive types
            continue
        if '/' in field_type:
            pkg, _, name = field_type.partition('/')
            name = name.replace('msg/', '')
        else:
            pkg, name = package, field_type
        deps.append(f'{pkg}/msg/{name}')
    return deps


def message_definition(full_name: str) -> str:
    """Return the ros2msg schema of e.g. 'sensor_msgs/msg/JointState' with its dependencies."""
    parts = [_msg_text(full_name)]
    seen = {full_name}
    pending = _dependencies(full_name.split('/')[0], parts[0])
    while pending:
        dep = pending.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        text = _msg_text(dep)
        parts.append(f'{SEPARATOR}\nMSG: {dep.replace("/msg/", "/")}\n{text}')
        pending += _dependencies(dep.split('/')[0], text)
    return '\n'.join(p.rstrip('\n') for p in parts) + '\n'


class McapLog:
    """An MCAP file of serialised ROS 2 messages, one channel per topic."""

    def __init__(self, path: Path) -> None:
        self._file: BinaryIO = open(path, 'wb')
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library='quat_jt_controller')
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    def channel(self, topic: str, type_name: str, latched: bool = False) -> int:
        """
        Register ``topic`` of type e.g. 'sensor_msgs/msg/JointState'; return its id.

        ``latched``: the topic was offered transient-local (see :data:`LATCHED_QOS_YAML`).
        """
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding='ros2msg',
                data=message_definition(type_name).encode())
        if topic not in self._channels:
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding='cdr', schema_id=self._schemas[type_name],
                metadata={'offered_qos_profiles': LATCHED_QOS_YAML} if latched else {})
        return self._channels[topic]

    def write(self, channel_id: int, data: bytes, log_time_ns: int,
              publish_time_ns: Optional[int] = None) -> None:
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns or log_time_ns)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()


class CdrWriter:
    """
    Plain CDR, little endian (XCDR1): the serialisation of ROS 2 messages (MCAP 'cdr').

    Each primitive is aligned to its own size, counted from the end of the 4-byte encapsulation
    header; strings are a uint32 length (with the terminating NUL) and the bytes; sequences a
    uint32 count and the elements. Compose a message by writing its fields in .msg order.
    """

    def __init__(self) -> None:
        self._buf = bytearray(b'\x00\x01\x00\x00')  # CDR_LE, no options

    def _align(self, size: int) -> None:
        self._buf += bytes(-(len(self._buf) - 4) % size)

    def int32(self, value: int) -> None:
        self._align(4)
        self._buf += struct.pack('<i', value)

    def uint32(self, value: int) -> None:
        self._align(4)
        self._buf += struct.pack('<I', value)

    def float64(self, value: float) -> None:
        self._align(8)
        self._buf += struct.pack('<d', value)

    def string(self, text: str) -> None:
        data = text.encode()
        self.uint32(len(data) + 1)
        self._buf += data + b'\x00'

    def float64_sequence(self, values: Sequence[float]) -> None:
        self.uint32(len(values))
        for v in values:
            self.float64(float(v))

    def string_sequence(self, texts: Sequence[str]) -> None:
        self.uint32(len(texts))
        for text in texts:
            self.string(text)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        """std_msgs/Header: builtin_interfaces/Time (int32 sec, uint32 nanosec), frame_id."""
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        self.int32(sec)
        self.uint32(nanosec)
        self.string(frame_id)

    def data(self) -> bytes:
        return bytes(self._buf)


def cdr_string(text: str) -> bytes:
    """Serialise a std_msgs/msg/String."""
    w = CdrWriter()
    w.string(text)
    return w.data()


def cdr_tf_message(transforms: Sequence[tuple[int, str, str, Sequence[float], Sequence[float]]]
                   ) -> bytes:
    """
    Serialise a tf2_msgs/msg/TFMessage.

    Each transform is (stamp_ns, parent frame, child frame, translation xyz in m, rotation as
    a quaternion x, y, z, w): a geometry_msgs/TransformStamped.
    """
    w = CdrWriter()
    w.uint32(len(transforms))
    for stamp_ns, parent, child, xyz, xyzw in transforms:
        w.header(stamp_ns, parent)
        w.string(child)
        for v in xyz:
            w.float64(float(v))
        for v in xyzw:
            w.float64(float(v))
    return w.data()


def cdr_joint_state(stamp_ns: int, names: Sequence[str], position: Sequence[float],
                    velocity: Sequence[float] = (), effort: Sequence[float] = (),
                    frame_id: str = '') -> bytes:
    """Serialise a sensor_msgs/msg/JointState."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.string_sequence(names)
    w.float64_sequence(position)
    w.float64_sequence(velocity)
    w.float64_sequence(effort)
    return w.data()

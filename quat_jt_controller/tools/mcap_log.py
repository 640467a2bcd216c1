"""
Write ROS 2 messages, as received serialised (CDR), to an MCAP file that rosbag2 can read.

The schema of each channel is the message definition in ROS 2's ``ros2msg`` form, the .msg text
followed by the definitions it depends on, as ``ros2 bag record`` writes it. ROS-free: works
on the raw bytes of an ``rclpy`` subscription created with ``raw=True``.
"""
import os
from pathlib import Path
import sys
from typing import BinaryIO, Optional

from mcap.writer import CompressionType, Writer

PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
              'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}
SEPARATOR = '=' * 80


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

    def channel(self, topic: str, type_name: str) -> int:
        """Register ``topic`` of type e.g. 'sensor_msgs/msg/JointState'; return its id."""
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding='ros2msg',
                data=message_definition(type_name).encode())
        if topic not in self._channels:
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding='cdr', schema_id=self._schemas[type_name])
        return self._channels[topic]

    def write(self, channel_id: int, data: bytes, log_time_ns: int,
              publish_time_ns: Optional[int] = None) -> None:
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns or log_time_ns)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()

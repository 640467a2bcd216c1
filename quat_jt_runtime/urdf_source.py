"""
Where a node's robot description (the URDF) comes from: one source, or the bundled wrist.

Both nodes take the URDF the ways a ROS 2 Jazzy node does, from at most one of:

- ``robot_description``: the XML itself, from a params file or a launch file (as
  robot_state_publisher and ros2_control's controller_manager take it);
- ``robot_description_file``: the path of a URDF file, the simplest with ``ros2 run``;
- ``robot_description_topic``: a topic on which robot_state_publisher (or the simulator)
  publishes it as ``std_msgs/String``, transient local, waited for at start-up.

None of them: the bundled spherical wrist. Two of them are refused, naming both: which one was
meant is not guessed. ROS-free: the choice, the file and the rows of the parameters
(``SOURCES``); the topic is ``description.py``'s.
"""
from dataclasses import dataclass
import enum
from pathlib import Path

from quat_jt_runtime.errors import QuatJtError
from quat_jt_runtime.param_table import Kind, Spec
from quat_jt_runtime.resources import DEFAULT_URDF, default_urdf_xml

DEFAULT_TIMEOUT_S = 30.0  # of the wait for robot_description_topic

ROBOT_DESCRIPTION_FILE = Spec(
    'robot_description_file', Kind.STRING, '',
    "Path of the robot's URDF file, read at start-up (the simplest with ros2 run: -p "
    'robot_description_file:=/path/robot.urdf). At most one of robot_description, '
    'robot_description_file and robot_description_topic; none = the bundled spherical wrist.',
    read_only=True)
ROBOT_DESCRIPTION_TOPIC = Spec(
    'robot_description_topic', Kind.STRING, '',
    'Topic to take the URDF from at start-up, e.g. robot_description (std_msgs/String, '
    'transient local, as robot_state_publisher publishes it); the node waits for it, '
    'robot_description_timeout at most, before it builds its model. At most one of '
    'robot_description, robot_description_file and robot_description_topic.', read_only=True)
ROBOT_DESCRIPTION_TIMEOUT = Spec(
    'robot_description_timeout', Kind.DOUBLE, DEFAULT_TIMEOUT_S,
    'Seconds to wait for the URDF on robot_description_topic before giving up with an error.',
    read_only=True, bounds=(0.1, 86400.0))
SOURCES = (ROBOT_DESCRIPTION_FILE, ROBOT_DESCRIPTION_TOPIC, ROBOT_DESCRIPTION_TIMEOUT)


class DescriptionError(QuatJtError):
    """No usable robot description: two sources given, an unreadable file, no message."""


class Source(enum.Enum):
    """Where the URDF in use came from (the value: the parameter that said so)."""

    TEXT = 'robot_description'
    FILE = 'robot_description_file'
    TOPIC = 'robot_description_topic'
    BUNDLED = 'bundled'


@dataclass(frozen=True)
class Choice:
    """The source a node's parameters name, and its value (the XML, a path or a topic)."""

    source: Source
    value: str = ''


@dataclass(frozen=True)
class Description:
    """The URDF in use and where it came from (``origin``: the path or the topic's name)."""

    xml: str
    source: Source
    origin: str = ''

    @property
    def given(self) -> str:
        """Return the URDF as given to the node; '' when it is the bundled wrist."""
        return '' if self.source is Source.BUNDLED else self.xml

    def describe(self) -> str:
        """Return where the URDF came from, for a log line."""
        if self.source is Source.BUNDLED:
            return f'the bundled {DEFAULT_URDF}'
        if self.source is Source.TEXT:
            return 'the robot_description parameter'
        kind = 'file' if self.source is Source.FILE else 'topic'
        return f'{kind} {self.origin} ({self.source.value})'


class WithDescription:
    """
    The URDF names a node's structural config gives, from its ``description`` field.

    Mixed into both nodes' frozen configs, so ``urdf_xml`` and ``given_urdf`` mean the same
    thing in each.
    """

    description: Description  # declared by the dataclass that mixes this in

    @property
    def urdf_xml(self) -> str:
        """Return the URDF in use (the bundled wrist's if none was given)."""
        return self.description.xml

    @property
    def given_urdf(self) -> str:
        """Return the URDF as given to the node ('' = none: the bundled wrist)."""
        return self.description.given


def choose(text: str, path: str, topic: str) -> Choice:
    """
    Return the one source the parameters name (none: the bundled wrist).

    Raises DescriptionError naming the parameters if more than one is set.
    """
    given = [Choice(source, value) for source, value in (
        (Source.TEXT, text), (Source.FILE, path), (Source.TOPIC, topic)) if value]
    if len(given) > 1:
        names = ' and '.join(c.source.value for c in given)
        raise DescriptionError(
            f'{names} are both set: give the robot description one way only (the XML in '
            'robot_description, a path in robot_description_file, or a topic in '
            'robot_description_topic)')
    return given[0] if given else Choice(Source.BUNDLED)


def read_file(path: str) -> Description:
    """Read ``robot_description_file``; raise DescriptionError saying why it cannot be read."""
    full = Path(path).expanduser()
    try:
        xml = full.read_text()
    except FileNotFoundError:
        raise DescriptionError(
            f"robot_description_file '{path}': no such file ({full.absolute()}); give "
            'the path of a URDF file, absolute or relative to the directory the node was '
            'started in') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DescriptionError(f"robot_description_file '{path}' cannot be read: {exc}"
                               ) from None
    if not xml.strip():
        raise DescriptionError(f"robot_description_file '{path}' is empty")
    return Description(xml, Source.FILE, str(full))


def resolve_offline(choice: Choice) -> Description:
    """Return the description of a text, a file or the bundled wrist (not of a topic)."""
    if choice.source is Source.TEXT:
        return Description(choice.value, Source.TEXT)
    if choice.source is Source.FILE:
        return read_file(choice.value)
    if choice.source is Source.BUNDLED:
        return Description(default_urdf_xml(), Source.BUNDLED)
    raise DescriptionError('a robot description on a topic needs a node to wait for it')

"""
Which DDS transport the nodes use: UDP, never Fast DDS's shared memory (ROS-free).

Fast DDS's shared-memory transport runs a health check on a port the first time a participant
sends to it. On an idle port of a process that has just joined (a ``ros2 topic echo``, say),
that check sleeps a third of ``healthy_check_timeout_ms``, 333 ms by default, inside the
sending call, and the participant's other sends wait for it (eProsima/Fast-DDS issue 6535). A
writer's first sample to a new reader is such a send, so anyone listening to any topic of a
node stopped its 1 kHz loop for a third of a second, and stopped the simulator's joint states
with it. Over UDP a send to a new reader is one ``sendto``.

:func:`choose` decides, from the environment before ``rclpy.init``, which Fast DDS profile
the process loads (``FASTRTPS_DEFAULT_PROFILES_FILE``):

- ``config/fastdds_udp.xml``: UDPv4 only, Fast DDS's default discovery;
- ``config/fastdds_udp_localhost.xml`` for ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``:
  rmw_fastrtps builds its own transports in that mode, shared memory among them, and ignores a
  profile's, so the process runs in ``SUBNET`` mode with a profile that confines it to
  127.0.0.1 as LOCALHOST does (sockets bound to loopback, unicast discovery to 127.0.0.1).

Nothing changes when the user chose otherwise: a profile file of their own, another RMW, a
discovery server, static peers with LOCALHOST (the peers are not on loopback), or
``QUAT_JT_SHARED_MEMORY=1``.
"""
from dataclasses import dataclass, field
from typing import Callable, Mapping

PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
OPT_OUT_VARIABLE = 'QUAT_JT_SHARED_MEMORY'
UDP_PROFILE = 'config/fastdds_udp.xml'
UDP_LOCALHOST_PROFILE = 'config/fastdds_udp_localhost.xml'
SHARED_MEMORY_RISK = ('a process joining a topic can hold a publish for 333 ms (docs/ros.md, '
                      'Transport)')


@dataclass(frozen=True)
class Choice:
    """The environment variables to set before ``rclpy.init``, and the line that says why."""

    changes: dict = field(default_factory=dict)
    note: str = ''


def choose(env: Mapping[str, str], share_path: Callable[[str], object]) -> Choice:
    """
    Return the transport choice for a process whose environment is ``env``.

    ``share_path`` maps a data file of the package (``config/...``) to its installed path.
    """
    rmw = env.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp') or 'rmw_fastrtps_cpp'
    if not rmw.startswith('rmw_fastrtps'):
        return Choice(note=f'DDS transport: {rmw}, as configured')
    if env.get(OPT_OUT_VARIABLE, '') not in ('', '0'):
        return Choice(note=f'DDS transport: Fast DDS defaults, shared memory on '
                      f'({OPT_OUT_VARIABLE}); {SHARED_MEMORY_RISK}')
    for name in PROFILE_VARIABLES:
        if env.get(name):
            return Choice(note=f'DDS transport: the Fast DDS profile {env[name]} ({name})')
    if env.get('ROS_DISCOVERY_SERVER'):
        return Choice(note='DDS transport: Fast DDS defaults (ROS_DISCOVERY_SERVER set)')
    localhost = (env.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '').upper() == 'LOCALHOST'
                 or env.get('ROS_LOCALHOST_ONLY', '') == '1')
    if localhost and env.get('ROS_STATIC_PEERS'):
        return Choice(note='DDS transport: Fast DDS defaults, shared memory on (LOCALHOST with '
                      f'ROS_STATIC_PEERS); {SHARED_MEMORY_RISK}')
    try:
        profile = str(share_path(UDP_LOCALHOST_PROFILE if localhost else UDP_PROFILE))
    except FileNotFoundError as exc:  # an install without the config files: say so, run on
        return Choice(note=f'DDS transport: Fast DDS defaults, shared memory on ({exc}); '
                      f'{SHARED_MEMORY_RISK}')
    if localhost:
        changes = {'FASTRTPS_DEFAULT_PROFILES_FILE': profile,
                   'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
        if 'ROS_LOCALHOST_ONLY' in env:
            changes['ROS_LOCALHOST_ONLY'] = '0'
        return Choice(changes, 'DDS transport: UDP on 127.0.0.1 only (LOCALHOST), shared '
                      'memory off (docs/ros.md, Transport)')
    return Choice({'FASTRTPS_DEFAULT_PROFILES_FILE': profile},
                  'DDS transport: UDP, shared memory off (docs/ros.md, Transport)')

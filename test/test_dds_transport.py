"""
The nodes' DDS transport: UDP, never Fast DDS's shared memory (quat_jt_runtime.dds_transport).

The choice is a function of the environment (unit); started as a user starts them, both nodes
run without a shared-memory port and still talk to a process on Fast DDS's defaults (dds).
"""
import os
from pathlib import Path
import re
import shutil
import subprocess
import time

from experiments import local_ros
import pytest
from quat_jt_runtime import dds_transport


def _share(relative: str) -> Path:
    return Path('/share') / relative


@pytest.mark.unit
def test_localhost_becomes_udp_on_loopback_in_subnet_mode():
    choice = dds_transport.choose({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}, _share)
    assert choice.changes == {
        'FASTRTPS_DEFAULT_PROFILES_FILE': str(_share(dds_transport.UDP_LOCALHOST_PROFILE)),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
    assert 'UDP on 127.0.0.1 only' in choice.note


@pytest.mark.unit
def test_the_deprecated_localhost_only_is_localhost_too():
    choice = dds_transport.choose({'ROS_LOCALHOST_ONLY': '1'}, _share)
    assert choice.changes['ROS_LOCALHOST_ONLY'] == '0'
    assert choice.changes['FASTRTPS_DEFAULT_PROFILES_FILE'].endswith('udp_localhost.xml')


@pytest.mark.unit
@pytest.mark.parametrize('scope', ['', 'SUBNET', 'SYSTEM_DEFAULT'])
def test_other_ranges_keep_their_discovery_and_drop_shared_memory(scope):
    choice = dds_transport.choose({'ROS_AUTOMATIC_DISCOVERY_RANGE': scope}, _share)
    assert choice.changes == {
        'FASTRTPS_DEFAULT_PROFILES_FILE': str(_share(dds_transport.UDP_PROFILE))}
    assert 'shared memory off' in choice.note


@pytest.mark.unit
@pytest.mark.parametrize('env, said', [
    ({'FASTRTPS_DEFAULT_PROFILES_FILE': '/my/profile.xml'}, '/my/profile.xml'),
    ({'FASTDDS_DEFAULT_PROFILES_FILE': '/my/profile.xml'}, '/my/profile.xml'),
    ({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}, 'rmw_cyclonedds_cpp'),
    ({'ROS_DISCOVERY_SERVER': '127.0.0.1:11811'}, 'ROS_DISCOVERY_SERVER'),
    ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_STATIC_PEERS': 'robot.local'},
     'ROS_STATIC_PEERS'),
    ({dds_transport.OPT_OUT_VARIABLE: '1'}, dds_transport.OPT_OUT_VARIABLE),
])
def test_a_users_own_choice_is_left_alone_and_named(env, said):
    choice = dds_transport.choose(env, _share)
    assert choice.changes == {}
    assert said in choice.note


@pytest.mark.unit
def test_a_missing_profile_leaves_the_defaults_and_says_so():
    def missing(relative):
        raise FileNotFoundError(f'{relative!r} not found')
    choice = dds_transport.choose({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}, missing)
    assert choice.changes == {}
    assert 'fastdds_udp_localhost.xml' in choice.note and 'shared memory on' in choice.note


@pytest.mark.unit
def test_the_profiles_are_shipped():
    from quat_jt_runtime.resources import share_path
    for relative in (dds_transport.UDP_PROFILE, dds_transport.UDP_LOCALHOST_PROFILE):
        text = share_path(relative).read_text()
        assert '<useBuiltinTransports>false</useBuiltinTransports>' in text
        assert '<type>UDPv4</type>' in text and 'SHM' not in text
    assert '<address>127.0.0.1</address>' in share_path(
        dds_transport.UDP_LOCALHOST_PROFILE).read_text()


def _thread_names(pid: int) -> list[str]:
    names = []
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            names.append(Path(f'/proc/{pid}/task/{tid}/comm').read_text().strip())
        except OSError:  # the thread ended meanwhile
            pass
    return names


def _udp_addresses(pid: int) -> set[str]:
    out = subprocess.run(['ss', '-uanp'], capture_output=True, text=True).stdout
    return {m.group(1) for line in out.splitlines() if f'pid={pid},' in line
            for m in [re.match(r'\S+\s+\S+\s+\S+\s+(\S+):\d+\s', line)] if m}


@pytest.mark.dds
@pytest.mark.skipif(not os.path.isdir('/proc'), reason='reads /proc')
def test_both_nodes_talk_udp_on_loopback_to_a_process_on_fast_dds_defaults(tmp_path):
    """Started as a user starts them in LOCALHOST mode: no shared memory, loopback only."""
    from experiments.probe import ProbeNode
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    domain_id = int(os.environ['ROS_DOMAIN_ID'])
    env = local_ros.isolated_env(tmp_path, domain_id)
    sim, ctrl = local_ros.spawn_wrist_pair(env, tmp_path)
    probe = ProbeNode('transport_probe', domain_id)  # LOCALHOST, shared memory on
    got = {'states': 0, 'commands': 0}
    probe.node.create_subscription(
        JointState, '/joint_states', lambda _: got.__setitem__('states', got['states'] + 1), 10)
    probe.node.create_subscription(
        Float64MultiArray, '/effort_controller/commands',
        lambda _: got.__setitem__('commands', got['commands'] + 1), 10)
    try:
        deadline = time.monotonic() + 60.0
        while min(got.values()) < 50:
            assert sim.poll() is None and ctrl.poll() is None, f'a node exited; see {tmp_path}'
            assert time.monotonic() < deadline, f'no states and commands came: {got}'
            probe.executor.spin_once(timeout_sec=0.05)
        for proc, name in ((sim, 'wrist_sim_node'), (ctrl, 'controller_node')):
            log = (tmp_path / f'{name}.log').read_text()
            assert 'DDS transport: UDP on 127.0.0.1 only (LOCALHOST)' in log, log
            threads = _thread_names(proc.pid)
            assert any(t.startswith('dds.udp.') for t in threads), threads
            assert not any(t.startswith('dds.shm') for t in threads), threads
            if shutil.which('ss'):  # iproute2's socket list
                addresses = _udp_addresses(proc.pid)
                assert addresses and addresses <= {'127.0.0.1'}, addresses
    finally:
        probe.close()
        local_ros.stop_nodes((sim, ctrl))

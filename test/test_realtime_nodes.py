"""
The ``cpu_affinity`` parameter of both nodes, and the tools' own node on loopback only.

Each node pins every thread of its process; the parameter is read-only; a CPU the process may
not use is a clear start-up error.
"""
import os
from pathlib import Path
import random
import subprocess

from cpus import linux_only, thread_cpus, two_cpus
from experiments import local_ros
from process_harness import ProcessHarnessMixin
import pytest
from quat_jt_runtime import lifecycle
from quat_jt_runtime import realtime
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient


class _Harness(ProcessHarnessMixin):
    """A test node and the node processes it talks to."""

    def __init__(self, work_dir: Path) -> None:
        self.work_dir = work_dir
        self.env = local_ros.isolated_env(work_dir, domain_id=int(os.environ['ROS_DOMAIN_ID']))
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('realtime_test', context=self.context)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.procs: dict[str, subprocess.Popen] = {}


@pytest.mark.dds
@linux_only
@two_cpus
def test_cpu_affinity_pins_each_node_and_is_read_only(tmp_path):
    """Both nodes pin their whole process; the parameter cannot be changed live."""
    ns = f'/pintest{random.randint(0, 9999)}'
    cpu = max(realtime.allowed_cpus())
    h = _Harness(tmp_path)
    try:
        for executable in ('wrist_sim_node', 'controller_node'):
            h.procs[executable] = local_ros.spawn_node(
                executable, h.env, tmp_path, params={'cpu_affinity': [cpu]},
                ros_args=('-r', f'__ns:={ns}'))
        clients = {'wrist_sim_node': AsyncParameterClient(h.node, f'{ns}/wrist_sim'),
                   'controller_node': AsyncParameterClient(h.node,
                                                           f'{ns}/quat_jt_controller')}
        h.spin_until(lambda: all(c.services_are_ready() for c in clients.values()), 30.0,
                     'both nodes')
        for executable, client in clients.items():
            # A reply means the node spins, which it does only once its process is pinned.
            got = client.get_parameters(['cpu_affinity'])
            h.spin_until(got.done, 10.0, 'get cpu_affinity')
            assert list(got.result().values[0].integer_array_value) == [cpu]
            cpus = thread_cpus(h.procs[executable].pid)
            assert len(cpus) > 1 and set(cpus.values()) == {str(cpu)}, (executable, cpus)
            res = client.set_parameters([Parameter('cpu_affinity', value=[0])])
            h.spin_until(res.done, 10.0, 'set cpu_affinity')
            assert not res.result().results[0].successful
        res = clients['controller_node'].set_parameters([Parameter('prewarm_lead', value=0.0)])
        h.spin_until(res.done, 10.0, 'set prewarm_lead')
        assert not res.result().results[0].successful  # read-only
        for executable in clients:
            assert 'process pinned to CPUs' in (tmp_path / f'{executable}.log').read_text()
        # Pinned too, a throwaway tick before each state (its CPU is awake when the state comes).
        assert 'prewarm: a throwaway tick 0.3 ms before each state is due' in (
            tmp_path / 'controller_node.log').read_text()
    finally:
        h.close()


@pytest.mark.dds
@linux_only
def test_unavailable_cpu_is_a_clear_start_up_error(tmp_path):
    missing = max(realtime.allowed_cpus()) + 1000
    env = local_ros.isolated_env(tmp_path, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    for executable in ('wrist_sim_node', 'controller_node'):
        proc = local_ros.spawn_node(executable, env, tmp_path, name=f'bad_{executable}',
                                    params={'cpu_affinity': [missing]})
        assert proc.wait(60.0) == 1
        text = (tmp_path / f'bad_{executable}.log').read_text()
        assert f'cpu_affinity [{missing}]' in text and 'not available' in text, text
        # A value of the wrong type: a FATAL line naming it, not a traceback.
        proc = local_ros.spawn_node(executable, env, tmp_path, name=f'typed_{executable}',
                                    params={'cpu_affinity': 'one'})
        assert proc.wait(60.0) == 1
        text = (tmp_path / f'typed_{executable}.log').read_text()
        assert 'cannot start' in text and 'cpu_affinity' in text, text
        assert 'Traceback' not in text, text


@pytest.mark.node
def test_the_tools_own_node_discovers_on_loopback_only(monkeypatch, tmp_path):
    """The recorder/probe of the tools must not discover over the subnet (Jazzy's default)."""
    from experiments.probe import ProbeNode
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    monkeypatch.setenv('ROS_STATIC_PEERS', '192.0.2.1')
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path))
    probe = ProbeNode('loopback_probe', int(os.environ['ROS_DOMAIN_ID']))
    try:
        assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
        assert 'ROS_STATIC_PEERS' not in os.environ
    finally:
        probe.close()


@pytest.mark.node
def test_composed_nodes_pin_their_process_once_to_all_their_cpus(monkeypatch):
    """``lifecycle.pin``: the union of the nodes' cpu_affinity, one pin, one log line."""
    pinned, logged = [], []

    class FakeNode:
        """A node as ``pin`` sees it: its cpu_affinity and a logger."""

        def __init__(self, cpus) -> None:
            self.cpu_affinity = cpus

        def get_logger(self):
            return type('Logger', (), {'info': lambda _self, text: logged.append(text)})()

    monkeypatch.setattr(realtime, 'pin_process', lambda cpus: pinned.append(cpus) or cpus)
    lifecycle.pin([FakeNode((1,)), FakeNode((0, 1))])
    assert pinned == [[0, 1]] and logged == ['process pinned to CPUs [0, 1] (cpu_affinity)']
    lifecycle.pin([FakeNode(()), FakeNode(())])  # nothing asked: nothing pinned
    assert len(pinned) == 1

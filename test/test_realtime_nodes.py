"""
The ``cpu_affinity`` and ``thread_priority`` parameters of both nodes; the tools' own node.

Each node pins every thread of its process, and runs them at its priority in real time; the
parameters are read-only; a CPU the process may not use is a clear start-up error. The tools'
own node discovers on loopback only.
"""
import os
from pathlib import Path
import random
import subprocess
from typing import Optional

from cpus import fifo_allowed, linux_only, thread_cpus, thread_policies, two_cpus
from experiments import local_ros
from process_harness import descendants_of, ProcessHarnessMixin
import pytest
from quat_jt_runtime import lifecycle
from quat_jt_runtime import realtime
from quat_jt_runtime.params import Realtime
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

    def start_both(self, params: dict,
                   own: Optional[dict] = None) -> dict[str, AsyncParameterClient]:
        """
        Start both nodes in a namespace of their own; return their parameter clients.

        ``params`` go to both, ``own`` (executable -> params) to one each.
        """
        ns = f'/rttest{random.randint(0, 9999)}'
        for executable in ('wrist_sim_node', 'controller_node'):
            self.procs[executable] = local_ros.spawn_node(
                executable, self.env, self.work_dir,
                params={**params, **(own or {}).get(executable, {})},
                ros_args=('-r', f'__ns:={ns}'))
        clients = {'wrist_sim_node': AsyncParameterClient(self.node, f'{ns}/wrist_sim'),
                   'controller_node': AsyncParameterClient(self.node,
                                                           f'{ns}/quat_jt_controller')}
        self.spin_until(lambda: all(c.services_are_ready() for c in clients.values()), 30.0,
                        'both nodes')
        return clients


@pytest.mark.dds
@linux_only
@two_cpus
def test_cpu_affinity_pins_each_node_and_is_read_only(tmp_path):
    """
    Both nodes pin their whole process; the parameter cannot be changed live.

    A CPU each, as docs/ros.md asks with thread_priority on: pinned to one CPU in SCHED_FIFO
    the two once starved each other.
    """
    allowed = realtime.allowed_cpus()
    cpus = {'wrist_sim_node': min(allowed), 'controller_node': max(allowed)}
    h = _Harness(tmp_path)
    try:
        clients = h.start_both({}, {exe: {'cpu_affinity': [cpu]} for exe, cpu in cpus.items()})
        for executable, client in clients.items():
            cpu = cpus[executable]
            # A reply means the node spins, which it does only once its process is pinned.
            got = client.get_parameters(['cpu_affinity'])
            h.spin_until(got.done, 10.0, 'get cpu_affinity')
            assert list(got.result().values[0].integer_array_value) == [cpu]
            threads = thread_cpus(h.procs[executable].pid)
            on = set(threads.values())
            assert len(threads) > 1 and on == {str(cpu)}, (executable, threads)
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
def test_composed_nodes_share_one_pinning_and_the_highest_priority(monkeypatch):
    """``lifecycle.apply_realtime``: the union of the CPUs, the highest priority, or none."""
    pinned, raised, logged = [], [], []

    class FakeNode:
        """A node as ``apply_realtime`` sees it: its real-time settings and a logger."""

        def __init__(self, cpus, priority, off_reason='') -> None:
            self.realtime = Realtime(cpus, priority, off_reason)

        def get_logger(self):
            return type('Logger', (), {
                'info': lambda _self, text: logged.append(text),
                'warning': lambda _self, text: logged.append('WARN ' + text)})()

    monkeypatch.setattr(realtime, 'pin_process', lambda cpus: pinned.append(cpus) or cpus)
    monkeypatch.setattr(realtime, 'set_thread_priority', lambda p: raised.append(p) or '')
    lifecycle.apply_realtime([FakeNode((1,), 0), FakeNode((0, 1), 50)])
    assert pinned == [[0, 1]] and raised == [50]
    assert logged == ['process pinned to CPUs [0, 1] (cpu_affinity)',
                      'every thread at SCHED_FIFO priority 50 (thread_priority)']
    lifecycle.apply_realtime([FakeNode((), 0), FakeNode((), 0)])  # nothing asked: nothing done
    assert len(pinned) == 1 and len(raised) == 1 and len(logged) == 2
    monkeypatch.setattr(realtime, 'set_thread_priority', lambda p: 'not permitted (...)')
    lifecycle.apply_realtime([FakeNode((), 30)])  # refused: a warning, and the node runs on
    assert logged[-1].startswith('WARN thread_priority 30: not permitted (...); running with '
                                 'normal scheduling'), logged
    # Composed with a simulator in lockstep (or with its window): no thread is raised.
    raised.clear()
    lifecycle.apply_realtime([FakeNode((), 0, 'lockstep'), FakeNode((), 50)])
    assert raised == [] and logged[-1] == 'thread_priority 50: off (lockstep): normal scheduling'


@pytest.mark.dds
@linux_only
def test_both_nodes_run_every_thread_at_their_priority_but_the_workers(tmp_path):
    """By default (50) in real time; read-only; the goal-check and design workers not."""
    allowed = fifo_allowed(realtime.DEFAULT_THREAD_PRIORITY)
    h = _Harness(tmp_path)
    try:
        clients = h.start_both({})
        for executable, client in clients.items():
            # A reply means the node spins, which it does only once its settings are applied.
            got = client.get_parameters(['thread_priority'])
            h.spin_until(got.done, 10.0, 'get thread_priority')
            assert got.result().values[0].integer_value == realtime.DEFAULT_THREAD_PRIORITY
            policies = set(thread_policies(h.procs[executable].pid).values())
            log = (tmp_path / f'{executable}.log').read_text()
            if allowed:
                assert policies == {('fifo', realtime.DEFAULT_THREAD_PRIORITY)}, policies
                assert 'every thread at SCHED_FIFO priority 50 (thread_priority)' in log, log
            else:
                assert policies == {('other', 0)} and 'thread_priority 50: not permitted' in log
            res = client.set_parameters([Parameter('thread_priority', value=10)])
            h.spin_until(res.done, 10.0, 'set thread_priority')
            assert not res.result().results[0].successful  # read-only
        ctrl = h.procs['controller_node'].pid
        h.spin_until(lambda: len(descendants_of(ctrl)) == 3, 30.0,
                     'the worker launcher, the goal-check and design workers')
        for worker in descendants_of(ctrl):
            assert set(thread_policies(worker).values()) == {('other', 0)}, worker
    finally:
        h.close()

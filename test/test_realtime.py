"""
Real-time settings of the nodes.

CPU affinity and timer slack (``realtime.py``), the ``cpu_affinity`` parameter of both nodes,
and the simulator's answer deadline.
"""
import os
from pathlib import Path
import random
import subprocess
import sys
import threading
import time

from process_harness import ProcessHarnessMixin
import pytest
from quat_jt_controller import realtime
from quat_jt_controller.tools import local_ros
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from wrist_sim.sim_node import answer_deadline, await_answer, DRAIN_EVENTS
from wrist_sim.sim_node import MIN_ANSWER_FRACTION, STEP_LEAD_S

linux_only = pytest.mark.skipif(not sys.platform.startswith('linux'), reason='Linux only')


def _thread_cpus(pid: int) -> dict[int, str]:
    """Return ``{thread id: Cpus_allowed_list}`` of every thread of ``pid``."""
    out = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        for line in (task / 'status').read_text().splitlines():
            if line.startswith('Cpus_allowed_list:'):
                out[int(task.name)] = line.split(':', 1)[1].strip()
    return out


# ------------------------------------------------------------------------------------ unit
@pytest.mark.unit
def test_check_cpus_accepts_available_cpus_and_names_the_others():
    allowed = sorted(realtime.allowed_cpus())
    assert realtime.check_cpus([]) == ()
    assert realtime.check_cpus([allowed[-1], allowed[0], allowed[0]]) == tuple(
        sorted({allowed[0], allowed[-1]}))
    missing = max(allowed) + 1000
    with pytest.raises(ValueError) as exc:
        realtime.check_cpus([allowed[0], missing])
    assert f'CPUs [{missing}] are not available' in str(exc.value)
    assert str(allowed) in str(exc.value)


@pytest.mark.unit
@linux_only
def test_pin_process_pins_every_thread_and_later_threads_inherit_it():
    cpu = max(realtime.allowed_cpus())
    script = (
        'import threading, time, json, os\n'
        'from quat_jt_controller import realtime\n'
        'stop = threading.Event()\n'
        'before = [threading.Thread(target=stop.wait) for _ in range(3)]\n'
        'for t in before: t.start()\n'
        f'print(json.dumps(realtime.pin_process([{cpu}])))\n'
        'after = threading.Thread(target=stop.wait); after.start()\n'
        'print(json.dumps(sorted(int(t) for t in os.listdir("/proc/self/task"))), flush=True)\n'
        'input()\n'
        'stop.set()\n')
    proc = subprocess.Popen([sys.executable, '-c', script], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == f'[{cpu}]'
        threads = proc.stdout.readline()
        cpus = _thread_cpus(proc.pid)
        assert len(cpus) >= 5, (threads, cpus)  # main, 3 before, 1 after
        assert set(cpus.values()) == {str(cpu)}, cpus
    finally:
        proc.communicate('\n', timeout=10)


@pytest.mark.unit
def test_pin_process_with_nothing_asked_changes_nothing():
    before = os.sched_getaffinity(0) if hasattr(os, 'sched_getaffinity') else None
    assert realtime.pin_process([]) == ()
    if before is not None:
        assert os.sched_getaffinity(0) == before


@pytest.mark.unit
@linux_only
def test_timer_slack_is_set_for_the_calling_thread_only():
    seen = []

    def worker() -> None:
        seen.append((realtime.set_timer_slack(1), realtime.timer_slack_ns()))

    main_slack = realtime.timer_slack_ns()
    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == [(True, 1)]
    assert realtime.timer_slack_ns() == main_slack


@pytest.mark.unit
def test_answer_deadline_gives_a_late_state_at_least_the_minimum_window():
    period = 1e-3
    # On time: the answer may come until STEP_LEAD_S before the next tick.
    assert answer_deadline(2.0, 1.0, period) == pytest.approx(2.0 - STEP_LEAD_S)
    # Published 0.9 ms late: the answer still gets MIN_ANSWER_FRACTION of a period.
    published = 2.0 - period + 0.9e-3
    assert answer_deadline(2.0, published, period) == pytest.approx(
        published + MIN_ANSWER_FRACTION * period)
    assert answer_deadline(2.0, published, period) > 2.0


class _QueueExecutor:
    """An executor whose queue holds callbacks that are already due; spin_once runs one."""

    def __init__(self, queued) -> None:
        self.queued = list(queued)
        self.spins = []

    def spin_once(self, timeout_sec: float) -> None:
        self.spins.append(timeout_sec)
        if self.queued:
            self.queued.pop(0)()


@pytest.mark.unit
def test_at_the_deadline_an_answer_already_queued_is_taken():
    """A process stalled past its deadline still takes the command waiting in its queue."""
    got = []
    # The deadline has passed; the state's callback, then the command, are queued.
    executor = _QueueExecutor([lambda: None, lambda: got.append('command')])
    assert await_answer(executor, lambda: bool(got), deadline_s=0.0, ok=lambda: True)
    assert executor.spins == [0.0, 0.0]  # no waiting past the deadline, just the queue


@pytest.mark.unit
def test_with_nothing_queued_the_deadline_gives_a_stale_tick_after_a_bounded_look():
    executor = _QueueExecutor([])
    assert not await_answer(executor, lambda: False, deadline_s=0.0, ok=lambda: True)
    assert executor.spins == [0.0] * DRAIN_EVENTS


@pytest.mark.unit
def test_before_the_deadline_the_wait_is_bounded_by_it():
    got = []
    executor = _QueueExecutor([lambda: got.append('command')])
    deadline = time.perf_counter() + 10.0
    assert await_answer(executor, lambda: bool(got), deadline_s=deadline, ok=lambda: True)
    assert len(executor.spins) == 1 and 0.0 < executor.spins[0] <= 10.0


# ------------------------------------------------------------------------------------ dds
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
            cpus = _thread_cpus(h.procs[executable].pid)
            assert len(cpus) > 1 and set(cpus.values()) == {str(cpu)}, (executable, cpus)
            got = client.get_parameters(['cpu_affinity'])
            h.spin_until(got.done, 10.0, 'get cpu_affinity')
            assert list(got.result().values[0].integer_array_value) == [cpu]
            res = client.set_parameters([Parameter('cpu_affinity', value=[0])])
            h.spin_until(res.done, 10.0, 'set cpu_affinity')
            assert not res.result().results[0].successful
        for executable in clients:
            assert 'process pinned to CPUs' in (tmp_path / f'{executable}.log').read_text()
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


@pytest.mark.node
def test_the_tools_own_node_discovers_on_loopback_only(monkeypatch, tmp_path):
    """The recorder/probe of the tools must not discover over the subnet (Jazzy's default)."""
    from quat_jt_controller.tools.probe import ProbeNode
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    monkeypatch.setenv('ROS_STATIC_PEERS', '192.0.2.1')
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path))
    probe = ProbeNode('loopback_probe', int(os.environ['ROS_DOMAIN_ID']))
    try:
        assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
        assert 'ROS_STATIC_PEERS' not in os.environ
    finally:
        probe.close()


@pytest.mark.unit
def test_run_check_asks_the_context_at_most_every_period_and_the_flag_every_time():
    from quat_jt_controller.lifecycle import CONTEXT_CHECK_S, RunCheck
    now, asked, running, alive = [100.0], [], [True], [True]

    def context_ok() -> bool:
        asked.append(now[0])
        return alive[0]
    check = RunCheck(lambda: running[0], context_ok, clock=lambda: now[0])
    assert check() and check() and asked == [100.0]  # asked once in the period
    alive[0] = False  # an external shutdown
    assert check()  # not seen yet...
    now[0] += CONTEXT_CHECK_S
    assert not check() and len(asked) == 2  # ... seen within one period
    running[0] = False  # Ctrl-C: seen at once
    alive[0] = True
    assert not check()

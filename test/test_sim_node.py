"""
Tests of wrist_sim_node.

Parameters in process; behaviour over real DDS with the node in its own process (local_ros),
observed and commanded from this test process.
"""
import json
import math
import os
from pathlib import Path
import random
import time

from experiments import local_ros
import numpy as np
from process_harness import call_service
import pytest
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from wrist_sim.simulator import SimulatorError

JOINTS = ['joint1', 'joint2', 'joint3']
INITIAL = [0.0, 0.3, 0.0]
COULOMB = [1.0, 3.0, 1.0]  # holds joint 2 at 0.3 rad against gravity (~0.4 N m)


# -- in process: parameters ------------------------------------------------------------------

@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _make_node(context, **overrides):
    from wrist_sim.sim_node import WristSimNode
    return WristSimNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])


@pytest.mark.node
def test_parameters_default_from_the_urdf(context):
    node = _make_node(context)
    try:
        assert node.get_parameter('joints').value == JOINTS
        assert list(node.get_parameter('coulomb_friction').value) == [0.0] * 3
        assert node.get_parameter('rate_hz').value == 1000
        assert node.sim.dt_s == pytest.approx(1e-3)
        assert node.get_parameter('command_timeout').value == pytest.approx(0.5)
    finally:
        node.destroy_node()


@pytest.mark.node
def test_the_node_declares_exactly_its_table(context):
    from quat_jt_runtime.params import rclpy_type, REALTIME
    from wrist_sim import parameters as table
    node = _make_node(context)
    try:
        rows = {spec.name: spec for spec in table.STRUCTURE + table.LIVE + REALTIME}
        declared = set(node._parameters) - {'use_sim_time', 'start_type_description_service'}
        assert declared == set(rows)
        for name, spec in rows.items():
            d = node.describe_parameter(name)
            assert (d.type, d.read_only) == (spec.kind.descriptor_type, spec.read_only), name
            assert node.get_parameter(name).type_ is rclpy_type(spec.kind), name
            assert d.description, name
    finally:
        node.destroy_node()


@pytest.mark.node
def test_the_file_design_gains_writes_holds_rows_of_the_simulators_table():
    """gain_output.sim_yaml (which may not import the simulator) writes the table's names."""
    import yaml
    from quat_jt_controller import gain_output as go
    from quat_jt_runtime.params import REALTIME
    from robots import panda_model
    from wrist_sim import parameters as table
    from wrist_sim.config import SimConfig
    from wrist_sim.simulator import ENGINES
    model = panda_model()
    for engine in ENGINES:
        text = go.sim_yaml(model, 1000.0, None, [0.1] * model.n, None, engine=engine)
        written = yaml.safe_load(text)['/**']['ros__parameters']
        rows = {spec.name: spec for spec in table.STRUCTURE + table.LIVE + REALTIME}
        assert set(written) <= set(rows), set(written) - set(rows)
        for name, value in written.items():
            kind = rows[name].kind
            python = {'bool': bool, 'int': int, 'double': float, 'string': str}
            values = value if kind.is_array else [value]
            assert all(type(v) is python[kind.label.rstrip('[]')] for v in values), name
        assert set(table.names(table.LIVE)) <= set(written)
        SimConfig.create(written, model.n)  # the simulator's own checks take it


@pytest.mark.node
@pytest.mark.parametrize('overrides, off_reason', [
    ({}, ''), ({'publish_clock': True}, 'lockstep'), ({'use_gui': True}, 'the PyBullet window')])
def test_thread_priority_is_off_in_lockstep_and_with_the_window(context, overrides, off_reason):
    """Read from the table alone (no simulator, no window): the mode decides, not the value."""
    from wrist_sim.parameters import declare_structure
    node = rclpy.create_node('structure_test', context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])
    try:
        settings = declare_structure(node).realtime
        assert settings.thread_priority == 50 and settings.off_reason == off_reason
    finally:
        node.destroy_node()


@pytest.mark.node
def test_friction_parameters_are_validated_and_applied(context):
    node = _make_node(context, coulomb_friction=[0.5, 0.5, 0.5])
    try:
        for bad in ([1.0, 2.0], [1.0, -1.0, 0.0], [1.0, math.nan, 0.0]):
            result = node.set_parameters([Parameter('coulomb_friction', value=bad)])[0]
            assert not result.successful, bad
        np.testing.assert_allclose(node.sim.friction[1], [0.5, 0.5, 0.5])
        # Both arrays in one call: applied together.
        results = node.set_parameters_atomically([
            Parameter('viscous_friction', value=[0.1, 0.2, 0.3]),
            Parameter('coulomb_friction', value=[1.0, 2.0, 3.0])])
        assert results.successful
        viscous, coulomb = node.sim.friction
        np.testing.assert_allclose(viscous, [0.1, 0.2, 0.3])
        np.testing.assert_allclose(coulomb, [1.0, 2.0, 3.0])
        # Structural parameters are read only.
        assert not node.set_parameters([Parameter('rate_hz', value=500)])[0].successful
        assert not node.set_parameters([Parameter('command_timeout', value=-1.0)])[0].successful
    finally:
        node.destroy_node()


@pytest.mark.node
def test_namespaced_and_renamed_sim_keeps_its_config_file(context):
    """config/wrist_sim.yaml is keyed /**: a namespace and a new name keep its values."""
    from quat_jt_runtime.resources import share_path
    from wrist_sim.sim_node import WristSimNode
    node = WristSimNode(context=context, cli_args=[
        '--ros-args', '-r', '__ns:=/arm', '-r', '__node:=xarm6_sim', '--params-file',
        str(share_path('config/wrist_sim.yaml'))])
    try:
        assert node.get_fully_qualified_name() == '/arm/xarm6_sim'
        assert list(node.get_parameter('coulomb_friction').value) == [2.0, 0.8, 0.5]
        np.testing.assert_allclose(node.sim.friction[1], [2.0, 0.8, 0.5])
    finally:
        node.destroy_node()


@pytest.mark.node
def test_the_panda_loads_from_its_config_with_its_meshes_missing(context, capfd):
    """
    config/panda_sim.yaml drives the seven arm joints; the fingers are held, not published.

    A robot_description whose meshes cannot be found still loads, with one WARN naming them.
    """
    from quat_jt_runtime.resources import share_path
    from robots import PANDA_JOINTS, PANDA_URDF
    from wrist_sim.sim_node import WristSimNode
    urdf = PANDA_URDF.read_text().replace('package://meshes/', 'package://not_installed/')
    node = WristSimNode(context=context, cli_args=[
        '--ros-args', '--params-file', str(share_path('config/panda_sim.yaml'))],
        parameter_overrides=[Parameter('robot_description', value=urdf)])
    try:
        assert node.sim.joint_names == PANDA_JOINTS
        assert node.sim.missing_meshes
        np.testing.assert_allclose(node.sim.q_rad, node.get_parameter('initial_positions').value)
        err = capfd.readouterr().err
        assert err.count('mesh file(s) of robot_description not found') == 1
        assert 'package://not_installed/visual/link1.obj' in err
    finally:
        node.destroy_node()


@pytest.mark.node
def test_the_xarm6_says_once_which_links_pybullet_gives_no_inertia(context, capfd):
    """Its link2 and link3 tensors are not physical: one WARN, none of PyBullet's six lines."""
    from quat_jt_runtime.resources import share_path
    from robots import XARM6_URDF
    from wrist_sim.sim_node import WristSimNode
    node = WristSimNode(context=context, cli_args=[
        '--ros-args', '--params-file', str(share_path('config/xarm6_sim.yaml'))],
        parameter_overrides=[Parameter('robot_description', value=XARM6_URDF.read_text())])
    try:
        out, err = capfd.readouterr()
        assert err.count('PyBullet simulates link2, link3 without rotational inertia') == 1
        assert 'Bad inertia' not in out + err
    finally:
        node.destroy_node()


@pytest.mark.node
def test_a_start_up_error_gives_the_urdf_advice_only_when_it_is_about_the_robot(
        context, monkeypatch):
    monkeypatch.delenv('DISPLAY', raising=False)
    with pytest.raises(SimulatorError) as no_window:
        _make_node(context, use_gui=True)
    assert 'DISPLAY is not set' in str(no_window.value)
    assert 'robot_description' not in str(no_window.value)
    with pytest.raises(SimulatorError, match="'nope'.*No robot description was given, so the "
                                             'bundled spherical wrist'):
        _make_node(context, joints=['joint1', 'nope'])


@pytest.mark.node
def test_bad_startup_parameters_are_refused(context):
    with pytest.raises(SimulatorError):
        _make_node(context, viscous_friction=[0.1, 0.2])
    with pytest.raises(SimulatorError):
        _make_node(context, joints=['joint1', 'nope'])


@pytest.mark.node
def test_no_command_since_start_is_a_warning_naming_the_topic(context, monkeypatch):
    """No controller: the start-up line says the joints are held; then a WARN, 0 publishers."""
    from rcl_interfaces.msg import Log
    from wrist_sim import sim_node
    monkeypatch.setattr(sim_node, 'NO_COMMAND_WARN_S', 0.5)  # the table's 5 s, shortened
    listener = rclpy.create_node('rosout_listener', context=context)
    logs: list[tuple[int, str]] = []
    listener.create_subscription(Log, '/rosout', lambda m: logs.append((m.level, m.msg)) if (
        m.name == sim_node.NODE_NAME) else None, 100)
    node = sim_node.WristSimNode(context=context, cli_args=[
        '--ros-args', '-r', 'effort_controller/commands:=/nowhere/commands'],
        parameter_overrides=[Parameter('initial_positions', value=[0.0, 0.6, 0.0])])
    executor = EventsExecutor(context=context)
    try:
        executor.add_node(listener)
        executor.add_node(node)
        deadline = time.monotonic() + 15.0
        node.run(executor, lambda: time.monotonic() < deadline and not any(
            level == Log.WARN for level, _ in logs))
        start = next(text for _, text in logs if 'simulating joints' in text)
        assert 'joints held at rest until the first command on /nowhere/commands' in start
        warning = next((text for level, text in logs if level == Log.WARN), None)
        assert warning is not None, logs
        assert warning.startswith('no command on /nowhere/commands '), warning
        assert '(0 publishers matched; is a controller running' in warning, warning
        assert node.sim.q_rad.tolist() == [0.0, 0.6, 0.0]  # held against gravity
    finally:
        executor.remove_node(node)
        executor.remove_node(listener)
        node.destroy_node()
        listener.destroy_node()


@pytest.mark.node
def test_the_engine_and_armature_are_read_once_and_an_unsimulated_armature_is_said(
        context, capfd):
    """Engine mujoco simulates the armature; pybullet keeps it and says, once, it cannot."""
    pytest.importorskip('mujoco')
    node = _make_node(context, engine='mujoco', armature=[0.1, 0.2, 0.3])
    try:
        assert node.sim.engine == 'mujoco' and node.sim.supports_armature
        np.testing.assert_array_equal(node.sim.armature, [0.1, 0.2, 0.3])
        assert not node.set_parameters([Parameter('engine', value='pybullet')])[0].successful
        assert 'NOT simulated' not in capfd.readouterr().err
    finally:
        node.destroy_node()
    node = _make_node(context, armature=[0.1, 0.2, 0.3])
    try:
        assert node.sim.engine == 'pybullet' and not node.sim.supports_armature
        err = capfd.readouterr().err
        assert err.count('NOT simulated') == 1, err
        assert "armature [0.1, 0.2, 0.3] kg m^2 is NOT simulated: engine 'pybullet'" in err
        assert "use engine 'mujoco'" in err
    finally:
        node.destroy_node()


@pytest.mark.node
def test_the_plant_carries_a_payload_the_urdf_does_not_list(context):
    """payload_link/mass/com: the plant holds still on the g(q) of a model told the payload."""
    from quat_jt_controller.model import RobotModel
    from quat_jt_runtime.resources import default_urdf_xml
    start = [0.3, 0.8, -0.5]
    node = _make_node(context, payload_link='tool0', payload_mass=1.0,
                      payload_com=[0.0, 0.05, 0.1], initial_positions=start)
    told = RobotModel(default_urdf_xml(), 'base_link', 'tool0', payload_kg=1.0,
                      payload_com_tip_m=(0.0, 0.05, 0.1))
    plain = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    try:
        drift = {}
        for name, model in (('told', told), ('untold', plain)):
            node.sim.reset(start)
            for _ in range(100):
                node.sim.step(model.gravity(node.sim.q_rad.tolist()))
            drift[name] = float(np.abs(node.sim.q_rad - start).max())
        assert drift['told'] < 1e-4 < 1e-2 < drift['untold'], drift
        with pytest.raises(SimulatorError, match="link 'nowhere' is not in the URDF"):
            _make_node(context, payload_link='nowhere', payload_mass=1.0)
        with pytest.raises(SimulatorError, match='needs a payload_link'):
            _make_node(context, payload_mass=1.0)
    finally:
        node.destroy_node()


@pytest.mark.node
@pytest.mark.parametrize('config', ['wrist_sim.yaml', 'xarm6_sim.yaml', 'panda_sim.yaml'])
def test_the_robots_of_the_configs_run_in_mujoco(context, config):
    """Each config's robot, friction and start in engine mujoco: a few steps, finite."""
    pytest.importorskip('mujoco')
    from quat_jt_runtime.resources import share_path
    from robots import PANDA_URDF, XARM6_URDF
    urdf = {'xarm6_sim.yaml': XARM6_URDF, 'panda_sim.yaml': PANDA_URDF}.get(config)
    from wrist_sim.sim_node import WristSimNode
    node = WristSimNode(context=context, cli_args=[
        '--ros-args', '--params-file', str(share_path(f'config/{config}'))],
        parameter_overrides=[Parameter('engine', value='mujoco')] + (
            [Parameter('robot_description', value=urdf.read_text())] if urdf else []))
    try:
        assert node.sim.engine == 'mujoco'
        start = list(node.get_parameter('initial_positions').value)
        np.testing.assert_allclose(node.sim.q_rad, start)
        np.testing.assert_allclose(node.sim.friction[1],
                                   node.get_parameter('coulomb_friction').value)
        for _ in range(20):
            node.sim.step(np.zeros(node.sim.n))
        assert np.all(np.isfinite(node.sim.q_rad)) and node.sim.step_count == 20
    finally:
        node.destroy_node()


@pytest.mark.node
@pytest.mark.parametrize('overrides, words', [
    ({'engine': 'ode'}, r"engine must be one of \['pybullet', 'mujoco'\], got 'ode'"),
    ({'armature': [0.1, -0.2, 0.0]}, r'armature: values must be >= 0, got \[0.1, -0.2, 0.0\]'),
    ({'armature': [0.1, 0.2]}, r'armature: expected 3 values \(one per joint\), got 2'),
    ({'armature': [0.1, math.nan, 0.0]}, 'armature: values must be finite'),
])
def test_a_bad_engine_or_armature_is_refused_by_name(context, overrides, words):
    with pytest.raises(SimulatorError, match=words):
        _make_node(context, **overrides)


# -- over DDS: the node in its own process ---------------------------------------------------

class Probe:
    """A test node: records joint_states (and /clock), publishes commands, calls reset."""

    def __init__(self, context, respond=None):
        self.node = rclpy.create_node('probe', context=context)
        self.executor = EventsExecutor(context=context)
        self.executor.add_node(self.node)
        self.msgs: list[tuple[float, int, list, list, list]] = []
        self.clock_ns: list[int] = []
        self.respond = respond  # called with each JointState: a controller stand-in
        self.pub = self.node.create_publisher(Float64MultiArray, 'effort_controller/commands',
                                              10)
        self.node.create_subscription(JointState, 'joint_states', self._on_js, 10)
        self.node.create_subscription(Clock, '/clock', lambda m: self.clock_ns.append(
            m.clock.sec * 1_000_000_000 + m.clock.nanosec), 10)
        self.reset = self.node.create_client(Trigger, '/wrist_sim/reset')

    def _on_js(self, msg: JointState) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.msgs.append((time.perf_counter(), stamp, list(msg.position), list(msg.velocity),
                          list(msg.effort)))
        self.names = list(msg.name)
        if self.respond is not None:
            cmd = self.respond(msg)
            if cmd is not None:
                self.send(cmd)

    def send(self, values) -> None:
        self.pub.publish(Float64MultiArray(data=[float(v) for v in values]))

    def spin_until(self, condition, timeout_s: float) -> bool:
        deadline = time.perf_counter() + timeout_s
        while time.perf_counter() < deadline:
            if condition():
                return True
            self.executor.spin_once(timeout_sec=0.01)
        return condition()

    def spin_for(self, duration_s: float) -> None:
        self.spin_until(lambda: False, duration_s)

    def latest(self):
        return self.msgs[-1]

    def destroy(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()


_used_domains = {int(os.environ['ROS_DOMAIN_ID'])}


class SimProcess:
    """The node in its own process on a private domain, and a context for probes."""

    def __init__(self, tmp: Path, params: dict) -> None:
        self.dir = tmp
        domain = random.choice([d for d in range(1, 101) if d not in _used_domains])
        _used_domains.add(domain)
        self.env = local_ros.isolated_env(tmp, domain_id=domain)
        self.stats = tmp / 'stats.json'
        self.proc = local_ros.spawn_node('wrist_sim_node', self.env, tmp,
                                         params={**params, 'stats_file': str(self.stats)})
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=int(self.env['ROS_DOMAIN_ID']))

    def log(self) -> str:
        path = self.dir / 'wrist_sim_node.log'
        return path.read_text(errors='replace') if path.exists() else '(no log)'

    def alive(self) -> bool:
        return self.proc.poll() is None

    def close(self) -> int:
        code = local_ros.stop_node(self.proc)
        rclpy.try_shutdown(context=self.context)
        return code


@pytest.fixture(scope='module')
def sim(tmp_path_factory):
    s = SimProcess(tmp_path_factory.mktemp('wrist_sim'), {
        'initial_positions': INITIAL, 'coulomb_friction': COULOMB,
        'viscous_friction': [0.05, 0.05, 0.05], 'command_timeout': 0.1})
    yield s
    s.close()


@pytest.fixture(scope='module')
def probe(sim):
    p = Probe(sim.context)
    ok = p.spin_until(lambda: len(p.msgs) > 100, 30.0)
    assert ok, f'no joint_states from the node:\n{sim.log()}'
    yield p
    p.destroy()


@pytest.mark.dds
def test_joint_states_arrive_at_about_1khz_with_monotonic_stamps(sim, probe):
    start = len(probe.msgs)
    t0 = time.perf_counter()
    probe.spin_for(2.0)
    window = probe.msgs[start:]
    rate = len(window) / (time.perf_counter() - t0)
    stamps = np.array([m[1] for m in probe.msgs])
    assert rate >= 500.0, f'{rate:.0f} Hz\n{sim.log()}'
    assert np.all(np.diff(stamps) > 0), 'stamps must be strictly increasing'
    assert abs(stamps[-1] * 1e-9 - time.time()) < 5.0, 'real-time mode stamps with ROS time'
    assert probe.names == JOINTS
    np.testing.assert_allclose(window[-1][2], INITIAL, atol=1e-6)  # stiction holds it
    print(f'joint_states rate {rate:.1f} Hz over 2 s')


def _stream(probe: Probe, cmd, duration_s: float) -> None:
    """Send ``cmd`` for each joint state received, for ``duration_s`` (a controller)."""
    probe.respond = lambda msg: cmd
    try:
        probe.spin_for(duration_s)
    finally:
        probe.respond = None


def _stream_until(probe: Probe, cmd, condition, timeout_s: float = 10.0) -> bool:
    """Send ``cmd`` for each joint state received until ``condition()`` (a controller)."""
    probe.respond = lambda msg: cmd
    try:
        return probe.spin_until(condition, timeout_s)
    finally:
        probe.respond = None


@pytest.mark.dds
def test_effort_command_moves_the_joint_the_right_way(sim, probe):
    q_before = np.array(probe.latest()[2])
    # Until the joints have moved: a slow host only takes longer (no fixed duration).
    moved = _stream_until(probe, [2.0, 0.0, -1.5], lambda: (
        probe.latest()[2][0] - q_before[0] > 0.01 and probe.latest()[2][2] - q_before[2] < -0.01
        and list(probe.latest()[4]) == [2.0, 0.0, -1.5]))
    _, _, q, qdot, effort = probe.latest()
    assert moved, f'{q_before} -> {q}\n{sim.log()}'
    assert qdot[0] > 0.0 and qdot[2] < 0.0, qdot
    assert abs(q[1] - q_before[1]) < 1e-3, 'joint 2 held by stiction'
    np.testing.assert_allclose(effort, [2.0, 0.0, -1.5])
    # Effort limits clamp what is applied (and reported).
    _stream_until(probe, [80.0, 0.0, -80.0], lambda: probe.latest()[4][0] != 2.0)
    np.testing.assert_allclose(probe.latest()[4], [50.0, 0.0, -20.0])


@pytest.mark.dds
def test_bad_commands_are_rejected_and_the_node_keeps_publishing(sim, probe):
    _stream(probe, [2.0, 0.0, 0.0], 0.1)
    n0 = len(probe.msgs)
    bad = iter([[1.0, 2.0], [math.nan, 0.0, 0.0], [0.0, math.inf, 0.0], []] * 10000)
    probe.respond = lambda msg: next(bad)
    try:
        probe.spin_for(0.04)  # < command_timeout: the last good command still applies
        assert probe.latest()[4] == [2.0, 0.0, 0.0]
        probe.spin_for(0.3)   # bad commands do not feed the watchdog
    finally:
        probe.respond = None
    assert sim.alive(), sim.log()
    assert len(probe.msgs) - n0 > 100, 'the node keeps publishing'
    assert probe.latest()[4] == [0.0, 0.0, 0.0]
    log = sim.log()
    assert 'rejected command: 2 values for 3 joints' in log, log
    assert 'rejected command with non-finite values' in log, log
    # Throttled: far fewer log lines than bad messages.
    assert log.count('rejected command') < 10, log


@pytest.mark.dds
def test_commands_beyond_the_effort_limits_are_clamped_and_said_so(sim, probe):
    _stream(probe, [1e9, 0.0, -1e9], 0.2)
    assert probe.latest()[4] == [50.0, 0.0, -20.0]  # the URDF limits 50 / 30 / 20 N m
    _stream(probe, [0.0, 0.0, 0.0], 0.05)
    probe.spin_until(lambda: 'exceeds the effort limits' in sim.log(), 5.0)
    log = sim.log()
    # Throttled (one line a second): an earlier test's clamped command may be the one logged.
    assert 'N m exceeds the effort limits [50.0, 30.0, 20.0] N m: applied clamped' in log, log
    assert log.count('exceeds the effort limits') < 5, 'throttled'


@pytest.mark.dds
def test_watchdog_zeroes_torque_and_recovers(sim, probe):
    _stream(probe, [0.0, 0.0, 2.5], 0.1)
    assert probe.latest()[4] == [0.0, 0.0, 2.5]
    t_stop = time.perf_counter()
    assert probe.spin_until(lambda: probe.latest()[4] == [0.0, 0.0, 0.0], 2.0), sim.log()
    assert time.perf_counter() - t_stop < 1.0
    assert 'torque set to zero' in sim.log()
    _stream(probe, [0.0, 0.0, -2.5], 0.1)
    assert probe.latest()[4] == [0.0, 0.0, -2.5]
    assert 'commands are back' in sim.log()


@pytest.mark.dds
def test_reset_returns_to_initial_positions_at_rest(sim, probe):
    _stream(probe, [5.0, 0.0, 5.0], 0.2)
    assert np.abs(np.array(probe.latest()[2]) - INITIAL).max() > 0.01
    assert probe.reset.wait_for_service(timeout_sec=5.0), sim.log()
    result = call_service(probe.executor, probe.reset, Trigger.Request())
    assert result.success, result.message
    n = len(probe.msgs)
    assert probe.spin_until(lambda: len(probe.msgs) > n + 20, 5.0)
    _, _, q, qdot, effort = probe.latest()
    np.testing.assert_allclose(q, INITIAL, atol=1e-6)
    np.testing.assert_allclose(qdot, 0.0, atol=1e-6)
    assert effort == [0.0, 0.0, 0.0]


@pytest.mark.dds
def test_shutdown_on_sigint_writes_stats(sim, probe):
    # Last test of the module: a controller stand-in for 1 s, then SIGINT.
    _stream(probe, [0.0, 0.0, 0.0], 1.0)
    t0 = time.perf_counter()
    code = local_ros.stop_node(sim.proc)
    assert code == 0 and time.perf_counter() - t0 < 5.0, sim.log()
    stats = json.loads(sim.stats.read_text())
    assert stats['steps'] > 1000 and stats['rejected_commands'] > 0
    assert stats['watchdog_trips'] >= 1, stats
    assert stats['fresh_steps'] > 0 and 'cmd_latency_us_p50' in stats, stats
    print('node stats', json.dumps(stats))


# -- lockstep with /clock --------------------------------------------------------------------

@pytest.mark.dds
def test_lockstep_clock_steps_once_per_command(tmp_path):
    s = SimProcess(tmp_path, {'publish_clock': True, 'lockstep_timeout': 0.5})
    p = Probe(s.context)
    try:
        assert p.spin_until(lambda: len(p.msgs) >= 1, 30.0), s.log()
        # No controller: a step per lockstep_timeout only.
        n = len(p.msgs)
        p.spin_for(0.3)
        assert len(p.msgs) - n <= 2
        # A controller answering every state: one step per command, sim time in 1 ms steps.
        p.respond = lambda msg: [0.0, 0.0, 0.0]
        p.send([0.0, 0.0, 0.0])
        t0, n = time.perf_counter(), len(p.msgs)
        p.spin_until(lambda: len(p.msgs) > n + 2000, 10.0)
        wall = time.perf_counter() - t0
        p.respond = None
        stamps = np.array([m[1] for m in p.msgs[n:]])
        assert len(stamps) > 500, s.log()
        assert np.all(np.diff(stamps) == 1_000_000), 'one 1 ms step per state'
        assert p.clock_ns and p.clock_ns[-1] >= stamps[0], '/clock follows the sim time'
        rtf = (stamps[-1] - stamps[0]) * 1e-9 / wall
        print(f'lockstep: {len(stamps)} steps, real-time factor {rtf:.2f}')
        assert rtf > 0.2, rtf
    finally:
        p.destroy()
        assert s.close() == 0, s.log()


@pytest.mark.dds
def test_joints_are_held_until_the_first_command(tmp_path):
    """hold_until_first_command: no fall under gravity while no controller has answered."""
    q0 = [0.0, 0.6, 0.0]  # joint 2 off vertical: gravity pulls it (~0.8 N m), no friction
    s = SimProcess(tmp_path, {'initial_positions': q0})
    p = Probe(s.context)
    try:
        assert p.spin_until(lambda: len(p.msgs) > 300, 30.0), s.log()
        first = p.msgs[0]
        last = p.latest()
        assert last[1] > first[1]  # time advances
        assert last[2] == q0 and last[3] == [0.0, 0.0, 0.0], last  # held exactly, at rest
        p.send([0.0, 0.0, 0.0])  # a controller connects, commanding zero torque: it falls
        assert p.spin_until(lambda: abs(p.latest()[2][1] - q0[1]) > 0.01, 5.0), s.log()
    finally:
        p.destroy()
        s.close()


@pytest.mark.dds
def test_start_up_prints_only_the_nodes_own_lines(sim, probe):
    """The banner of PyBullet (its build time, 'argv[0]=') does not open the output."""
    text = sim.log()
    assert '[wrist_sim]: simulating joints' in text, text[-2000:]
    assert 'build time' not in text and 'argv[0]=' not in text, text[:2000]


@pytest.mark.dds
def test_the_mujoco_engine_publishes_joint_states_and_takes_efforts(tmp_path):
    """Engine mujoco behind the same topics: states at rate, a command moves the joints."""
    pytest.importorskip('mujoco')
    s = SimProcess(tmp_path, {'engine': 'mujoco', 'initial_positions': INITIAL,
                              'coulomb_friction': COULOMB, 'armature': [0.05, 0.05, 0.05]})
    p = Probe(s.context)
    try:
        assert p.spin_until(lambda: len(p.msgs) > 100, 30.0), s.log()
        assert p.names == JOINTS
        np.testing.assert_allclose(p.latest()[2], INITIAL, atol=1e-6)  # held before a command
        moved = _stream_until(p, [2.0, 0.0, -1.5], lambda: (
            p.latest()[2][0] - INITIAL[0] > 0.01 and p.latest()[2][2] - INITIAL[2] < -0.01))
        _, _, q, qdot, effort = p.latest()
        assert moved, f'{INITIAL} -> {q}\n{s.log()}'
        assert qdot[0] > 0.0 and qdot[2] < 0.0, qdot
        assert abs(q[1] - INITIAL[1]) < 1e-3, 'joint 2 held by stiction'
        np.testing.assert_allclose(effort, [2.0, 0.0, -1.5])
        _stream_until(p, [80.0, 0.0, -80.0], lambda: p.latest()[4][0] != 2.0)
        np.testing.assert_allclose(p.latest()[4], [50.0, 0.0, -20.0])  # the effort limits
        assert 'in mujoco at 1000 Hz, armature [0.05, 0.05, 0.05]' in s.log()
        assert 'NOT simulated' not in s.log()
    finally:
        p.destroy()
        assert s.close() == 0, s.log()

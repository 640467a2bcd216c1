"""
The launch files, run against recording stand-ins of launch/launch_ros (not on PyPI).

Every demo: the two nodes with the package's config files, the launch arguments, the nodes'
names (the xArm6's simulator has its own), and ``on_exit`` shutting the whole launch down when
either node exits on its own (so a simulator that cannot open its window does not leave a
controller running alone), but adding nothing, and logging nothing, once a shutdown is under
way (Ctrl-C). ``rviz:=true`` starts robot_state_publisher with the robot's URDF and RViz with
the shipped config, whose displays read the topics the nodes publish, with their QoS.
"""
import ast
import importlib.util
from pathlib import Path
import sys
import types

import pytest
from robots import PANDA_URDF, XARM6_URDF
import yaml

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parent.parent
COMPOSED = {'wrist_demo.launch.py'}  # launch files with composed:=true
WRIST_URDF = REPO / 'urdf' / 'spherical_wrist.urdf'
RVIZ = REPO / 'rviz' / 'quat_jt.rviz'
DEMOS = {
    'wrist_demo.launch.py': ('wrist_sim', 'wrist_sim.yaml', 'wrist_controller.yaml', None),
    'xarm6_demo.launch.py': ('xarm6_sim', 'xarm6_sim.yaml', 'xarm6_controller.yaml',
                             XARM6_URDF),
    'panda_demo.launch.py': ('panda_sim', 'panda_sim.yaml', 'panda_controller.yaml',
                             PANDA_URDF),
}


class Recorder:

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class ShutdownRecorder(Recorder):
    """Stands in for launch.actions.Shutdown."""


class IfRecorder(Recorder):
    """Stands in for launch.conditions.IfCondition."""


class UnlessRecorder(Recorder):
    """Stands in for launch.conditions.UnlessCondition."""


class NotRecorder(Recorder):
    """Stands in for launch.substitutions.NotSubstitution."""


class Context:
    """Stands in for launch.LaunchContext, shutting down or not."""

    def __init__(self, is_shutdown: bool) -> None:
        self.is_shutdown = is_shutdown


def describe(monkeypatch, launch_file: str):
    stand_ins = {
        'launch': {'LaunchDescription': Recorder},
        'launch.actions': {'DeclareLaunchArgument': Recorder, 'Shutdown': ShutdownRecorder},
        'launch.substitutions': {'LaunchConfiguration': Recorder,
                                 'NotSubstitution': NotRecorder},
        'launch.conditions': {'IfCondition': IfRecorder, 'UnlessCondition': UnlessRecorder},
        'launch_ros': {},
        'launch_ros.actions': {'Node': Recorder},
        'launch_ros.parameter_descriptions': {'ParameterValue': Recorder},
        'ament_index_python': {},
        'ament_index_python.packages': {'get_package_share_directory': lambda pkg: str(REPO)},
    }
    for name, attrs in stand_ins.items():
        monkeypatch.setitem(sys.modules, name, types.SimpleNamespace(**attrs))
    spec = importlib.util.spec_from_file_location('demo_launch', REPO / 'launch' / launch_file)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description().args[0]


@pytest.mark.parametrize('launch_file', sorted(DEMOS) + ['arm_demo.launch.py'])
def test_launch_file_is_jazzy_launch_code(launch_file):
    path = REPO / 'launch' / launch_file
    tree = ast.parse(path.read_text(), str(path))
    compile(tree, str(path), 'exec')
    assert 'generate_launch_description' in {n.name for n in tree.body
                                             if isinstance(n, ast.FunctionDef)}
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert {'launch', 'launch.actions', 'launch_ros.actions'} <= imported
    if launch_file in DEMOS:  # their config files are in the package's share directory
        assert 'ament_index_python.packages' in imported


@pytest.mark.parametrize('launch_file', sorted(DEMOS))
def test_launch_description(monkeypatch, launch_file):
    sim_name, sim_config, controller_config, urdf = DEMOS[launch_file]
    actions = describe(monkeypatch, launch_file)
    nodes = {a.kwargs['executable']: a.kwargs for a in actions if 'executable' in a.kwargs}
    composed = nodes.pop('composed', None)
    nodes.pop('rviz2'), nodes.pop('robot_state_publisher')  # rviz:=true, below
    assert (composed is not None) == (launch_file in COMPOSED)
    assert set(nodes) == {'controller_node', 'wrist_sim_node'}
    if composed is not None:  # composed:=true runs one process instead of the two
        assert isinstance(composed['condition'], IfRecorder)
        assert all(isinstance(n['condition'], UnlessRecorder) for n in nodes.values())
        assert composed['condition'].args == nodes['wrist_sim_node']['condition'].args
        assert 'name' not in composed  # a name would rename both nodes to one
        files = [Path(f) for f in composed['parameters'][:2]]
        assert files == [REPO / 'config' / sim_config, REPO / 'config' / controller_config]
        assert exit_shuts_down(composed['on_exit'])
    assert nodes['controller_node']['name'] == 'quat_jt_controller'
    assert nodes['wrist_sim_node']['name'] == sim_name
    for exe, config in (('controller_node', controller_config),
                        ('wrist_sim_node', sim_config)):
        config_path, overrides = nodes[exe]['parameters']
        assert Path(config_path) == REPO / 'config' / config
        if urdf is not None:
            assert overrides['robot_description'] == urdf.read_text()
        # Either node exiting ends the launch.
        assert exit_shuts_down(nodes[exe]['on_exit'])
    assert nodes['controller_node']['parameters'][1]['potential'].kwargs == {'value_type': str}
    assert nodes['wrist_sim_node']['parameters'][1]['use_gui'].kwargs == {'value_type': bool}
    defaults = {a.args[0]: a.kwargs['default_value'] for a in actions
                if 'default_value' in a.kwargs}
    assert defaults == {'potential': 'tanh', 'use_gui': 'false', 'namespace': '', 'rviz': 'false',
                        **({'composed': 'false'} if composed is not None else {})}
    # Every process in the launch's namespace, with its simulated clock there too.
    for node in [*nodes.values(), *([composed] if composed is not None else [])]:
        assert node['namespace'].args == ('namespace',)
        assert node['remappings'] == [('/clock', 'clock')]
    choices = {a.args[0]: a.kwargs['choices'] for a in actions if 'choices' in a.kwargs}
    assert choices['potential'] == ['tanh', 'quadratic'] and choices['use_gui'] == [
        'true', 'false'] and choices['rviz'] == ['true', 'false']


def test_any_arm_runs_from_its_urdf_and_the_two_files_design_gains_writes(monkeypatch):
    """arm_demo.launch.py: the URDF, and design_gains' --out and --sim-out, all required."""
    actions = describe(monkeypatch, 'arm_demo.launch.py')
    arguments = {a.args[0]: a.kwargs for a in actions if 'description' in a.kwargs}
    required = {name for name, kw in arguments.items() if 'default_value' not in kw}
    assert required == {'urdf', 'controller_params', 'sim_params'}
    assert {name: kw['default_value'] for name, kw in arguments.items()
            if name not in required} == {'use_gui': 'false', 'namespace': ''}
    nodes = {a.kwargs['executable']: a.kwargs for a in actions if 'executable' in a.kwargs}
    assert set(nodes) == {'controller_node', 'wrist_sim_node'}
    assert nodes['controller_node']['name'] == 'quat_jt_controller'
    assert nodes['wrist_sim_node']['name'] == 'arm_sim'
    for exe, params_file in (('controller_node', 'controller_params'),
                             ('wrist_sim_node', 'sim_params')):
        node = nodes[exe]
        given, overrides = node['parameters']
        assert given.args == (params_file,)
        assert overrides['robot_description_file'].args == ('urdf',)  # both read the file
        assert exit_shuts_down(node['on_exit'])
        assert node['namespace'].args == ('namespace',)
        assert node['remappings'] == [('/clock', 'clock')]
    assert nodes['wrist_sim_node']['parameters'][1]['use_gui'].kwargs == {'value_type': bool}


def test_the_files_design_gains_writes_name_the_urdf_the_launch_gives(tmp_path):
    """What the nodes build from --out and --sim-out plus robot_description_file: one arm."""
    from quat_jt_controller import gain_design
    from quat_jt_controller.controller_config import controller_from_config
    from robots import small_arm_urdf
    urdf = tmp_path / 'arm.urdf'
    urdf.write_text(small_arm_urdf(('revolute',) * 4))
    out, sim_out = tmp_path / 'arm_controller.yaml', tmp_path / 'arm_sim.yaml'
    assert gain_design.main(['--urdf', str(urdf), '--task', 'orientation', '--out', str(out),
                             '--sim-out', str(sim_out)]) == 0
    controller = yaml.safe_load(out.read_text())['/**']['ros__parameters']
    sim = yaml.safe_load(sim_out.read_text())['/**']['ros__parameters']
    assert controller['robot_description'] == '' and sim['robot_description'] == ''
    built = controller_from_config({**controller, 'robot_description_file': str(urdf)})
    assert list(built.model.joint_names) == controller['joints'] == sim['joints']


def exit_shuts_down(on_exit) -> bool:
    """Tell whether ``on_exit`` shuts the launch down once, with a reason, and not again."""
    first = on_exit('a ProcessExited', Context(is_shutdown=False))
    again = on_exit('a ProcessExited', Context(is_shutdown=True))  # Ctrl-C, or after a first
    return (again is None and len(first) == 1 and isinstance(first[0], ShutdownRecorder)
            and bool(first[0].kwargs['reason']))


@pytest.mark.parametrize('launch_file', sorted(DEMOS))
def test_rviz_starts_robot_state_publisher_and_rviz_with_the_shipped_config(
        monkeypatch, launch_file):
    """rviz:=true: the URDF to robot_state_publisher, RViz on the robot's base link."""
    urdf = DEMOS[launch_file][3] or WRIST_URDF
    config = yaml.safe_load((REPO / 'config' / DEMOS[launch_file][2]).read_text())
    base_link = config['/**']['ros__parameters']['base_link']
    actions = describe(monkeypatch, launch_file)
    nodes = {a.kwargs['executable']: a.kwargs for a in actions if 'executable' in a.kwargs}
    rsp, rviz = nodes['robot_state_publisher'], nodes['rviz2']
    for node in (rsp, rviz):  # only with rviz:=true, in the launch's namespace
        assert isinstance(node['condition'], IfRecorder)
        assert node['condition'].args[0].args == ('rviz',)
        assert node['namespace'].args == ('namespace',)
        assert 'on_exit' not in node  # closing RViz does not stop the robot
    description = rsp['parameters'][0]['robot_description']
    assert description.args == (urdf.read_text(),) and description.kwargs == {
        'value_type': str}
    assert rviz['arguments'] == ['-d', str(RVIZ), '-f', base_link]
    # robot_state_publisher publishes robot_description then: the simulator does not
    for exe in ('wrist_sim_node', 'composed'):
        if exe in nodes:
            published = [p for p in nodes[exe]['parameters'] if isinstance(p, dict)][-1][
                'publish_robot_description']
            assert published.kwargs == {'value_type': bool}
            assert isinstance(published.args[0], NotRecorder)
            assert published.args[0].args[0].args == ('rviz',)
    # RViz reads the namespace's own topics
    assert ('/quat_jt_controller/goal_pose', 'quat_jt_controller/goal_pose') in rviz[
        'remappings']


def test_the_rviz_config_shows_the_robot_the_goal_and_the_measured_pose():
    """The displays read the topics the nodes publish, with a QoS that matches theirs."""
    config = yaml.safe_load(RVIZ.read_text())
    displays = {d['Class'].split('/')[-1] + ':' + d['Name']: d
                for d in config['Visualization Manager']['Displays']}
    robot = next(d for key, d in displays.items() if key.startswith('RobotModel:'))
    assert robot['Description Source'] == 'Topic'
    assert robot['Description Topic']['Value'] == '/robot_description'
    assert robot['Description Topic']['Durability Policy'] == 'Transient Local'
    poses = {d['Topic']['Value']: d['Topic'] for key, d in displays.items()
             if key.startswith('Pose:')}
    assert poses['/quat_jt_controller/goal_pose']['Durability Policy'] == 'Transient Local'
    assert poses['/quat_jt_controller/current_pose']['Durability Policy'] == 'Volatile'
    assert all(topic['Reliability Policy'] == 'Reliable' for topic in poses.values())
    from quat_jt_bringup.launch_parts import RVIZ_TOPICS
    assert set(RVIZ_TOPICS) == {'/robot_description', *poses}

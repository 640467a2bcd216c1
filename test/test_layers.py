"""
The arrows point one way: experiments -> bringup -> nodes -> shared runtime -> ROS-free cores.

Read from the source with ``ast`` (nothing is imported): which package each module imports, and
which modules touch ROS at all.
"""
import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ('quat_jt_runtime', 'quat_jt_controller', 'wrist_sim', 'quat_jt_bringup')
# The Python packages of ROS itself (rclpy and the message and service packages).
ROS = ('rclpy', 'rcl_interfaces', 'sensor_msgs', 'geometry_msgs', 'std_msgs', 'std_srvs',
       'diagnostic_msgs', 'rosgraph_msgs', 'builtin_interfaces')
# The modules that marshal for ROS; everything else in the packages is ROS-free.
ROS_MODULES = {
    'quat_jt_runtime': {'params', 'lifecycle', 'messages', 'prewarm_timer', 'description'},
    'quat_jt_controller': {'controller_node', 'parameters', 'reports'},
    'wrist_sim': {'sim_node', 'parameters'},
    'quat_jt_bringup': {'parameter_docs'},
}
# What each package may import of the others.
ALLOWED = {
    'quat_jt_runtime': set(),
    'quat_jt_controller': {'quat_jt_runtime'},
    'wrist_sim': {'quat_jt_runtime'},
    'quat_jt_bringup': {'quat_jt_runtime', 'quat_jt_controller', 'wrist_sim'},
}


def imported_roots(path: Path) -> set[str]:
    """Return the top-level names of every module ``path`` imports (at any depth)."""
    roots = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split('.')[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split('.')[0])
    return roots


def modules(package: str) -> list[Path]:
    return sorted((ROOT / package).glob('*.py'))


@pytest.mark.parametrize('package', PACKAGES)
def test_a_package_imports_only_the_layers_below_it(package):
    wrong = {}
    for path in modules(package):
        others = imported_roots(path) & (set(PACKAGES) | {'experiments', 'test'})
        bad = others - ALLOWED[package] - {package}
        if bad:
            wrong[path.name] = sorted(bad)
    assert not wrong, f'{package} imports layers above or beside it: {wrong}'


@pytest.mark.parametrize('package', PACKAGES)
def test_only_the_marshalling_modules_import_ros(package):
    touching = {path.stem for path in modules(package) if imported_roots(path) & set(ROS)}
    assert touching <= ROS_MODULES[package], (
        f'ROS imported outside the marshalling modules of {package}: '
        f'{sorted(touching - ROS_MODULES[package])}')


def test_the_simulator_never_imports_the_controller():
    for path in modules('wrist_sim'):
        assert 'quat_jt_controller' not in imported_roots(path), path.name


def test_the_layer_test_sees_every_package_and_module():
    for package in PACKAGES:
        assert (ROOT / package / '__init__.py').is_file(), package
        assert modules(package), package

"""The repo is an ament_python package: colcon builds it into a workspace as a Jazzy user would."""
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys

import pytest

pytestmark = pytest.mark.packaging

REPO = Path(__file__).resolve().parent.parent
COLCON = Path(sys.executable).parent / 'colcon'
IGNORE = shutil.ignore_patterns('.venv', '.git', 'build', 'install', 'log', '*.egg-info',
                                '__pycache__', '.pytest_cache', '.hypothesis', 'results')


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory):
    if not COLCON.exists():
        pytest.fail(f'colcon not found next to {sys.executable}: install the [test] extra')
    ws = tmp_path_factory.mktemp('colcon_ws')
    shutil.copytree(REPO, ws / 'src' / 'quat_jt_controller', ignore=IGNORE)
    result = subprocess.run([str(COLCON), 'build', '--base-paths', 'src'], cwd=ws,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return ws / 'install' / 'quat_jt_controller'


def test_install_tree_has_index_marker_executables_and_data(colcon_install):
    prefix = colcon_install
    assert (prefix / 'share/ament_index/resource_index/packages/quat_jt_controller').is_file()
    for exe in ('controller_node', 'wrist_sim_node'):
        path = prefix / 'lib' / 'quat_jt_controller' / exe
        assert path.is_file() and os.access(path, os.X_OK), path
    share = prefix / 'share' / 'quat_jt_controller'
    assert (share / 'package.xml').is_file()
    assert (share / 'urdf' / 'spherical_wrist.urdf').is_file()
    repo_configs = sorted(p.name for p in (REPO / 'config').glob('*.yaml'))
    repo_launch = sorted(p.name for p in (REPO / 'launch').glob('*.launch.py'))
    assert repo_configs and repo_launch, 'the repo ships config and launch files'
    assert sorted(p.name for p in (share / 'config').glob('*.yaml')) == repo_configs
    assert sorted(p.name for p in (share / 'launch').glob('*.launch.py')) == repo_launch
    assert (share / 'rviz' / 'quat_jt.rviz').is_file()  # the launch files' rviz:=true


def test_installed_package_finds_its_data_through_the_ament_prefix(colcon_install, tmp_path):
    site = next((colcon_install / 'lib').glob('python3*/site-packages'))
    env = dict(os.environ, PYTHONPATH=str(site), AMENT_PREFIX_PATH=str(colcon_install))
    code = ('import quat_jt_runtime.resources as r; '
            "print(r.__file__); print(r.share_path('urdf/spherical_wrist.urdf'))")
    out = subprocess.run([sys.executable, '-c', code], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    module_file, urdf = out.stdout.split()
    assert Path(module_file).is_relative_to(site)
    assert Path(urdf) == colcon_install / 'share/quat_jt_controller/urdf/spherical_wrist.urdf'


def test_the_experiments_are_not_installed(colcon_install):
    """What runs on a robot is installed; the experiments and benchmarks stay in the repo."""
    site = next((colcon_install / 'lib').glob('python3*/site-packages'))
    assert (site / 'quat_jt_controller' / 'regulator.py').is_file()
    for package in ('quat_jt_runtime', 'wrist_sim', 'quat_jt_bringup'):  # the other floors
        assert (site / package / '__init__.py').is_file(), package
    assert not (site / 'quat_jt_controller' / 'tools').exists()
    assert not (site / 'experiments').exists()
    importing = [p.name for p in site.glob('*/*.py')
                 if re.search(r'^\s*(from|import) experiments\b', p.read_text(), re.M)]
    assert not importing, importing  # the arrows point one way


def test_the_core_extra_installs_no_simulator():
    """``pip install .[core,ros]`` is all a real robot needs: no PyBullet, no MuJoCo."""
    from importlib.metadata import requires
    core = [r for r in requires('quat_jt_controller') or []
            if re.search(r'extra\s*==\s*[\'"]core[\'"]', r)]
    assert core, 'the core extra is empty'
    assert not [r for r in core if r.startswith(('pybullet', 'mujoco'))], core


# The controller and the gain design with the simulators made unimportable, as on a machine
# where only the core and ros extras are installed.
WITHOUT_SIMULATORS = """
import sys
for name in ('pybullet', 'pybullet_data', 'mujoco', 'wrist_sim'):
    sys.modules[name] = None  # any import of it raises ImportError
from quat_jt_controller import controller_node  # noqa: F401 - the node's whole import tree
from quat_jt_controller.gain_design import main
sys.exit(main(sys.argv[1:]))
"""


def test_controller_node_and_design_gains_run_without_a_simulator(tmp_path):
    out = tmp_path / 'wrist_controller.yaml'
    result = subprocess.run(
        [sys.executable, '-c', WITHOUT_SIMULATORS, '--task', 'orientation', '--out', str(out)],
        cwd=tmp_path, env={**os.environ, 'PYTHONPATH': str(REPO)}, capture_output=True,
        text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'kp:' in out.read_text()

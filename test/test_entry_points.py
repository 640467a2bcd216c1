"""
The executables' ``--help``: usage on stdout, status 0, and nothing started (no rclpy).

Each runs as ``ros2 run`` would run it, through its console-script function, in a fresh
interpreter.
"""
from pathlib import Path
import subprocess
import sys

import pytest
from quat_jt_bringup.entry_points import ENTRY_POINTS, help_asked

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parent.parent
# The console script's body (setup.py entry_points), then a check that nothing was started.
SCRIPT = """
import sys
from quat_jt_bringup.entry_points import ENTRY_POINTS
name = sys.argv.pop(1)
ENTRY_POINTS[name]()
started = sorted(m for m in ('rclpy', 'pybullet', 'pinocchio') if m in sys.modules)
sys.stderr.write(f'imported: {started}\\n')
"""


@pytest.mark.parametrize('flag', ['--help', '-h'])
@pytest.mark.parametrize('name', sorted(ENTRY_POINTS))
def test_help_prints_the_usage_and_starts_nothing(name, flag):
    result = subprocess.run(
        [sys.executable, '-c', SCRIPT, name, flag, '--ros-args', '-p', 'use_gui:=true'],
        capture_output=True, text=True, timeout=60, cwd=REPO,
        env={'PYTHONPATH': str(REPO), 'PATH': '/usr/bin:/bin'})
    assert result.returncode == 0, result.stderr
    assert result.stderr == 'imported: []\n', result.stderr
    out = result.stdout
    assert out.startswith(f'usage: ros2 run quat_jt_controller {name} [-h] [--ros-args ...]')
    assert '--params-file' in out and '-p NAME:=VALUE' in out and '-r FROM:=TO' in out
    for page in ('docs/ros.md', 'docs/parameters.md'):
        path = out.split(page)[0].split()[-1] + page  # the installed page, by its path
        assert Path(path).is_file(), path
    for config in {'controller_node': ['wrist_controller.yaml'],
                   'wrist_sim_node': ['wrist_sim.yaml'],
                   'composed': ['wrist_sim.yaml', 'wrist_controller.yaml']}[name]:
        assert f'/config/{config}' in out, out


def test_only_a_flag_before_the_ros_arguments_asks_for_help():
    assert help_asked(['--help']) and help_asked(['-h', '--ros-args', '-p', 'a:=1'])
    assert not help_asked([])
    assert not help_asked(['--ros-args', '-p', 'robot_description:=-h'])
    assert not help_asked(['--ros-args', '--help'])  # ROS's own arguments: rcl's business

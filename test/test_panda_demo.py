"""The Panda demo (ROS-free sampled loop): a sequence of goals, its MCAP, GIF and figure."""
import subprocess
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image
import pytest

pytestmark = pytest.mark.e2e


def test_panda_demo_reaches_each_goal_holds_the_elbow_and_writes_its_files(tmp_path):
    out = subprocess.run([sys.executable, '-m', 'experiments.panda_demo', '--out',
                          str(tmp_path), '--hold', '4'], capture_output=True, text=True,
                         timeout=300)  # the demo's own 4 s a goal
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    goals = [x for x in out.stdout.splitlines() if x.strip().startswith('goal ')]
    assert len(goals) == 4
    for line in goals:  # each goal reached, then the arm at rest at the q* it was given
        assert 'after nan' not in line, line
        speed = float(line.split('last 0.5 s ')[1].split(' rad/s')[0])
        away = float(line.split('|q_j - q*_j| ')[1].split(' rad')[0])
        assert speed < 1e-3 and away < 0.05, line
    with open(tmp_path / 'panda_tanh.mcap', 'rb') as f:
        counts: dict[str, int] = {}
        goal_frames = 0
        for _, ch, _, msg in make_reader(
                f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counts[ch.topic] = counts.get(ch.topic, 0) + 1
            if ch.topic == '/joint_states':
                assert len(msg.position) == 7  # the arm; the fingers are not regulated
            if ch.topic == '/tf':
                goal_frames += sum(t.child_frame_id == 'goal' for t in msg.transforms)
    tf = counts.pop('/tf')
    assert counts == {'/joint_states': 16000, '/robot_description': 1, '/tf_static': 1}
    assert tf in (1600, 1601)  # at 100 Hz; the bins follow the wall-clock start
    assert goal_frames == tf  # the goal in force, on /tf with the arm
    with Image.open(tmp_path / 'panda_tanh.gif') as gif:
        assert gif.n_frames == 321 and gif.size == (320, 240)
    assert (tmp_path / 'panda_tanh.png').stat().st_size > 20_000
    assert 'argv[0]' not in out.stdout + out.stderr  # PyBullet's banner silenced

"""The xArm6 demo tool (ROS-free sampled loop) writes its MCAP, animations and figure."""
import subprocess
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image
import pytest

pytestmark = pytest.mark.e2e


def test_xarm6_demo_writes_replayable_mcap_animation_and_figure(tmp_path):
    out = subprocess.run([sys.executable, '-m', 'experiments.xarm6_demo', '--out',
                          str(tmp_path), '--duration', '1.0'], capture_output=True, text=True,
                         timeout=180)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    for potential in ('quadratic', 'tanh'):
        with open(tmp_path / f'xarm6_{potential}.mcap', 'rb') as f:
            counts: dict[str, int] = {}
            for _, ch, _, msg in make_reader(
                    f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                counts[ch.topic] = counts.get(ch.topic, 0) + 1
                if ch.topic == '/joint_states':
                    assert len(msg.position) == 6
        assert counts == {'/joint_states': 1001, '/robot_description': 1, '/tf_static': 1,
                          '/tf': 101}
        with Image.open(tmp_path / f'xarm6_{potential}.gif') as gif:
            assert gif.n_frames == 26 and gif.size == (320, 240)
        # The arm moved towards the goal: the position error printed at the end is < 1 cm.
        line = next(x for x in out.stdout.splitlines() if x.startswith(f'[xarm6 {potential}]'))
        assert float(line.split('||p_d - p|| = ')[1].split(' mm')[0]) < 10.0, line
    assert (tmp_path / 'xarm6_errors.png').stat().st_size > 20_000

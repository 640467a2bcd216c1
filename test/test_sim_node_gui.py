"""
``wrist_sim_node`` with ``use_gui:=true`` under a private Xvfb display, over DDS.

The node opens the PyBullet window, keeps publishing joint_states at its rate, and the window
shows the robot. Skipped where Xvfb is not installed.
"""
import os
import random
import time

from experiments import local_ros
import numpy as np
import pytest
import rclpy
from rclpy.experimental import EventsExecutor
from sensor_msgs.msg import JointState
from test_simulator_gui import is_grey
from xvfb import Xvfb

pytestmark = pytest.mark.dds


def test_sim_node_with_gui_publishes_joint_states_and_shows_the_robot(tmp_path):
    display = Xvfb(tmp_path)
    domain = random.choice([d for d in range(1, 101)
                            if d != int(os.environ['ROS_DOMAIN_ID'])])
    env = local_ros.isolated_env(tmp_path, domain_id=domain, base=display.env())
    proc = local_ros.spawn_node('wrist_sim_node', env, tmp_path,
                                params={'use_gui': True, 'initial_positions': [0.0, 0.5, 0.0]})
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('gui_probe', context=context)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    stamps: list[int] = []
    names: list[str] = []

    def on_state(msg: JointState) -> None:
        stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
        names[:] = msg.name

    node.create_subscription(JointState, 'joint_states', on_state, 100)

    def log() -> str:
        path = tmp_path / 'wrist_sim_node.log'
        return path.read_text(errors='replace')[-4000:] if path.exists() else '(no log)'

    try:
        deadline = time.monotonic() + 60.0
        while len(stamps) < 500 and time.monotonic() < deadline and proc.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        assert len(stamps) >= 500, f'{len(stamps)} joint states (exit {proc.poll()})\n{log()}'
        assert names == ['joint1', 'joint2', 'joint3']
        assert np.all(np.diff(stamps) > 0)
        # The window shows the robot: a body of grey (shaded white) pixels on the lavender
        # background, around the middle of the window where the simulator aims its camera.
        deadline = time.monotonic() + 30.0
        while True:
            image = display.screenshot()[:768, :1024]
            h, w, _ = image.shape
            centre = image[h // 4:3 * h // 4, w // 4:3 * w // 4].reshape(-1, 3)
            grey = sum(is_grey(px) for px in centre[::7])
            background = np.mean(image[:, :, 2].astype(int) - image[:, :, 0] > 15)
            if (grey > 300 and background > 0.5) or time.monotonic() > deadline:
                break
            executor.spin_once(timeout_sec=0.1)
        assert grey > 300 and background > 0.5, (grey, background)
        print(f'grey samples {grey}, background share {background:.2f}')
        assert proc.poll() is None, log()
    finally:
        code = local_ros.stop_node(proc)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        display.close()
    assert code == 0, log()

"""
The simulator's PyBullet window (``use_gui``), under a private Xvfb display.

ROS-free. A screenshot of the window must show the robot and the goal frame drawn by
``RobotSimulator.show_frame`` where the GUI's own camera projects them. Skipped where Xvfb is
not installed.
"""
import json
from pathlib import Path
import select
import subprocess
import sys
import time

import numpy as np
import pytest
from xvfb import Xvfb

pytestmark = pytest.mark.gui

AXIS_RGB = ((255, 0, 0), (0, 255, 0), (0, 0, 255))


def is_grey(px) -> bool:
    """Tell a shaded white link: neutral grey (the window's background is lavender)."""
    r, g, b = (int(v) for v in px)
    return abs(r - g) < 16 and abs(g - b) < 16 and 60 < r < 252


def is_axis(px, axis: int) -> bool:
    """Tell pure red, green or blue, as debug lines are drawn (a little shading allowed)."""
    v = np.asarray(px, int)
    others = [c for c in range(3) if c != axis]
    return v[axis] > 150 and all(v[c] < 110 for c in others)


def patch(image: np.ndarray, uv, half: int) -> np.ndarray:
    u, v = (int(round(c)) for c in uv)
    return image[max(v - half, 0):v + half + 1, max(u - half, 0):u + half + 1].reshape(-1, 3)


def check(image: np.ndarray, scene: dict) -> list[str]:
    """Return what is missing from the screenshot (empty when robot and goal frame show)."""
    missing = []
    for uv in scene['robot_uv']:
        grey = np.mean([is_grey(px) for px in patch(image, uv, 3)])
        if grey < 0.8:
            missing.append(f'robot at pixel {uv}: {grey:.0%} grey')
    origin = np.array(scene['goal_origin_uv'])
    for axis, end in enumerate(scene['goal_ends_uv']):
        hits = sum(any(is_axis(px, axis) for px in patch(image, origin + s * (end - origin), 2))
                   for s in np.linspace(0.5, 0.9, 5))
        if hits < 4:
            missing.append(f'goal axis {"xyz"[axis]}: {hits} of 5 points in its colour')
    corner = image[scene['height'] - 20, 20]
    if is_grey(corner) or any(is_axis(corner, a) for a in range(3)):
        missing.append(f'background corner is {corner.tolist()}')
    return missing


@pytest.fixture(scope='module')
def display(tmp_path_factory):
    x = Xvfb(tmp_path_factory.mktemp('xvfb'))
    yield x
    x.close()


def test_gui_window_shows_the_robot_and_the_goal_frame(display, tmp_path):
    scene_script = Path(__file__).with_name('gui_scene.py')
    child = subprocess.Popen([sys.executable, str(scene_script)], env=display.env(),
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        scene, deadline = None, time.monotonic() + 60.0
        while scene is None and time.monotonic() < deadline:  # PyBullet prints too
            ready, _, _ = select.select([child.stdout], [], [], 1.0)
            line = child.stdout.readline() if ready else ''
            if line.startswith('SCENE '):
                scene = json.loads(line[len('SCENE '):])
            elif ready and not line:
                break  # the process ended
        assert scene is not None, (f'no scene from the GUI process (exit {child.poll()}): '
                                   f'{child.stderr.read() if child.poll() is not None else ""}')
        assert scene['width'] <= 1024 and scene['height'] <= 768  # the window fits the screen
        deadline = time.monotonic() + 30.0
        while True:  # the window draws asynchronously: wait until it shows the scene
            image = display.screenshot()
            missing = check(image, scene)
            if not missing or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        from PIL import Image
        Image.fromarray(image).save(tmp_path / 'gui.png')
        assert not missing, f'{missing}; screenshot {tmp_path / "gui.png"}'
    finally:
        child.stdin.close()
        try:
            child.wait(20)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


def test_without_gui_show_frame_draws_nothing():
    from quat_jt_runtime.resources import default_urdf_xml
    from wrist_sim.simulator import RobotSimulator
    with RobotSimulator(default_urdf_xml()) as sim:
        assert sim.show_frame('goal', (0.0, 0.0, 0.45), (0.0, 0.0, 0.0, 1.0)) is False
        assert sim.gui_camera() is None

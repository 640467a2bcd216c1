"""The offscreen animation: a few frames of a synthetic wrist trajectory, checked by pixel."""
from experiments import animation
import numpy as np
from PIL import Image, ImageSequence
import pytest
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml

pytestmark = pytest.mark.unit


def _near(rgb, target, tolerance=60) -> bool:
    return bool(np.all(np.abs(np.asarray(rgb, int) - np.asarray(target, int)) <= tolerance))


def test_frame_indices_subsample_by_time():
    t = np.arange(0.0, 1.0005, 1e-3)  # 1 kHz for 1 s
    idx = animation.frame_indices(t, 25.0)
    assert len(idx) == 26
    np.testing.assert_allclose(t[idx], np.arange(26) * 0.04, atol=6e-4)
    # Irregular stamps (a real recording): the nearest sample is taken.
    t_irregular = np.array([0.0, 0.011, 0.038, 0.043, 0.079, 0.081])
    assert animation.frame_indices(t_irregular, 25.0).tolist() == [0, 2, 5]


def test_wrist_animation_shows_the_robot_the_goal_and_the_tip_frame(tmp_path):
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    t_s = np.arange(0.0, 0.2001, 1e-3)
    q_rad = np.outer(t_s / t_s[-1], paper.Q_JOINT_DESIRED_RAD)  # from q = 0 to the goal
    p_goal, _ = model.forward_kinematics(paper.Q_JOINT_DESIRED_RAD)
    R_goal = np.array(quat.to_rotation_matrix(paper.Q_DESIRED))
    path, still = tmp_path / 'wrist.gif', tmp_path / 'last.png'
    result = animation.animate(
        default_urdf_xml(), model.joint_names, t_s, q_rad, path, tip_link='tool0',
        base_link='base_link', goal=(p_goal, R_goal),
        text=lambda i: [f't = {t_s[i]:.2f} s'], still_at_s=0.2, still_path=still)
    assert result.frames == 6 and result.still_path == still
    with Image.open(path) as gif:
        frames = [f.convert('RGB') for f in ImageSequence.Iterator(gif)]
    assert len(frames) == 6 and frames[0].size == (320, 240)
    print(f'{result.frames} frames in {result.render_s:.2f} s, {result.size_bytes} bytes')

    # Reproduce the camera to know where things must appear.
    with animation.RobotRenderer(default_urdf_xml(), model.joint_names) as renderer:
        renderer.set_camera(result.camera)
        base_uv = renderer.project([[0.0, 0.0, 0.12]])[0]
        goal_ends = renderer.project(np.asarray(p_goal) + 0.13 * R_goal.T)
        goal_origin = renderer.project([p_goal])[0]
        tip_start_uv = renderer.project([[0.0, 0.0, 0.45]])[0]  # tool0 at q = 0
    last = np.asarray(Image.open(still).convert('RGB'))
    first = np.asarray(frames[0])
    # The base link (dark grey) is where it should be, on every frame.
    u, v = np.round(base_uv).astype(int)
    for image in (first, last):
        assert _near(image[v, u], [77, 77, 84], 45), image[v, u]
    # The goal axes: red, green and blue pixels along each axis, 60-90 % of its length.
    for axis, colour in enumerate(animation.AXIS_RGB):
        hits = 0
        for s in np.linspace(0.6, 0.9, 7):
            u, v = np.round(goal_origin + s * (goal_ends[axis] - goal_origin)).astype(int)
            patch = last[v - 1:v + 2, u - 1:u + 2].reshape(-1, 3)
            hits += any(_near(px, colour) for px in patch)
        assert hits >= 5, f'axis {"xyz"[axis]}: {hits} of 7 points in its colour'
    # The robot moved: at q = 0 the tip frame sits above the base, at the end it does not.
    u, v = np.round(tip_start_uv).astype(int)
    assert not np.array_equal(first[v - 3:v + 4, u - 3:u + 4], last[v - 3:v + 4, u - 3:u + 4])
    # The corner text is on a white box.
    assert (first[2:14, 2:60] < 100).any() and (first[2:14, 2:60] == 255).any()

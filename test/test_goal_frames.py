"""
Goals in the robot's own frames (``goal_frames.GoalFrames``), ROS-free.

A goal in a link F of the URDF is placed in the base with the measured joints q:
Q_d = Q_F(q) * Q_d^F and p_d = p_F(q) + R_F(q) p_d^F. Checked against the model's own forward
kinematics of that link as a tip (the Jacobian pass, another path through Pinocchio), on the
wrist (orientation task) and the xArm6 (pose task); the refusals name the frames accepted.
"""
import math

import numpy as np
import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_frames import GoalFrames
from quat_jt_controller.model import RobotModel
from quat_jt_controller.regulator import Goal
from robots import random_q, wrist_model, xarm6_model, XARM6_URDF

pytestmark = pytest.mark.unit

IDENTITY = (0.0, 0.0, 0.0, 1.0)


def rotation(q_scalar_first) -> np.ndarray:
    return np.array(quat.to_rotation_matrix(q_scalar_first))


def same_rotation(qa, qb, tol=1e-9) -> bool:
    return np.allclose(rotation(qa), rotation(qb), atol=tol)


def test_a_base_frame_goal_is_taken_as_given():
    frames = GoalFrames(xarm6_model(), Task.POSE)
    xyzw, p = (0.0, 0.6, 0.0, 0.8), (0.3, 0.1, 0.4)
    want = Goal.from_xyzw(*xyzw, p)
    assert frames.goal('link_base', xyzw, p, None) == want
    assert frames.goal('', xyzw, p, None) == want  # empty: the base
    # the orientation task ignores the position
    wrist = GoalFrames(wrist_model(), Task.ORIENTATION)
    assert wrist.goal('base_link', xyzw, p, None).p_desired_base == (0.0, 0.0, 0.0)


@pytest.mark.parametrize('link', ['link6', 'link3', 'link1'])
def test_a_link_goal_is_placed_with_the_measured_joints(link):
    """Identity in link F is F's pose; an offset and a turn are taken in F's axes."""
    model = xarm6_model()
    frames = GoalFrames(model, Task.POSE)
    as_tip = RobotModel(XARM6_URDF.read_text(), 'link_base', link)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = random_q(model, rng).tolist()
        p_f, R_f = as_tip.forward_kinematics(q)
        here = frames.goal(link, IDENTITY, (0.0, 0.0, 0.0), q)
        assert np.allclose(here.p_desired_base, p_f, atol=1e-12)
        assert same_rotation(here.q_desired_base, quat.from_rotation_matrix(R_f))
        # 0.1 m along F's z, turned 90 degrees about F's x
        c = math.cos(math.pi / 4)
        moved = frames.goal(link, (c, 0.0, 0.0, c), (0.0, 0.0, 0.1), q)
        R_f = np.array(R_f)
        assert np.allclose(moved.p_desired_base, np.array(p_f) + 0.1 * R_f[:, 2], atol=1e-12)
        turn = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
        assert np.allclose(rotation(moved.q_desired_base), R_f @ turn, atol=1e-9)
        assert abs(quat.norm(moved.q_desired_base) - 1.0) < 1e-12


def test_the_orientation_task_places_the_orientation_only():
    model = wrist_model()
    frames = GoalFrames(model, Task.ORIENTATION)
    q = [0.3, -0.4, 0.5]
    _, R_tip = model.forward_kinematics(q)
    goal = frames.goal('tool0', IDENTITY, (1.0, 2.0, 3.0), q)
    assert goal.p_desired_base == (0.0, 0.0, 0.0)
    assert same_rotation(goal.q_desired_base, quat.from_rotation_matrix(R_tip))


def test_a_placed_goal_stays_where_it_was_placed():
    """Placed once: the joints moving afterwards do not move it (a relative move ends)."""
    model = xarm6_model()
    frames = GoalFrames(model, Task.POSE)
    q0 = [0.0, -0.5, -1.0, 0.0, 1.5, 0.0]
    goal = frames.goal('link6', IDENTITY, (0.0, 0.0, 0.05), q0)
    p_tip, _ = model.forward_kinematics(q0)
    q1 = [0.1, -0.4, -1.1, 0.1, 1.4, 0.1]
    again = frames.goal('link_base', goal.xyzw(), goal.p_desired_base, q1)
    assert np.allclose(again.p_desired_base, goal.p_desired_base)
    assert math.dist(goal.p_desired_base, p_tip) == pytest.approx(0.05)


def test_unknown_frames_and_early_link_goals_are_refused_with_the_reason():
    frames = GoalFrames(wrist_model(), Task.ORIENTATION)
    with pytest.raises(ValueError) as refused:
        frames.goal('world', IDENTITY, (0.0, 0.0, 0.0), [0.0, 0.0, 0.0])
    assert str(refused.value).startswith(
        "header.frame_id is 'world', expected 'base_link' (or empty) or a link of the robot: "
        "['link1', 'link2', 'link3', 'tool0']")
    with pytest.raises(ValueError, match=r"'/tool0', expected 'tool0' \(tf2 frame ids have no "
                                         'leading slash'):
        frames.goal('/tool0', IDENTITY, (0.0, 0.0, 0.0), [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="'tool0' is a link of the robot, placed with the "
                                         'measured joints, and no joint state has come yet'):
        frames.goal('tool0', IDENTITY, (0.0, 0.0, 0.0), None)
    with pytest.raises(ValueError, match='quaternion is not unit'):  # checked in its own frame
        frames.goal('tool0', (0.0, 0.0, 0.0, 2.0), (0.0, 0.0, 0.0), [0.0, 0.0, 0.0])


def test_the_link_names_are_the_urdf_links():
    assert wrist_model().link_names() == ('base_link', 'link1', 'link2', 'link3', 'tool0')
    with pytest.raises(ValueError, match="link 'joint1' is not in the URDF"):
        wrist_model().link_pose('joint1', [0.0, 0.0, 0.0])

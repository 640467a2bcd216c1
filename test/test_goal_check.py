"""The A1 / A2 goal check (quat_jt_controller.goal_check) on the wrist and the xArm6."""
import math

import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_check import check_goal
from quat_jt_controller.inverse_kinematics import solve_ik
from robots import Q_DESIRED, wrist_model, xarm6_model

pytestmark = pytest.mark.unit

ORI, POSE = Task.ORIENTATION, Task.POSE


def goal_at(model, q):
    p, R = model.forward_kinematics(q)
    return quat.from_rotation_matrix(R), p


def test_paper_goal_is_fine_from_the_singular_start():
    assert check_goal(wrist_model(), [0.0, 0.0, 0.0], quat.normalized(Q_DESIRED), (0, 0, 0),
                      ORI) == ''


def test_wrist_goal_reachable_only_at_q2_zero_breaks_a2():
    rz = (math.cos(0.4), 0.0, 0.0, math.sin(0.4))  # Rz(0.8): only q2 = 0 reaches it
    warning = check_goal(wrist_model(), [0.5, 0.5, 0.5], rz, (0, 0, 0), ORI)
    assert 'singular' in warning and 'A2' in warning, warning


def test_wrist_centre_cannot_move_so_a_far_position_may_break_a1():
    warning = check_goal(wrist_model(), [0.0, 0.0, 0.0], quat.normalized(Q_DESIRED),
                         (1.0, 0.0, 0.0), POSE)
    assert 'A1' in warning, warning


def test_xarm_goal_across_the_full_turn_joint_is_reached():
    """Joint 6 spans +-2 pi: the IK wraps it instead of sticking at a limit."""
    model = xarm6_model()
    q_goal = [0.2, -0.4, -1.1, 0.2, 1.4, 0.3]
    q_d, p_d = goal_at(model, q_goal)
    q_start = [0.0, -0.5, -1.0, 0.0, 1.5, 6.0]
    _, residual, _ = solve_ik(model, q_start, q_d, p_d, POSE)
    assert residual < 1e-4
    assert check_goal(model, q_start, q_d, p_d, POSE) == ''


def test_xarm_goal_outside_the_workspace_breaks_a1():
    model = xarm6_model()
    q_d, _ = goal_at(model, [0.0, -0.5, -1.0, 0.0, 1.5, 0.0])
    warning = check_goal(model, [0.0, -0.5, -1.0, 0.0, 1.5, 0.0], q_d, (1.2, 0.0, 0.5), POSE)
    assert 'A1' in warning, warning

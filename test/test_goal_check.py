"""The A1 / A2 goal check (quat_jt_controller.goal_check) on the wrist and the xArm6."""
import math

import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_check import check_goal, solve_ik
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


def test_a_stream_of_goals_keeps_one_ik_branch_from_the_warm_start():
    """Goals along a joint path: each q* (warm-started from the last) follows the path."""
    from quat_jt_controller.goal_check import goal_configuration, WARM_STEP_RAD
    model = xarm6_model()
    q_path = [[0.2 + 0.01 * k, -0.4, -1.1 + 0.01 * k, 0.2, 1.4 - 0.01 * k, 0.3]
              for k in range(20)]
    q_last = None
    for q_goal in q_path:
        q_d, p_d = goal_at(model, q_goal)
        q_star = goal_configuration(model, q_path[0], q_d, p_d, POSE, 0.1, q_warm=q_last)
        assert q_star is not None
        if q_last is not None:  # the same branch: a small step from the last q*
            assert max(abs(a - b) for a, b in zip(q_star, q_last)) < WARM_STEP_RAD
        q_last = q_star.tolist()
    assert max(abs(a - b) for a, b in zip(q_last, q_path[-1])) < 1e-3  # still the path's branch


def test_the_goal_configuration_is_polished_to_the_models_precision():
    """q* reaches the goal to 1e-10, not to the search's 1e-5: U_a and U_c share a minimum."""
    import numpy as np
    from quat_jt_controller.goal_check import goal_configuration, POLISHED_TOLERANCE
    for model, task, q_goal in ((xarm6_model(), POSE, [0.4, -0.3, -1.2, 0.3, 1.1, 0.2]),
                                (wrist_model(), ORI, [0.3, 2.5, -3.0])):
        p_d, R_d = model.forward_kinematics(q_goal)
        q_d = quat.from_rotation_matrix(R_d)
        q_star = goal_configuration(model, [0.0] * model.n, q_d, p_d, task, 0.25)
        assert q_star is not None
        p, R = model.forward_kinematics(list(q_star))
        _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
        assert np.linalg.norm(e) < POLISHED_TOLERANCE  # ||e|| = sin(angle / 2)
        if task is POSE:
            assert np.linalg.norm(np.subtract(p, p_d)) < POLISHED_TOLERANCE

"""The inverse kinematics (quat_jt_controller.inverse_kinematics): q*, its polish and posture."""
import math

import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from robots import panda_model, wrist_model, xarm6_model

pytestmark = pytest.mark.unit

POSE = Task.POSE
ORI = Task.ORIENTATION


def goal_at(model, q):
    p, R = model.forward_kinematics(q)
    return quat.from_rotation_matrix(R), p


def test_a_stream_of_goals_keeps_one_ik_branch_from_the_warm_start():
    """Goals along a joint path: each q* (warm-started from the last) follows the path."""
    from quat_jt_controller.inverse_kinematics import goal_configuration, WARM_STEP_RAD
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
    from quat_jt_controller.inverse_kinematics import goal_configuration, POLISHED_TOLERANCE
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


def test_a_redundant_arm_gets_the_goal_configuration_nearest_along_its_self_motion():
    """
    The Panda reaches a pose along a 1-D self-motion: q* is slid along it towards q.

    It still reaches the goal exactly, it is nearer the measured q than the solution it was
    slid from, and there the gradient of the posture cost has no part in the null space of J
    (a minimum along the self-motion).
    """
    import numpy as np
    from quat_jt_controller.inverse_kinematics import goal_configuration, polish, posture, \
        POLISHED_TOLERANCE, solve_ik
    model = panda_model()
    q_now = np.array([0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.6])
    q_goal = [0.9, 0.1, -0.4, -1.6, 0.5, 1.5, 1.2]
    q_d, p_d = goal_at(model, q_goal)
    q_ik = polish(model, solve_ik(model, q_goal, q_d, p_d, POSE)[0], q_d, p_d, POSE)
    q_mid = 0.5 * (np.array(model.position_lower) + np.array(model.position_upper))
    q_star = posture(model, q_ik, q_d, p_d, POSE, q_now, q_mid, 0.0)
    assert q_star is not None
    p, R = model.forward_kinematics(q_star.tolist())
    _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
    assert np.linalg.norm(e) < POLISHED_TOLERANCE
    assert np.linalg.norm(np.subtract(p, p_d)) < POLISHED_TOLERANCE
    assert np.linalg.norm(q_star - q_now) < np.linalg.norm(q_ik - q_now) - 0.1
    J = np.array(model.kinematics(q_star.tolist())[2])
    null = np.eye(7) - np.linalg.pinv(J) @ J
    assert np.linalg.norm(null @ (q_star - q_now)) < 1e-4
    # the preferred posture pulls it along the self-motion, towards q_mid
    q_pref = posture(model, q_ik, q_d, p_d, POSE, q_now, q_mid, 1.0)
    assert np.linalg.norm(q_pref - q_mid) < np.linalg.norm(q_star - q_mid)
    # goal_configuration does the same from its own starts
    found = goal_configuration(model, q_now, q_d, p_d, POSE, 0.157)
    assert found is not None and np.linalg.norm(found - q_now) <= np.linalg.norm(
        q_ik - q_now)


def test_the_posture_search_settles_where_a_band_holds_it_back():
    """
    Measured joints deep in a band: the nearest posture lies against the band (margin > 0).

    The search stops at a local minimum of its cost along the self-motion: there the cost's
    gradient has no part in the null space of J, and more iterations change nothing.
    """
    import numpy as np
    from quat_jt_controller import inverse_kinematics as gc
    model = panda_model()
    margin = 0.157
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    q_now = np.array([0.5, -0.2, 0.4, -3.05, 0.3, 2.0, 0.5])  # joint 4 deep in its band
    q_goal = [0.3, -0.4, 0.2, -3.0, 0.1, 2.0, 0.5]  # joint 4 in its band too
    q_d, p_d = goal_at(model, q_goal)
    q_ik = gc.polish(model, gc.solve_ik(model, q_goal, q_d, p_d, POSE)[0], q_d, p_d, POSE)
    q_mid = np.array(model.middle_of_ranges())
    found = gc.posture(model, q_ik, q_d, p_d, POSE, q_now, q_mid, 0.1, margin)
    assert found is not None
    inner_lo, inner_hi = lower + margin, upper - margin
    depth = np.minimum(found - inner_lo, 0.0) + np.maximum(found - inner_hi, 0.0)
    grad = (found - q_now) + 0.1 * (found - q_mid) + gc.POSTURE_BAND_WEIGHT * depth
    J = np.array(model.kinematics(found.tolist())[2])
    Z = np.linalg.svd(J)[2][6:].T
    assert depth[3] < 0.0 and np.count_nonzero(depth) == 1  # against joint 4's band
    assert np.abs(Z.T @ grad).max() < 1e-3 * np.abs(grad).max()  # stationary along S
    more = gc.POSTURE_ITERATIONS
    try:
        gc.POSTURE_ITERATIONS = 10 * more
        again = gc.posture(model, q_ik, q_d, p_d, POSE, q_now, q_mid, 0.1, margin)
    finally:
        gc.POSTURE_ITERATIONS = more
    assert np.abs(again - found).max() < 1e-6


def test_an_arm_without_self_motion_keeps_its_solution():
    """posture() changes nothing where J has as many rows as columns (the xArm6's pose)."""
    import numpy as np
    from quat_jt_controller.inverse_kinematics import polish, posture, solve_ik
    model = xarm6_model()
    q_goal = [0.4, -0.3, -1.2, 0.3, 1.1, 0.2]
    q_d, p_d = goal_at(model, q_goal)
    q_ik = polish(model, solve_ik(model, [0.3, -0.4, -1.1, 0.2, 1.0, 0.1], q_d, p_d,
                                  POSE)[0], q_d, p_d, POSE)
    moved = posture(model, q_ik, q_d, p_d, POSE, [0.0] * 6, [0.0] * 6, 1.0)
    assert np.max(np.abs(moved - q_ik)) < 1e-9


def test_a_full_turn_joint_keeps_away_from_its_stop_when_it_can():
    """Of q*_j and q*_j -/+ 2 pi, both within the range, the one away from the stop is taken."""
    import numpy as np
    from quat_jt_controller.inverse_kinematics import representative
    lower, upper = np.array([-2.0 * math.pi]), np.array([2.0 * math.pi])
    near_stop = np.array([6.21])  # 0.07 from the stop, 2.86 from the measured 3.35
    assert representative(near_stop, np.array([3.35]), lower, upper)[0] == pytest.approx(6.21)
    away = representative(near_stop, np.array([3.35]), lower, upper, margin_rad=0.2)
    assert away[0] == pytest.approx(6.21 - 2.0 * math.pi)

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
    slid from (in the travel's time, the distance weighted by the joints' velocity limits),
    and there the gradient of the posture cost has no part in the null space of J (a minimum
    along the self-motion).
    """
    import numpy as np
    from quat_jt_controller.inverse_kinematics import goal_configuration, polish, posture, \
        POLISHED_TOLERANCE, solve_ik, travel_weights
    model = panda_model()
    w = travel_weights(model)

    def travel(q):
        return np.sqrt(np.sum(w * (q - q_now) ** 2))
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
    assert travel(q_star) < travel(q_ik) - 0.1
    J = np.array(model.kinematics(q_star.tolist())[2])
    null = np.eye(7) - np.linalg.pinv(J) @ J
    assert np.linalg.norm(null @ (w * (q_star - q_now))) < 1e-4
    # the preferred posture pulls it along the self-motion, towards q_mid
    q_pref = posture(model, q_ik, q_d, p_d, POSE, q_now, q_mid, 1.0)
    assert np.linalg.norm(q_pref - q_mid) < np.linalg.norm(q_star - q_mid)
    # goal_configuration does the same from its own starts
    found = goal_configuration(model, q_now, q_d, p_d, POSE, 0.157)
    assert found is not None and travel(found) <= travel(q_ik)


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


def test_a_band_is_a_wall_for_the_posture_where_the_self_motion_leaves_it():
    """
    Romeo's left arm (8 joints, from its base): a goal whose nearest posture lay in a band.

    With the bands weighted 100 times, the slide along the self-motion stopped with the wrist's
    yaw 0.004 rad from its stop, 0.040 rad deep in its 0.044 rad band (leaving it cost more
    distance on the other joints), and the arm touched that stop settling at q*. A band is a
    wall in the posture cost now: q* lies out of it, to within 1e-3 rad, and reaches the goal.
    """
    import numpy as np
    from quat_jt_controller import inverse_kinematics as gc
    from quat_jt_controller.model import RobotModel
    from quat_jt_runtime.joints import chain_joints
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('romeo_description/urdf/romeo_small.urdf').read_text()
    model = RobotModel(urdf, 'base_link', 'l_wrist', chain_joints(urdf, 'base_link', 'l_wrist'))
    margin = 0.044
    q_start = [0.1682, -0.7421, 0.0195, 0.8955, -0.1733, -0.5387, 0.2394, 0.4624]
    q_goal = [-0.0542, 1.0876, 0.4535, -0.1651, -1.0731, -0.349, -0.3011, 0.4953]
    q_d, p_d = goal_at(model, q_goal)
    q_star = gc.goal_configuration(model, q_start, q_d, p_d, POSE, margin,
                                   q_preferred=model.middle_of_ranges(), posture_weight=0.1)
    assert q_star is not None
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    assert np.min(np.minimum(q_star - lower, upper - q_star)) > margin - 1e-3
    p, _ = model.forward_kinematics(q_star.tolist())
    assert np.linalg.norm(np.array(p) - np.array(p_d)) < 1e-6


def test_a_posture_held_against_a_band_counts_as_out_of_it():
    """
    Baxter's right arm (7 joints): a posture held against a band is taken, not passed by.

    The band's wall weight leaves a joint pulled against it a little inside (here about 1e-5
    rad of its 0.133 rad band). Counted as in the band, that posture lost to a worse branch
    (with the Euclidean distance, one 5.8 rad from the arm instead of 3.0). Up to
    ``BAND_DEPTH_TOLERANCE_RAD`` deep it counts as out: q* is the nearer posture, at the wall.
    """
    import numpy as np
    from quat_jt_controller import inverse_kinematics as gc
    from quat_jt_controller.model import RobotModel
    from quat_jt_runtime.joints import chain_joints
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('baxter_description/urdf/baxter.urdf').read_text()
    model = RobotModel(urdf, 'base', 'right_wrist', chain_joints(urdf, 'base', 'right_wrist'))
    margin = 0.133
    q_start = np.array([0.364, -1.1147, -1.5346, 1.2606, -0.7161, -0.9223, 1.0257])
    q_d, p_d = goal_at(model, [0.794, -1.7144, 0.6153, 0.7501, -0.356, 1.1133, 0.1547])
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)

    def search():
        return gc.goal_configuration(model, q_start, q_d, p_d, POSE, margin)
    q_star = search()
    gap = np.minimum(q_star - lower, upper - q_star)
    assert gap.min() > margin - gc.BAND_DEPTH_TOLERANCE_RAD  # out of the bands, by the rule
    assert gap.min() < margin + 1e-6  # against a band's wall: where the cost holds it
    p, _ = model.forward_kinematics(q_star.tolist())
    assert np.linalg.norm(np.array(p) - np.array(p_d)) < 1e-6
    tolerance = gc.BAND_DEPTH_TOLERANCE_RAD
    try:  # any depth counted as in the band: the search passes it by for a farther branch
        gc.BAND_DEPTH_TOLERANCE_RAD = 0.0
        strict = search()
    finally:
        gc.BAND_DEPTH_TOLERANCE_RAD = tolerance
    w = gc.travel_weights(model)
    travel = [np.sqrt(np.sum(w * (q - q_start) ** 2)) for q in (q_star, strict)]
    deep = np.minimum(strict - lower, upper - strict).min() < margin - tolerance
    assert deep or travel[1] > travel[0] + 1.0  # a branch deep in a band, or a farther one


def test_the_goal_configuration_is_nearest_in_the_joints_travel_time():
    """
    Romeo's left arm (8 joints): its wrist roll turns at 1.1 rad/s, its elbow at 3.7.

    Nearest in the Euclidean distance, q* took the wrist roll 2.5 rad (2.2 s at its limit);
    nearest in the travel's time (each joint's travel over its velocity limit, travel_weights),
    the elbow takes more of the way and the slowest joint's time halves.
    """
    import numpy as np
    from quat_jt_controller import inverse_kinematics as gc
    from quat_jt_controller.model import RobotModel
    from quat_jt_runtime.joints import chain_joints
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('romeo_description/urdf/romeo_small.urdf').read_text()
    model = RobotModel(urdf, 'base_link', 'l_wrist', chain_joints(urdf, 'base_link', 'l_wrist'))
    velocity = np.array(model.velocity_limits)
    q_start = np.array([0.4249, -0.0151, 0.3659, 1.5192, -0.6054, 0.0564, 0.1735, 0.2318])
    q_d, p_d = goal_at(model, [-0.1212, 0.2076, 0.2908, -0.2248, -0.6037, -3.0278, -0.2395,
                               0.1781])

    def seconds(weights):
        kept = gc.travel_weights
        try:
            if weights is not None:
                gc.travel_weights = weights
            q_star = gc.goal_configuration(model, q_start, q_d, p_d, POSE, 0.044,
                                           q_preferred=model.middle_of_ranges(),
                                           posture_weight=0.1)
        finally:
            gc.travel_weights = kept
        p, _ = model.forward_kinematics(q_star.tolist())
        assert np.linalg.norm(np.array(p) - np.array(p_d)) < 1e-6
        return float(np.max(np.abs(q_star - q_start) / velocity))
    weights = gc.travel_weights(model)
    assert weights.max() == 1.0 and weights[5] == 1.0  # the wrist roll is the slowest joint
    in_time, euclidean = seconds(None), seconds(lambda m: np.ones(m.n))
    assert in_time < 0.7 * euclidean


def test_the_travel_time_reads_placeholder_limits_as_none():
    """
    Alex's right arm: 100 rad/s on its shoulder and elbow (placeholders), 25 on its wrist.

    A limit no drive has says nothing of the joint's speed: its travel counts as that of a
    joint without a limit (2 pi rad/s), not as 100 rad/s, which would make the shoulder's
    radians all but free.
    """
    import math

    import numpy as np
    from quat_jt_controller.inverse_kinematics import travel_weights
    from quat_jt_controller.model import RobotModel
    from quat_jt_controller.shaping import DEFAULT_SPEED_CAP_RAD_S, PLAUSIBLE_SPEED_RAD_S
    from quat_jt_runtime.joints import chain_joints
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('alex_description/urdf/alex_sake_hands.urdf').read_text()
    model = RobotModel(urdf, 'Torso', 'RightGripperYawLink',
                       chain_joints(urdf, 'Torso', 'RightGripperYawLink'))
    velocity = np.array(model.velocity_limits)
    placeholder = velocity > PLAUSIBLE_SPEED_RAD_S
    assert placeholder.any() and not placeholder.all()
    weights = travel_weights(model)
    slowest = min(DEFAULT_SPEED_CAP_RAD_S, velocity[~placeholder].min())
    np.testing.assert_allclose(weights[placeholder], (slowest / DEFAULT_SPEED_CAP_RAD_S) ** 2)
    np.testing.assert_allclose(weights[~placeholder], (slowest / velocity[~placeholder]) ** 2)
    assert math.isclose(weights.max(), 1.0)


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


def assert_reaches_within_limits(model, task, q_star, q_d, p_d):
    """q* lies within the joint limits and reaches the goal to the model's precision."""
    import numpy as np
    from quat_jt_controller.inverse_kinematics import POLISHED_TOLERANCE
    assert q_star is not None
    assert np.all(q_star >= np.array(model.position_lower))
    assert np.all(q_star <= np.array(model.position_upper))
    p, R = model.forward_kinematics(q_star.tolist())
    _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
    assert np.linalg.norm(e) < POLISHED_TOLERANCE
    if task is POSE:
        assert np.linalg.norm(np.subtract(p, p_d)) < POLISHED_TOLERANCE


def ur3_model():
    """Return UR3: 6 joints spanning +-2 pi (the elbow +-pi), five of them full turns."""
    from quat_jt_controller.model import RobotModel
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('ur_description/urdf/ur3_robot.urdf').read_text()
    return RobotModel(urdf, 'world', 'wrist_3_link')


def so100_model():
    """Return the SO-100's 5 joints: a pose goal's J_G has more rows than columns."""
    from quat_jt_controller.model import RobotModel
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('so_arm_description/urdf/so100.urdf').read_text()
    return RobotModel(urdf, 'base', 'gripper', ('shoulder_pan', 'shoulder_lift', 'elbow_flex',
                                                'wrist_flex', 'wrist_roll'))


def small_five_joint_model():
    """Return a 5-joint arm of two continuous and three revolute (+-2 rad) joints."""
    from quat_jt_controller.model import RobotModel
    from robots import small_arm_urdf
    return RobotModel(small_arm_urdf(), 'base_link', 'tool')


@pytest.mark.parametrize('make_model', [ur3_model, so100_model, small_five_joint_model])
def test_the_pose_of_any_configuration_within_the_limits_is_found(make_model):
    """
    Goals that are the forward kinematics of random configurations, from random starts.

    Each is exactly reachable within the limits, so q* is found, within the limits, to the
    model's precision: on full-turn ranges (starts and goals up to 2 pi apart) and on 5-joint
    arms, where the pose's six rows are met in least squares.
    """
    import numpy as np
    from quat_jt_controller.inverse_kinematics import goal_configuration, sampling_box
    model = make_model()
    lo, hi = sampling_box(model)
    rng = np.random.default_rng(3)
    for _ in range(6):
        q_goal, q_start = rng.uniform(lo, hi), rng.uniform(lo, hi)
        q_d, p_d = goal_at(model, q_goal.tolist())
        q_star = goal_configuration(model, q_start, q_d, p_d, POSE, 0.1)
        assert_reaches_within_limits(model, POSE, q_star, q_d, p_d)


def test_the_search_holds_a_joint_at_its_stop_and_moves_the_others():
    """A goal whose configuration has a joint at its stop: the search reaches it from afar."""
    import numpy as np
    from quat_jt_controller.inverse_kinematics import RESIDUAL_TOLERANCE, solve_ik
    model = small_five_joint_model()
    q_goal = np.array([0.4, 2.0, -1.0, 0.3, -0.6])  # joint 2 at its upper stop
    q_d, p_d = goal_at(model, q_goal.tolist())
    q, residual, _ = solve_ik(model, [0.1, 1.2, -0.2, 0.0, 0.0], q_d, p_d, POSE)
    assert residual < RESIDUAL_TOLERANCE
    assert np.all(q >= np.array(model.position_lower))
    assert np.all(q <= np.array(model.position_upper))


def test_a_full_turn_joint_ends_on_the_turn_nearest_the_start():
    """solve_ik wraps a +-2 pi joint to the angle within its range nearest where it started."""
    import numpy as np
    from quat_jt_controller.inverse_kinematics import solve_ik
    model = ur3_model()
    q_goal = np.array([4.5, -1.2, 1.0, -1.5, 1.3, -5.0])
    q_d, p_d = goal_at(model, q_goal.tolist())
    q, residual, _ = solve_ik(model, q_goal + 0.05, q_d, p_d, POSE)
    assert residual < 1e-4
    assert np.abs(q - q_goal).max() < 1e-3  # not q_goal - 2 pi: the same angles, nearest


def test_a_goal_reached_only_at_a_singularity_gets_q_star_and_the_a2_warning():
    """Rz(0.8) is reached only at the wrist's q2 = 0: q* is given, and A2 is said not to hold."""
    from quat_jt_controller.goal_check import configuration_verdict
    from quat_jt_controller.inverse_kinematics import search_goal_configuration
    model = wrist_model()
    rz = (math.cos(0.4), 0.0, 0.0, math.sin(0.4))
    search = search_goal_configuration(model, [0.5, 0.5, 0.5], rz, (0, 0, 0), ORI, 0.1)
    assert_reaches_within_limits(model, ORI, search.q_star, rz, (0, 0, 0))
    assert not search.regular and search.sigma_min < 0.05
    verdict = configuration_verdict(search)
    assert 'singular' in verdict and 'A2' in verdict, verdict


def test_an_unreachable_goal_gets_no_q_star_and_a_message_that_says_so():
    """A position past the arm's reach: no q*, and the verdict says what was tried and found."""
    from quat_jt_controller.goal_check import configuration_verdict
    from quat_jt_controller.inverse_kinematics import search_goal_configuration
    model = xarm6_model()
    q_d, _ = goal_at(model, [0.0, -0.5, -1.0, 0.0, 1.5, 0.0])
    search = search_goal_configuration(model, [0.0, -0.5, -1.0, 0.0, 1.5, 0.0], q_d,
                                       (1.2, 0.0, 0.5), POSE, 0.1, starts_range=(4, 4))
    assert search.q_star is None and search.starts == 4
    assert search.best_residual > 0.1  # 1.2 m out: the nearest pose is far
    verdict = configuration_verdict(search)
    assert 'no joint configuration within the limits' in verdict, verdict
    assert 'from 4 IK starts' in verdict and 'A1' in verdict, verdict
    assert 'no goal configuration q*' in verdict, verdict


def test_a_near_singular_posture_is_slid_along_the_self_motion_until_regular():
    """
    docs/lyapunov.md, section 9: q* leaves a near-singular stretch of the self-motion.

    Here the Panda's posture nearest the measured q has sigma_min below SINGULAR_SIGMA_MIN;
    along its self-motion it becomes regular within 2 rad. Before, the search passed it over
    for a regular branch 5.6 rad away, 4.4 rad round joint 1.
    """
    import numpy as np
    from quat_jt_controller.inverse_kinematics import (
        polish, posture, POLISHED_TOLERANCE, regular_posture, search_goal_configuration,
        sigma_min, SINGULAR_SIGMA_MIN, solve_ik)
    model = panda_model()
    q_now = np.array([2.11, -0.82, 1.52, -2.41, 0.06, 0.77, 0.88])
    q_d, p_d = goal_at(model, [1.58, -0.21, 2.12, -0.79, -0.75, 2.1, 1.17])
    margin = 0.15
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    q_ik = polish(model, solve_ik(model, q_now, q_d, p_d, POSE)[0], q_d, p_d, POSE)
    nearest = posture(model, q_ik, q_d, p_d, POSE, q_now, model.middle_of_ranges(), 0.1,
                      margin)
    assert sigma_min(model, nearest, POSE) < SINGULAR_SIGMA_MIN
    regular = regular_posture(model, nearest, q_d, p_d, POSE, margin)
    assert regular is not None and sigma_min(model, regular, POSE) >= SINGULAR_SIGMA_MIN
    p, R = model.forward_kinematics(regular.tolist())
    _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
    assert np.linalg.norm(e) < POLISHED_TOLERANCE
    assert np.linalg.norm(np.subtract(p, p_d)) < POLISHED_TOLERANCE
    assert np.all(regular >= lower + margin) and np.all(regular <= upper - margin)
    assert np.abs(regular - nearest).max() < 2.0
    found = search_goal_configuration(model, q_now, q_d, p_d, POSE, margin,
                                      q_preferred=model.middle_of_ranges(), posture_weight=0.1)
    assert found.regular
    assert np.linalg.norm(found.q_star - q_now) < 4.0  # not the branch round joint 1
    # an arm without self-motion has nothing to slide along: its wrist singularity stays
    xarm = xarm6_model()
    q_x = [0.1, 0.2, -0.3, 0.4, 0.0, 0.6]
    x_d, x_p = goal_at(xarm, q_x)
    assert sigma_min(xarm, q_x, POSE) < SINGULAR_SIGMA_MIN
    assert regular_posture(xarm, np.array(q_x), x_d, x_p, POSE) is None


@pytest.mark.parametrize('task', [POSE, Task.POSITION])
def test_the_climb_to_a_regular_posture_stays_on_the_goal_and_within_the_limits(task):
    """
    Near-singular Panda configurations, no band margin: what the climb returns is regular.

    A step clipped at a joint limit leaves the goal; such a step is not taken, so the result
    is on the goal, within the limits and regular, or None.
    """
    import numpy as np
    from quat_jt_controller.inverse_kinematics import (
        POLISHED_TOLERANCE, regular_posture, sigma_min, SINGULAR_SIGMA_MIN)
    model = panda_model()
    rng = np.random.default_rng(0)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    tried = climbed = 0
    while tried < 20:
        q = rng.uniform(lower, upper)
        if sigma_min(model, q, task) >= SINGULAR_SIGMA_MIN:
            continue
        tried += 1
        q_d, p_d = goal_at(model, q.tolist())
        out = regular_posture(model, q, q_d, p_d, task)
        if out is None:
            continue
        climbed += 1
        assert np.all(out >= lower) and np.all(out <= upper)
        assert sigma_min(model, out, task) >= SINGULAR_SIGMA_MIN
        p, R = model.forward_kinematics(out.tolist())
        assert np.linalg.norm(np.subtract(p, p_d)) < POLISHED_TOLERANCE
        if task is POSE:
            _, e = quat.orientation_error(quat.from_rotation_matrix(R), q_d)
            assert np.linalg.norm(e) < POLISHED_TOLERANCE
    assert climbed >= 3  # not vacuous

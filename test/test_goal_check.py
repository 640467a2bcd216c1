"""The A1 / A2 goal check (quat_jt_controller.goal_check) on the wrist, the xArm6, a small arm."""
import math
import re

import numpy as np
import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_check import check_goal, heavy_warning
from quat_jt_controller.inverse_kinematics import sigma_min, solve_ik
from quat_jt_controller.model import RobotModel, SINGULAR_SIGMA_MIN
from robots import Q_DESIRED, small_arm_urdf, wrist_model, xarm6_model, XARM6_URDF

pytestmark = pytest.mark.unit

ORI, POSE, POSITION = Task.ORIENTATION, Task.POSE, Task.POSITION


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


def test_a_goal_where_gravity_takes_most_of_an_effort_limit_is_warned_of():
    """The design reserves 0.75 x the effort for gravity: a goal past it is named."""
    urdf = XARM6_URDF.read_text()
    joint2 = urdf.index('<limit effort="50.0" lower="-2.059"')
    weak = RobotModel(urdf[:joint2] + urdf[joint2:].replace('effort="50.0"', 'effort="12.0"', 1),
                      'link_base', 'link6')
    assert weak.effort_limits[1] == 12.0
    light, heavy = [0.0, -0.5, -1.0, 0.0, 1.5, 0.0], [0.0, 1.0, -1.0, 0.0, 1.0, 0.0]
    assert abs(weak.gravity(light)[1]) < 9.0 < abs(weak.gravity(heavy)[1])  # 0.75 x 12 N m
    assert check_goal(weak, light, *goal_at(weak, light), POSE) == ''
    warning = check_goal(weak, heavy, *goal_at(weak, heavy), POSE)
    assert re.search(r'gravity takes more than 0.75 x the effort limit \(joint2 16.5 of 12 N m\)',
                     warning), warning
    assert check_goal(xarm6_model(), heavy, *goal_at(weak, heavy), POSE) == ''
    no_limit = urdf[:joint2] + urdf[joint2:].replace('effort="50.0"', 'effort="0"', 1)
    unlimited = RobotModel(no_limit, 'link_base', 'link6')
    assert heavy_warning(unlimited, heavy) == ''  # 0: no effort limit, as the clamp has it


def scaled_small_arm(scale):
    """Return the small arm of the tests, each joint origin ``scale`` x as far from its parent."""
    def origin(match):
        return 'origin xyz="' + ' '.join(str(scale * float(v)) for v in match.group(1).split())
    return RobotModel(re.sub(r'origin xyz="([^"]*)', origin, small_arm_urdf()),
                      'base_link', 'tool')


def test_the_arms_length_is_its_chain_from_the_first_joint_to_the_tip():
    """The small arm: four links of 0.2 m from joint 1 to the tip (0.1 m below it excluded)."""
    for scale in (0.1, 1.0, 10.0):
        assert scaled_small_arm(scale).length_m == pytest.approx(4 * 0.2 * scale)


@pytest.mark.parametrize('task', [POSITION, POSE])
def test_the_near_singular_test_is_the_same_for_an_arm_of_any_size(task):
    """
    sigma_min(J_p) in m/rad grows with the arm; per unit of its length it does not.

    The same configuration of the same arm drawn 0.1x, 1x and 10x as large: the raw
    sigma_min of its position rows scales with it, the one compared with SINGULAR_SIGMA_MIN
    does not, and the goal check's verdict on the goal there is the same. A bend of 0.1 rad
    near full stretch is near-singular at every size (a fixed threshold in m/rad would have
    passed it on the large arm); a bend of 1.2 rad is regular at every size.
    """
    arms = {scale: scaled_small_arm(scale) for scale in (0.1, 1.0, 10.0)}
    for bend, singular in ((0.1, True), (1.2, False)):
        q = [0.3, -0.4, bend, 0.2, 0.1]
        raw, scaled, verdicts = {}, {}, set()
        for scale, model in arms.items():
            _, _, J = model.kinematics(q)
            raw[scale] = np.linalg.svd(np.array(J)[:3], compute_uv=False)[-1]
            scaled[scale] = sigma_min(model, q, task)
            p, R = model.forward_kinematics(q)
            verdicts.add('singular' in check_goal(model, [0.0, 0.5, 0.5, 0.0, 0.0],
                                                  quat.from_rotation_matrix(R), p, task))
        assert raw[10.0] == pytest.approx(100.0 * raw[0.1])
        assert scaled[10.0] == pytest.approx(scaled[0.1]) == pytest.approx(scaled[1.0])
        assert (scaled[1.0] < SINGULAR_SIGMA_MIN) == singular
        assert verdicts == {singular}, (bend, verdicts)
        if singular:  # a fixed threshold in m/rad would call the large arm regular here
            assert raw[10.0] > SINGULAR_SIGMA_MIN


def test_the_orientation_task_keeps_its_dimensionless_rows():
    """J_o is in rad/rad: the wrist's near-singular test reads sigma_min(J_o) as it is."""
    model = wrist_model()
    q = [0.3, 0.02, -0.5]
    _, _, J = model.kinematics(q)
    assert sigma_min(model, q, ORI) == pytest.approx(
        np.linalg.svd(np.array(J)[3:], compute_uv=False)[-1], rel=1e-12)

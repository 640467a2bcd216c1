"""The velocity of a streamed goal (goal_motion) and its joint velocity at q* (goal_check)."""
import math

import numpy as np
import pytest
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_motion import GoalVelocityEstimator, MAX_GAP_S, MIN_HOLD_S
from quat_jt_controller.inverse_kinematics import configuration_velocity, goal_configuration
from robots import wrist_model, xarm6_model

pytestmark = pytest.mark.unit

AXIS = (0.48, 0.36, 0.8)


def turned(angle: float, center=paper.Q_DESIRED) -> quat.Quaternion:
    s = math.sin(0.5 * angle)
    return quat.multiply((math.cos(0.5 * angle), AXIS[0] * s, AXIS[1] * s, AXIS[2] * s), center)


def test_rotation_vector_is_axis_times_angle_the_short_way():
    for angle in (1e-9, 0.3, 3.0):
        s = math.sin(0.5 * angle)
        for sign in (1.0, -1.0):  # q and -q: the same rotation
            w = quat.rotation_vector(sign * math.cos(0.5 * angle),
                                     [sign * a * s for a in AXIS])
            np.testing.assert_allclose(w, [a * angle for a in AXIS], atol=1e-12)


@pytest.mark.parametrize('rate_hz', [30.0, 100.0, 1000.0])
def test_a_steady_stream_gives_its_angular_velocity(rate_hz):
    estimator = GoalVelocityEstimator(with_position=False)
    omega = 0.8  # rad/s about AXIS, in the base frame
    out = [estimator.update(100.0 + k / rate_hz, turned(omega * k / rate_hz), (0, 0, 0))
           for k in range(int(0.2 * rate_hz))]
    assert out[0] is None  # one goal: fixed
    np.testing.assert_allclose(out[-1], [omega * a for a in AXIS], atol=1e-9)
    assert estimator.hold_s() == pytest.approx(max(MIN_HOLD_S, 3.0 / rate_hz))


def test_the_pose_task_gives_linear_then_angular_velocity():
    estimator = GoalVelocityEstimator(with_position=True)
    for k in range(10):
        t = 0.01 * k
        nu = estimator.update(5.0 + t, turned(0.5 * t), (0.1 * t, -0.2 * t, 0.0))
    np.testing.assert_allclose(nu, [0.1, -0.2, 0.0] + [0.5 * a for a in AXIS], atol=1e-9)


def test_unstamped_repeated_and_late_goals_start_again_as_fixed_goals():
    estimator = GoalVelocityEstimator(with_position=False)
    for k in range(5):
        estimator.update(1.0 + 0.01 * k, turned(0.01 * k), (0, 0, 0))
    assert estimator.update(1.05, turned(0.05), (0, 0, 0)) is not None
    assert estimator.update(0.0, turned(0.06), (0, 0, 0)) is None  # not stamped
    estimator.update(2.0, turned(0.0), (0, 0, 0))
    assert estimator.update(2.0 + 0.05, turned(0.05), (0, 0, 0)) is not None
    assert estimator.update(2.0 + 0.05, turned(0.05), (0, 0, 0)) is None  # not newer
    estimator.update(3.0, turned(0.0), (0, 0, 0))
    assert estimator.update(3.0 + MAX_GAP_S + 0.01, turned(0.1), (0, 0, 0)) is None  # late


@pytest.mark.parametrize('robot, task', [('wrist', Task.ORIENTATION), ('xarm6', Task.POSE)])
def test_the_joint_velocity_at_q_star_gives_the_goal_velocity(robot, task):
    model = wrist_model() if robot == 'wrist' else xarm6_model()
    q_goal = [0.3, 0.9, -0.4] if robot == 'wrist' else [0.2, -0.4, -1.1, 0.2, 1.4, 0.3]
    p, R = model.forward_kinematics(q_goal)
    q_star = goal_configuration(model, q_goal, quat.from_rotation_matrix(R), p, task)
    nu = np.array([0.05, -0.02, 0.03, 0.4, -0.3, 0.2])[-task.dim:]
    qdot = configuration_velocity(model, q_star, nu, task)
    J = np.array(model.kinematics(q_star.tolist())[2])
    np.testing.assert_allclose((J[3:] if task is Task.ORIENTATION else J) @ qdot, nu,
                               atol=1e-9)

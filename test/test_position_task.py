"""
The position task (y = p_d - p, J = J_p): any reachable point on an arm with 4 or 5 joints.

* The law: the potential torque is -grad_q U_a of the position rows alone (no Q, no e), the
  tick reports no orientation error (e = 0, eta_e = 1), and the gains have three rows.
* The design finishes on a 4-joint arm, the goal check and q* find a reachable point, and the
  ideal loop (RK4) with the designed gains reaches it with V never increasing.
* Bad input is still refused: a non-finite position, gains of the wrong size; a goal's
  orientation is not read (all zeros accepted), and a goal in a link is placed in the base.
"""
import dataclasses
import functools
import math

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import gain_design as gd
from quat_jt_controller import gain_output as go
from quat_jt_controller import shaping as sh
from quat_jt_controller.goal_check import check_goal
from quat_jt_controller.goal_frames import GoalFrames
from quat_jt_controller.inverse_kinematics import goal_configuration
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop
from quat_jt_controller.regulator import Goal, Regulator
from robots import small_arm_urdf

pytestmark = pytest.mark.unit

POS = cl.Task.POSITION
FOUR = ('continuous', 'revolute', 'revolute', 'revolute')
Q_GOAL = (0.4, 0.6, -0.9, 0.3)  # the point reached here is the goal
Q_START = (-0.3, -0.2, 0.5, 0.0)


@functools.lru_cache(maxsize=None)
def four_joint_arm() -> RobotModel:
    return RobotModel(small_arm_urdf(FOUR), 'base_link', 'tool')


@functools.lru_cache(maxsize=None)
def four_joint_design() -> gd.Design:
    return gd.design(four_joint_arm(), POS)


def goal_point() -> tuple:
    p, _ = four_joint_arm().forward_kinematics(list(Q_GOAL))
    return tuple(p)


def test_the_task_has_three_position_rows_and_no_orientation():
    assert POS.dim == 3 and POS.has_position and not POS.has_orientation
    J = [[float(6 * i + j) for j in range(4)] for i in range(6)]
    assert POS.rows(J) == J[:3]
    assert cl.Task.ORIENTATION.rows(J) == J[3:] and cl.Task.POSE.rows(J) == J


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_the_torque_is_minus_the_gradient_of_the_position_potential(potential):
    model = four_joint_arm()
    gains = cl.Gains.create(potential, (3.0, 4.0, 5.0), (1.0,) * 4, (20.0, 30.0, 40.0), POS, 4,
                            gravity_compensation=False)
    # a large-error gain has no orientation error to act on: it changes nothing
    reg = Regulator(model, POS, gains, [math.inf] * 4, Goal.at_position(goal_point()),
                    sh.Shaping.create(4, large_error_gain=5.0))
    q = np.array(Q_START)
    out = reg.update(q.tolist(), [0.0] * 4)
    p, _, J = model.kinematics(q.tolist())
    y = np.subtract(goal_point(), p)
    assert out.y_tilde == pytest.approx(tuple(y), abs=1e-12)
    slope = np.array(gains.kp) * (y if potential == 'quadratic'
                                  else np.tanh(np.array(gains.lam) * y))
    np.testing.assert_allclose(out.tau_nm, np.array(J)[:3].T @ slope, atol=1e-12)
    h = 1e-6
    grad = [(reg.potential_energy((q + h * np.eye(4)[j]).tolist())
             - reg.potential_energy((q - h * np.eye(4)[j]).tolist())) / (2 * h)
            for j in range(4)]
    np.testing.assert_allclose(out.tau_potential_nm, -np.array(grad), atol=1e-6)
    assert out.eta_e == 1.0 and out.orientation_error == (0.0, 0.0, 0.0)
    assert out.orientation_error_norm == 0.0
    assert out.position_error_norm_m == pytest.approx(float(np.linalg.norm(y)))


def test_the_friction_fade_reads_the_position_error_alone():
    shaping = sh.Shaping.create(4, friction_compensation=(0.1,) * 4)
    band = shaping.friction_position_band_m
    assert sh.fade((2.0 * band, 0.0, 0.0), shaping, position_only=True) == 1.0
    assert sh.fade((0.4 * band, 0.0, 0.0), shaping, position_only=True) == 0.0


def test_the_design_finishes_with_three_rows_and_every_joint_damped():
    d = four_joint_design()
    assert d.task is POS and len(d.kp) == 3 and len(d.lam) == 3 and len(d.kv) == 4
    assert min(d.kv) > 0.0 and min(d.shaping.configuration_gain) > 0.0
    assert max(d.figures['spectral_radius'].values()) < 1.0
    text = go.to_yaml(d)
    assert 'task: position' in text and 'K_p, x, y, z (N/m)' in text


def test_the_goal_check_finds_q_star_for_a_reachable_point_nearest_the_arm():
    model, p_d = four_joint_arm(), goal_point()
    any_orientation = (0.0, 0.0, 0.0, 0.0)  # not read by the position task
    assert check_goal(model, Q_START, any_orientation, p_d, POS) == ''
    q_star = goal_configuration(model, Q_START, any_orientation, p_d, POS)
    assert q_star is not None
    p, _ = model.forward_kinematics(q_star.tolist())
    assert np.linalg.norm(np.subtract(p, p_d)) < 1e-9
    # the last joint turns about an axis through the tip: q* leaves it where the arm is
    assert q_star[3] == pytest.approx(Q_START[3], abs=1e-6)
    far = (5.0, 0.0, 0.0)  # beyond the arm's reach
    assert 'assumption A1 may not hold' in check_goal(model, Q_START, any_orientation, far, POS,
                                                      max_starts=3)
    assert goal_configuration(model, Q_START, any_orientation, far, POS,
                              starts_range=(3, 3)) is None


def test_the_ideal_loop_reaches_the_point_with_v_never_increasing():
    model, d, p_d = four_joint_arm(), four_joint_design(), goal_point()
    q_star = goal_configuration(model, Q_START, (1.0, 0.0, 0.0, 0.0), p_d, POS,
                                d.shaping.joint_limit_margin_rad)
    shaping = dataclasses.replace(d.shaping, friction_learning_limit_nm=())  # no friction here
    loop = ClosedLoop(model, d.gains('tanh'), POS, (1.0, 0.0, 0.0, 0.0), p_d, shaping=shaping,
                      q_star=q_star)
    traj = loop.run(Q_START, 1.5, dt_s=2e-3)
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert traj.error_norm[0] > 0.1 and traj.error_norm[-1] < 1e-3


def test_a_position_goal_ignores_the_orientation_and_refuses_a_bad_position():
    model = four_joint_arm()
    frames = GoalFrames(model, POS)
    goal = frames.goal('base_link', (0.0, 0.0, 0.0, 0.0), (0.3, 0.1, 0.2), None)
    assert goal.p_desired_base == (0.3, 0.1, 0.2) and goal.q_desired_base == (1.0, 0.0, 0.0, 0.0)
    assert frames.goal('', (math.nan,) * 4, (0.3, 0.1, 0.2), None) == goal
    with pytest.raises(ValueError, match='finite'):
        frames.goal('base_link', (0.0, 0.0, 0.0, 1.0), (0.3, math.nan, 0.2), None)
    # a point given in the tip link: the tip's position plus the point turned into the base
    p_tip, R_tip = model.link_pose('tool', list(Q_START))
    placed = frames.goal('tool', (0.0, 0.0, 0.0, 0.0), (0.1, 0.0, 0.0), list(Q_START))
    np.testing.assert_allclose(placed.p_desired_base,
                               np.add(p_tip, np.array(R_tip) @ [0.1, 0.0, 0.0]), atol=1e-12)
    assert goal.describe(True, False).startswith('position (0.3, 0.1, 0.2)')


def test_gains_of_the_wrong_size_are_refused():
    with pytest.raises(cl.GainsError, match='kp must have 3 values'):
        cl.Gains.create('tanh', (1.0,) * 6, (1.0,) * 4, (1.0,) * 6, POS, 4)
    pose_gains = cl.Gains.create('tanh', (1.0,) * 6, (1.0,) * 4, (1.0,) * 6, cl.Task.POSE, 4)
    with pytest.raises(cl.GainsError, match='for the position task'):
        Regulator(four_joint_arm(), POS, pose_gains)


def test_a_stream_of_points_has_a_velocity_of_three_rows():
    from quat_jt_controller.goal_motion import GoalVelocityEstimator
    motion = GoalVelocityEstimator(True, with_orientation=False)
    identity = (1.0, 0.0, 0.0, 0.0)
    assert motion.update(1.0, identity, (0.0, 0.0, 0.0)) is None
    v = motion.update(1.05, identity, (0.01, 0.0, -0.005))
    assert v == pytest.approx((0.2, 0.0, -0.1))

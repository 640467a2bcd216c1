"""
ROS-free: full pose regulation (Section 4, Eqs. 24 and 32) of the 6-DOF xArm6.

With the gains and extensions of config/xarm6_controller.yaml (designed by
quat_jt_controller.gain_design), from the non-singular start of config/xarm6_sim.yaml, with
both potentials:

* the ideal closed loop (Eq. 25 / 33) reaches a reachable goal (assumption A1) to < 1 mm and
  ||e|| < 0.01 and its Lyapunov function (Eq. 27 / 34, with the extensions' terms) never
  increases (Eq. 28 / 35);
* the loop linearised at the goal stays stable when sampled at 1 kHz and delayed 1..6 steps;
* the loop as ROS runs it (sampled, delayed, clamped to the effort limits, PyBullet's
  integrator, the demo's friction) holds the goal to < 1 mm and ||e|| < 0.01;
* the config and launch files are consistent with the model.
"""
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_runtime.resources import config_parameters
from robots import xarm6_model, XARM6_URDF
from sampled_loop import goal_of, linearized_spectral_radius
from sampled_loop import time_constant_s, xarm6_gains, xarm6_shaping
from wrist_sim.simulator import RobotSimulator

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parent.parent
POTENTIALS = ('quadratic', 'tanh')
POSITION_TOL_M = 1e-3  # the hold tolerances
ORIENTATION_TOL = 1e-2  # ||e|| of Eq. (10)
# Reachable goals: the arm's own pose at these joint angles (A1), regular there (A2).
Q_GOAL_NEAR = (0.2, -0.4, -1.1, 0.2, 1.4, 0.3)  # 0.10 m and 0.25 rad from the start
Q_GOAL_FAR = (0.5, -0.1, -1.3, 0.4, 1.2, 0.6)  # 0.26 m and 0.48 rad from the start


@pytest.fixture(scope='module')
def model():
    return xarm6_model()


@pytest.fixture(scope='module')
def sim_params():
    return config_parameters('xarm6_sim.yaml')


def sigma_min(model, q) -> float:
    _, _, J = model.kinematics(list(q))
    return float(np.linalg.svd(np.array(J), compute_uv=False)[-1])


def test_config_files_match_the_model(model, sim_params):
    ctrl = config_parameters('xarm6_controller.yaml')
    assert ctrl['task'] == 'pose'
    assert (ctrl['base_link'], ctrl['tip_link']) == ('link_base', 'link6')
    assert tuple(ctrl['joints']) == model.joint_names == tuple(sim_params['joints'])
    for potential in POTENTIALS:
        gains = xarm6_gains(potential)  # validated by Gains.create for the pose task
        assert len(gains.kp) == len(gains.lam) == 6 and len(gains.kv) == 6
    q0 = np.array(sim_params['initial_positions'])
    assert np.all(q0 > np.array(model.position_lower))
    assert np.all(q0 < np.array(model.position_upper))
    assert sigma_min(model, q0) > 0.1, 'the start must be non-singular'
    assert sigma_min(model, [0.0] * 6) < 1e-6  # the zero configuration is singular
    for name in ('viscous_friction', 'coulomb_friction'):
        assert len(sim_params[name]) == 6 and min(sim_params[name]) >= 0.0


def test_pose_task_rejects_three_element_gain_vectors():
    ctrl = config_parameters('xarm6_controller.yaml')
    with pytest.raises(cl.GainsError, match=r'kp must have 6 values, got 3'):
        cl.Gains.create('tanh', ctrl['kp'][3:], ctrl['kv'], ctrl['lambda'], cl.Task.POSE, 6)
    with pytest.raises(cl.GainsError, match=r'lambda must have 6 values, got 3'):
        cl.Gains.create('tanh', ctrl['kp'], ctrl['kv'], ctrl['lambda'][:3], cl.Task.POSE, 6)


@pytest.mark.parametrize('potential', POTENTIALS)
def test_ideal_loop_reaches_goal_and_lyapunov_never_increases(model, sim_params, potential):
    q0 = sim_params['initial_positions']
    p_d, q_d = goal_of(model, Q_GOAL_NEAR)
    assert sigma_min(model, Q_GOAL_NEAR) > 0.1  # A2: no self-motion at the goal
    # The ideal loop has no friction, so no friction compensation either: without friction to
    # cancel, the compensation would feed energy in (docs/lyapunov.md, section 4).
    shaping = dataclasses.replace(xarm6_shaping(), friction_compensation_nm=())
    loop = ClosedLoop(model, xarm6_gains(potential), cl.Task.POSE, q_d, p_d, shaping=shaping,
                      q_star=Q_GOAL_NEAR)
    traj = loop.run(q0, 5.0)

    y0, _, _ = loop.error(q0)
    assert np.linalg.norm(y0[:3]) > 0.09 and np.linalg.norm(y0[3:]) > 0.1
    y, _, _ = loop.error(traj.q_rad[-1])
    assert np.linalg.norm(y[:3]) < POSITION_TOL_M / 10, y
    assert np.linalg.norm(y[3:]) < ORIENTATION_TOL / 10, y
    assert np.abs(traj.qdot_rad_s[-1]).max() < 1e-2
    # Eq. (28) / (35): dV/dt = -qdot^T K_v qdot <= 0, up to the RK4 error.
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert traj.lyapunov[-1] < 1e-3 * traj.lyapunov[0]


@pytest.mark.parametrize('potential', POTENTIALS)
def test_linearised_sampled_loop_is_stable_with_up_to_six_steps_of_delay(model, potential):
    """The margin behind the gains: a 1 kHz loop over ROS adds one or more steps of delay."""
    gains, shaping = xarm6_gains(potential), xarm6_shaping()
    for q_goal in (Q_GOAL_NEAR, Q_GOAL_FAR):
        rho = [linearized_spectral_radius(model, q_goal, gains, d, shaping=shaping)
               for d in range(1, 7)]
        assert max(rho) < 1.0, rho
        assert time_constant_s(rho[0]) < 1.5, rho
    # The link-6 mode (8e-5 kg m^2) is what limits the damping (gain_design's speed rule):
    # twice the largest damping stable on joint 6 diverges with one step of delay, as K_v
    # alone; with the inertial damping on, the tick brings that mode down to beta
    # (docs/lyapunov.md, section 10) and the loop is stable again.
    inertia_6 = model.mass_matrix(list(Q_GOAL_NEAR))[5, 5]
    kv = gains.kv[:5] + (2.0 * inertia_6 / 1e-3,)
    harder = cl.Gains.create(potential, gains.kp, kv, gains.lam, cl.Task.POSE, 6)
    kv_alone = dataclasses.replace(shaping, inertial_damping=(0.0,) * 6)
    assert linearized_spectral_radius(model, Q_GOAL_NEAR, harder, 1, shaping=kv_alone) > 1.0
    assert linearized_spectral_radius(model, Q_GOAL_NEAR, harder, 1, shaping=shaping) < 1.0


@pytest.mark.parametrize('potential, q_goal, delay_ticks', [
    ('quadratic', Q_GOAL_NEAR, 1), ('tanh', Q_GOAL_NEAR, 1),
    ('quadratic', Q_GOAL_FAR, 3), ('tanh', Q_GOAL_FAR, 3), ('tanh', Q_GOAL_FAR, 6)])
def test_sampled_delayed_saturated_loop_holds_goal_in_pybullet(model, sim_params, potential,
                                                               q_goal, delay_ticks):
    p_d, q_d = goal_of(model, q_goal)
    with RobotSimulator(XARM6_URDF.read_text(), model.joint_names,
                        initial_positions_rad=sim_params['initial_positions'],
                        viscous_nm_s_per_rad=sim_params['viscous_friction'],
                        coulomb_nm=sim_params['coulomb_friction'],
                        enforce_velocity_limits=sim_params['enforce_velocity_limits']) as sim:
        limits = sim.effort_limits_nm.copy()
        loop = ClosedLoop(model, xarm6_gains(potential), cl.Task.POSE, q_d, p_d,
                          shaping=xarm6_shaping())
        # q* arrives 0.1 s after the goal, as from the node's goal-check worker.
        run = run_sampled(loop, sim, 5.0, delay_ticks, q_goal, 0.1)
    assert run.all_finite
    assert run.max_abs_torque_nm.max() <= limits.max() + 1e-9
    position_m, orientation = run.final(window_s=0.5)
    assert position_m < POSITION_TOL_M, f'{position_m * 1e3:.3f} mm'
    assert orientation < ORIENTATION_TOL, f'||e|| = {orientation:.4f}'
    assert run.settled_at_s() < 4.5

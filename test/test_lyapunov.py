"""
The Lyapunov argument of docs/lyapunov.md, checked in the ideal loop and at rest in PyBullet.

* Ideal loop (reference_sim.ClosedLoop, RK4) with every potential and damping term on: the
  joint-limit band (entered), the large-error term, the goal-configuration term, the cubic
  damping, the inertial damping. V, whose potential is every term's (Regulator.lyapunov),
  never increases.
* The friction compensation is not a gradient: its part of the argument is the inequality
  qdot (tau_fc + tau_f) <= 0 against a Coulomb friction with stiction at least as large as
  the estimate plus what was learned, checked pointwise. The ideal loop has no stiction (a
  smooth friction vanishes at rest, the breakaway does not), so there the compensation is an
  energy source: V does increase (why the estimate must not exceed the friction).
* A redundant arm (the Panda, section 9): on the goal's self-motion the task potential is zero
  and without the goal-configuration term every point there is an equilibrium; with it, V never
  increases and the arm slides along the self-motion to q*, elbow included.
* On the PyBullet core (stiction), sampled with a tick of delay: with compensation the
  quadratic law's friction stall of the paper's experiment vanishes, and at rest the torque is
  steady, with no sign flips (no chattering, no limit cycle).
"""
import dataclasses
import functools
import math

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_runtime.resources import default_urdf_xml
from robots import wrist_model
from wrist_sim.simulator import RobotSimulator

pytestmark = pytest.mark.unit

ORI = cl.Task.ORIENTATION
FRICTION = (2.0, 0.8, 0.5)  # config/wrist_sim.yaml
EVERYTHING = {'joint_limit_margin': 0.3, 'joint_limit_gain': (40.0, 30.0, 20.0),
              'large_error_gain': 5.0, 'configuration_gain': (6.0, 6.0, 6.0),
              'configuration_radius': 0.0, 'configuration_ramp': 0.25,
              'damping_speed': (3.0, 3.0, 3.0), 'inertial_damping': (8.0, 8.0, 12.0),
              'inertial_damping_rate': 300.0}


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_lyapunov_never_increases_with_every_term_on(potential):
    model = wrist_model()
    gains = cl.Gains.create(potential, (8.0, 8.0, 8.0), (1.5, 1.2, 0.8), (4.0, 4.0, 4.0), ORI,
                            3)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    loop = ClosedLoop(model, gains, ORI, quat.from_rotation_matrix(R),
                      shaping=sh.Shaping.create(3, **EVERYTHING), q_star=q_goal)
    # start moving towards joint 2's upper stop, 0.2 rad from it: the band is entered
    q0 = (2.5, model.position_upper[1] - 0.2, 2.8)
    # the inertial damping is above K_v on some joints here, so its part is tested too
    assert np.any(np.array(loop.regulator.linear_damping(q0)) > np.array(gains.kv))
    traj = loop.run(q0, 3.0, dt_s=5e-4, qdot0=(2.0, 3.0, -2.0))
    band_edge = model.position_upper[1] - 0.3
    assert traj.q_rad[:, 1].max() > band_edge + 0.05, 'the test must enter the band'
    assert traj.q_rad[:, 1].max() < model.position_upper[1]  # and never reach the stop
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert traj.error_norm[-1] < 0.01 < traj.error_norm[0]
    assert traj.lyapunov[-1] < 1e-3 * traj.lyapunov[0]


def soft_wrist_run(potential: str, values: dict, duration_s: float):
    """
    Run the wrist with K_v 0.3 and the shaping ``values`` from afar towards a fixed goal.

    Returns ``(model, gains, loop, trajectory)`` once it is checked that V never increased.
    """
    model = wrist_model()
    gains = cl.Gains.create(potential, (8.0, 8.0, 8.0), (0.3, 0.3, 0.3), (4.0, 4.0, 4.0), ORI,
                            3)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    loop = ClosedLoop(model, gains, ORI, quat.from_rotation_matrix(R),
                      shaping=sh.Shaping.create(3, **values), q_star=q_goal)
    traj = loop.run((2.5, 0.4, 1.4), duration_s, dt_s=5e-4, qdot0=(1.0, -1.0, 1.0))
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    return model, gains, loop, traj


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_lyapunov_never_increases_with_the_settling_damping(potential):
    """
    docs/lyapunov.md, section 11: -psi(y) alpha M(q) qdot is a dissipation, psi included.

    From far (psi = 0) into the linear range of the tanh (psi = 1): V never increases, with a
    settling damping strong enough that the opposite sign would feed the loop.
    """
    values = dict(EVERYTHING, settling_damping_rate=40.0, inertial_damping=(0.0, 0.0, 0.0),
                  damping_speed=(0.0, 0.0, 0.0))
    model, gains, loop, traj = soft_wrist_run(potential, values, 3.0)
    psi = [sh.settling_fade(loop.regulator.update(q.tolist(), [0.0] * 3).y_tilde, gains.lam)
           for q in traj.q_rad[::100]]
    assert psi[0] == 0.0 and psi[-1] == 1.0  # from far into the linear range
    assert any(0.0 < p < 1.0 for p in psi)  # through the fade
    assert traj.lyapunov[-1] < 1e-3 * traj.lyapunov[0]


def test_lyapunov_never_increases_through_the_speed_guard():
    """
    Started above 0.8 of the wrist's velocity limits, the speed guard damps the excess.

    docs/lyapunov.md, section 6: it is a dissipation (the inertial damping's cap on the
    speed above the guard), so V never increases while it acts.
    """
    model = wrist_model()
    gains = cl.Gains.create('tanh', (8.0, 8.0, 8.0), (1.5, 1.2, 0.8), (4.0, 4.0, 4.0), ORI, 3)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    # the inertial damping below its cap beta I_j, and no cubic part: the guard damps the excess
    values = dict(EVERYTHING, inertial_damping=(0.5, 0.5, 0.5), damping_speed=(0.0, 0.0, 0.0))
    loop = ClosedLoop(model, gains, ORI, quat.from_rotation_matrix(R),
                      shaping=sh.Shaping.create(3, **values), q_star=q_goal)
    q0 = (0.0, 1.0, 0.0)
    cap = values['inertial_damping_rate'] * np.array(model.inertias(list(q0))[1])
    assert np.all(cap > np.array(loop.regulator.linear_damping(q0)))
    guard = sh.SPEED_GUARD_FRACTION * np.array(model.velocity_limits)
    qdot0 = 0.98 * np.array(model.velocity_limits) * np.array([1.0, -1.0, 1.0])
    traj = loop.run(q0, 1.0, dt_s=2e-4, qdot0=tuple(qdot0))
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    speeds = np.abs(np.diff(traj.q_rad, axis=0)) / np.diff(traj.t_s)[:, None]
    assert np.any(speeds > guard)  # the guard acted
    assert traj.lyapunov[-1] < 0.5 * traj.lyapunov[0]


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_lyapunov_never_increases_where_a_mode_of_the_damping_is_capped(potential):
    """
    docs/lyapunov.md, section 10: the damping with its fast modes brought down to beta.

    Every joint's inertial damping at its cap beta I_j: M(q) couples them into a mode faster
    than beta, which the tick brings down to it. What is left is still positive definite, a
    dissipation, so V never increases.
    """
    values = dict(EVERYTHING, inertial_damping=(500.0, 500.0, 500.0),
                  damping_speed=(0.0, 0.0, 0.0))
    model, _, loop, traj = soft_wrist_run(potential, values, 2.0)
    capped = 0
    for q in traj.q_rad[::100]:
        caps = values['inertial_damping_rate'] * np.array(model.inertias(q.tolist())[1])
        capped += bool(np.any(np.array(loop.regulator.linear_damping(q.tolist()))
                              < 0.999 * caps))
    assert capped > len(traj.q_rad[::100]) // 2, 'a mode must be capped along the way'
    assert traj.lyapunov[-1] < 0.5 * traj.lyapunov[0]  # heavily damped, but on its way


def test_lyapunov_never_increases_through_the_stop_guard(monkeypatch):
    """
    Moving fast at a stop, below the speed guard, the stop guard brakes it short of the stop.

    docs/lyapunov.md, section 6: towards a stop the guard's speed falls with the room left
    before the stop's clearance, and the push of the other joints along the motion is taken
    away; both oppose the motion and vanish at rest, so V never increases. The joint comes to
    rest about the clearance from its stop, nearer without the stop guard.
    """
    model = wrist_model()
    gains = cl.Gains.create('tanh', (8.0, 8.0, 8.0), (1.5, 1.2, 0.8), (4.0, 4.0, 4.0), ORI, 3)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    # a weak band, the inertial damping below its cap and no cubic part
    values = dict(EVERYTHING, inertial_damping=(0.5, 0.5, 0.5), damping_speed=(0.0, 0.0, 0.0),
                  joint_limit_gain=(1.0, 1.0, 1.0))
    clearance = sh.STOP_CLEARANCE_SHARE * values['joint_limit_margin']
    q0 = (2.5, model.position_upper[1] - 0.09, 1.0)
    qdot0 = (0.0, 0.78 * model.velocity_limits[1], 0.0)  # below the speed guard
    gaps, guarded = {}, sh.STOP_GUARD_SHARE
    for share in (guarded, math.inf):  # with the stop guard, and without
        monkeypatch.setattr(sh, 'STOP_GUARD_SHARE', share)
        loop = ClosedLoop(model, gains, ORI, quat.from_rotation_matrix(R),
                          shaping=sh.Shaping.create(3, **values), q_star=q_goal)
        traj = loop.run(q0, 1.0, dt_s=2e-4, qdot0=qdot0)
        dV = np.diff(traj.lyapunov)
        assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
        assert traj.lyapunov[-1] < 1e-3 * traj.lyapunov[0]
        gaps[share] = model.position_upper[1] - traj.q_rad[:, 1].max()
    assert gaps[guarded] > 0.9 * clearance > gaps[math.inf] > 0.0, gaps


def test_compensation_never_does_more_than_the_friction_it_cancels():
    """
    Check section 4's inequality pointwise.

    |tau_fc| <= f + a, so against a Coulomb friction f_true >= f + a (set-valued at rest) the
    power qdot (tau_fc + tau_f) is never positive.
    """
    rng = np.random.default_rng(4)
    estimate, limit = (1.8, 0.72, 0.45), (1.8, 0.72, 0.45)
    shaping = sh.Shaping.create(3, friction_compensation=estimate,
                                friction_learning_limit=limit)
    for _ in range(2000):
        learned = rng.uniform(0.0, 1.0, 3) * limit
        f_true = np.array(estimate) + learned + rng.uniform(0.0, 0.5, 3)
        qdot = rng.choice([0.0, 1.0], 3) * rng.normal(0.0, 0.1, 3)
        tau_p = rng.normal(0.0, 2.0, 3)
        phi = float(rng.choice([0.0, rng.uniform(), 1.0]))
        fc = np.array(sh.friction_compensation(tau_p, qdot, phi, shaping, list(learned)))
        assert np.all(np.abs(fc) <= np.array(estimate) + learned + 1e-12)
        assert np.all(qdot * (fc - f_true * np.sign(qdot)) <= 1e-12)
        overshoot = qdot * tau_p < 0.0  # moving against the potential: no push along it
        assert np.all(fc[overshoot] * qdot[overshoot] <= 1e-12)
        if phi == 0.0:
            assert np.all(fc == 0.0)  # off near the goal: nothing to feed a cycle there


def test_compensation_without_friction_to_cancel_feeds_energy_in():
    """What an over-estimate does: the same loop without plant friction, V increases."""
    model = wrist_model()
    gains = cl.Gains.create('tanh', (8.0, 8.0, 8.0), (1.5, 1.2, 0.8), (4.0, 4.0, 4.0), ORI, 3)
    shaping = sh.Shaping.create(3, friction_compensation=FRICTION, friction_error_band=1e-5)
    loop = ClosedLoop(model, gains, ORI, paper.Q_DESIRED, shaping=shaping)
    traj = loop.run((0.0, 0.5, 0.0), 0.5, qdot0=(1.0, 1.0, 1.0))
    assert np.diff(traj.lyapunov).max() > 1e-4


def rest_trace(potential, compensation, duration_s=6.0):
    """Run the paper's experiment on the PyBullet core (stiction), one tick of delay."""
    model = wrist_model()
    gains = cl.Gains.create(potential, paper.KP, paper.KV, paper.LAMBDA, ORI, 3)
    shaping = sh.Shaping.create(3, friction_compensation=compensation)
    loop = ClosedLoop(model, gains, ORI, paper.Q_DESIRED, shaping=shaping)
    with RobotSimulator(default_urdf_xml(), model.joint_names, coulomb_nm=FRICTION) as sim:
        return run_sampled(loop, sim, duration_s, delay_ticks=1)


def test_friction_compensation_removes_the_quadratic_stall_without_chattering():
    stalled = rest_trace('quadratic', None)
    assert stalled.orientation_error[-1] > 0.15  # the paper's friction stall (0.2043)
    run = rest_trace('quadratic', FRICTION)
    assert run.orientation_error[-1] < 0.005
    band = sh.Shaping().friction_error_band
    assert run.orientation_error[-1] > 0.5 * band * 0.5  # it stops in the fade band
    last = run.tau_nm[-1000:]  # the last second, at rest
    assert np.all(last.max(axis=0) - last.min(axis=0) < 1e-9), 'torque not steady at rest'
    signs = np.sign(last)
    assert np.all((signs == signs[0]) | (np.abs(last) < 1e-12)), 'torque flips sign'
    moved = np.abs(run.q_rad[-1000:] - run.q_rad[-1]).max()
    assert moved < 1e-6, 'still moving: a limit cycle'


def test_at_rest_with_compensation_on_the_goal_the_torque_is_gravity_alone():
    """Within half the band the at-rest part is off: nothing left to chatter."""
    model = wrist_model()
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, ORI, 3)
    shaping = sh.Shaping.create(3, friction_compensation=FRICTION)
    loop = ClosedLoop(model, gains, ORI, paper.Q_DESIRED, shaping=shaping)
    q = list(paper.Q_JOINT_DESIRED_RAD)
    out = loop.clamped.update(q, [0.0, 0.0, 0.0])
    assert out.orientation_error_norm < 0.5 * shaping.friction_error_band
    expected = np.array(model.gravity(q)) + np.array(out.tau_potential_nm)
    np.testing.assert_allclose(out.tau_nm, expected, atol=1e-12)
    assert math.isclose(sh.fade(out.y_tilde, shaping), 0.0)
    assert dataclasses.replace(shaping, friction_error_band=1e-6).friction_on


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_a_redundant_arm_comes_to_rest_at_the_goal_configuration_elbow_included(potential):
    """
    Section 9 on the Panda (config/panda_controller.yaml, friction off: the ideal loop has none).

    Start at rest on the goal's self-motion, 0.3 rad of elbow away from q*: the task error is
    zero there. Without U_c the torque is g(q) alone, so the arm stays (every point of the
    self-motion is an equilibrium). With U_c, V never increases and the arm ends at q*.
    """
    from quat_jt_controller.controller_config import controller_from_package_config
    from quat_jt_controller.inverse_kinematics import polish
    from quat_jt_controller.regulator import Regulator
    from robots import PANDA_URDF
    controller = controller_from_package_config('panda_controller.yaml',
                                                PANDA_URDF.read_text(), potential)
    model, gains = controller.model, controller.gains
    shaping = dataclasses.replace(controller.shaping, friction_compensation_nm=(),
                                  friction_learning_limit_nm=())
    q_star = np.array([0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.9])
    p_d, R_d = model.forward_kinematics(q_star.tolist())
    q_d = quat.from_rotation_matrix(R_d)
    J = np.array(model.kinematics(q_star.tolist())[2])
    null = np.linalg.svd(J)[2][-1]  # the self-motion direction at q*
    q_start = polish(model, q_star + 0.3 * null / np.abs(null).max(), q_d, p_d, cl.Task.POSE)
    assert q_start is not None and np.abs(q_start - q_star).max() > 0.25
    alone = Regulator(model, cl.Task.POSE, gains, None, None,
                      dataclasses.replace(shaping, configuration_gain=()))
    alone.set_goal(alone.pose(q_star.tolist()))
    tau = alone.update(q_start.tolist(), [0.0] * 7).tau_nm
    np.testing.assert_allclose(tau, model.gravity(q_start.tolist()), atol=1e-6)

    loop = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d, shaping=shaping, q_star=q_star)
    traj = loop.run(q_start, 2.5, dt_s=1e-3)
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert np.abs(traj.q_rad[-1] - q_star).max() < 1e-3
    assert traj.error_norm[-1] < 1e-4


@functools.lru_cache(maxsize=None)
def _unmeasured_friction_design(share):
    from quat_jt_controller import gain_design as gd
    return gd.design(wrist_model(), ORI, friction_effort_share=share)


def test_with_no_estimate_the_learning_is_bounded_by_the_effort_budget():
    """Estimate 0: a_max is a share of each effort limit; a never leaves [0, a_max]."""
    from quat_jt_controller import gain_design as gd
    model = wrist_model()
    shaping = _unmeasured_friction_design(gd.FRICTION_EFFORT_SHARE).shaping
    a_max = np.array(shaping.friction_learning_limit_nm)
    np.testing.assert_allclose(a_max, gd.FRICTION_EFFORT_SHARE * np.array(model.effort_limits))
    rng = np.random.default_rng(3)
    learned = [0.0, 0.0, 0.0]
    for _ in range(4000):  # stuck and pushed, then freed, at random: 4 s of ticks
        tau_p = rng.normal(0.0, 1.0, 3)
        qdot = rng.choice([0.0, 1.0], 3) * rng.normal(0.0, 0.2, 3)
        phi = float(rng.choice([0.0, 0.5, 1.0]))
        stuck = [0.0, 0.0, 0.0]
        fc = sh.friction_compensation(tau_p, qdot, phi, shaping, learned, stuck)
        sh.learn_friction(learned, stuck, phi, shaping, 1e-3)
        assert np.all(np.array(learned) >= 0.0) and np.all(np.array(learned) <= a_max)
        assert np.all(np.abs(fc) <= a_max + 1e-12)
        # positive work only along the potential's torque
        assert np.all(np.array(fc) * qdot <= 1e-12 + np.maximum(0.0, np.sign(tau_p) * qdot)
                      * a_max)
    # pushed at rest off the goal for the learning time, a reaches its bound (not more)
    learned = [0.0, 0.0, 0.0]
    for _ in range(3000):
        stuck = [0.0, 0.0, 0.0]
        sh.friction_compensation([1.0, -1.0, 1.0], [0.0] * 3, 1.0, shaping, learned, stuck)
        sh.learn_friction(learned, stuck, 1.0, shaping, 1e-3)
    np.testing.assert_allclose(learned, a_max)


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_lyapunov_never_increases_with_the_unmeasured_friction_extension(potential):
    """The ideal loop with the design's extensions, estimate 0 and learning on: V decreases."""
    model = wrist_model()
    d = _unmeasured_friction_design(0.03)
    assert d.shaping.learning_on and not any(d.shaping.friction_compensation_nm)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    loop = ClosedLoop(model, d.gains(potential), ORI, quat.from_rotation_matrix(R),
                      shaping=d.shaping, q_star=q_goal)
    traj = loop.run((0.2, 0.8, 0.3), 0.8, dt_s=1e-3)
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert traj.lyapunov[-1] < 0.1 * traj.lyapunov[0]


def test_with_no_estimate_a_friction_plant_still_reaches_the_goal():
    """Coulomb friction of 2% of effort, untold: the learned part breaks it; without, a stall."""
    model = wrist_model()
    coulomb = (0.02 * np.array(model.effort_limits)).tolist()
    final = {}
    for share in (0.0, 0.03):
        d = _unmeasured_friction_design(share)
        loop = ClosedLoop(model, d.gains('quadratic'), ORI, paper.Q_DESIRED, shaping=d.shaping)
        with RobotSimulator(default_urdf_xml(), model.joint_names, coulomb_nm=coulomb) as sim:
            run = run_sampled(loop, sim, 2.0, 1, list(paper.Q_JOINT_DESIRED_RAD), 0.05)
        final[share] = (run.final()[1], run.settled_at_s(orientation=0.01))
        learned = loop.clamped.learned_friction_nm
        assert np.all(np.array(learned) <= np.array(d.shaping.friction_learning_limit_nm)
                      + 1e-12)
    assert final[0.0][0] > 0.01  # stalls short of the goal with nothing to learn
    assert final[0.03][1] < 1.5 and final[0.03][0] < 0.01  # reaches within 1.5 s, and stays


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
def test_on_a_plant_without_friction_the_learning_finds_nothing_to_learn(potential):
    """
    The design's learning of an unmeasured friction, advanced every tick, on a frictionless plant.

    Nothing holds a joint, so the learning must not mistake the approach's slow end or a
    swing's turning points for stiction: what it learns stays a small share of its bound, the
    wrist reaches the goal and stays, and its torque does not keep changing sign there.
    """
    from quat_jt_controller import gain_design as gd
    model = wrist_model()
    d = gd.design(model, ORI, friction_effort_share=gd.FRICTION_EFFORT_SHARE)
    assert d.shaping.learning_on and not any(d.shaping.friction_compensation_nm)
    loop = ClosedLoop(model, d.gains(potential), ORI, paper.Q_DESIRED, shaping=d.shaping)
    regulator, most = loop.clamped, np.zeros(3)
    tick = regulator.update

    def watched_tick(*args):  # the regulator's tick, and the most learned after each
        out = tick(*args)
        np.maximum(most, regulator.learned_friction_nm, out=most)
        return out
    regulator.update = watched_tick
    with RobotSimulator(default_urdf_xml(), model.joint_names, coulomb_nm=[0.0] * 3,
                        viscous_nm_s_per_rad=[0.0] * 3) as sim:
        run = run_sampled(loop, sim, 2.0, 1, list(paper.Q_JOINT_DESIRED_RAD), 0.05)
    assert np.all(most <= 0.05 * np.array(d.shaping.friction_learning_limit_nm))
    assert run.final()[1] < 0.005
    last = run.tau_nm[int(np.searchsorted(run.t_s, run.t_s[-1] - 0.5)):]
    flips = [np.count_nonzero(np.diff(np.sign(last[:, j][np.abs(last[:, j]) > 1e-3])))
             for j in range(3)]
    assert max(flips) <= 1, flips

"""The one control tick (quat_jt_controller.regulator) against the law written out by hand."""
import math

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.regulator import CONFIGURATION_FADE_IN_S, Goal, Regulator
from robots import random_q, wrist_model, xarm6_model

pytestmark = pytest.mark.unit

ORI, POSE = cl.Task.ORIENTATION, cl.Task.POSE


def paper_gains(potential: str = 'tanh', kp=paper.KP) -> cl.Gains:
    return cl.Gains.create(potential, kp, paper.KV, paper.LAMBDA, ORI, 3)


def eq38_by_hand(model, q, qdot, q_desired, gains):
    """Eq. (38) + g(q) with numpy: J_o^T Q_o^T K_p tanh(Lambda e) - K_v qdot + g(q)."""
    _, R, J = model.kinematics(q)
    eta_e, e = quat.orientation_error(quat.from_rotation_matrix(R), q_desired)
    Q = np.array(quat.q_matrix(eta_e, e))
    force = np.array(gains.kp) * np.tanh(np.array(gains.lam) * np.array(e))
    return (np.array(J)[3:].T @ Q.T @ force - np.array(gains.kv) * np.array(qdot)
            + np.array(model.gravity(q)))


@pytest.mark.parametrize('seed', range(5))
def test_tick_is_eq38_plus_gravity_clamped(seed):
    model = wrist_model()
    rng = np.random.default_rng(seed)
    q, qdot = random_q(model, rng).tolist(), rng.normal(size=3).tolist()
    reg = Regulator(model, ORI, paper_gains(), goal=Goal(paper.Q_DESIRED))
    out = reg.update(q, qdot)
    want = np.clip(eq38_by_hand(model, q, qdot, paper.Q_DESIRED, reg.gains),
                   -np.array(model.effort_limits), model.effort_limits)
    np.testing.assert_allclose(out.tau_nm, want, atol=1e-12)
    assert out.finite and out.orientation_error_norm == pytest.approx(
        np.linalg.norm(out.y_tilde))
    assert out.position_error_norm_m == 0.0


def test_saturation_is_reported_and_clamped_to_the_urdf_limits():
    model = wrist_model()
    reg = Regulator(model, ORI, paper_gains(kp=(500.0, 500.0, 500.0)), goal=Goal(
        paper.Q_DESIRED))
    out = reg.update([0.0, 0.3, 0.0], [0.0, 0.0, 0.0])
    assert out.saturated
    assert all(abs(t) <= lim for t, lim in zip(out.tau_nm, model.effort_limits))
    assert any(abs(t) == lim for t, lim in zip(out.tau_nm, model.effort_limits))


def test_non_finite_law_gives_zero_torque_and_says_so():
    """Gains of 1.7e308 are finite and positive, but the law overflows: zero, never NaN."""
    reg = Regulator(wrist_model(), ORI, paper_gains(kp=(1.7e308,) * 3),
                    goal=Goal(paper.Q_DESIRED))
    out = reg.update([1.0, 1.0, 1.0], [0.0, 0.0, 0.0])  # J^T Q^T K_p tanh(.) overflows here
    assert not out.finite and out.tau_nm == [0.0, 0.0, 0.0]


def test_a_non_finite_tick_does_not_poison_the_learned_friction():
    shaping = sh.Shaping.create(3, friction_compensation=(1.0, 1.0, 1.0),
                                friction_learning_limit=(1.0, 1.0, 1.0))
    reg = Regulator(wrist_model(), ORI, paper_gains(kp=(1.7e308,) * 3),
                    goal=Goal(paper.Q_DESIRED), shaping=shaping)
    assert not reg.update([1.0, 1.0, 1.0], [0.0, 0.0, 0.0], 1e-3).finite
    assert reg.learned_friction_nm == (0.0, 0.0, 0.0)


def test_a_non_finite_velocity_does_not_poison_the_acceleration_the_learning_reads():
    """One NaN velocity, then the joints held at rest: the learning still learns."""
    shaping = sh.Shaping.create(3, friction_learning_limit=(0.5, 0.5, 0.5))
    reg = Regulator(wrist_model(), ORI, paper_gains(), goal=Goal(paper.Q_DESIRED),
                    shaping=shaping)
    near = [v + 0.05 for v in paper.Q_JOINT_DESIRED_RAD]
    assert not reg.update(near, [math.nan, 0.0, 0.0], 1e-3).finite
    for _ in range(500):
        reg.update(near, [0.0, 0.0, 0.0], 1e-3)
    assert min(reg.learned_friction_nm) > 0.0


def test_a_joint_its_push_accelerates_learns_nothing_one_held_at_rest_does():
    """
    docs/lyapunov.md, section 4: the tick reads M(q) qddot from the velocities it is given.

    Fed velocities that ramp as M(q) qddot = tau_p (a frictionless joint starting to move
    under its push, slower than its creep speed throughout), the learning finds nothing held;
    fed zeros (held at rest), it learns.
    """
    model = wrist_model()
    shaping = sh.Shaping.create(3, friction_learning_limit=(0.5, 0.5, 0.5))
    # a weak push and weaker damping: the push goes into the acceleration, not the damping
    gains = cl.Gains.create('tanh', tuple(2e-4 * k for k in paper.KP),
                            tuple(1e-3 * k for k in paper.KV), paper.LAMBDA, ORI, 3)
    near = [v + 0.05 for v in paper.Q_JOINT_DESIRED_RAD]
    held = Regulator(model, ORI, gains, goal=Goal(paper.Q_DESIRED), shaping=shaping)
    moving = Regulator(model, ORI, gains, goal=Goal(paper.Q_DESIRED), shaping=shaping)
    tau_p = np.array(held.update(near, [0.0] * 3).tau_potential_nm)
    qddot = np.linalg.solve(model.mass_matrix(near), tau_p)
    dt, steps = 1e-3, 400
    creep = sh.CREEP_SPEED_FACTOR * shaping.friction_velocity_rad_s
    assert np.abs(qddot).max() * dt * steps < creep / 2  # slower than its creep speed
    for k in range(steps):
        held.update(near, [0.0] * 3, dt)
        moving.update(near, (qddot * k * dt).tolist(), dt)
    assert min(held.learned_friction_nm) > 0.0
    assert moving.learned_friction_nm == (0.0, 0.0, 0.0)


def test_hold_makes_the_measured_pose_the_goal_and_gives_gravity_alone():
    model = wrist_model()
    reg = Regulator(model, ORI, paper_gains())
    q = [0.3, 0.7, -0.2]
    goal = reg.hold(q)
    assert reg.goal is goal and goal.q_desired_base[0] >= 0.0
    np.testing.assert_allclose(reg.update(q, [0.0] * 3).tau_nm, model.gravity(q), atol=1e-12)


def test_gain_and_goal_swaps_are_whole_and_checked():
    reg = Regulator(wrist_model(), ORI, paper_gains())
    with pytest.raises(cl.GainsError, match='kp and lambda must have 3'):
        reg.set_gains(cl.Gains.create('tanh', (1.0,) * 6, paper.KV, (1.0,) * 6, POSE, 3))
    new = paper_gains('quadratic')
    reg.set_gains(new)
    assert reg.gains is new


def test_pose_task_on_the_xarm6_reports_the_position_error():
    model = xarm6_model()
    gains = cl.Gains.create('tanh', (200.0,) * 3 + paper.KP, (1.0,) * 6,
                            (2.0,) * 3 + paper.LAMBDA, POSE, 6)
    reg = Regulator(model, POSE, gains)
    q_goal = [0.2, -0.4, -1.1, 0.2, 1.4, 0.3]
    reg.set_goal(reg.pose(q_goal))
    out = reg.update([0.0, -0.5, -1.0, 0.0, 1.5, 0.0], [0.0] * 6)
    p_goal, _ = model.forward_kinematics(q_goal)
    p_now, _ = model.forward_kinematics([0.0, -0.5, -1.0, 0.0, 1.5, 0.0])
    assert out.position_error_norm_m == pytest.approx(
        float(np.linalg.norm(np.subtract(p_goal, p_now))), rel=1e-12)
    assert len(out.tau_nm) == 6 and out.finite
    assert reg.update(q_goal, [0.0] * 6).position_error_norm_m < 1e-12


def test_goal_validation_names_the_problem_in_ros_order():
    with pytest.raises(ValueError, match=r'\(x, y, z, w\) = \(nan, 0.0, 0.0, 1.0\)'):
        Goal.from_xyzw(math.nan, 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match='not unit'):
        Goal.from_xyzw(*quat.to_xyzw(paper.Q_DESIRED_AS_PRINTED))
    with pytest.raises(ValueError, match='non-finite position'):
        Goal.from_xyzw(0.0, 0.0, 0.0, 1.0, (0.0, math.inf, 0.0))
    g = Goal.from_xyzw(*(1.004 * c for c in quat.to_xyzw(paper.Q_DESIRED)))
    assert quat.norm(g.q_desired_base) == pytest.approx(1.0)


@pytest.mark.parametrize('seed', range(3))
def test_the_goal_velocity_term_adds_k_v_g_v_qdot_star_and_nothing_else(seed):
    """docs/lyapunov.md, section 7: without qdot*_d, or with g_v = 0, the law to the bit."""
    model = wrist_model()
    rng = np.random.default_rng(seed)
    q, qdot = random_q(model, rng).tolist(), rng.normal(size=3).tolist()
    qdot_star = rng.normal(size=3).tolist()
    unlimited = [math.inf] * 3
    paper_law = Regulator(model, ORI, paper_gains(), unlimited, Goal(paper.Q_DESIRED))
    reg = Regulator(model, ORI, paper_gains(), unlimited, Goal(paper.Q_DESIRED),
                    sh.Shaping.create(3, goal_velocity_gain=0.5))
    assert reg.update(q, qdot).tau_nm == paper_law.update(q, qdot).tau_nm  # a fixed goal
    reg.set_goal_joint_velocity(qdot_star)
    want = [t + 0.5 * kv * v for t, kv, v in zip(paper_law.update(q, qdot).tau_nm,
                                                 paper.KV, qdot_star)]
    np.testing.assert_allclose(reg.update(q, qdot).tau_nm, want, atol=1e-12)
    reg.set_shaping(sh.Shaping.create(3, goal_velocity_gain=0.0))
    assert reg.update(q, qdot).tau_nm == paper_law.update(q, qdot).tau_nm  # g_v = 0: off
    reg.set_goal_joint_velocity(None)
    assert reg.goal_joint_velocity is None
    with pytest.raises(ValueError, match='expected 3 joint velocities'):
        reg.set_goal_joint_velocity([1.0, 2.0])
    with pytest.raises(sh.ShapingError, match=r'goal_velocity_gain must be in \[0, 1\]'):
        sh.Shaping.create(3, goal_velocity_gain=1.5)


def test_a_far_new_q_star_fades_in_and_a_near_one_keeps_its_share():
    """
    docs/lyapunov.md, section 5: U_c rises over CONFIGURATION_FADE_IN_S after a far q*.

    A near q* (a streamed goal's) keeps the share; while no q* is in force it falls at the
    rate it rises; a gain raised live keeps the joint's term where it was and rises from
    there, the other joints' untouched. Evaluations without a time step (the ideal loop) apply
    U_c whole.
    """
    model = wrist_model()
    unlimited = [math.inf] * 3
    shaping = sh.Shaping.create(3, configuration_gain=(2.0, 2.0, 2.0))
    paper_law = Regulator(model, ORI, paper_gains(), unlimited, Goal(paper.Q_DESIRED))
    q, qdot, dt = [0.3, 0.6, -0.2], [0.0, 0.0, 0.0], 1e-3

    def guide(reg, dt_s=dt):  # the goal-configuration term's torque this tick
        return (np.array(reg.update(q, qdot, dt_s).tau_nm)
                - np.array(paper_law.update(q, qdot).tau_nm))

    ideal = Regulator(model, ORI, paper_gains(), unlimited, Goal(paper.Q_DESIRED), shaping)
    ideal.set_goal_configuration(ideal.goal, [1.3, 1.6, 0.8])  # T_j saturated on each joint
    np.testing.assert_allclose(guide(ideal, 0.0), [2.0, 2.0, 2.0], atol=1e-12)  # no ticks
    reg = Regulator(model, ORI, paper_gains(), unlimited, Goal(paper.Q_DESIRED), shaping)
    reg.set_goal_configuration(reg.goal, [1.3, 1.6, 0.8])
    share = dt / CONFIGURATION_FADE_IN_S
    ticks = int(round(CONFIGURATION_FADE_IN_S / dt))  # the fade's length in ticks
    np.testing.assert_allclose(guide(reg), [2.0 * share] * 3, atol=1e-12)
    np.testing.assert_allclose(guide(reg, 0.0), [2.0 * share] * 3, atol=1e-12)  # re-evaluated
    for _ in range(ticks):
        torque = guide(reg)
    np.testing.assert_allclose(torque, [2.0, 2.0, 2.0], atol=1e-12)
    reg.set_goal_configuration(reg.goal, [1.31, 1.59, 0.8])  # a streamed goal's next q*
    np.testing.assert_allclose(guide(reg), [2.0, 2.0, 2.0], atol=1e-12)
    reg.set_goal_configuration(reg.goal, [1.31, 1.59, 1.3])  # 0.5 rad: farther than the ramp
    np.testing.assert_allclose(guide(reg), [2.0 * share] * 3, atol=1e-12)
    for _ in range(9):
        guide(reg)
    reg.set_goal_configuration(reg.goal, [1.3, 1.6, 1.3])  # near, mid-fade: it goes on
    np.testing.assert_allclose(guide(reg), [2.0 * 11 * share] * 3, atol=1e-12)
    for _ in range(ticks):  # (to the full share)
        guide(reg)
    goal = Goal(paper.Q_DESIRED)  # a new goal: no q* until the goal check gives it
    reg.set_goal(goal)
    for _ in range(30):  # 30 ticks without q*: the share falls as it rises
        np.testing.assert_allclose(guide(reg), [0.0, 0.0, 0.0], atol=1e-12)
    reg.set_goal_configuration(goal, [1.3, 1.6, 1.29])  # back near the last q*
    np.testing.assert_allclose(guide(reg), [2.0 * (ticks - 29) * share] * 3, atol=1e-12)
    for _ in range(ticks):  # (to the full share)
        guide(reg)
    reg.set_shaping(sh.Shaping.create(3, configuration_gain=(2.0, 1.0, 3.0)))  # set live
    # joint3 raised: 2 N m still in force, then rising by 3 N m a fade; joint2 lowered: at once
    np.testing.assert_allclose(guide(reg), [2.0, 1.0, 2.0 + 3.0 * share], atol=1e-12)
    for _ in range(ticks):
        torque = guide(reg)
    np.testing.assert_allclose(torque, [2.0, 1.0, 3.0], atol=1e-12)


def xarm6_case(seed: int, speed: float):
    """Return an xArm6 at a random q and qdot (``speed`` x normal), gains, no clamp, a goal."""
    model = xarm6_model()
    rng = np.random.default_rng(seed)
    q, qdot = random_q(model, rng).tolist(), (speed * rng.normal(size=model.n)).tolist()
    gains = cl.Gains.create('tanh', [50.0] * 3 + [2.0] * 3, [0.5] * 6, [20.0] * 3 + [4.0] * 3,
                            POSE, 6)
    goal = Regulator(model, POSE, gains).pose(random_q(model, rng).tolist())
    return model, rng, q, qdot, gains, [math.inf] * model.n, goal


def modes_capped(M, D, beta):
    """
    D with every rate of M^-1 D above beta brought down to beta, by hand (the oracle).

    M = L L^T; the rates are the eigenvalues of L^-1 D L^-T = Z W Z^T, so D = L Z W Z^T L^T,
    and the capped damping is L Z min(W, beta) Z^T L^T.
    """
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    w, Z = np.linalg.eigh(Li @ D @ Li.T)
    return L @ Z @ np.diag(np.minimum(w, beta)) @ Z.T @ L.T


@pytest.mark.parametrize('seed', range(6))
def test_no_mode_of_the_inertial_damping_is_faster_than_its_rate(seed):
    """
    docs/lyapunov.md, section 10: each mode of M^-1 D faster than beta is brought down to it.

    M(q) couples the joints, so a mode can be faster than beta though each joint's own entry
    is within it. The tick brings each such mode down to beta (K_v included) and leaves the
    others as they are.
    """
    model, rng, q, qdot, gains, unlimited, goal = xarm6_case(seed, 0.1)
    M = np.array(model.mass_matrix(q))
    own, seen = np.diag(M), 1.0 / np.diag(np.linalg.inv(M))
    beta = 50.0
    c = (2.0 * beta * seen / np.sqrt(own)).tolist()  # every joint on its cap beta I_j
    reg = Regulator(model, POSE, gains, unlimited, goal,
                    sh.Shaping.create(model.n, inertial_damping=c, inertial_damping_rate=beta))
    D = np.diag(np.maximum(0.5, beta * seen))
    rates = np.linalg.eigvals(np.linalg.solve(M, D)).real
    assert rates.max() > 1.05 * beta, 'the coupling must make a mode faster than beta'
    capped = modes_capped(M, D, beta)
    capped_rates = np.sort(np.linalg.eigvals(np.linalg.solve(M, capped)).real)
    np.testing.assert_allclose(capped_rates, np.minimum(np.sort(rates), beta), rtol=1e-9)
    assert np.linalg.eigvalsh(capped).min() > 0.0, 'still a dissipation'
    plain = Regulator(model, POSE, gains, unlimited, goal)
    want = np.array(plain.update(q, qdot).tau_nm) - (capped - 0.5 * np.eye(6)) @ qdot
    np.testing.assert_allclose(reg.update(q, qdot).tau_nm, want, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(reg.linear_damping(q), np.diag(capped), rtol=1e-9)
    # at a rate no mode reaches, nothing is taken away: the diagonal damping as it was
    high = float(1.01 * rates.max())
    reg.set_shaping(sh.Shaping.create(model.n, inertial_damping=c, inertial_damping_rate=high))
    D_high = np.diag(np.maximum(0.5, np.minimum(c * np.sqrt(own), high * seen)))
    np.testing.assert_allclose(reg.linear_damping(q), np.diag(D_high), rtol=1e-12)
    want = np.array(plain.update(q, qdot).tau_nm) - (D_high - 0.5 * np.eye(6)) @ qdot
    np.testing.assert_allclose(reg.update(q, qdot).tau_nm, want, rtol=1e-9, atol=1e-9)


def test_a_non_finite_inverse_inertia_caps_nothing_and_raises_nothing():
    """A singular M(q) (inf or NaN in M^-1): no mode is capped; the tick's finite check acts."""
    coupled = [[1.0, 0.9], [0.9, 1.0]]  # rates 0.1 and 1.9: one above beta = 1.5
    capped = sh.fast_damping_modes(coupled, [1.0, 1.0], 1.5)
    assert len(capped) == 1 and capped[0][0] == pytest.approx(1.0 - 1.5 / 1.9)
    for bad in (math.inf, math.nan):
        assert sh.fast_damping_modes([[1.0, 0.9], [0.9, bad]], [1.0, 1.0], 1.5) is None
        assert sh.fast_damping_modes(coupled, [1.0, bad], 1.5) is None


@pytest.mark.parametrize('seed', range(4))
def test_the_inertial_damping_follows_the_joints_inertia_within_the_sampled_cap(seed):
    """
    docs/lyapunov.md, section 10: per joint max(k_v, min(c sqrt(M_jj), beta I_j)) on qdot.

    I_j = 1 / (M^-1)_jj. The case has joints on each of the three sides: k_v, c sqrt(M_jj),
    and the cap beta I_j.
    """
    model, rng, q, qdot, gains, unlimited, goal = xarm6_case(seed, 0.01)
    M = model.mass_matrix(q)  # the inertias, by hand
    own, seen = np.diag(M), 1.0 / np.diag(np.linalg.inv(M))
    np.testing.assert_allclose(model.inertias(q), [own, seen], rtol=1e-9)
    c = np.array([0.1, 40.0, 0.1, 40.0, 0.1, 0.1]) * rng.uniform(0.8, 1.2, 6)
    ratios = sorted(c[[1, 3]] * np.sqrt(own[[1, 3]]) / seen[[1, 3]])
    beta = float(np.sqrt(ratios[0] * ratios[1]))  # the cap binds on one of joints 2 and 4
    plain = Regulator(model, POSE, gains, unlimited, goal)
    reg = Regulator(model, POSE, gains, unlimited, goal,
                    sh.Shaping.create(model.n, inertial_damping=c.tolist(),
                                      inertial_damping_rate=beta))
    damping = np.maximum(0.5, np.minimum(c * np.sqrt(own), beta * seen))
    assert np.any(damping == 0.5), 'k_v must win somewhere'
    assert np.any((damping > 0.5) & (damping == c * np.sqrt(own))), 'c sqrt(M_jj) somewhere'
    assert np.any((damping > 0.5) & (damping == beta * seen)), 'the cap somewhere'
    capped = modes_capped(M, np.diag(damping), beta)  # and no mode of M^-1 D above beta
    np.testing.assert_allclose(reg.linear_damping(q), np.diag(capped), rtol=1e-9)
    assert plain.linear_damping(q) == [0.5] * 6
    extra = capped - 0.5 * np.eye(model.n)
    want = np.array(plain.update(q, qdot).tau_nm) - extra @ np.array(qdot)
    np.testing.assert_allclose(reg.update(q, qdot).tau_nm, want, rtol=1e-9, atol=1e-12)
    # towards a streamed goal's velocity it damps qdot - g_v qdot*_d, as k_v does
    reg.set_shaping(sh.Shaping.create(model.n, inertial_damping=c.tolist(),
                                      inertial_damping_rate=beta, goal_velocity_gain=0.5))
    reg.set_goal_joint_velocity(qdot)
    half = (0.5 * np.array(qdot)).tolist()
    np.testing.assert_allclose(reg.update(q, qdot).tau_nm,
                               np.array(plain.update(q, half).tau_nm)
                               - extra @ np.array(half), rtol=1e-9, atol=1e-9)
    for values, match in (({'inertial_damping': [-1.0] * 6}, 'inertial_damping'),
                          ({'inertial_damping': [1.0] * 5}, 'inertial_damping'),
                          ({'inertial_damping': [math.nan] * 6}, 'inertial_damping'),
                          ({'inertial_damping_rate': 0.0}, 'inertial_damping_rate'),
                          ({'inertial_damping_rate': math.inf}, 'inertial_damping_rate')):
        with pytest.raises(sh.ShapingError, match=match):
            sh.Shaping.create(model.n, **values)


@pytest.mark.parametrize('seed', range(3))
def test_the_settling_damping_is_alpha_m_qdot_near_the_goal_and_nothing_far(seed):
    """
    docs/lyapunov.md, section 11: ``-psi alpha M(q) qdot``, psi from max_i |lambda_i y_i|.

    psi = 1 within the linear range of every tanh (r <= 1), 0 from r = 2, smooth between; it
    damps ``qdot - g_v qdot*_d`` of a streamed goal, as K_v does.
    """
    model = xarm6_model()
    rng = np.random.default_rng(seed)
    gains = cl.Gains.create('tanh', [50.0] * 3 + [2.0] * 3, [0.5] * 6, [20.0] * 3 + [4.0] * 3,
                            POSE, 6)
    unlimited = [math.inf] * model.n
    q_goal = random_q(model, rng)
    goal = Regulator(model, POSE, gains).pose(q_goal.tolist())
    alpha = 3.0
    plain = Regulator(model, POSE, gains, unlimited, goal)
    reg = Regulator(model, POSE, gains, unlimited, goal,
                    sh.Shaping.create(model.n, settling_damping_rate=alpha))
    seen = set()
    direction = rng.normal(size=model.n)
    for step in np.geomspace(1e-4, 0.5, 40):  # from psi = 1 to psi = 0
        q = (q_goal + step * direction).tolist()
        qdot = rng.normal(size=model.n).tolist()
        y = plain.update(q, qdot).y_tilde
        r = max(abs(yi * li) for yi, li in zip(y, gains.lam))
        psi = sh.settling_fade(y, gains.lam)
        assert psi == (1.0 if r <= 1.0 else 0.0 if r >= 2.0 else pytest.approx(
            (2.0 - r) ** 2 * (3.0 - 2.0 * (2.0 - r))))
        seen.add(0.0 if psi == 0.0 else 1.0 if psi == 1.0 else 0.5)
        M = model.mass_matrix(q)  # by hand
        want = np.array(plain.update(q, qdot).tau_nm) - psi * alpha * M @ np.array(qdot)
        np.testing.assert_allclose(reg.update(q, qdot).tau_nm, want, rtol=1e-9, atol=1e-10)
        if psi == 0.0:
            assert reg.update(q, qdot).tau_nm == plain.update(q, qdot).tau_nm
    assert seen == {0.0, 0.5, 1.0}, 'the cases must cover psi = 1, between and 0'
    q = (q_goal + 0.001 * rng.normal(size=model.n)).tolist()  # psi = 1
    qdot = rng.normal(size=model.n).tolist()
    streamed = Regulator(model, POSE, gains, unlimited, goal,
                         sh.Shaping.create(model.n, settling_damping_rate=alpha,
                                           goal_velocity_gain=0.5))
    plain_streamed = Regulator(model, POSE, gains, unlimited, goal,
                               sh.Shaping.create(model.n, goal_velocity_gain=0.5))
    for r in (streamed, plain_streamed):
        r.set_goal_joint_velocity(qdot)
    want = (np.array(plain_streamed.update(q, qdot).tau_nm)
            - alpha * model.mass_matrix(q) @ (0.5 * np.array(qdot)))
    np.testing.assert_allclose(streamed.update(q, qdot).tau_nm, want, rtol=1e-9, atol=1e-10)
    for value in (-1.0, math.nan, math.inf, 41.0):
        with pytest.raises(sh.ShapingError, match='settling_damping_rate'):
            sh.Shaping.create(model.n, settling_damping_rate=value)


def test_the_learning_counts_only_a_joints_own_share_of_the_settling_damping():
    """
    docs/lyapunov.md, section 11: the other joints' share of alpha M qdot is no damping of j.

    Joint 1 is held at rest and pushed by its goal-configuration term while joints 2 and 3
    swing: their motion puts ``-alpha (M_12 qdot_2 + M_13 qdot_3)`` on joint 1, which would
    look like a damping taking its push. Joint 1 learns as much with the settling damping as
    without it.
    """
    model = xarm6_model()
    gains = cl.Gains.create('tanh', [50.0] * 3 + [2.0] * 3, [0.5] * 6, [20.0] * 3 + [4.0] * 3,
                            POSE, 6)
    q_goal = np.array([0.3, -0.2, -0.6, 0.1, 0.7, 0.2])
    goal = Regulator(model, POSE, gains).pose(q_goal.tolist())
    q = (q_goal + np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])).tolist()
    qdot = [0.0, 3.0, -3.0, 0.0, 0.0, 0.0]
    learned = {}
    for alpha in (0.0, 40.0):
        reg = Regulator(model, POSE, gains, [math.inf] * 6, goal, sh.Shaping.create(
            6, settling_damping_rate=alpha, friction_learning_limit=[1.0] * 6,
            configuration_gain=[2.0] * 6, configuration_radius=0.0))
        reg.set_goal_configuration(goal, q_goal.tolist())
        for _ in range(600):
            out = reg.update(q, qdot, 1e-3)
        assert sh.settling_fade(out.y_tilde, gains.lam) == 1.0
        learned[alpha] = reg.learned_friction_nm[0]
    coupling = 40.0 * abs(float(model.mass_matrix(q)[0] @ np.array(qdot)))
    assert coupling > 0.5 * abs(out.tau_potential_nm[0])  # it would take most of the push
    assert learned[0.0] > 0.2 and learned[40.0] == pytest.approx(learned[0.0], rel=1e-9)
    # the stall diagnosis reads the same diagonal
    M = model.mass_matrix(q)
    np.testing.assert_allclose(reg.settling_damping(q, out.y_tilde), 40.0 * np.diag(M),
                               rtol=1e-9)
    # joint 1 creeping along its push, with the inertial damping on (c tiny: k_v wins; beta
    # high: no mode capped): its own share, 40 M_11 qdot_1, counts as a damping, as the same
    # k_v more would
    creep = [0.02 * np.sign(out.tau_potential_nm[0])] + qdot[1:]
    own = {}
    for alpha, kv0 in ((40.0, 0.5), (0.0, 0.5 + 40.0 * M[0, 0])):
        g = cl.Gains.create('tanh', gains.kp, [kv0] + [0.5] * 5, gains.lam, POSE, 6)
        reg = Regulator(model, POSE, g, [math.inf] * 6, goal, sh.Shaping.create(
            6, settling_damping_rate=alpha, friction_learning_limit=[1.0] * 6,
            configuration_gain=[2.0] * 6, configuration_radius=0.0,
            inertial_damping=[1e-6] * 6, inertial_damping_rate=1e6))
        reg.set_goal_configuration(goal, q_goal.tolist())
        for _ in range(600):
            reg.update(q, creep, 1e-3)
        own[alpha] = reg.learned_friction_nm[0]
    assert 0.0 < own[40.0] == pytest.approx(own[0.0], rel=1e-9)


def test_above_the_speed_guard_the_damping_rises_to_the_sampled_cap():
    """
    docs/lyapunov.md, section 6: above 0.8 v_lim the guarded joints are damped on the excess.

    Below the guard the tick is the inertial damping's alone. A joint at 0.95 of its limit
    gets ``-beta I_j (|qdot| - 0.8 v_lim) sgn(qdot)`` more, and no other joint does; nothing
    of the other joints' push is taken away on the way. Two joints above their guards at once
    get ``-beta S^(1/2) ((M^-1)_GG)^-1 S^(1/2) qdot_G`` through the block of M^-1 that couples
    them, not ``beta I_j`` on each apart.
    """
    model = xarm6_model()
    rng = np.random.default_rng(4)
    q = random_q(model, rng).tolist()
    limits = np.array(model.velocity_limits)
    assert np.all(np.isfinite(limits))
    gains = cl.Gains.create('tanh', [50.0] * 3 + [2.0] * 3, [0.5] * 6, [20.0] * 3 + [4.0] * 3,
                            POSE, 6)
    goal = Regulator(model, POSE, gains).pose(random_q(model, rng).tolist())
    seen = np.array(model.inertias(q)[1])
    beta = 4.0 / seen.min()  # the cap above k_v = 0.5 on every joint
    reg = Regulator(model, POSE, gains, [math.inf] * 6, goal,
                    sh.Shaping.create(model.n, inertial_damping=[0.1] * 6,
                                      inertial_damping_rate=beta))
    d = np.array(reg.linear_damping(q))
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    assert np.all(np.minimum(q - lower, upper - q) > 0.05)  # the stops' own guard: none here
    slow = (0.7 * limits * np.where(np.arange(6) % 2, 1.0, -1.0)).tolist()
    base = np.array(reg.update(q, slow).tau_nm)
    minv = np.array(model.inverse_inertia(q))
    np.testing.assert_allclose(1.0 / np.diag(minv), seen, rtol=1e-9)
    guard = sh.SPEED_GUARD_FRACTION * limits
    for j in range(6):
        for sign in (1.0, -1.0):
            fast = list(slow)
            fast[j] = 0.95 * limits[j] * sign
            want = base.copy()
            want[j] -= d[j] * (fast[j] - slow[j])  # the linear damping on the faster joint
            want[j] -= beta * seen[j] * (fast[j] - sign * guard[j])
            np.testing.assert_allclose(reg.update(q, fast).tau_nm, want, rtol=1e-9,
                                       atol=1e-9)
    for pair in ((3, 5), (0, 4)):  # two at once, through the block of M^-1
        fast = list(slow)
        for j in pair:
            fast[j] = 0.95 * limits[j] * (1.0 if j % 2 else -1.0)
        G = list(pair)
        v = np.array(fast)[G]
        share = (np.abs(v) - guard[G]) / np.abs(v)
        root = np.sqrt(share)
        block = minv[np.ix_(G, G)]
        want = base.copy()
        want[G] -= d[G] * (v - np.array(slow)[G])
        want[G] -= beta * root * np.linalg.solve(block, root * v)
        got = np.array(reg.update(q, fast).tau_nm)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
        apart = want.copy()  # beta I_j on each joint's excess apart: not what the tick does
        apart[G] += beta * root * np.linalg.solve(block, root * v)
        apart[G] -= beta * seen[G] * share * v
        assert not np.allclose(got, apart, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize('within', [False, True])
def test_towards_a_stop_the_guard_acts_above_what_its_cap_stops_in_the_room_left(within):
    """
    docs/lyapunov.md, section 6: towards a stop the guard is at s beta (room - clearance).

    Each joint in turn is put near a stop (outside the clearance, or within it), moving
    towards it slower than 0.8 v_lim: it is damped at beta I_j more on the speed above
    ``STOP_GUARD_SHARE beta (distance - clearance)`` (0 within the clearance), and within the
    clearance the other joints' push along its motion is taken away, all of it; outside, none.
    Moving away from the same stop, nothing of this.
    """
    model = xarm6_model()
    rng = np.random.default_rng(7)
    limits = np.array(model.velocity_limits)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    gains = cl.Gains.create('tanh', [50.0] * 3 + [2.0] * 3, [0.5] * 6, [20.0] * 3 + [4.0] * 3,
                            POSE, 6)
    goal = Regulator(model, POSE, gains).pose(random_q(model, rng).tolist())
    margin = 0.2
    clearance = sh.STOP_CLEARANCE_SHARE * margin
    beta = 2e4  # the cap beta I_j above k_v, but on the lightest joints
    reg = Regulator(model, POSE, gains, [math.inf] * 6, goal,
                    sh.Shaping.create(model.n, inertial_damping=[0.1] * 6,
                                      inertial_damping_rate=beta, joint_limit_margin=margin,
                                      joint_limit_gain=[0.0] * 6))
    cancelled = 0
    for j in range(6):
        for sign in (1.0, -1.0):
            q = random_q(model, rng)
            distance = 0.5 * clearance if within else clearance + 1e-4
            q[j] = upper[j] - distance if sign > 0.0 else lower[j] + distance
            q = q.tolist()
            seen = np.array(model.inertias(q)[1])
            d = np.array(reg.linear_damping(q))
            gravity = np.array(model.gravity(q))
            minv = np.array(model.inverse_inertia(q))
            rest = np.array(reg.update(q, [0.0] * 6).tau_nm)
            guard = 0.0 if within else sh.STOP_GUARD_SHARE * beta * 1e-4
            speed = 0.5 * sh.SPEED_GUARD_FRACTION * limits[j]  # below the speed guard
            assert guard < speed
            qdot = [0.0] * 6
            qdot[j] = sign * speed
            want = rest.copy()
            want[j] -= d[j] * qdot[j]
            over = sign * (speed - guard)
            want[j] -= beta * seen[j] * over
            push = (minv[j] @ (want - gravity) - minv[j, j] * (want[j] - gravity[j]))
            if push * over > 0.0 and within:  # on towards the stop: taken away
                cancelled += 1
                want[j] -= push * seen[j]
            np.testing.assert_allclose(reg.update(q, qdot).tau_nm, want, rtol=1e-9,
                                       atol=1e-9)
            qdot[j] = -qdot[j]  # away from the stop: the linear damping alone
            np.testing.assert_allclose(reg.update(q, qdot).tau_nm,
                                       rest - d * np.array(qdot), rtol=1e-9, atol=1e-9)
    assert (cancelled > 0) == within


@pytest.mark.parametrize('with_q_star', [True, False])
def test_the_learned_push_is_gone_along_a_motion_at_six_tenths_of_the_velocity_limit(
        with_q_star):
    """Learned at rest, the push is whole at rest and nothing along a motion at 0.6 v_lim."""
    model = wrist_model()
    goal = Goal(paper.Q_DESIRED)
    q = [1.0, 1.0, 1.0]

    def regulator(limit):
        shaping = sh.Shaping.create(3, friction_learning_limit=(limit,) * 3,
                                    friction_learning_time=0.1)
        reg = Regulator(model, ORI, paper_gains(), goal=goal, shaping=shaping)
        if with_q_star:  # far from q*: the creep speed at its top, 0.4 v_lim
            assert reg.set_goal_configuration(goal, [-1.0, -1.0, -1.0])
        return reg
    learning, plain = regulator(2.0), regulator(0.0)
    for _ in range(1000):  # held at rest: it learns
        learning.update(q, [0.0] * 3, 1e-3)
    learned = learning.learned_friction_nm
    assert all(a > 1.0 for a in learned), learned
    rest = np.subtract(learning.update(q, [0.0] * 3).tau_nm, plain.update(q, [0.0] * 3).tau_nm)
    push = np.sign(plain.update(q, [0.0] * 3).tau_potential_nm)
    np.testing.assert_allclose(np.abs(rest), learned, rtol=1e-2)
    assert np.all(np.sign(rest) == push)
    v_lim = np.array(model.velocity_limits)
    for share in (0.6, 1.0, 3.0):  # along the push, at and above the fade's top
        qdot = (share * v_lim * push).tolist()
        extra = np.subtract(learning.update(q, qdot).tau_nm, plain.update(q, qdot).tau_nm)
        assert np.all(np.abs(extra) < 1e-6 * np.array(learned)), (share, extra)


@pytest.mark.parametrize('inertial', [False, True])
def test_a_learned_push_and_its_tick_of_delay_leave_a_light_joint_within_its_limit(inertial):
    """
    docs/lyapunov.md, section 4: the larger the push learned, the lower its fade starts.

    The wrist's joint 3, held at rest, learns the most design_gains lets it: a push that
    changes its speed by 0.4 of its velocity limit in one tick on the inertia it sees. Along
    the push, at every speed up to the limit, two ticks of what the learned push adds (the
    tick and the loop's tick of delay), with no friction to take it, leave the joint within
    its limit; at rest all of it acts. With and without the inertial damping (which computes
    that inertia in the tick).
    """
    from quat_jt_controller.gain_design import TICK_SPEED_SHARE
    model = wrist_model()
    dt = 1e-3
    near = [v + 0.3 for v in paper.Q_JOINT_DESIRED_RAD]
    seen = model.inertias(near)[1][2]
    v_lim = model.velocity_limits[2]
    a_max = TICK_SPEED_SHARE * v_lim * seen / dt
    extra = {'inertial_damping': (1e-3,) * 3, 'inertial_damping_rate': 100.0} if inertial else {}
    shaping = sh.Shaping.create(3, friction_learning_limit=(0.0, 0.0, a_max), **extra)
    unclamped = [math.inf] * 3  # the push is larger than the effort limit: the law itself
    learned, bare = (Regulator(model, ORI, paper_gains(), unclamped, Goal(paper.Q_DESIRED),
                               shaping) for _ in range(2))
    for _ in range(3000):
        learned.update(near, [0.0] * 3, dt)
    assert learned.learned_friction_nm[2] > 0.95 * a_max
    far = [near[0], near[1], near[2] - 2.0]  # q*: creeping at the top of its creep speed
    for reg in (learned, bare):
        assert reg.set_goal_configuration(reg.goal, far)
    sign = math.copysign(1.0, learned.update(near, [0.0] * 3).tau_potential_nm[2])
    landed = []
    for v in np.linspace(0.0, v_lim, 400):
        qdot = [0.0, 0.0, sign * v]
        push = learned.update(near, qdot).tau_nm[2] - bare.update(near, qdot).tau_nm[2]
        landed.append(v + 2.0 * sign * push * dt / seen)
    assert landed[0] == pytest.approx(2.0 * TICK_SPEED_SHARE * v_lim, rel=0.06)  # all of it
    assert max(landed) <= v_lim * (1.0 + 1e-9)

"""
The extensions of the law (quat_jt_controller.shaping, docs/lyapunov.md), ROS-free.

Each potential term's torque is minus the gradient of its energy (finite differences) through
the one tick, ``Regulator.update``; the joint-limit term is C1 and zero away from the limits;
the large-error term keeps the torque where the paper's fades; the friction compensation
never exceeds its estimate and acts in the direction of the potential torque at rest.
"""
import dataclasses
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.regulator import Goal, Regulator
from robots import random_q, wrist_model, xarm6_model

pytestmark = pytest.mark.unit

ORI, POSE = cl.Task.ORIENTATION, cl.Task.POSE
ALL_ON = {'joint_limit_margin': 0.3, 'joint_limit_gain': (40.0, 30.0, 20.0),
          'large_error_gain': 5.0, 'configuration_gain': (6.0, 5.0, 4.0),
          'configuration_radius': 0.05, 'configuration_ramp': 0.3}


def wrist_regulator(shaping: sh.Shaping, potential: str = 'tanh') -> Regulator:
    gains = cl.Gains.create(potential, (8.0, 8.0, 8.0), (1.0, 1.0, 1.0), (4.0, 4.0, 4.0),
                            ORI, 3)
    return Regulator(wrist_model(), ORI, gains, [math.inf] * 3, Goal(paper.Q_DESIRED),
                     shaping)


def numeric_gradient(f, q, h=1e-6):
    q = np.asarray(q, float)
    return np.array([(f(q + h * np.eye(q.size)[i]) - f(q - h * np.eye(q.size)[i])) / (2 * h)
                     for i in range(q.size)])


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
@pytest.mark.parametrize('seed', range(4))
def test_wrist_torque_is_minus_the_gradient_of_the_whole_potential(potential, seed):
    """Eq. (21)-(22) with U = U_a + k_L B + U_lim + U_c: tau(qdot = 0) - g = -grad U."""
    rng = np.random.default_rng(seed)
    reg = wrist_regulator(sh.Shaping.create(3, **ALL_ON), potential)
    q_star = random_q(reg.model, rng)
    assert reg.set_goal_configuration(reg.goal, q_star)
    # joint 1 inside its band, the others anywhere: every term contributes somewhere
    q = random_q(reg.model, rng, margin=0.0)
    q[0] = math.pi - 0.1
    tau = np.array(reg.update(q.tolist(), [0.0] * 3).tau_nm) - reg.model.gravity(q.tolist())
    grad = numeric_gradient(lambda x: reg.potential_energy(x.tolist()), q)
    np.testing.assert_allclose(tau, -grad, atol=2e-5 * max(1.0, np.abs(grad).max()))


def test_xarm6_pose_torque_is_minus_the_gradient_of_the_whole_potential():
    model = xarm6_model()
    rng = np.random.default_rng(3)
    gains = cl.Gains.create('tanh', (30.0,) * 3 + (2.0,) * 3, (1.0,) * 6, (20.0,) * 3 + (4.0,) * 3,
                            POSE, 6)
    shaping = sh.Shaping.create(6, joint_limit_margin=0.3, joint_limit_gain=(10.0,) * 6,
                                large_error_gain=1.0, configuration_gain=(2.0,) * 6,
                                configuration_radius=0.0, configuration_ramp=0.5)
    q_goal = random_q(model, rng)
    p, R = model.forward_kinematics(q_goal.tolist())
    reg = Regulator(model, POSE, gains, [math.inf] * 6,
                    Goal(quat.from_rotation_matrix(R), tuple(p)), shaping)
    reg.set_goal_configuration(reg.goal, q_goal)
    q = random_q(model, rng, margin=0.0)
    q[2] = model.position_upper[2] - 0.1  # joint 3 in its band
    assert reg.limit_band is not None and 2 in reg.limit_band.joints
    assert 0 not in reg.limit_band.joints  # joint 1 turns through 4 pi: no limit term
    tau = np.array(reg.update(q.tolist(), [0.0] * 6).tau_nm) - model.gravity(q.tolist())
    grad = numeric_gradient(lambda x: reg.potential_energy(x.tolist()), q)
    np.testing.assert_allclose(tau, -grad, atol=2e-5 * max(1.0, np.abs(grad).max()))


def test_joint_limit_potential_is_c1_zero_outside_the_band_and_pushes_out():
    model = wrist_model()
    band = sh.LimitBand.create(model.position_lower, model.position_upper,
                               sh.Shaping.create(3, joint_limit_margin=0.25,
                                                 joint_limit_gain=(40.0, 30.0, 20.0)))
    edge = model.position_upper[1] - 0.25
    for q2 in (0.0, edge - 1e-9, edge):
        tau = [0.0] * 3
        band.add_torque([0.0, q2, 0.0], tau)
        assert tau == [0.0, 0.0, 0.0] and band.energy([0.0, q2, 0.0]) == 0.0
    for depth in (1e-6, 1e-3, 0.1, 0.25):  # continuous torque from zero at the edge: C1
        tau = [0.0] * 3
        band.add_torque([0.0, edge + depth, 0.0], tau)
        assert tau[1] == pytest.approx(-30.0 * depth) and tau[0] == tau[2] == 0.0
        assert band.energy([0.0, edge + depth, 0.0]) == pytest.approx(15.0 * depth ** 2)
    tau = [0.0] * 3
    band.add_torque([model.position_lower[0] + 0.05, 0.0, 0.0], tau)
    assert tau[0] == pytest.approx(40.0 * 0.2)  # lower band: pushes up
    assert band.depth([0.0, model.position_upper[1], 0.0])[1] == pytest.approx(1.0)


def test_joint_limit_margin_must_fit_the_range():
    model = wrist_model()
    with pytest.raises(sh.ShapingError, match='leaves no room'):  # a 1 rad range, 0.6 bands
        sh.LimitBand.create((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5),
                            sh.Shaping.create(3, joint_limit_margin=0.6,
                                              joint_limit_gain=(1.0, 1.0, 1.0)))
    assert sh.LimitBand.create(model.position_lower, model.position_upper,
                               sh.Shaping.create(3, joint_limit_margin=0.3)) is None


@pytest.mark.parametrize('name, kwargs, words', [
    ('negative gain', {'joint_limit_gain': (1.0, -1.0, 1.0)}, 'joint_limit_gain[1]'),
    ('wrong size', {'friction_compensation': (1.0, 1.0)}, 'must have 3 values'),
    ('nan', {'large_error_gain': math.nan}, 'large_error_gain must be finite'),
    ('zero band', {'friction_error_band': 0.0}, 'friction_error_band must be in [1e-05, 1]'),
    ('above its range', {'large_error_gain': 1001.0}, 'large_error_gain must be in [0, 1000]'),
])
def test_invalid_extensions_are_refused_with_their_name(name, kwargs, words):
    with pytest.raises(sh.ShapingError, match=words.replace('[', r'\[').replace(']', r'\]')):
        sh.Shaping.create(3, **kwargs)


def test_large_error_term_keeps_the_torque_where_the_papers_fades():
    """Near a half turn Q^T K_p e fades like eta_e; with k_L B it stays near k_L / 2."""
    k, k_l = 10.0, 10.0
    paper_only = cl.Gains.create('quadratic', (k,) * 3, (1.0,) * 3, (1.0,) * 3, ORI, 3)
    for theta_deg in (90.0, 150.0, 165.0):
        half = math.radians(theta_deg) / 2.0
        e = (0.0, 0.0, math.sin(half))
        eta_e = math.cos(half)
        base = np.linalg.norm(cl.task_force(e, eta_e, paper_only))
        extended = np.linalg.norm(cl.task_force(e, eta_e, paper_only, k_l))
        assert base == pytest.approx(0.5 * k * eta_e * math.sin(half))
        assert extended - base > 0.8 * 0.5 * k_l * math.sin(half) ** 2 * eta_e / math.sqrt(
            eta_e ** 2 + cl.LARGE_ERROR_DELTA ** 2) - 1e-12
        if theta_deg >= 150.0:
            assert extended > 3.0 * base
    # it fades to zero at the half turn itself (continuous torque) and is flat at the goal
    assert np.linalg.norm(cl.task_force((0.0, 0.0, 1.0), 0.0, paper_only, k_l)) < 1e-12
    assert cl.large_error_energy(1e-3, k_l) < 1e-8
    h = 1e-6
    for x in (0.1, 0.5, 0.9, 0.999):  # B' = s^2 / sqrt(a^2 - s^2) = (gradient scale) s
        slope = (cl.large_error_energy(x + h, k_l) - cl.large_error_energy(x - h, k_l)) / (2 * h)
        assert slope == pytest.approx(cl.large_error_gradient_scale(x * x, k_l) * x, rel=1e-5)


@settings(max_examples=200, deadline=None)
@given(tau_p=st.lists(st.floats(-50, 50), min_size=3, max_size=3),
       qdot=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
       error=st.floats(0.0, 1.0))
def test_friction_compensation_never_exceeds_its_estimate(tau_p, qdot, error):
    shaping = sh.Shaping.create(3, friction_compensation=(2.0, 0.8, 0.5))
    y = (error, 0.0, 0.0)
    fc = sh.friction_compensation(tau_p, qdot, sh.fade(y, shaping), shaping)
    for value, f in zip(fc, shaping.friction_compensation_nm):
        assert abs(value) <= f * (1.0 + 1e-12)


def test_friction_compensation_at_rest_pushes_with_the_potential_and_fades_at_the_goal():
    shaping = sh.Shaping.create(3, friction_compensation=(2.0, 0.8, 0.5),
                                friction_error_band=0.004)
    at_rest = [0.0, 0.0, 0.0]
    far = sh.fade((0.1, 0.0, 0.0), shaping)
    assert far == 1.0
    fc = sh.friction_compensation([0.3, -0.2, 0.0], at_rest, far, shaping)
    assert fc[0] == pytest.approx(2.0) and fc[1] == pytest.approx(-0.8) and fc[2] == 0.0
    assert sh.fade((0.0019, 0.0, 0.0), shaping) == 0.0  # below half the band: off
    assert 0.0 < sh.fade((0.003, 0.0, 0.0), shaping) < 1.0
    # moving the way the potential pushes: the friction of the moving joint is compensated
    moving = sh.friction_compensation([0.3, -0.2, 0.0], [1.0, -1.0, 0.0], far, shaping)
    assert moving[0] == pytest.approx(2.0) and moving[1] == pytest.approx(-0.8)
    # moving against it (past the goal): nothing along the motion, the friction brakes it
    overshoot = sh.friction_compensation([-0.3, 0.2, 0.0], [1.0, -1.0, 0.0], far, shaping)
    assert -2.0 * (1.0 - math.tanh(20.0)) <= overshoot[0] <= 0.0
    assert 0.0 <= overshoot[1] <= 0.8 * (1.0 - math.tanh(20.0))
    slow = sh.friction_compensation([-0.3, 0.0, 0.0], [0.01, 0.0, 0.0], far, shaping)
    assert slow[0] == pytest.approx(-2.0 * (1.0 - math.tanh(0.2)))  # towards the potential
    # near the goal all of it is off: an over-estimate cannot cycle there
    assert sh.friction_compensation([0.3, -0.2, 0.0], [1.0, -1.0, 0.0], 0.0, shaping) == [0.0] * 3
    pose = sh.fade((0.002, 0.0, 0.0, 0.0, 0.0, 0.0), shaping)  # 2 mm, band 0.5 mm
    assert pose == 1.0


def test_friction_learning_grows_only_while_stuck_off_the_goal_and_leaks_at_it():
    shaping = sh.Shaping.create(2, friction_compensation=(1.0, 1.0),
                                friction_learning_limit=(0.5, 0.0), friction_learning_time=1.0)
    assert shaping.learning_on and shaping.friction_on
    learned = [0.0, 0.0]

    def learn(tau_p, qdot, phi):  # one tick, as the regulator runs it
        stuck = [0.0, 0.0]
        sh.friction_compensation(tau_p, qdot, phi, shaping, learned, stuck)
        sh.learn_friction(learned, stuck, phi, shaping, 1e-3)
    for _ in range(250):  # stuck, pushed, far from the goal: 0.5 N m/s
        learn([0.3, 0.3], [0.0, 0.0], 1.0)
    assert learned[0] == pytest.approx(0.125, rel=1e-3) and learned[1] == 0.0
    fc = sh.friction_compensation([0.3, 0.3], [0.0, 0.0], 1.0, shaping, learned)
    assert fc[0] == pytest.approx(1.125, rel=1e-3) and fc[1] == pytest.approx(1.0)
    for _ in range(2000):  # capped at the limit
        learn([0.3, 0.3], [0.0, 0.0], 1.0)
    assert learned[0] == 0.5
    before = list(learned)
    learn([0.3, 0.3], [1.0, 0.0], 1.0)  # moving: holds
    assert learned == before
    for _ in range(1000):  # within the band (phi = 0): leaks with the learning time
        learn([0.3, 0.3], [0.0, 0.0], 0.0)
    assert learned[0] == pytest.approx(0.5 * math.exp(-1.0), rel=2e-3)


def _learning_tick(shaping, learned, held, tau_p, qdot, damping, phi=1.0, inertial=None,
                   slid=None):
    """
    One tick of the learning as the regulator runs it, with the damping torque given.

    With ``slid`` (learn_friction's ``g`` per joint, kept by the caller as ``held``) the
    friction a sliding joint meets counts too, as in the regulator; without it, the rule for
    a held joint alone.
    """
    n = len(qdot)
    stuck, unmet = [0.0] * n, [0.0] * n
    sliding = None if slid is None else [0.0] * n
    sh.friction_compensation(tau_p, qdot, phi, shaping, learned, stuck, damping, unmet,
                             inertial_nm=inertial,
                             equilibrium_band_nm=shaping.learning_torque_band,
                             sliding_out=sliding)
    sh.learn_friction(learned, stuck, phi, shaping, 1e-3, unmet, held, sliding, slid)


def test_friction_learning_tells_a_stuck_joint_from_a_slow_approach_and_a_turning_point():
    """
    Held by stiction it learns; slowed by its damping, or only turning round, it does not.

    Joint 0 is at rest and pushed (no damping torque at rest): held. Joint 1 moves slowly the
    way it is pushed, its damping taking the whole push (an approach). Joint 2 swings: at rest
    for 20 ms at each turning point, pushed back, then moving at speed, what its damping does
    not take of the push going into its acceleration (``M qddot``).
    """
    kv = 0.5
    shaping = sh.Shaping.create(3, friction_learning_limit=(0.5, 0.5, 0.5),
                                friction_learning_time=1.0)
    learned, held, slid = [0.0] * 3, [0.0] * 3, [0.0] * 3
    for k in range(1000):
        swing = 0.0 if k % 200 < 20 else (0.4 if (k // 200) % 2 else -0.4)
        tau_p = [0.3, 0.3, 0.3 if (k // 200) % 2 else -0.3]
        qdot = [0.0, 0.3 / kv * 0.01, swing]
        damping = [-kv * v for v in qdot]
        tau_p[1] = kv * qdot[1]  # the push the damping balances: a slow, steady approach
        inertial = [0.0, 0.0, tau_p[2] + damping[2] if swing else 0.0]
        _learning_tick(shaping, learned, held, tau_p, qdot, damping, inertial=inertial,
                       slid=slid)
    assert learned[0] > 0.5 * 0.5 * (1.0 - 2.0 * sh.HOLD_TIME_FRACTION)  # stiction: learns
    assert learned[1] == 0.0 and learned[2] == 0.0
    # a held joint starts learning only after it has stayed held a while (no turning point)
    learned, held = [0.0], [0.0]
    one = sh.Shaping.create(1, friction_learning_limit=(0.5,))
    for _ in range(int(0.5 * sh.HOLD_TIME_FRACTION * 1000)):
        _learning_tick(one, learned, held, [0.3], [0.0], [0.0])
    assert learned == [0.0]
    for _ in range(int(2.0 * sh.HOLD_TIME_FRACTION * 1000)):
        _learning_tick(one, learned, held, [0.3], [0.0], [0.0])
    assert learned[0] > 0.0


def test_a_joint_at_its_own_equilibrium_learns_little():
    """
    Held at rest, a joint learns as fast as its potential torque says it is away from its rest.

    With the goal-configuration term (gain T, ramp w), ``LEARNING_ANGLE_RAD T / w`` is what it
    asks that far from q*. Joint 0 is pushed with 10 x that (held away from its rest by a
    friction: it learns as before), joint 1 with a tenth of it (it sits at its own equilibrium:
    a friction is no reason to push it, and a learned push there only makes it slip to and
    fro): below about an eighth of the band it does not even count as held. Without the term,
    both learn alike (the band is 0).
    """
    values = {'friction_learning_limit': (0.5, 0.5), 'friction_learning_time': 1.0,
              'configuration_gain': (2.0, 2.0), 'configuration_ramp': 0.25}
    shaping = sh.Shaping.create(2, **values)
    band = sh.LEARNING_ANGLE_RAD * 2.0 / 0.25
    assert shaping.learning_torque_band == pytest.approx((band, band))
    learned, held = [0.0, 0.0], [0.0, 0.0]
    for _ in range(500):
        _learning_tick(shaping, learned, held, [10.0 * band, 0.1 * band], [0.0, 0.0],
                       [0.0, 0.0])
    free = sh.Shaping.create(2, **dict(values, configuration_gain=(0.0, 0.0)))
    assert free.learning_torque_band == (0.0, 0.0)
    alike, held_free = [0.0, 0.0], [0.0, 0.0]
    for _ in range(500):
        _learning_tick(free, alike, held_free, [10.0 * band, 0.1 * band], [0.0, 0.0],
                       [0.0, 0.0])
    assert alike[1] == pytest.approx(alike[0], rel=1e-3) and alike[0] > 0.1
    assert learned[0] == pytest.approx(alike[0], rel=1e-3)  # tanh(10): as before
    # a tenth of the band: tanh(0.1) x 4 < 1/2, never counts as held, learns nothing; half
    # of it: held, learning at tanh(0.5) of the rate
    assert learned[1] == 0.0
    half, held_half = [0.0], [0.0]
    one = sh.Shaping.create(1, **{k: v[:1] if isinstance(v, tuple) else v
                                  for k, v in values.items()})
    for _ in range(500):
        _learning_tick(one, half, held_half, [0.5 * band], [0.0], [0.0])
    assert 0.3 * learned[0] < half[0] < 0.6 * learned[0]
    # without q* (the regulator passes no band then) the joint learns as without the term
    stuck = [0.0, 0.0]
    sh.friction_compensation([0.1 * band] * 2, [0.0, 0.0], 1.0, shaping, [0.0, 0.0], stuck)
    assert stuck[1] == pytest.approx(1.0, rel=1e-3)


def test_a_joint_the_push_accelerates_is_not_held():
    """
    What the acceleration takes (``M qddot``) is not friction: a joint it takes is not held.

    Joint 0 is at rest, pushed, not accelerating: held (``w`` = 1). Joint 1 is at rest at a
    swing's turning point, its push all going into acceleration: ``w`` = 0, and nothing is
    learned however long that lasts. Joint 2 is braked harder than its damping explains (a
    friction): ``w`` stays at most 1.
    """
    shaping = sh.Shaping.create(3, friction_learning_limit=(0.5, 0.5, 0.5))
    stuck, unmet = [0.0] * 3, [0.0] * 3
    tau_p = [0.3, 0.3, 0.3]
    sh.friction_compensation(tau_p, [0.0] * 3, 1.0, shaping, [0.0] * 3, stuck, [0.0] * 3,
                             unmet, inertial_nm=[0.0, 0.3, -0.2])
    assert unmet == [1.0, 0.0, 1.0]
    assert stuck[0] == pytest.approx(1.0) and stuck[1] == 0.0
    learned, held = [0.0] * 3, [0.0] * 3
    for _ in range(1000):
        stuck, unmet = [0.0] * 3, [0.0] * 3
        sh.friction_compensation(tau_p, [0.0] * 3, 1.0, shaping, learned, stuck, [0.0] * 3,
                                 unmet, inertial_nm=[0.0, 0.3 + learned[1], 0.0])
        sh.learn_friction(learned, stuck, 1.0, shaping, 1e-3, unmet, held)
    assert learned[0] > 0.25 and learned[1] == 0.0


def test_friction_learning_goes_on_in_a_steady_creep_below_the_creep_speed():
    """
    A joint sliding steadily at 0.6 x its creep speed, a friction taking the push, learns.

    It is held (the damping takes almost none of the push) and slower than its creep speed:
    the compensation is not yet enough, so ``a`` must grow until the joint reaches the creep
    speed, not stall at a crawl. The same slide at the creep speed learns nothing held. (The
    rule for a held joint alone: at a speed fixed whatever the push, the friction met, which
    a sliding joint also learns, would be all of the push, learned or not: no plant's.)
    """
    shaping = sh.Shaping.create(2, friction_learning_limit=(1.0, 1.0), friction_velocity=0.05)
    creep = sh.CREEP_SPEED_FACTOR * 0.05
    kv = 0.01
    learned, held = [0.0, 0.0], [0.0, 0.0]
    qdot = [0.6 * creep, creep]
    for _ in range(1000):
        _learning_tick(shaping, learned, held, [0.3, 0.3], qdot, [-kv * v for v in qdot])
    assert learned[0] > 0.1
    assert learned[1] == 0.0


def test_friction_learning_outgrows_its_leak_where_a_friction_takes_most_of_the_push():
    """
    Sliding at half its creep speed with a friction taking 80% of the push, ``a`` grows.

    The damping takes the other 20%: the joint is moving, but slower than its creep speed
    because the friction holds it back, so the learned push must grow past its leak (with a
    leak linear in the damping's share, it settled where it was, a crawl).
    """
    shaping = sh.Shaping.create(1, friction_learning_limit=(1.0,), friction_velocity=0.05)
    creep = sh.CREEP_SPEED_FACTOR * 0.05
    learned, held, slid = [0.3], [1.0], [0.0]
    qdot = [0.5 * creep]
    for _ in range(2000):
        push = 0.3 + learned[0]  # tau_p + the learned push along the motion
        _learning_tick(shaping, learned, held, [0.3], qdot, [-0.2 * push], slid=slid)
    assert learned[0] > 0.6


def test_a_joint_sliding_against_a_friction_learns_it_up_to_its_creep_speed():
    """
    A joint a friction slows, moving the way it is pushed, learns what takes it to its creep speed.

    Quasi-static slide of one joint (Romeo's left-arm joint of docs/reach.md, "A joint sliding
    against a friction"): ``K_v qdot = tau_p + tau_fc - F``, the friction ``F`` near the
    potential's push. Held at rest, the rule for a held joint lets it go and then keeps a
    share of ``F`` where its growth, weak near the creep speed, meets the leak of the damping's
    share: it slides at under 0.8 of its creep speed. What the friction takes of the push,
    ``w |u|``, is ``F``, and with it counted ``a`` rises until the joint slides between 3/4 of
    its creep speed and that speed, no faster (a light joint pushed on into the fade of the
    learned push there swung each tick between the two speeds). Without the friction the
    damping takes the whole push: nothing is learned.
    """
    v_eps = 0.02
    shaping = sh.Shaping.create(2, friction_learning_limit=(0.1, 0.1), friction_velocity=v_eps)
    kv, tau_p, friction = 0.032, 0.025, (0.0218, 0.0)
    creep, fade = [0.44] * 2, [0.66] * 2  # the creep and fade speeds of a far q*

    def slide(counted):  # 3 s of the slide; the friction met counted or not
        learned, held, slid, qdot = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
        for _ in range(3000):
            stuck, unmet, sliding = [0.0] * 2, [0.0] * 2, [0.0] * 2
            fc = sh.friction_compensation([tau_p] * 2, qdot, 1.0, shaping, learned, stuck,
                                          [-kv * v for v in qdot], unmet, creep, fade,
                                          sliding_out=sliding if counted else None)
            sh.learn_friction(learned, stuck, 1.0, shaping, 1e-3, unmet, held,
                              sliding if counted else None, slid if counted else None)
            qdot = [max(0.0, tau_p + c - f) / kv for c, f in zip(fc, friction)]
        return learned, qdot
    held_only, crawl = slide(False)
    learned, qdot = slide(True)
    assert crawl[0] < 0.8 * creep[0]
    assert 0.85 * creep[0] < qdot[0] <= creep[0] and held_only[0] < learned[0] < friction[0]
    assert learned[1] == 0.0 and qdot[1] == pytest.approx(tau_p / kv)


def test_the_friction_met_sliding_is_given_on_its_own_and_only_along_the_push():
    """
    ``sliding_out`` alone (no ``stuck_out`` or ``unmet_out``): ``w |u| - f`` along the push.

    Joint 0 slides along its push at half its creep speed, its damping taking 0.1 of the 0.3
    N m: the friction met is 0.2. Joint 1 is at rest, joint 2 moves against its push and
    joint 3 above its creep speed: none. Every entry is written, whatever the list held.
    """
    v_eps = 0.05
    shaping = sh.Shaping.create(4, friction_learning_limit=(1.0,) * 4, friction_velocity=v_eps)
    creep = sh.CREEP_SPEED_FACTOR * v_eps
    qdot = [0.5 * creep, 0.0, -0.5 * creep, 1.5 * creep]
    sliding = [9.9] * 4
    sh.friction_compensation([0.3] * 4, qdot, 1.0, shaping, [0.0] * 4,
                             damping_nm=[-0.1] * 4, sliding_out=sliding)
    along = math.tanh(0.5 * creep / v_eps) * math.tanh(0.3 / (0.001 * 1.0))
    assert sliding[0] == pytest.approx(0.2 * along) and sliding[1:] == [0.0, 0.0, 0.0]


def test_learned_friction_holds_against_a_friction_and_leaks_where_the_damping_takes_it():
    """Sliding with friction taking the push, ``a`` holds; moving freely it leaks fast."""
    shaping = sh.Shaping.create(1, friction_learning_limit=(1.0,), friction_velocity=0.05)
    kv, friction = 1.0, 0.895
    learned, held, slid = [0.8], [1.0], [0.0]
    for _ in range(300):  # sliding at 5 mm/s: the friction takes nearly all of the push
        push = 0.1 + learned[0]
        qdot = (push - friction) / kv
        _learning_tick(shaping, learned, held, [0.1], [qdot], [-kv * qdot], slid=slid)
    assert learned[0] > 0.7
    learned = [0.8]
    for _ in range(300):  # released: nothing holds it, the damping takes the push
        qdot = (0.1 + learned[0]) / kv
        _learning_tick(shaping, learned, held, [0.1], [qdot], [-kv * qdot], slid=slid)
    assert learned[0] < 0.8 * math.exp(-0.3 / (sh.HOLD_TIME_FRACTION * 1.0)) * 1.5
    for _ in range(1000):  # near the goal (phi 0) it leaks with the learning time
        _learning_tick(shaping, learned, held, [0.0], [0.0], [0.0], phi=0.0, slid=slid)
    assert learned[0] < 0.1


def test_regulator_releases_a_stuck_joint_then_forgets_what_nothing_holds():
    """A joint held off the goal: the regulator learns to push it; moving freely, it stops."""
    model = wrist_model()
    gains = cl.Gains.create('tanh', (8.0,) * 3, (1.5, 1.2, 0.8), (4.0,) * 3, ORI, 3)
    shaping = sh.Shaping.create(3, friction_learning_limit=(1.5, 0.9, 0.6))
    reg = Regulator(model, ORI, gains, None, None, shaping)
    q_held = [0.0, 0.5, 0.0]
    reg.hold(q_held)
    reg.set_goal(reg.pose([0.2, 0.6, 0.1]))
    push = [abs(t) for t in reg.update(q_held, [0.0] * 3).tau_potential_nm]
    for _ in range(1000):  # held at rest for 1 s: the learned push grows
        out = reg.update(q_held, [0.0] * 3, 1e-3)
    learned = reg.learned_friction_nm
    assert all(a > 0.1 * a_max for a, a_max in zip(learned, shaping.friction_learning_limit_nm))
    gravity = model.gravity(q_held)
    assert all(abs(t - g) > p for t, g, p in zip(out.tau_nm, gravity, push))  # pushes harder
    # released: it moves the way it is pushed, as fast as its damping lets the push drive it
    qdot = [(p + a) / k * math.copysign(1.0, t)
            for p, a, k, t in zip(push, learned, gains.kv, out.tau_potential_nm)]
    for _ in range(int(3 * sh.HOLD_TIME_FRACTION * 1000)):
        reg.update(q_held, qdot, 1e-3)
    assert all(a < 0.1 * a0 for a, a0 in zip(reg.learned_friction_nm, learned))


def test_regulator_learns_friction_only_from_ticks_with_a_time_step():
    model = wrist_model()
    gains = cl.Gains.create('tanh', (8.0,) * 3, (1.5, 1.2, 0.8), (4.0,) * 3, ORI, 3)
    shaping = sh.Shaping.create(3, friction_compensation=(1.0, 0.5, 0.3),
                                friction_learning_limit=(1.0, 0.5, 0.3))
    reg = Regulator(model, ORI, gains, None, None, shaping)
    reg.hold([0.0, 0.5, 0.0])
    reg.set_goal(reg.pose([0.2, 0.6, 0.1]))  # off the goal, at rest
    for _ in range(100):
        reg.update([0.0, 0.5, 0.0], [0.0] * 3)  # re-evaluations: no time passes
    assert reg.learned_friction_nm == (0.0, 0.0, 0.0)
    for _ in range(int(2.0 * sh.HOLD_TIME_FRACTION * 1000)):  # stuck for a while
        reg.update([0.0, 0.5, 0.0], [0.0] * 3, 1e-3)
    assert all(a > 0.0 for a in reg.learned_friction_nm)
    reg.set_shaping(dataclasses.replace(shaping, friction_learning_limit_nm=()))
    assert reg.learned_friction_nm == (0.0, 0.0, 0.0)  # learning off: forgotten


def test_the_band_ends_at_a_goal_configuration_inside_it():
    """A q* in the band is a minimum of the whole potential: no push away from the goal."""
    model = wrist_model()
    gains = cl.Gains.create('tanh', (8.0,) * 3, (1.5, 1.2, 0.8), (4.0,) * 3, ORI, 3)
    shaping = sh.Shaping.create(3, joint_limit_margin=0.25, joint_limit_gain=(40.0,) * 3,
                                configuration_gain=(6.0,) * 3, configuration_radius=0.0)
    reg = Regulator(model, ORI, gains, [math.inf] * 3, None, shaping)
    q_star = [0.3, model.position_upper[1] - 0.1, -0.2]  # joint 2 0.15 rad deep in its band
    reg.set_goal(reg.pose(q_star))
    band_push = reg.update(q_star, [0.0] * 3).tau_potential_nm  # q* not known yet
    assert band_push[1] < -1.0  # the band pushes joint 2 away from its goal
    assert reg.set_goal_configuration(reg.goal, q_star)
    assert reg.goal_in_band() == (1,)
    out = reg.update(q_star, [0.0] * 3)
    np.testing.assert_allclose(out.tau_potential_nm, 0.0, atol=1e-9)
    beyond = list(q_star)
    beyond[1] += 0.05  # towards the stop, beyond q*: pushed back, by the band too
    tau = reg.update(beyond, [0.0] * 3).tau_potential_nm
    assert tau[1] < -40.0 * 0.05 * 0.99
    assert reg.potential_energy(q_star) == pytest.approx(0.0, abs=1e-12)
    assert reg.potential_energy(beyond) > 0.0
    reg.set_goal_configuration(reg.goal, [0.3, 0.5, -0.2])  # outside the bands
    assert reg.goal_in_band() == ()
    wall = model.position_upper[1] - 0.25  # the band's inner edge
    for depth, joints in ((0.5 * sh.BAND_DEPTH_TOLERANCE_RAD, ()),
                          (2.0 * sh.BAND_DEPTH_TOLERANCE_RAD, (1,))):  # as the goal check
        q_wall = [0.3, wall + depth, -0.2]
        reg.set_goal(reg.pose(q_wall))
        assert reg.set_goal_configuration(reg.goal, q_wall)
        assert reg.goal_in_band() == joints


def test_goal_configuration_term_is_a_huber_spring_with_a_dead_zone():
    shaping = sh.Shaping.create(2, configuration_gain=(4.0, 0.0), configuration_radius=0.1,
                                configuration_ramp=0.2)
    q_star = (1.0, 1.0)
    for q0, want in ((1.05, 0.0), (1.2, -2.0), (0.8, 2.0), (1.5, -4.0), (-3.0, 4.0)):
        tau = [0.0, 0.0]
        sh.add_configuration_torque((q0, 5.0), q_star, shaping, tau)
        assert tau == [pytest.approx(want), 0.0]
    q = np.array([1.25, 0.0])
    grad = numeric_gradient(lambda x: sh.configuration_energy(x, q_star, shaping), q)
    tau = [0.0, 0.0]
    sh.add_configuration_torque(q, q_star, shaping, tau)
    np.testing.assert_allclose(tau, -grad, atol=1e-6)


def test_cubic_damping_only_dissipates_and_is_linear_near_rest():
    shaping = sh.Shaping.create(3, damping_speed=(2.0, 0.0, 1.0))
    kv = (1.0, 1.0, 0.5)
    cap = (3.0, 3.0, 3.0)
    for qdot in ([0.01, 0.01, 0.01], [3.0, -2.0, -4.0], [50.0, 1.0, -50.0]):
        tau = [0.0] * 3
        sh.add_speed_damping(qdot, kv, shaping, tau, cap)
        assert sum(t * v for t, v in zip(tau, qdot)) <= 0.0
    # above the cap it is linear: the slope the sampled loop must tolerate stays bounded
    a, b = [0.0] * 3, [0.0] * 3
    sh.add_speed_damping([10.0, 0.0, 0.0], kv, shaping, a, cap)
    sh.add_speed_damping([20.0, 0.0, 0.0], kv, shaping, b, cap)
    assert b[0] == pytest.approx(2.0 * a[0]) and a[0] == pytest.approx(-10.0 * 9.0 / 4.0)
    tau = [0.0] * 3
    sh.add_speed_damping([0.01, 0.01, 0.01], kv, shaping, tau, cap)
    assert max(abs(t) for t in tau) < 1e-6  # qdot^3 / v_c^2: negligible near rest
    assert tau[1] == 0.0


def test_the_paper_law_is_unchanged_with_the_extensions_off():
    """Shaping() is the paper's law exactly; the node's default."""
    model = wrist_model()
    rng = np.random.default_rng(0)
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, ORI, 3)
    plain = Regulator(model, ORI, gains, goal=Goal(paper.Q_DESIRED))
    off = Regulator(model, ORI, gains, goal=Goal(paper.Q_DESIRED), shaping=sh.Shaping())
    for _ in range(5):
        q, qdot = random_q(model, rng).tolist(), rng.normal(size=3).tolist()
        assert plain.update(q, qdot).tau_nm == off.update(q, qdot).tau_nm


def test_shaping_swaps_whole_and_q_star_only_for_the_goal_in_force():
    reg = wrist_regulator(sh.Shaping())
    new = sh.Shaping.create(3, **ALL_ON)
    reg.set_shaping(new)
    assert reg.shaping is new and reg.limit_band is not None
    old_goal = reg.goal
    reg.set_goal(Goal((1.0, 0.0, 0.0, 0.0)))
    assert not reg.set_goal_configuration(old_goal, (0.0, 0.5, 0.0))  # too late: replaced
    assert reg.goal_configuration is None
    assert reg.set_goal_configuration(reg.goal, (0.0, 0.5, 0.0))
    assert reg.goal_configuration == (0.0, 0.5, 0.0)
    with pytest.raises(sh.ShapingError, match='must have 3 values'):
        reg.set_shaping(dataclasses.replace(new, configuration_gain=(1.0,)))
    assert reg.shaping is new
    held = reg.hold([0.1, 0.2, 0.3])
    assert reg.goal is held and reg.goal_configuration == (0.1, 0.2, 0.3)


def test_the_learned_push_fades_out_along_the_motion_above_the_creep_speed():
    """A learned push drives a joint no faster than the fade speed, whatever its size."""
    shaping = sh.Shaping.create(1, friction_learning_limit=(2.0,), friction_velocity=0.05)
    v_eps = shaping.friction_velocity_rad_s
    creep, fade = sh.CREEP_SPEED_FACTOR * v_eps, sh.FADE_SPEED_FACTOR * v_eps
    learned = [2.0]

    def push(v):
        return sh.friction_compensation([0.3], [v], 1.0, shaping, learned)[0]
    assert push(0.0) == pytest.approx(2.0, rel=1e-3)  # at rest: the whole of it
    assert push(creep) == pytest.approx(2.0 * math.tanh(creep / v_eps) + 2.0 * (
        1.0 - math.tanh(creep / v_eps)), rel=1e-6)
    middle = 0.5 * (creep + fade)
    assert 0.0 < push(middle) < push(creep)
    assert push(fade) == pytest.approx(2.0 * (1.0 - math.tanh(fade / v_eps)), abs=1e-9)
    assert abs(push(2.0 * fade)) < 1e-9  # none along a fast motion
    assert push(-fade) >= 0.0  # against the motion (an overshoot): never along it
    # the estimate f is not faded: a measured friction is compensated at any speed
    measured = sh.Shaping.create(1, friction_compensation=(1.0,), friction_velocity=0.05)
    assert sh.friction_compensation([0.3], [2.0 * fade], 1.0, measured)[0] == pytest.approx(
        1.0, rel=1e-6)


def test_a_joint_creeping_below_the_creep_speed_with_a_friction_keeps_learning():
    """
    Sliding slower than the creep speed with a friction taking the push, ``a`` keeps growing.

    The rule before stopped near ``v_eps``, which left joints creeping for seconds; a joint
    given a faster creep speed (far from its goal configuration) learns up to that. (The rule
    for a held joint alone, at speeds fixed whatever the push, as in the test above.)
    """
    shaping = sh.Shaping.create(1, friction_learning_limit=(1.0,), friction_velocity=0.05)
    v_eps = shaping.friction_velocity_rad_s
    learned, held = [0.2], [1.0]
    qdot = [1.2 * v_eps]  # above v_eps, below the creep speed: still learning
    for _ in range(200):
        _learning_tick(shaping, learned, held, [0.1], qdot, [-0.01 * qdot[0]])
    assert learned[0] > 0.25
    fast = [3.0 * v_eps]  # above the creep speed: it learns no more ...
    before = learned[0]
    for _ in range(200):
        _learning_tick(shaping, learned, held, [0.1], fast, [-0.01 * fast[0]])
    assert learned[0] <= before
    # ... unless the joint is given a faster creep speed (far from its goal configuration)
    stuck, unmet = [0.0], [0.0]
    creep, fade = [10.0 * v_eps], [16.0 * v_eps]
    sh.friction_compensation([0.1], fast, 1.0, shaping, learned, stuck, [-0.01 * fast[0]],
                             unmet, creep, fade)
    assert stuck[0] > 0.5


def test_the_fade_starts_where_the_learned_push_and_its_delay_land_at_the_limit():
    """``fade_tops``: v_lim - 2 a dt / I, within [FADE_FLOOR, FADE_TOP] x v_lim; creep in step."""
    assert sh.FADE_DELAY_TICKS == 1
    v_lim, dt = [2.0] * 5, 1e-3
    inertia = [0.01, 0.01, 0.01, 0.0, math.nan]
    # what moves the joint 0.1, 0.3 and 0.6 v_lim in one tick, and pushes on no inertia
    learned = [0.1 * 2.0 * 0.01 / dt, 0.3 * 2.0 * 0.01 / dt, 0.6 * 2.0 * 0.01 / dt, 5.0, 5.0]
    creep, fade = [0.0] * 5, [0.0] * 5
    sh.fade_tops(learned, inertia, dt, v_lim, creep, fade)
    floor = sh.FADE_FLOOR_FRACTION * 2.0
    assert fade == pytest.approx([sh.FADE_TOP_FRACTION * 2.0, 0.4 * 2.0, floor, floor, floor])
    assert creep == pytest.approx([f * sh.CREEP_TOP_FRACTION / sh.FADE_TOP_FRACTION
                                   for f in fade])

"""Core tests of control_law.py: Eq. (21), Eqs. (22)-(24)/(31)-(32) against finite differences."""
import dataclasses
import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.regulator import Goal, Regulator
from robots import PAPER_KP, PAPER_KV, PAPER_LAMBDA, Q_DESIRED, random_q, wrist_model, \
    xarm6_model

pytestmark = pytest.mark.unit

ORI, POSE = cl.Task.ORIENTATION, cl.Task.POSE
H = 1e-6


def gains(potential, task, n, kp=None, lam=None, kv=None, gravity=True):
    kp = kp or (PAPER_KP if task is ORI else (300.0, 300.0, 300.0) + PAPER_KP)
    lam = lam or (PAPER_LAMBDA if task is ORI else (20.0, 20.0, 20.0) + PAPER_LAMBDA)
    return cl.Gains.create(potential, kp, kv or (1.0,) * n, lam, task, n, gravity)


def y_of_q(model, q, p_d, q_d, task):
    p, R = model.forward_kinematics(q)
    return np.array(cl.output_error(p, R, p_d, q_d, task)[0])


def random_goal(model, rng):
    """Return a reachable goal (p_d, q_d): the pose at random joint angles (A1)."""
    p_d, R_d = model.forward_kinematics(random_q(model, rng))
    return p_d, quat.from_rotation_matrix(R_d)


CASES = [(wrist_model, ORI), (wrist_model, POSE), (xarm6_model, ORI), (xarm6_model, POSE)]


@pytest.mark.parametrize('make_model, task', CASES)
def test_eq21_error_jacobian_is_minus_q_times_geometric_jacobian(make_model, task):
    """Check d y_tilde / dq = -Q(eta_e, e) J_G(q), Eq. (21), by central differences."""
    model = make_model()
    rng = np.random.default_rng(21)
    for _ in range(20):
        p_d, q_d = random_goal(model, rng)
        q = random_q(model, rng)
        p, R, J = model.kinematics(q)
        y, eta_e = cl.output_error(p, R, p_d, q_d, task)
        Q = np.eye(6)
        Q[3:, 3:] = np.array(quat.q_matrix(eta_e, y[-3:]))
        analytic = -(Q @ np.array(J))[6 - task.dim:]
        fd = np.column_stack([(y_of_q(model, q + H * e, p_d, q_d, task)
                               - y_of_q(model, q - H * e, p_d, q_d, task)) / (2 * H)
                              for e in np.eye(model.n)])
        np.testing.assert_allclose(fd, analytic, atol=1e-7)


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
@pytest.mark.parametrize('make_model, task', CASES)
def test_torque_is_minus_gradient_of_potential(make_model, task, potential):
    """At rest and without g, the tick's Eq. (24)/(32) is -grad_q U_a(y_tilde(q)) (23)/(31)."""
    model = make_model()
    rng = np.random.default_rng(23)
    g = gains(potential, task, model.n, gravity=False)
    for _ in range(10):
        p_d, q_d = random_goal(model, rng)
        q = random_q(model, rng)
        regulator = Regulator(model, task, g, [math.inf] * model.n, Goal(q_d, tuple(p_d)))
        tau = regulator.update(q, [0.0] * model.n).tau_nm

        def energy(qq):
            return cl.potential_energy(y_of_q(model, qq, p_d, q_d, task), g)

        grad = [(energy(q + H * e) - energy(q - H * e)) / (2 * H) for e in np.eye(model.n)]
        np.testing.assert_allclose(tau, -np.array(grad), atol=1e-5, rtol=1e-6)


def test_damping_and_gravity_terms():
    """The tick adds -K_v qdot (Eq. 22) and, if asked, g(q); nothing else depends on them."""
    model = wrist_model()
    g = gains('quadratic', ORI, 3, kv=(2.0, 3.0, 4.0))
    q, qdot = [0.2, 0.7, -0.3], [1.0, -1.0, 0.5]
    on = Regulator(model, ORI, g, [math.inf] * 3, Goal(Q_DESIRED))
    off = Regulator(model, ORI, dataclasses.replace(g, gravity_compensation=False),
                    [math.inf] * 3, Goal(Q_DESIRED))
    at_rest = np.array(off.update(q, [0.0] * 3).tau_nm)
    np.testing.assert_allclose(off.update(q, qdot).tau_nm - at_rest, [-2.0, 3.0, -2.0],
                               atol=1e-12)
    np.testing.assert_allclose(np.array(on.update(q, qdot).tau_nm) - off.update(q, qdot).tau_nm,
                               model.gravity(q), atol=1e-12)


def test_task_force_matches_numpy_form():
    """Q^T K_p tanh(Lambda y) with Q of Eq. (15), pose task."""
    g = gains('tanh', POSE, 6)
    y = np.array([0.01, -0.02, 0.03, 0.1, -0.2, 0.15])
    eta_e = math.sqrt(1 - y[3:] @ y[3:])
    Q = np.eye(6)
    Q[3:, 3:] = 0.5 * eta_e * np.eye(3) + 0.5 * np.array(quat.skew(y[3:]))
    expected = Q.T @ (np.array(g.kp) * np.tanh(np.array(g.lam) * y))
    np.testing.assert_allclose(cl.task_force(y, eta_e, g), expected, atol=1e-14)


unit_q = st.tuples(*[st.floats(-1, 1)] * 4).filter(
    lambda v: np.linalg.norm(v) > 1e-2).map(quat.normalized)


@settings(max_examples=200, deadline=None)
@given(unit_q, unit_q, st.sampled_from(['quadratic', 'tanh']))
def test_torque_unchanged_when_measured_or_desired_quaternion_flips_sign(q, q_d, potential):
    """docs/errata.md note 6: e and Q flip together and grad U_a is odd, so tau is unchanged."""
    g = gains(potential, ORI, 3)
    J = [[0.3, -0.2, 0.5], [0.1, 0.9, -0.4], [1.0, 0.0, 0.2]]

    def torque(qm, qd):
        eta_e, e = quat.orientation_error(qm, qd)
        return cl.potential_torque(J, e, eta_e, g)

    ref = torque(q, q_d)
    neg = tuple(-c for c in q)
    neg_d = tuple(-c for c in q_d)
    for other in (torque(neg, q_d), torque(q, neg_d), torque(neg, neg_d)):
        np.testing.assert_allclose(other, ref, atol=1e-12)


def test_log_cosh_potential_is_finite_for_large_errors():
    g = gains('tanh', POSE, 6, lam=(1e3,) * 6)
    u = cl.potential_energy([10.0] * 6, g)
    assert math.isfinite(u)
    # For large x, ln cosh(x) ~ x - ln 2.
    assert u == pytest.approx(sum(k / 1e3 * (1e4 - math.log(2)) for k in g.kp), rel=1e-12)


# -- gains validation ---------------------------------------------------------------------------

def test_paper_gains_are_accepted_and_immutable():
    g = cl.Gains.create('tanh', PAPER_KP, PAPER_KV, PAPER_LAMBDA, ORI, 3)
    assert g.potential is cl.Potential.TANH and g.kp == PAPER_KP and g.lam == PAPER_LAMBDA
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.kp = (1.0, 1.0, 1.0)


@pytest.mark.parametrize('kwargs, match', [
    ({'potential': 'cubic'}, "potential must be one of .* got 'cubic'"),
    ({'kp': (1.0, 2.0)}, r'kp must have 3 values, got 2'),
    ({'kp': (1.0, 0.0, 2.0)}, r'kp\[1\] must be finite and > 0, got 0.0'),
    ({'kv': (1.0, -1.0, 1.0)}, r'kv\[1\] must be finite and > 0, got -1.0'),
    ({'lam': (1.0, math.nan, 1.0)}, r'lambda\[1\] must be finite and > 0, got nan'),
    ({'lam': (1.0, 1.0, math.inf)}, r'lambda\[2\] must be finite and > 0, got inf'),
    ({'kp': 'abc'}, r'kp must be a list of numbers'),
    ({'task': POSE}, r'kp must have 6 values, got 3'),
])
def test_invalid_gains_are_rejected_naming_the_value(kwargs, match):
    args = {'potential': 'quadratic', 'kp': PAPER_KP, 'kv': PAPER_KV, 'lam': PAPER_LAMBDA,
            'task': ORI, 'n_joints': 3}
    args.update(kwargs)
    with pytest.raises(cl.GainsError, match=match):
        cl.Gains.create(**args)


def test_saturate_clamps_in_place_and_reports():
    tau = [60.0, -35.0, 1.0]
    assert cl.saturate(tau, (50.0, 30.0, 20.0)) is True
    assert tau == [50.0, -30.0, 1.0]
    assert cl.saturate(tau, (50.0, 30.0, 20.0)) is False


def test_goal_error_is_zero_at_q_desired():
    model = wrist_model()
    p, R = model.forward_kinematics(paper.Q_JOINT_DESIRED_RAD)
    y, eta_e = cl.output_error(p, R, None, quat.normalized(Q_DESIRED), ORI)
    assert np.linalg.norm(y) < 1e-4 and abs(eta_e) > 0.9999

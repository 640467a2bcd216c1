"""Core tests of quaternion.py: Shepperd conversion, Yuan's error, Q, and the paper's numbers."""
import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat

pytestmark = pytest.mark.unit

# docs/errata.md notes 2 and 3: the corrected desired quaternion and its rotation (the oracle
# against which quat_jt_controller.paper, the code's one source of them, is checked).
Q_DESIRED = (0.5566, 0.0, 0.4226, 0.7152)
R_DESIRED_ERRATA = np.array([[-0.3803, -0.7962, 0.4705],
                             [0.7962, -0.0231, 0.6045],
                             [-0.4705, 0.6045, 0.6428]])


def axis_angle_rotation(axis, angle):
    """Rodrigues' formula, an independent oracle for the conversions."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


unit_axes = st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3)
angles = st.floats(0.0, math.pi)
quaternions = st.tuples(*[st.floats(-1, 1)] * 4).filter(
    lambda v: np.linalg.norm(v) > 1e-2).map(quat.normalized)


def same_rotation(q1, q2, tol=1e-9):
    """Compare as rotations: q and -q are the same rotation."""
    return min(np.abs(np.subtract(q1, q2)).max(), np.abs(np.add(q1, q2)).max()) < tol


@settings(max_examples=300, deadline=None)
@given(unit_axes, angles)
def test_shepperd_matches_axis_angle(axis, angle):
    R = axis_angle_rotation(axis, angle)
    q = quat.from_rotation_matrix(R)
    k = np.asarray(axis) / np.linalg.norm(axis)
    expected = (math.cos(angle / 2), *(math.sin(angle / 2) * k))
    assert q[0] >= 0.0
    assert abs(quat.norm(q) - 1.0) < 1e-12
    assert same_rotation(q, expected, 1e-9)
    np.testing.assert_allclose(quat.to_rotation_matrix(q), R, atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(quaternions)
def test_quaternion_round_trip(q):
    R = np.array(quat.to_rotation_matrix(q))
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    assert same_rotation(quat.from_rotation_matrix(R), q, 1e-9)


@pytest.mark.parametrize('angle', [0.0, 1e-9, 1e-6, 1e-3,
                                   math.pi - 1e-3, math.pi - 1e-6, math.pi - 1e-9, math.pi])
@pytest.mark.parametrize('axis', [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1), (-0.3, 0.9, 0.1)])
def test_shepperd_round_trip_near_0_and_180_degrees(axis, angle):
    R = axis_angle_rotation(axis, angle)
    q = quat.from_rotation_matrix(R)
    np.testing.assert_allclose(quat.to_rotation_matrix(q), R, atol=1e-12)
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    assert same_rotation(q, (math.cos(angle / 2), *(math.sin(angle / 2) * k)), 1e-9)


@settings(max_examples=300, deadline=None)
@given(quaternions, quaternions)
def test_yuan_error_is_vector_part_of_qd_times_conjugate_q(q, q_d):
    """Eq. (10) and eta_e equal q_d * conj(q), and Eq. (10) term by term with S of Eq. (11)."""
    eta_e, e = quat.orientation_error(q, q_d)
    r = quat.multiply(q_d, (q[0], -q[1], -q[2], -q[3]))
    assert eta_e == pytest.approx(r[0], abs=1e-12)
    np.testing.assert_allclose(e, r[1:], atol=1e-12)
    eta, eps = q[0], np.array(q[1:])
    eta_d, eps_d = q_d[0], np.array(q_d[1:])
    e_paper = eta * eps_d - eta_d * eps + np.array(quat.skew(eps)) @ eps_d
    np.testing.assert_allclose(e, e_paper, atol=1e-12)
    assert eta_e == pytest.approx(eta * eta_d + eps_d @ eps, abs=1e-12)
    assert eta_e ** 2 + np.dot(e, e) == pytest.approx(1.0, abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(quaternions, quaternions)
def test_error_sign_behaviour(q, q_d):
    """docs/errata.md note 6: negating either quaternion negates both e and eta_e."""
    eta_e, e = quat.orientation_error(q, q_d)
    neg = tuple(-c for c in q)
    for eta2, e2 in (quat.orientation_error(neg, q_d),
                     quat.orientation_error(q, tuple(-c for c in q_d))):
        assert eta2 == pytest.approx(-eta_e, abs=1e-12)
        np.testing.assert_allclose(e2, np.negative(e), atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(quaternions)
def test_error_vanishes_at_the_goal(q):
    eta_e, e = quat.orientation_error(q, q)
    assert eta_e == pytest.approx(1.0, abs=1e-12)
    assert np.abs(e).max() < 1e-12


@settings(max_examples=100, deadline=None)
@given(st.tuples(*[st.floats(-2, 2)] * 3), st.tuples(*[st.floats(-2, 2)] * 3),
       st.floats(-1, 1))
def test_skew_and_q_matrix(x, y, eta_e):
    np.testing.assert_allclose(np.array(quat.skew(x)) @ y, np.cross(x, y), atol=1e-12)
    Q = np.array(quat.q_matrix(eta_e, x))
    np.testing.assert_allclose(Q, 0.5 * eta_e * np.eye(3) + 0.5 * np.array(quat.skew(x)),
                               atol=1e-15)
    np.testing.assert_allclose(quat.q_transpose_times(eta_e, x, y), Q.T @ y, atol=1e-12)


def test_ros_order_round_trip():
    q = quat.from_xyzw(0.1, 0.2, 0.3, 0.9)
    assert q == (0.9, 0.1, 0.2, 0.3)
    assert quat.to_xyzw(q) == (0.1, 0.2, 0.3, 0.9)


def test_errata_goal_maps_to_errata_rotation():
    q_d = quat.validate_unit(Q_DESIRED)
    np.testing.assert_allclose(quat.to_rotation_matrix(q_d), R_DESIRED_ERRATA, atol=2e-4)
    assert same_rotation(quat.from_rotation_matrix(R_DESIRED_ERRATA), q_d, 2e-4)


def test_printed_eq40_is_detected_as_not_unit():
    with pytest.raises(ValueError, match='not unit'):
        quat.validate_unit(paper.Q_DESIRED_AS_PRINTED)
    assert quat.norm(paper.Q_DESIRED_AS_PRINTED) == pytest.approx(1.0509, abs=1e-4)


@pytest.mark.parametrize('bad', [(math.nan, 0, 0, 1), (0, math.inf, 0, 1), (0, 0, 0, 0),
                                 (1, 1, 0, 0)])
def test_validate_unit_rejects(bad):
    with pytest.raises(ValueError):
        quat.validate_unit(bad)


def test_validate_unit_normalises_small_deviation():
    q = quat.validate_unit((1.004, 0.0, 0.0, 0.0))
    assert q == pytest.approx((1.0, 0.0, 0.0, 0.0))


def test_package_constants_are_the_errata_values():
    """quat_jt_controller.paper, the code's single source, agrees with docs/errata.md."""
    assert same_rotation(paper.Q_DESIRED, quat.normalized(Q_DESIRED), 1e-12)
    assert paper.KP == (4.5, 20.5, 17.5) and paper.LAMBDA == (30.0, 30.0, 30.0)
    assert paper.FINAL_ERROR == {'quadratic': 0.2043, 'tanh': 5.3184e-3}

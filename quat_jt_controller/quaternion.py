"""
Unit quaternions (Euler parameters) and Yuan's orientation error, in plain Python floats.

Component order: inside this package a quaternion is ``(eta, ex, ey, ez)``, scalar first, as in
the paper (``eta`` = scalar part, ``eps`` = vector part). ROS messages use ``(x, y, z, w)``;
convert only at the boundary with :func:`from_xyzw` / :func:`to_xyzw`.

Everything here works on plain floats and tuples (no numpy): at 1 kHz a handful of numpy calls
on 3-vectors costs more than the arithmetic itself. Rotation matrices are indexable as
``R[i][j]`` (nested lists/tuples or a numpy array).
"""
from math import atan2, isfinite, sqrt
from typing import Sequence

Quaternion = tuple[float, float, float, float]
Vector3 = tuple[float, float, float]
Matrix3 = Sequence[Sequence[float]]

# tf2 rejects a quaternion whose squared norm is farther than this from 1 (and normalises it
# otherwise); the controller node uses the same rule for goals.
UNIT_NORM_SQ_TOLERANCE = 0.01


def from_xyzw(x: float, y: float, z: float, w: float) -> Quaternion:
    """ROS order (x, y, z, w) -> package order (eta, ex, ey, ez)."""
    return (w, x, y, z)


def to_xyzw(q: Sequence[float]) -> tuple[float, float, float, float]:
    """Package order (eta, ex, ey, ez) -> ROS order (x, y, z, w)."""
    return (q[1], q[2], q[3], q[0])


def norm(q: Sequence[float]) -> float:
    return sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


def normalized(q: Sequence[float]) -> Quaternion:
    n = norm(q)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def validate_unit(q: Sequence[float],
                  tolerance: float = UNIT_NORM_SQ_TOLERANCE) -> Quaternion:
    """
    Check a quaternion the way tf2 does and return it normalised.

    Raises ValueError, saying why, if a component is NaN/Inf or if |norm^2 - 1| > tolerance
    (the printed Eq. 40 of the paper, with norm 1.0509, is such a case).
    """
    if len(q) != 4:
        raise ValueError(f'a quaternion has 4 components, got {len(q)}')
    if not all(isfinite(c) for c in q):
        raise ValueError(f'quaternion has a non-finite component: {tuple(q)}')
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if abs(n2 - 1.0) > tolerance:
        raise ValueError(
            f'quaternion is not unit: norm {sqrt(n2):.4f} (|norm^2 - 1| = {abs(n2 - 1.0):.4f} '
            f'> {tolerance})')
    return normalized(q)


def skew(x: Sequence[float]) -> tuple[Vector3, Vector3, Vector3]:
    """Return the skew-symmetric matrix S(x) of Eq. (11): S(x) y = x cross y."""
    return ((0.0, -x[2], x[1]),
            (x[2], 0.0, -x[0]),
            (-x[1], x[0], 0.0))


def cross(a: Sequence[float], b: Sequence[float]) -> Vector3:
    return (a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


def multiply(a: Sequence[float], b: Sequence[float]) -> Quaternion:
    """Hamilton product a * b, both scalar first."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


def from_rotation_matrix(R: Matrix3) -> Quaternion:
    """
    Convert a rotation matrix to a unit quaternion by Shepperd's method, with eta >= 0.

    Replaces Eqs. (4)-(5) of the paper (see docs/errata.md, note 1): the component with the largest
    of 1 + tr R and 1 + 2 r_ii - tr R is found by a square root, the others from sums and
    differences of off-diagonal entries, so the result is accurate near 0 and 180 degrees.
    """
    r00, r01, r02 = R[0][0], R[0][1], R[0][2]
    r10, r11, r12 = R[1][0], R[1][1], R[1][2]
    r20, r21, r22 = R[2][0], R[2][1], R[2][2]
    trace = r00 + r11 + r22
    if trace >= r00 and trace >= r11 and trace >= r22:
        s = 2.0 * sqrt(max(1.0 + trace, 0.0))  # s = 4 eta
        q = (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * sqrt(max(1.0 + 2.0 * r00 - trace, 0.0))  # s = 4 ex
        q = ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    elif r11 >= r22:
        s = 2.0 * sqrt(max(1.0 + 2.0 * r11 - trace, 0.0))  # s = 4 ey
        q = ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    else:
        s = 2.0 * sqrt(max(1.0 + 2.0 * r22 - trace, 0.0))  # s = 4 ez
        q = ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
    if q[0] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    return normalized(q)


def to_rotation_matrix(q: Sequence[float]) -> tuple[Vector3, Vector3, Vector3]:
    """Rotation matrix of a unit quaternion (scalar first)."""
    w, x, y, z = q
    return ((1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
            (2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
            (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)))


def orientation_error(q: Sequence[float], q_desired: Sequence[float]) -> tuple[float, Vector3]:
    """
    Yuan's orientation error, Eq. (10), and eta_e (defined after Eq. 13).

    ``q`` is the measured quaternion ``(eta, eps)``, ``q_desired`` is ``(eta_d, eps_d)``:

        e     = eta eps_d - eta_d eps + S(eps) eps_d
        eta_e = eta eta_d + eps_d^T eps

    ``(eta_e, e)`` is the quaternion ``q_desired * conj(q)``, the rotation still to go, in base
    frame axes. ``e = 0`` with ``eta_e = +-1`` at the goal; ``eta_e = 0`` at a 180-degree error.
    Returns ``(eta_e, e)``.
    """
    eta, e1, e2, e3 = q
    eta_d, d1, d2, d3 = q_desired
    # S(eps) eps_d = eps x eps_d
    e = (eta * d1 - eta_d * e1 + (e2 * d3 - e3 * d2),
         eta * d2 - eta_d * e2 + (e3 * d1 - e1 * d3),
         eta * d3 - eta_d * e3 + (e1 * d2 - e2 * d1))
    eta_e = eta * eta_d + d1 * e1 + d2 * e2 + d3 * e3
    return eta_e, e


def rotation_vector(eta_e: float, e: Sequence[float]) -> Vector3:
    """
    Return the rotation vector (axis times angle, rad) of the unit quaternion ``(eta_e, e)``.

    The shorter way round: ``(eta_e, e)`` and ``(-eta_e, -e)`` give the same vector, of norm
    at most pi.
    """
    if eta_e < 0.0:
        eta_e, e = -eta_e, (-e[0], -e[1], -e[2])
    s = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    if s < 1e-12:
        return (2.0 * e[0], 2.0 * e[1], 2.0 * e[2])  # the small-angle limit
    k = 2.0 * atan2(s, eta_e) / s
    return (k * e[0], k * e[1], k * e[2])


def q_matrix(eta_e: float, e: Sequence[float]) -> tuple[Vector3, Vector3, Vector3]:
    """Return the orientation block of Q(eta_e, e), Eq. (15): 1/2 eta_e I + 1/2 S(e)."""
    h = 0.5 * eta_e
    return ((h, -0.5 * e[2], 0.5 * e[1]),
            (0.5 * e[2], h, -0.5 * e[0]),
            (-0.5 * e[1], 0.5 * e[0], h))


def q_transpose_times(eta_e: float, e: Sequence[float], w: Sequence[float]) -> Vector3:
    """Q_o(eta_e, e)^T w = 1/2 (eta_e w - e x w), the orientation block of Eq. (15)."""
    c = cross(e, w)
    return (0.5 * (eta_e * w[0] - c[0]),
            0.5 * (eta_e * w[1] - c[1]),
            0.5 * (eta_e * w[2] - c[2]))


def same_hemisphere(q: Sequence[float], reference: Sequence[float]) -> Quaternion:
    """Return ``q`` or ``-q`` (the same rotation), whichever is closer to ``reference``."""
    if q[0] * reference[0] + q[1] * reference[1] + q[2] * reference[2] + q[3] * reference[3] < 0:
        return (-q[0], -q[1], -q[2], -q[3])
    return (q[0], q[1], q[2], q[3])

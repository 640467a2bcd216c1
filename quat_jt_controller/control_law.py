"""
The transpose-Jacobian regulators of Campa and Kelly, Eq. (22), with two potentials.

    tau = J_G(q)^T Q(eta_e, e)^T grad U_a(y_tilde) - K_v qdot + g(q)                 (22)

* quadratic potential  U_a = 1/2 y^T K_p y                      -> grad = K_p y        (23, 24)
* log-cosh potential   U_a = sum k_pi / l_i ln cosh(l_i y_i)    -> grad = K_p tanh(L y) (31, 32)
* either, plus the optional large-error term k_L B(||e||) (docs/lyapunov.md,
  section 3), which keeps the orientation torque from fading towards 180 degrees

Three tasks share one implementation:

* ``orientation``: y_tilde = e (3-D), J = J_o (3 x n): Eqs. (37) and (38) of the wrist experiment.
* ``pose``: y_tilde = [p_d - p; e] (6-D), J = J_G = [J_p; J_o] (6 x n): Eqs. (24) and (32).
* ``position``: y_tilde = p_d - p (3-D), J = J_p (3 x n): the position rows of Eqs. (24) and
  (32) alone, for an arm that cannot reach a full pose (4 or 5 joints). There is no
  orientation error: Q is the identity on position rows (Eq. 15), and eta_e is reported as 1.

K_p, K_v and Lambda are diagonal and given as vectors. The law runs at 1 kHz, so it is written
in plain Python floats over short tuples; the tests check it against numpy and finite
differences.
"""
from dataclasses import dataclass
import enum
from math import asin, exp, inf, isfinite, log, log1p, sqrt, tanh
from typing import Optional, Sequence

from quat_jt_controller import quaternion as quat
from quat_jt_runtime.errors import QuatJtError
from quat_jt_runtime.param_table import check_all

LN2 = log(2.0)
# Width of the fade of the large-error term at 180 degrees, in eta_e (docs/lyapunov.md, 3).
LARGE_ERROR_DELTA = 0.1


class Potential(str, enum.Enum):
    """The artificial potential energy U_a(y_tilde)."""

    QUADRATIC = 'quadratic'  # Eq. (23)
    TANH = 'tanh'  # Eq. (31), the hyperbolic-tangent law


class Task(str, enum.Enum):
    """
    What is regulated: orientation only (Section 5), the full pose (Section 4), or position.

    The position task keeps the position rows of the pose task (Eq. 9): any reachable point is
    a goal, whatever the orientation there.
    """

    ORIENTATION = 'orientation'
    POSE = 'pose'
    POSITION = 'position'

    @property
    def dim(self) -> int:
        """Return the number of task rows: 6 (pose) or 3."""
        return 6 if self is Task.POSE else 3

    @property
    def has_position(self) -> bool:
        """Return True if y_tilde has the position rows p_d - p (first)."""
        return self is not Task.ORIENTATION

    @property
    def has_orientation(self) -> bool:
        """Return True if y_tilde has the orientation rows e (last)."""
        return self is not Task.POSITION

    def rows(self, jacobian):
        """Return the task's rows of J_G = [J_p; J_o] (Eq. 12): J_o, J_G or J_p."""
        if self is Task.ORIENTATION:
            return jacobian[3:]
        if self is Task.POSITION:
            return jacobian[:3]
        return jacobian


ZERO3 = (0.0, 0.0, 0.0)


def orientation_part(y_tilde: Sequence[float], task: Optional[Task] = None) -> Sequence[float]:
    """
    Return e, the orientation rows of ``y_tilde`` (Eq. 10); zeros for the position task.

    ``task`` None: the orientation rows are the last three (the orientation and pose tasks).
    """
    return ZERO3 if task is Task.POSITION else y_tilde[-3:]


class GainsError(QuatJtError):
    """An invalid gain; the message names the parameter and the offending value."""


# A gain is refused if its term alone would ask for more than the largest effort limit at an
# error (or speed) of this size: past that it only saturates the joints (a bang-bang law).
SATURATING_ERROR = 1e-3  # rad (orientation rows), m (position rows), rad/s (K_v)
# tanh(Lambda y) with Lambda above this switches as sign(y) within sensor noise: it chatters.
MAX_LAMBDA = 1e4
MAX_GAIN_WITHOUT_LIMITS = 1e6  # when the URDF gives no effort limit


def gain_ceiling(effort_limits_nm: Sequence[float]) -> float:
    """Return the largest sane K_p or K_v entry for these effort limits (see SATURATING_ERROR)."""
    finite = [lim for lim in effort_limits_nm if isfinite(lim) and lim > 0.0]
    return max(finite) / SATURATING_ERROR if finite else MAX_GAIN_WITHOUT_LIMITS


@dataclass(frozen=True)
class Gains:
    """
    Validated, immutable controller gains (diagonals of K_p, K_v, Lambda).

    Units (docs/errata.md, note 7): K_p in N m (orientation rows) or N/m (position rows), K_v in
    N m s/rad, Lambda dimensionless (orientation) or 1/m (position). Build with :meth:`create`,
    which validates; the 1 kHz loop reads one instance and a parameter change swaps in a new one.
    """

    potential: Potential
    kp: tuple[float, ...]
    kv: tuple[float, ...]
    lam: tuple[float, ...]
    gravity_compensation: bool = True

    @classmethod
    def create(cls, potential: str, kp: Sequence[float], kv: Sequence[float],
               lam: Sequence[float], task: Task, n_joints: int,
               gravity_compensation: bool = True,
               effort_limits_nm: Optional[Sequence[float]] = None) -> 'Gains':
        """
        Validate and build by the rows of ``parameter_table.GAINS``; raise GainsError naming it.

        With ``effort_limits_nm``, K_p and K_v are also bounded by :func:`gain_ceiling` and
        Lambda by MAX_LAMBDA, so that no gain makes the law a saturating switch.
        """
        # The rows import this module (Task, Potential, the ceilings): imported at the call.
        from quat_jt_controller import parameter_table as table
        task = Task(task)
        ceiling, lam_ceiling = inf, inf
        if effort_limits_nm is not None:
            ceiling, lam_ceiling = gain_ceiling(effort_limits_nm), MAX_LAMBDA
        context = {'task': task, 'dim': task.dim, 'n': n_joints, 'ceiling': ceiling,
                   'lambda_ceiling': lam_ceiling, 'effort_max': f'{ceiling * SATURATING_ERROR:g}'}
        v = check_all(table.GAINS, {'potential': potential, 'kp': kp, 'kv': kv, 'lambda': lam,
                                    'gravity_compensation': bool(gravity_compensation)},
                      context, GainsError)
        return cls(potential=Potential(v['potential']), kp=v['kp'], kv=v['kv'], lam=v['lambda'],
                   gravity_compensation=v['gravity_compensation'])


def large_error_energy(s: float, k_l: float) -> float:
    """
    k_L B(s), s = ||e||: the large-error term of U_a (docs/lyapunov.md, section 3).

    B(s) = integral of sigma^2 / sqrt(a^2 - sigma^2) from 0 to s, a^2 = 1 + delta^2:
    a^2 / 2 asin(s / a) - s / 2 sqrt(a^2 - s^2).
    """
    a2 = 1.0 + LARGE_ERROR_DELTA * LARGE_ERROR_DELTA
    a = sqrt(a2)
    return k_l * (0.5 * a2 * asin(min(s / a, 1.0)) - 0.5 * s * sqrt(max(a2 - s * s, 0.0)))


def large_error_gradient_scale(s2: float, k_l: float) -> float:
    """
    Return c with grad_e (k_L B(||e||)) = c e: c = k_L ||e|| / sqrt(1 + delta^2 - ||e||^2).

    ``s2`` is ||e||^2. Since 1 + delta^2 - ||e||^2 = eta_e^2 + delta^2, Q^T grad has the size
    1/2 k_L ||e||^2 |eta_e| / sqrt(eta_e^2 + delta^2): ~ 1/2 k_L at large errors, 0 at 180.
    """
    return k_l * sqrt(s2) / sqrt(1.0 + LARGE_ERROR_DELTA * LARGE_ERROR_DELTA - s2)


def potential_energy(y_tilde: Sequence[float], gains: Gains, k_l: float = 0.0,
                     task: Optional[Task] = None) -> float:
    """
    U_a(y_tilde): Eq. (23) (quadratic) or Eq. (31) (log-cosh), + k_L B(||e||) if k_l > 0.

    ``task`` None: the orientation or pose task, from the size of ``y_tilde``; the position
    task has no e, so no large-error term.
    """
    extra = 0.0
    if k_l > 0.0 and task is not Task.POSITION:
        e = y_tilde[-3:]
        extra = large_error_energy(sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]), k_l)
    if gains.potential is Potential.QUADRATIC:
        return 0.5 * sum(k * y * y for k, y in zip(gains.kp, y_tilde)) + extra
    total = extra
    for k, lam, y in zip(gains.kp, gains.lam, y_tilde):
        x = abs(lam * y)
        total += k / lam * (x + log1p(exp(-2.0 * x)) - LN2)  # = ln cosh x, without overflow
    return total


def potential_gradient(y_tilde: Sequence[float], gains: Gains, k_l: float = 0.0,
                       task: Optional[Task] = None) -> tuple[float, ...]:
    """
    grad_y U_a: K_p y (Eq. 24) or K_p tanh(Lambda y) (Eq. 32), + the large-error term.

    ``task`` as in :func:`potential_energy`.
    """
    if gains.potential is Potential.QUADRATIC:
        w = tuple(k * y for k, y in zip(gains.kp, y_tilde))
    else:
        w = tuple(k * tanh(lam * y) for k, lam, y in zip(gains.kp, gains.lam, y_tilde))
    if k_l <= 0.0 or task is Task.POSITION:
        return w
    e = y_tilde[-3:]
    c = large_error_gradient_scale(e[0] * e[0] + e[1] * e[1] + e[2] * e[2], k_l)
    return w[:-3] + (w[-3] + c * e[0], w[-2] + c * e[1], w[-1] + c * e[2])


def task_force(y_tilde: Sequence[float], eta_e: float, gains: Gains,
               k_l: float = 0.0, task: Optional[Task] = None) -> tuple[float, ...]:
    """
    Q(eta_e, e)^T grad U_a(y_tilde), the task-space 'force' that J^T maps to torque.

    ``y_tilde`` is ``e`` (3) or ``[p_tilde, e]`` (6), or ``p_tilde`` (3) for the position task
    (``task`` Task.POSITION; None: orientation or pose, from the size); Q is Eq. (15):
    identity on the position rows, 1/2 (eta_e I + S(e)) on the orientation rows. ``k_l`` > 0
    adds the large-error term (no effect on the position task).
    """
    w = potential_gradient(y_tilde, gains, k_l, task)
    if task is Task.POSITION:
        return w
    e = y_tilde[-3:]
    w_o = quat.q_transpose_times(eta_e, e, w[-3:])
    return w_o if len(w) == 3 else (w[0], w[1], w[2]) + w_o


def potential_torque(jacobian: Sequence[Sequence[float]], y_tilde: Sequence[float],
                     eta_e: float, gains: Gains, k_l: float = 0.0,
                     task: Optional[Task] = None) -> list[float]:
    """
    J^T Q(eta_e, e)^T grad U_a(y_tilde) = -grad_q U_a(y_tilde(q)) (Eqs. 21-22), in N m.

    ``jacobian`` has the task's rows (``Task.rows``); ``task`` as in :func:`task_force`.
    """
    f = task_force(y_tilde, eta_e, gains, k_l, task)
    n = len(jacobian[0])
    tau = [0.0] * n
    for row, fi in zip(jacobian, f):
        for j in range(n):
            tau[j] += row[j] * fi
    return tau


def saturate(tau: list[float], limits: Sequence[float]) -> bool:
    """Clamp ``tau`` in place to +-limits; return True if any entry was clamped."""
    clamped = False
    for j, lim in enumerate(limits):
        if tau[j] > lim:
            tau[j] = lim
            clamped = True
        elif tau[j] < -lim:
            tau[j] = -lim
            clamped = True
    return clamped


def output_error(p: Sequence[float], R: quat.Matrix3, p_desired: Sequence[float],
                 q_desired: Sequence[float], task: Task) -> tuple[tuple[float, ...], float]:
    """
    Return the output error y_tilde of Eq. (8) and eta_e, from the measured pose (p, R).

    Orientation task: y_tilde = e. Pose task: y_tilde = [p_d - p (Eq. 9); e (Eq. 10)].
    Position task: y_tilde = p_d - p, and eta_e = 1 (``q_desired`` is not read).
    """
    if task is Task.POSITION:
        return (p_desired[0] - p[0], p_desired[1] - p[1], p_desired[2] - p[2]), 1.0
    eta_e, e = quat.orientation_error(quat.from_rotation_matrix(R), q_desired)
    if task is Task.ORIENTATION:
        return e, eta_e
    return (p_desired[0] - p[0], p_desired[1] - p[1], p_desired[2] - p[2]) + e, eta_e

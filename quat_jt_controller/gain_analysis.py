"""
The sampled, delayed loop of the regulator, linearised: what the gain design checks its rules by.

The plant M(q) qddot = tau is integrated with semi-implicit Euler at the control period, the
torque computed from the state some ticks ago (zero-order hold). At a goal (eta_e = 1, e = 0)
Eq. (24) / (32) minus g(q) is a joint stiffness K_q (:func:`joint_stiffness`, Eq. 15) and the
damping K_v, so the loop is linear and stable when the spectral radius of its state matrix is
below 1 (:func:`spectral_radius`). The checks of ``gain_design`` add margins: ``DELAY_MARGIN``
ticks more than asked for, and ``GAIN_MARGIN`` x the gains (:func:`margin_cases`). Also here:
the inertia a joint sees, the damping ratios, the steady speed under the cubic damping and the
expected time to a goal (docs/gain_design.md).

ROS-free.
"""
from typing import Optional, Sequence

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller.model import RobotModel
from quat_jt_controller.shaping import fast_damping_modes, Shaping

DELAY_MARGIN = 1  # the loop must also be stable with this many ticks more than asked for
GAIN_MARGIN = 1.5  # ... and with the gains (stiffness and damping) this many times larger
QO = 0.5  # |Q| on the orientation rows (Eq. 15)


def _dynamics_matrix(M: np.ndarray, K: np.ndarray, D: np.ndarray, delay_ticks: int,
                     dt_s: float) -> np.ndarray:
    """State matrix of M qddot = -K q - D qdot, sampled, torque from ``delay_ticks`` ago."""
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    size = 2 * n * (delay_ticks + 1)  # [q_k, v_k, q_k-1, v_k-1, ..., q_k-d, v_k-d]
    A = np.zeros((size, size))
    old = 2 * n * delay_ticks
    A[n:2 * n, n:2 * n] = np.eye(n)
    A[n:2 * n, old:old + n] -= dt_s * Minv @ K
    A[n:2 * n, old + n:old + 2 * n] -= dt_s * Minv @ D
    A[:n, :n] = np.eye(n)
    A[:n, :] += dt_s * A[n:2 * n, :]  # q_k+1 = q_k + dt v_k+1 (semi-implicit Euler)
    for j in range(1, delay_ticks + 1):
        A[2 * n * j:2 * n * (j + 1), 2 * n * (j - 1):2 * n * j] = np.eye(2 * n)
    return A


def spectral_radius(M: np.ndarray, K: np.ndarray, D: np.ndarray, delay_ticks: int = 1,
                    dt_s: float = 1e-3) -> float:
    """
    Spectral radius of the sampled, delayed loop M qddot = -K q - D qdot (zero-order hold).

    The plant is integrated with semi-implicit Euler (as PyBullet does) at ``dt_s``; the
    torque applied in step k is computed from the state of step k - ``delay_ticks``. Below 1:
    locally stable; the slowest mode decays with the time constant -dt / ln(rho).
    """
    A = _dynamics_matrix(np.atleast_2d(M), np.atleast_2d(K), np.atleast_2d(D), delay_ticks,
                         dt_s)
    return float(np.abs(np.linalg.eigvals(A)).max())


def joint_stiffness(jacobian: np.ndarray, slope: Sequence[float],
                    task: cl.Task = cl.Task.POSE) -> np.ndarray:
    """
    K_q = J^T Q^T diag(slope) Q J at the goal (eta_e = 1, e = 0): Q = diag(I, I/2) (Eq. 15).

    ``slope`` is k_p (quadratic, Eq. 23) or k_p lambda (log-cosh, Eq. 31), one per task row;
    ``jacobian`` has one row per task coordinate (J_o, J_G = [J_p; J_o] or J_p). Q is 1/2 on
    the orientation rows, the last three unless ``task`` is the position task (Q = I).
    """
    J = np.asarray(jacobian, dtype=float)
    q_diag = np.ones(J.shape[0])
    if cl.Task(task).has_orientation:
        q_diag[-3:] = QO
    QJ = q_diag[:, None] * J
    return QJ.T @ np.diag(np.asarray(slope, dtype=float)) @ QJ


def linearized_spectral_radius(model: RobotModel, q_goal_rad: Sequence[float], gains: cl.Gains,
                               delay_ticks: int = 1, dt_s: float = 1e-3,
                               mass_matrix: Optional[np.ndarray] = None,
                               task: cl.Task = cl.Task.POSE,
                               shaping: Optional[Shaping] = None) -> float:
    """
    Spectral radius of the regulator's loop linearised at a goal, sampled and delayed.

    At y_tilde = 0 (eta_e = 1) Eq. (24) / (32) minus g(q) is tau = -K_q dq - K_v qdot with
    K_q of :func:`joint_stiffness`, slopes k_p (quadratic) or k_p lambda (log-cosh). Of the
    extensions (``shaping``) only the goal-configuration term without a dead zone adds
    stiffness there (:func:`configuration_stiffness`; q* = the goal), and the inertial damping
    raises the damping (:func:`damping_at`), and the settling damping adds ``alpha M``
    (:func:`damping_matrix`); the others are zero near the goal. See :func:`spectral_radius`.
    """
    _, _, J = model.kinematics(list(q_goal_rad))
    task = cl.Task(task)
    rows = task.rows(np.array(J))
    slope = np.array(gains.kp)
    if gains.potential is cl.Potential.TANH:
        slope = slope * np.array(gains.lam)
    M = model.mass_matrix(list(q_goal_rad)) if mass_matrix is None else mass_matrix
    K = joint_stiffness(rows, slope, task)
    if shaping is not None and shaping.configuration_on:
        K = K + np.diag(configuration_stiffness(shaping))
    if shaping is None:
        D = np.diag(np.asarray(gains.kv, dtype=float))
    else:
        D = damping_matrix(gains.kv, shaping.inertial_damping,
                           shaping.inertial_damping_rate_per_s, M,
                           shaping.settling_damping_rate_per_s)
    return spectral_radius(M, K, D, delay_ticks, dt_s)


def time_constant_s(rho: float, dt_s: float = 1e-3) -> float:
    """Time constant of a discrete mode of modulus ``rho`` (inf if not decaying)."""
    return -dt_s / np.log(rho) if rho < 1.0 else float('inf')


def configuration_stiffness(shaping: Shaping) -> np.ndarray:
    """Joint stiffness (N m/rad) of the goal-configuration term at q* (0 with a dead zone)."""
    if shaping.configuration_radius_rad > 0.0 or not shaping.configuration_gain:
        return np.zeros(len(shaping.configuration_gain))
    return np.array(shaping.configuration_gain) / shaping.configuration_ramp_rad


def seen_inertia(M: np.ndarray) -> np.ndarray:
    """Return ``1 / (M^-1)_jj``: the inertia joint j sees when the other joints move freely."""
    return 1.0 / np.diag(np.linalg.inv(M))


def carried_speed(configs, kv: np.ndarray, push_nm: np.ndarray) -> np.ndarray:
    """
    Return the speed per joint that the other joints' pushes give it through M(q), roughly.

    Far from the goal joint k is pushed with up to ``push_nm[k]`` and reaches its own cruise
    ``push_k / k_v,k`` in about ``tau_k = I_k / k_v,k`` (``I_k = 1 / (M^-1)_kk``, the inertia
    it sees). Through ``M^-1`` the same push accelerates joint j by ``(M^-1)_jk push_k`` (a
    light link keeps its place in the world while the arm under it turns), and j's own
    damping takes such a speed away in ``tau_j``: a lag of ``tau_j`` driven for about
    ``tau_k`` leaves j with about ``|(M^-1)_jk| push_k tau_j tau_k / (tau_j + tau_k)``. The
    sum over ``k != j``, every sign against j, the largest over ``configs`` (rad/s). It leaves
    out the cubic damping, which brakes more near the limit, and the goal-configuration
    term's fade-in, so it overestimates (docs/gain_design.md says by how much).
    """
    out = np.zeros(len(kv))
    for _, _, M in configs:
        inverse = np.linalg.inv(M)
        tau = 1.0 / (np.diag(inverse) * kv)
        lag = tau[:, None] * tau[None, :] / (tau[:, None] + tau[None, :])
        pushed = np.abs(inverse) * push_nm[None, :] * lag
        out = np.maximum(out, pushed.sum(axis=1) - np.diag(pushed))
    return out


def sigma_min(rows: np.ndarray) -> float:
    """Return the smallest singular value of ``rows`` (a task Jacobian: 0 at a singularity)."""
    return float(np.linalg.svd(rows, compute_uv=False)[-1])


def _inertial_on(inertial: Optional[np.ndarray], rate_per_s: float) -> bool:
    """Return True if the inertial damping acts (``Shaping.inertial_damping_on``'s test)."""
    return inertial is not None and rate_per_s > 0.0 and bool(np.any(np.asarray(inertial) > 0.0))


def damping_at(kv: np.ndarray, inertial: Optional[np.ndarray], rate_per_s: float,
               M: np.ndarray) -> np.ndarray:
    """
    Return the linear damping per joint at a configuration of mass matrix ``M`` (N m s/rad).

    ``max(k_v,j, min(c_j sqrt(M_jj), beta I_j))``, ``I_j`` the inertia the joint sees there
    (:func:`seen_inertia`), as the regulator's tick damps (``inertial_damping``: ``c``,
    ``inertial_damping_rate``: ``beta``; None or zeros: ``k_v`` alone).
    """
    kv = np.asarray(kv, dtype=float)
    if not _inertial_on(inertial, rate_per_s):
        return kv
    own = np.asarray(inertial, dtype=float) * np.sqrt(np.diag(M))
    return np.maximum(kv, np.minimum(own, rate_per_s * seen_inertia(M)))


def joint_damping_matrix(kv: np.ndarray, inertial: Optional[np.ndarray], rate_per_s: float,
                         M: np.ndarray) -> np.ndarray:
    """
    Return the tick's linear joint damping at a configuration of mass matrix ``M`` (N m s/rad).

    ``diag(damping_at(...))`` with each mode of ``M^-1 D`` faster than ``beta`` brought down
    to it (``shaping.fast_damping_modes``, the tick's own; docs/lyapunov.md, section 10);
    ``K_v`` alone where the inertial damping is off.
    """
    d = damping_at(kv, inertial, rate_per_s, M)
    D = np.diag(d)
    if not _inertial_on(inertial, rate_per_s):  # k_v alone, as the tick: nothing capped
        return D
    modes = fast_damping_modes(np.linalg.inv(M).tolist(), d.tolist(), rate_per_s)
    for c, y in modes or ():
        y = np.asarray(y)
        D -= c * np.outer(y, y)
    return D


def damping_matrix(kv: np.ndarray, inertial: Optional[np.ndarray], rate_per_s: float,
                   M: np.ndarray, settling_per_s: float = 0.0) -> np.ndarray:
    """
    Return the linear damping matrix near the goal (N m s/rad): the joint damping + alpha M.

    :func:`joint_damping_matrix` ``+ settling_per_s M``: the joint damping and the settling
    damping ``alpha M(q)`` (docs/lyapunov.md, section 11), which acts in full near the goal.
    """
    D = joint_damping_matrix(kv, inertial, rate_per_s, M)
    return D + settling_per_s * M if settling_per_s > 0.0 else D


def slowest_decay_per_s(M: np.ndarray, K: np.ndarray, D: np.ndarray) -> float:
    """
    Return the decay rate (1/s) of the slowest mode of M qddot = -K q - D qdot (continuous).

    The smallest ``-Re(s)`` over the eigenvalues ``s`` of the loop; a mode without stiffness
    (``s`` = 0: a redundant arm's free self-motion, which moves no task coordinate) is left
    out.
    """
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ D]])
    s = np.linalg.eigvals(A)
    size = np.abs(s)
    moving = size > 1e-9 * max(float(size.max()), 1.0)
    return float(np.min(-s.real[moving])) if moving.any() else 0.0


def settling_rate(configs, slope: np.ndarray, kv: np.ndarray, extra: np.ndarray,
                  rates_per_s: Sequence[float], near_best: float,
                  task: cl.Task = cl.Task.POSE, inertial: Optional[np.ndarray] = None,
                  rate_per_s: float = 0.0) -> tuple[float, float, float]:
    """
    Choose alpha of the settling damping ``alpha M`` among ``rates_per_s`` (1/s).

    For each alpha, the median over the configurations of the slowest mode's decay rate
    (:func:`slowest_decay_per_s`, the loop linearised at each as a goal: the joint stiffness of
    the tanh slopes plus ``extra``, the damping of :func:`damping_matrix`). Returns
    ``(alpha, decay at 0, decay at alpha)``: the smallest alpha whose median decay is at least
    ``near_best`` x the best (more damping than that slows the creep of a joint a friction
    holds, for nothing).
    """
    decay = np.zeros(len(rates_per_s))
    for i, alpha in enumerate(rates_per_s):
        decay[i] = np.median([
            slowest_decay_per_s(M, joint_stiffness(rows, slope, task) + np.diag(extra),
                                damping_matrix(kv, inertial, rate_per_s, M, alpha))
            for _, rows, M in configs])
    best = int(np.flatnonzero(decay >= near_best * decay.max())[0])
    return float(rates_per_s[best]), float(decay[0]), float(decay[best])


def median_damping_ratio(configs, slope: np.ndarray, kv: np.ndarray,
                         extra: np.ndarray, task: cl.Task = cl.Task.POSE,
                         inertial: Optional[np.ndarray] = None,
                         rate_per_s: float = 0.0) -> np.ndarray:
    """Median over the configurations of b_j / (2 sqrt(M_jj k_jj)), b of :func:`damping_at`."""
    zeta = [damping_at(kv, inertial, rate_per_s, M)
            / (2.0 * np.sqrt(np.diag(M) * (np.diag(joint_stiffness(rows, slope, task))
                                           + extra)))
            for _, rows, M in configs]
    return np.median(zeta, axis=0)


def worst_rho(configs, kp, kv, lam, extra, delays, dt_s, task=cl.Task.POSE,
              inertial: Optional[np.ndarray] = None, rate_per_s: float = 0.0,
              settling_per_s: float = 0.0) -> dict:
    """
    Worst spectral radius per potential over the configurations, with the margins.

    DELAY_MARGIN more ticks of delay than asked for, and GAIN_MARGIN x the gains; the damping
    at each configuration is :func:`damping_matrix`'s (with the settling damping).
    """
    cases = margin_cases(delays)
    worst = {}
    for potential, slope in (('quadratic', kp), ('tanh', kp * lam)):
        rho = 0.0
        for _, rows, M in configs:
            K = joint_stiffness(rows, slope, task) + np.diag(extra)
            D = damping_matrix(kv, inertial, rate_per_s, M, settling_per_s)
            for scale, d in cases:
                rho = max(rho, spectral_radius(M, scale * K, scale * D, d, dt_s))
        worst[potential] = rho
    return worst


def joint_spectral_radius(inertia: float, stiffness: float, damping: float, delays, dt_s) -> float:
    """Worst spectral radius of one joint's mass-spring-damper, with the margins."""
    return max(spectral_radius(np.array([[inertia]]), np.array([[scale * stiffness]]),
                               np.array([[scale * damping]]), d, dt_s)
               for scale, d in margin_cases(delays))


def checked_delays(delays) -> tuple[int, ...]:
    """Return the delays asked for, plus DELAY_MARGIN ticks more than the largest."""
    return tuple(sorted(set(delays) | {max(delays) + DELAY_MARGIN}))


def margin_cases(delays) -> list[tuple[float, int]]:
    """Return the (gain scale, delay) pairs checked: 1x up to one tick more, 1.5x as asked."""
    return ([(1.0, d) for d in checked_delays(delays)]
            + [(GAIN_MARGIN, d) for d in delays])


def largest_stable_damping(inertia: float, delays, dt_s) -> float:
    """Return the largest D with v_k+1 = v_k - dt D / I v_k-d stable for every delay."""
    lo, hi = 0.0, 2.0 * inertia / dt_s
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        stable = damper_spectral_radius(inertia, mid, delays, dt_s) < 1.0
        lo, hi = (mid, hi) if stable else (lo, mid)
    return lo


def coupled_damper_spectral_radius(M: np.ndarray, D: np.ndarray, delays, dt_s: float) -> float:
    """
    Return the spectral radius of v_k+1 = v_k - dt M^-1 D v_k-d, the worst over ``delays``.

    The arm's speeds under its damping alone, coupled through ``M`` (the positions, which
    nothing holds then, left out): :func:`damper_spectral_radius` for a whole arm.
    """
    n = M.shape[0]
    step = dt_s * np.linalg.solve(M, D)
    worst = 0.0
    for d in delays:
        A = np.zeros((n * (d + 1), n * (d + 1)))
        A[:n, :n] = np.eye(n)
        A[:n, n * d:] -= step
        for i in range(1, d + 1):
            A[n * i:n * (i + 1), n * (i - 1):n * i] = np.eye(n)
        worst = max(worst, float(np.abs(np.linalg.eigvals(A)).max()))
    return worst


def damper_spectral_radius(inertia: float, damping: float, delays, dt_s: float) -> float:
    """Return the spectral radius of v_k+1 = v_k - dt D / I v_k-d: one damped joint's speed."""
    return coupled_damper_spectral_radius(np.array([[inertia]]), np.array([[damping]]), delays,
                                          dt_s)


def cruising_speed(push_nm: np.ndarray, kv: np.ndarray, damping_speed_rad_s: np.ndarray,
                   speed_cap_rad_s: np.ndarray,
                   linear: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Return the steady speed per joint where the damping meets a constant ``push_nm``.

    The damping is the regulator's (``shaping.add_speed_damping``): ``b v + k_v v min(v,
    v_m)^2 / v_c^2``, ``v_m`` = ``speed_cap_rad_s``, no cubic part where ``v_c`` is 0, ``b``
    the linear damping ``linear`` (default ``k_v``; :func:`damping_at` with the inertial
    damping). It rises monotonically with ``v``; the speed is found by bisection.
    """
    out = np.zeros(len(push_nm))
    linear = kv if linear is None else linear
    for j, (push, k, v_c, v_m, b) in enumerate(zip(push_nm, kv, damping_speed_rad_s,
                                                   speed_cap_rad_s, linear)):
        lo_v, hi_v = 0.0, push / b
        for _ in range(60):
            v = 0.5 * (lo_v + hi_v)
            f = b * v + (k * v * (min(v, v_m) / v_c) ** 2 if v_c > 0.0 else 0.0)
            lo_v, hi_v = (v, hi_v) if f < push else (lo_v, v)
        out[j] = 0.5 * (lo_v + hi_v)
    return out


def time_to_goal_s(cruise_rad_s: np.ndarray, configs, kp: np.ndarray, kv: np.ndarray,
                   lam: np.ndarray, extra: np.ndarray, dt_s: float,
                   move_rad: float = 1.0, task: cl.Task = cl.Task.POSE,
                   inertial: Optional[np.ndarray] = None, rate_per_s: float = 0.0,
                   settling_per_s: float = 0.0) -> float:
    """
    Return the expected time to a goal ``move_rad`` away in every joint (s), roughly.

    The slowest joint's cruise, ``move_rad / v_j`` at its cruising speed (the design passes the
    median over its configurations, with the damping there), plus the linearised
    tanh loop's settling, ln(1000) time constants of its slowest mode (an error 1000 x
    smaller: a 0.5 rad error down to ~0.5 mrad), at the median of the representative
    configurations, nominal gains (the damping of :func:`damping_matrix`) and one tick of
    delay.
    """
    rhos = sorted(spectral_radius(M, joint_stiffness(rows, kp * lam, task) + np.diag(extra),
                                  damping_matrix(kv, inertial, rate_per_s, M, settling_per_s),
                                  1, dt_s)
                  for _, rows, M in configs)
    settle = np.log(1000.0) * time_constant_s(rhos[len(rhos) // 2], dt_s)
    return float(move_rad / np.min(cruise_rad_s) + settle)

"""
Inverse kinematics on the URDF model: a joint configuration within the limits that reaches a goal.

A damped-least-squares search (:func:`solve_ik`) from several starts, undamped Newton steps to
the model's precision (:func:`polish`), and for a redundant arm a slide along the self-motion
to the best posture (:func:`posture`). :func:`goal_configuration` puts them together to find
q*, the configuration the goal-configuration term pulls towards (docs/lyapunov.md section 5),
and :func:`configuration_velocity` maps a moving goal's velocity to the joints there. The work
is bounded by a number of starts and of iterations, never by wall time, so the same start and
goal give the same answer on any host. It costs milliseconds: the controller runs it in the
goal-check worker (:mod:`quat_jt_controller.goal_check`), never on the control thread.
"""
from math import pi
from typing import Optional, Sequence

import numpy as np

from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.model import RobotModel

SINGULAR_SIGMA_MIN = 0.05  # sigma_min(J) below this at the goal: reported singular (A2)
RESIDUAL_TOLERANCE = 1e-4  # IK residual (m and rad) below this: the goal is reached (A1)
# q* is polished by Newton steps to this residual (m and rad), the model's precision, or refused:
# the task and goal-configuration potentials must share their minimum exactly
POLISHED_TOLERANCE = 1e-10
POLISH_ITERATIONS = 12


def _pose_residual(model: RobotModel, q: np.ndarray, q_desired: Sequence[float],
                   p_desired: Sequence[float], task: Task) -> tuple[np.ndarray, np.ndarray]:
    """Residual (rotation vector of q_d * conj(q), and p_d - p for the pose) and its J."""
    p, R, rows = model.kinematics(q.tolist())
    rot = np.array(quat.rotation_vector(*quat.orientation_error(quat.from_rotation_matrix(R),
                                                                q_desired)))
    J = np.array(rows)
    if task is Task.POSE:
        return np.concatenate((np.subtract(p_desired, p), rot)), J
    return rot, J[3:]


def _sigma_min(model: RobotModel, q: np.ndarray, task: Task) -> float:
    """Return the smallest singular value of the task Jacobian at ``q``."""
    _, _, rows = model.kinematics(q.tolist())
    J = np.array(rows) if task is Task.POSE else np.array(rows)[3:]
    return float(np.linalg.svd(J, compute_uv=False)[-1])


def solve_ik(model: RobotModel, q_start: Sequence[float], q_desired: Sequence[float],
             p_desired: Sequence[float], task: Task, iterations: int = 200,
             damping: float = 1e-2) -> tuple[np.ndarray, float, np.ndarray]:
    """
    Damped least squares from ``q_start``; return (q, residual norm, J at q).

    Joints whose limits span a full turn are wrapped into (-pi, pi]; others are clamped.
    """
    lower = np.array(model.position_lower)
    upper = np.array(model.position_upper)
    full_turn = (upper - lower) >= 2.0 * pi - 1e-6
    bounded = ~full_turn & np.isfinite(lower) & np.isfinite(upper) & (upper > lower)
    q = np.array(q_start, dtype=float)
    damping_sq = damping * damping
    for _ in range(iterations):
        err, J = _pose_residual(model, q, q_desired, p_desired, task)
        if np.linalg.norm(err) < 0.1 * RESIDUAL_TOLERANCE:
            break
        q = q + J.T @ np.linalg.solve(J @ J.T + damping_sq * np.eye(J.shape[0]), err)
        q[full_turn] = np.mod(q[full_turn] + pi, 2.0 * pi) - pi
        q[bounded] = np.clip(q[bounded], lower[bounded], upper[bounded])
    err, J = _pose_residual(model, q, q_desired, p_desired, task)
    return q, float(np.linalg.norm(err)), J


def polish(model: RobotModel, q: Sequence[float], q_desired: Sequence[float],
           p_desired: Sequence[float], task: Task) -> Optional[np.ndarray]:
    """
    Refine an IK solution by undamped Newton steps; return it, or None if it does not converge.

    The step is the minimum-norm least-squares one (a redundant arm moves least). Converges
    quadratically from the damped solver's 1e-5 to ``POLISHED_TOLERANCE`` in two or three
    steps at a regular configuration.
    """
    q = np.array(q, dtype=float)
    for _ in range(POLISH_ITERATIONS):
        err, J = _pose_residual(model, q, q_desired, p_desired, task)
        if np.linalg.norm(err) < POLISHED_TOLERANCE:
            return q
        q = q + np.linalg.lstsq(J, err, rcond=None)[0]
    return None


POSTURE_ITERATIONS = 60  # null-space steps of posture(), at most
POSTURE_MAX_STEP_RAD = 0.1  # the longest null-space step (any joint)
POSTURE_HALVINGS = 12  # of a step that does not lower the posture cost, before giving up
POSTURE_STEP_RAD = 1e-7  # posture() stops once a step moves no joint more than this
POSTURE_BAND_WEIGHT = 100.0  # of the joint-limit bands in the posture cost, x the others


def posture(model: RobotModel, q: Sequence[float], q_desired: Sequence[float],
            p_desired: Sequence[float], task: Task, q_measured: Sequence[float],
            q_preferred: Sequence[float], weight: float,
            margin_rad: float = 0.0) -> Optional[np.ndarray]:
    """
    Slide an IK solution along the self-motion of a redundant arm to its best posture.

    Among the configurations that reach the goal, the one reached from ``q`` by steps in the
    null space of J that minimise

        c(q) = 1/2 ||q - q_measured||^2 + 1/2 weight ||q - q_preferred||^2
               + 1/2 POSTURE_BAND_WEIGHT ||x(q)||^2

    ``x`` the depth in the joint-limit bands of width ``margin_rad`` (section 2 of
    docs/lyapunov.md): nearest the measured configuration, then the preferred posture, and out
    of the bands where the self-motion allows. Each step is the Newton step of ``c`` within the
    null space of J (a basis ``Z`` from the SVD of J: ``-Z (Z^T H Z)^-1 Z^T grad c``, ``H``
    the diagonal Hessian of ``c``), at most ``POSTURE_MAX_STEP_RAD`` long, taken back onto the
    goal by Newton steps, and halved until ``c`` decreases there (a backtracking line search:
    ``c`` never increases, so the search settles at a local minimum of ``c`` along the
    self-motion). The result is polished (:func:`polish`), or None. A robot with no more joints
    than task rows has no self-motion: ``q`` comes back polished, unchanged.
    """
    q = np.array(q, dtype=float)
    q_now = np.asarray(q_measured, dtype=float)
    q_pref = np.asarray(q_preferred, dtype=float)
    lower = np.array(model.position_lower, dtype=float)
    upper = np.array(model.position_upper, dtype=float)
    limited = (upper - lower) < 2.0 * pi - 1e-6
    inner_lo = np.where(limited, lower + margin_rad, -np.inf)
    inner_hi = np.where(limited, upper - margin_rad, np.inf)

    def depth(x: np.ndarray) -> np.ndarray:  # signed depth in the bands (0 outside them)
        return np.minimum(x - inner_lo, 0.0) + np.maximum(x - inner_hi, 0.0)

    def cost(x: np.ndarray) -> float:
        return 0.5 * (float(np.sum((x - q_now) ** 2)) + weight * float(np.sum((x - q_pref) ** 2))
                      + POSTURE_BAND_WEIGHT * float(np.sum(depth(x) ** 2)))

    def onto_goal(x: np.ndarray) -> np.ndarray:
        for _ in range(2):
            err, J = _pose_residual(model, x, q_desired, p_desired, task)
            x = np.clip(x + np.linalg.lstsq(J, err, rcond=None)[0], lower, upper)
        return x

    _, J = _pose_residual(model, q, q_desired, p_desired, task)
    rows = J.shape[0]
    if rows >= J.shape[1]:
        return polish(model, q, q_desired, p_desired, task)
    c_now = cost(q)
    for _ in range(POSTURE_ITERATIONS):
        _, J = _pose_residual(model, q, q_desired, p_desired, task)
        Z = np.linalg.svd(J)[2][rows:].T  # the self-motion's directions at q
        band = depth(q)
        grad = (q - q_now) + weight * (q - q_pref) + POSTURE_BAND_WEIGHT * band
        hessian = 1.0 + weight + POSTURE_BAND_WEIGHT * (band != 0.0)
        step = -Z @ np.linalg.solve(Z.T @ (hessian[:, None] * Z), Z.T @ grad)
        largest = float(np.max(np.abs(step)))
        if largest < POSTURE_STEP_RAD:
            break
        if largest > POSTURE_MAX_STEP_RAD:  # the self-motion is curved: short steps
            step *= POSTURE_MAX_STEP_RAD / largest
        for _ in range(POSTURE_HALVINGS):
            q_try = onto_goal(np.clip(q + step, lower, upper))
            c_try = cost(q_try)
            if c_try < c_now:
                break
            step *= 0.5
        else:
            break  # no step along the self-motion lowers c: a local minimum
        q, c_now = q_try, c_try
    return polish(model, q, q_desired, p_desired, task)


MAX_STARTS = 12  # IK starts per check: measured q, mid-range, then seeded random ones


def _representative(q: np.ndarray, near: np.ndarray, lower: np.ndarray,
                    upper: np.ndarray, margin_rad: float = 0.0) -> np.ndarray:
    """
    Move each full-turn joint by whole turns to the angle within its range nearest ``near``.

    An angle at least ``margin_rad`` from both limits is preferred: a full-turn joint has no
    joint-limit band, and a q* next to its stop leaves no room for an overshoot. A joint
    without stops (URDF ``continuous``) takes the angle nearest ``near``.
    """
    out = q.copy()
    for j in range(q.size):
        if not np.isfinite(upper[j] - lower[j]):
            out[j] = q[j] + 2.0 * pi * np.round((near[j] - q[j]) / (2.0 * pi))
        elif upper[j] - lower[j] >= 2.0 * pi - 1e-6:
            turns = np.round((near[j] - q[j]) / (2.0 * pi))
            best = None
            for k in (turns - 2, turns - 1, turns, turns + 1, turns + 2):
                c = q[j] + 2.0 * pi * k
                if not lower[j] <= c <= upper[j]:
                    continue
                key = (not lower[j] + margin_rad <= c <= upper[j] - margin_rad,
                       abs(c - near[j]))
                if best is None or key < best[0]:
                    best = (key, c)
            if best is not None:
                out[j] = best[1]
    return out


CONFIGURATION_STARTS = (MAX_STARTS, 48)  # at least / at most, for goal_configuration
WARM_STEP_RAD = 0.5  # a warm-started q* this close (every joint) to the last one is taken as is


def goal_configuration(model: RobotModel, q_measured: Optional[Sequence[float]],
                       q_desired: Sequence[float], p_desired: Sequence[float], task: Task,
                       margin_rad: float = 0.0,
                       starts_range: tuple[int, int] = CONFIGURATION_STARTS,
                       seed: int = 0,
                       q_warm: Optional[Sequence[float]] = None,
                       q_preferred: Optional[Sequence[float]] = None,
                       posture_weight: float = 0.0) -> Optional[np.ndarray]:
    """
    Return q*, a regular joint configuration within the limits that reaches the goal, or None.

    q* reaches the goal to the model's precision (``POLISHED_TOLERANCE``, :func:`polish`).

    The goal-configuration potential (docs/lyapunov.md, section 5) pulls towards
    it. The starts of :func:`check_goal` (a robot has several IK branches, so at least
    ``starts_range[0]`` of them, and more, up to ``starts_range[1]``, until a solution outside
    the joint-limit bands is found); among the solutions with ``sigma_min(J) >=
    SINGULAR_SIGMA_MIN``, full-turn joints moved by whole turns to the angle nearest the
    measured one, but ``margin_rad`` from their stops when a whole turn allows (the joint box
    is convex: the way there stays within the limits), it prefers
    those outside the joint-limit bands (``margin_rad``), then the nearest to ``q_measured``.
    Deterministic.

    ``q_warm`` (the last goal's q*, for a stream of goals) is tried first: a solution from it
    that is regular, within the limits, outside the bands and within ``WARM_STEP_RAD`` of it on
    every joint is returned at once. So a goal that moves keeps one IK branch, and each of its
    goals costs a few iterations instead of a dozen searches.

    A redundant arm reaches a goal along a whole self-motion: each solution is slid along it
    to its best posture (:func:`posture`: nearest ``q_measured``, then ``q_preferred``, by
    default the middle of the ranges, with ``posture_weight``, and out of the bands), so q*
    fixes the elbow where the arm already is (docs/lyapunov.md, section 9).
    """
    lower = np.array(model.position_lower, dtype=float)
    upper = np.array(model.position_upper, dtype=float)
    lo = np.maximum(lower, -pi)
    hi = np.minimum(upper, pi)
    q_now = (0.5 * (lo + hi) if q_measured is None else np.asarray(q_measured, float))
    q_pref = np.asarray(model.middle_of_ranges() if q_preferred is None else q_preferred,
                        dtype=float)
    rng = np.random.default_rng(seed)
    starts = [q_now, 0.5 * (lo + hi)]
    limited = (upper - lower) < 2.0 * pi - 1e-6

    def accept(q: np.ndarray, residual: float, J: np.ndarray) -> Optional[tuple[bool, np.ndarray]]:
        """Return (in a band, q polished and moved to its representative), or None."""
        if residual >= RESIDUAL_TOLERANCE:
            return None
        if float(np.linalg.svd(J, compute_uv=False)[-1]) < SINGULAR_SIGMA_MIN:
            return None
        q = polish(model, q, q_desired, p_desired, task)
        if q is None:
            return None
        q = _representative(q, q_now, lower, upper, margin_rad)
        if J.shape[0] < J.shape[1]:
            q = posture(model, q, q_desired, p_desired, task, q_now, q_pref, posture_weight,
                        margin_rad)
            if q is None or _sigma_min(model, q, task) < SINGULAR_SIGMA_MIN:
                return None
            q = _representative(q, q_now, lower, upper, margin_rad)  # it may have slid
        if np.any(q < lower) or np.any(q > upper):
            return None
        return bool(np.any(limited & ((q < lower + margin_rad) | (q > upper - margin_rad)))), q

    if q_warm is not None:
        warm = np.asarray(q_warm, float)
        found = accept(*solve_ik(model, warm, q_desired, p_desired, task))
        if found is not None and not found[0] and np.max(np.abs(found[1] - warm)) <= (
                WARM_STEP_RAD):
            return found[1]
    best = None
    for k in range(starts_range[1]):
        if k >= starts_range[0] and best is not None and not best[0][0]:
            break
        q_start = starts.pop(0) if starts else rng.uniform(lo, hi)
        found = accept(*solve_ik(model, q_start + 1e-3, q_desired, p_desired, task))
        if found is None:
            continue
        in_band, q = found
        score = (in_band, float(np.linalg.norm(q - q_now)))
        if best is None or score < best[0]:
            best = (score, q)
    return None if best is None else best[1]


def configuration_velocity(model: RobotModel, q_star: Sequence[float],
                           nu_desired: Sequence[float], task: Task) -> np.ndarray:
    """
    Return qdot*_d with J(q*) qdot*_d = nu_d: the joint velocity of a moving goal at q*.

    ``nu_desired`` is the goal's task velocity in the task's rows (``[v; omega]`` or
    ``omega``, base frame). Least squares: the minimum-norm solution for a redundant arm. It
    runs in the worker, so the tick never inverts a Jacobian (docs/lyapunov.md, section 7).
    """
    _, _, rows = model.kinematics(list(q_star))
    J = np.array(rows)
    if task is Task.ORIENTATION:
        J = J[3:]
    return np.linalg.lstsq(J, np.asarray(nu_desired, dtype=float), rcond=None)[0]

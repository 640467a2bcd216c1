"""
Inverse kinematics on the URDF model: a joint configuration within the limits that reaches a goal.

A Levenberg-Marquardt search that respects the joint limits (:func:`solve_ik`) from several
starts (:func:`starts`), undamped Newton steps to the model's precision (:func:`polish`), and
for a redundant arm a slide along the self-motion to the best posture (:func:`posture`), and
on from a near-singular one until it is regular (:func:`regular_posture`).
:func:`search_goal_configuration` puts them together to find q*, the configuration the
goal-configuration term pulls towards (docs/lyapunov.md section 5), and
:func:`configuration_velocity` maps a moving goal's velocity to the joints there.

The goal is a unit quaternion ``quat_desired`` (w, x, y, z) and, for the pose and position tasks, a
position ``p_desired`` (m), both in the base frame (the position task reads the position alone: its
residual is p_d - p, its self-motion larger); joint configurations are ``q`` (rad). The work is
bounded by a number of starts and of iterations, never by wall time, so the same start and goal
give the same answer on any host. The controller runs it in the goal-check worker
(:mod:`quat_jt_controller.goal_check`), never on the control thread.
"""
from math import pi
from typing import Iterator, NamedTuple, Optional, Sequence

import numpy as np

from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.model import RobotModel, SINGULAR_SIGMA_MIN
from quat_jt_controller.shaping import (BAND_DEPTH_TOLERANCE_RAD, DEFAULT_SPEED_CAP_RAD_S,
                                        FULL_TURN_RAD, PLAUSIBLE_SPEED_RAD_S)

RESIDUAL_TOLERANCE = 1e-4  # IK residual (m and rad) below this: the goal is reached (A1)
# q* is polished by Newton steps to this residual (m and rad), the model's precision, or refused:
# the task and goal-configuration potentials must share their minimum exactly
POLISHED_TOLERANCE = 1e-10
POLISH_ITERATIONS = 12

IK_ITERATIONS = 100  # Levenberg-Marquardt steps of solve_ik() per start, at most (tried or taken)
IK_DAMPING = 1e-2  # its first damping lambda (in the units of the residual, m and rad)
IK_DAMPING_RANGE = (1e-6, 1e2)  # lambda shrinks x 1/3 after a step taken, grows x 4 after one
# refused; past the upper bound no step lowers the residual: a local minimum, the start is spent
IK_MAX_STEP_RAD = 0.5  # the longest step of any joint (the model is linearised over it)
# a start whose ||r||^2 falls by less than this share over IK_STALL_STEPS steps has settled in
# a local minimum: it is spent (the next start costs less than the crawl)
IK_STALL_SHARE = 0.01
IK_STALL_STEPS = 10


def _pose_residual(model: RobotModel, q: np.ndarray, quat_desired: Sequence[float],
                   p_desired: Sequence[float], task: Task) -> tuple[np.ndarray, np.ndarray]:
    """Residual (rotation vector of quat_d * conj(quat) and/or p_d - p, per task) and its J."""
    p, R, rows = model.kinematics(q.tolist())
    task = Task(task)
    if task is Task.POSITION:
        return np.subtract(p_desired, p), np.array(rows)[:3]
    rot = np.array(quat.rotation_vector(*quat.orientation_error(quat.from_rotation_matrix(R),
                                                                quat_desired)))
    J = np.array(rows)
    if task is Task.POSE:
        return np.concatenate((np.subtract(p_desired, p), rot)), J
    return rot, J[3:]


def sigma_min(model: RobotModel, q: Sequence[float], task: Task) -> float:
    """
    Return the smallest singular value of the task Jacobian (J_G, J_o or J_p) at ``q``.

    Its position rows are in units of the arm's length (``RobotModel.task_sigma_min``), so
    it compares with SINGULAR_SIGMA_MIN on an arm of any size.
    """
    _, _, rows = model.kinematics(list(q))
    task = Task(task)
    return model.task_sigma_min(task.rows(np.array(rows)), task.has_position)


def _limits(model: RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the lower and upper limits, and which joints are bounded (not a full turn)."""
    lower = np.array(model.position_lower, dtype=float)
    upper = np.array(model.position_upper, dtype=float)
    return lower, upper, np.isfinite(upper - lower) & (upper - lower < FULL_TURN_RAD)


TRAVEL_SPEED_RATIO_MAX = 100.0  # travel_weights: at most this x the slowest joint's speed


def travel_weights(model: RobotModel) -> np.ndarray:
    """
    Return each joint's weight in the distance q* is the nearest in: ``(v_min / v_j)^2``.

    ``v_j`` is the joint's URDF velocity limit (``DEFAULT_SPEED_CAP_RAD_S`` where the URDF
    gives none or a placeholder, above ``PLAUSIBLE_SPEED_RAD_S``), ``v_min`` the slowest
    joint's: ``sqrt(sum_j w_j dq_j^2)`` is the travel's time at the limits (its 2-norm over
    the joints, not the slowest joint's alone) in units of the slowest joint's, so of two goal
    configurations the one the slow joints travel less to is the nearer. Joints that share one
    limit keep the Euclidean distance. A joint more than ``TRAVEL_SPEED_RATIO_MAX`` times
    faster than the slowest counts as that much faster: the posture's Newton steps stay well
    conditioned.
    """
    v = travel_speeds(model)
    return np.maximum(float(v.min()) / v, 1.0 / TRAVEL_SPEED_RATIO_MAX) ** 2


def travel_speeds(model: RobotModel) -> np.ndarray:
    """
    Return the speed each joint travels at in the travel's time (rad/s, :func:`travel_weights`).

    Its URDF velocity limit; ``DEFAULT_SPEED_CAP_RAD_S`` where the URDF gives none or a
    placeholder (above ``PLAUSIBLE_SPEED_RAD_S``): a limit no drive has says nothing of the
    joint's speed.
    """
    v = np.array(model.velocity_limits, dtype=float)
    return np.where(np.isfinite(v) & (v > 0.0) & (v <= PLAUSIBLE_SPEED_RAD_S), v,
                    DEFAULT_SPEED_CAP_RAD_S)


def _in_band(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, limited: np.ndarray,
             margin_rad: float) -> bool:
    """
    Return whether a bounded joint of ``q`` lies within ``margin_rad`` of a limit.

    A joint less than ``BAND_DEPTH_TOLERANCE_RAD`` deep counts as out of the band: that is
    where :func:`posture` leaves a joint its cost pulls against the band's wall (the pull over
    ``POSTURE_BAND_WEIGHT``: at most 1e-4 rad per rad of distance to the measured q).
    """
    inner = margin_rad - BAND_DEPTH_TOLERANCE_RAD
    return bool(np.any(limited & ((q < lower + inner) | (q > upper - inner))))


def solve_ik(model: RobotModel, q_start: Sequence[float], quat_desired: Sequence[float],
             p_desired: Sequence[float], task: Task, iterations: int = IK_ITERATIONS,
             damping: float = IK_DAMPING) -> tuple[np.ndarray, float, np.ndarray]:
    """
    Search from ``q_start`` for q within the limits that reaches the goal; return (q, residual, J).

    Levenberg-Marquardt on the residual ``r(q)`` (:func:`_pose_residual`): the step ``dq``
    solves ``(J_f^T J_f + lambda^2 I) dq_f = J_f^T r`` on the free joints ``f``, at most
    ``IK_MAX_STEP_RAD`` long. It is taken if ``||r||`` decreases (then lambda shrinks, so the
    search ends with Gauss-Newton steps), else lambda grows. Past ``IK_DAMPING_RANGE``, or
    once ``||r||^2`` falls by less than ``IK_STALL_SHARE`` over ``IK_STALL_STEPS`` steps, the
    search has settled in a local minimum and stops. In least squares, a task with more rows
    than joints (a 5-joint arm's pose) still reaches a goal it can reach exactly.

    A bounded joint is clamped to its limits, and one at a limit that the step would push out
    is held there (not free) for that step, so the others still move. A joint whose range
    spans a full turn (or a continuous one) moves freely and ends on the angle nearest
    ``q_start`` within its range (:func:`representative`). ``residual`` is ``||r||``, J the
    task Jacobian at q.
    """
    lower, upper, bounded = _limits(model)
    q_start = np.asarray(q_start, dtype=float)
    q_rad = np.where(bounded, np.clip(q_start, lower, upper), q_start)
    r, J = _pose_residual(model, q_rad, quat_desired, p_desired, task)
    cost = float(r @ r)
    lam = damping
    target = (0.1 * RESIDUAL_TOLERANCE) ** 2
    costs = [cost]  # after each step, tried or taken
    for _ in range(iterations):
        if cost < target or (len(costs) > IK_STALL_STEPS and cost > (
                1.0 - IK_STALL_SHARE) * costs[-1 - IK_STALL_STEPS]):
            break
        descent = J.T @ r  # minus the gradient of 1/2 ||r||^2 in q
        free = ~(bounded & (((q_rad <= lower) & (descent < 0.0))
                            | ((q_rad >= upper) & (descent > 0.0))))
        if not free.any():  # every joint held at a stop: nothing can move
            break
        J_free = J[:, free]
        normal = J_free.T @ J_free
        normal.flat[::normal.shape[0] + 1] += lam * lam
        step = np.zeros_like(q_rad)
        step[free] = np.linalg.solve(normal, J_free.T @ r)
        largest = float(np.abs(step).max())
        if largest > IK_MAX_STEP_RAD:
            step *= IK_MAX_STEP_RAD / largest
        q_try = q_rad + step
        q_try[bounded] = np.clip(q_try[bounded], lower[bounded], upper[bounded])
        r_try, J_try = _pose_residual(model, q_try, quat_desired, p_desired, task)
        cost_try = float(r_try @ r_try)
        if cost_try < cost:
            q_rad, r, J, cost = q_try, r_try, J_try, cost_try
            lam = max(lam / 3.0, IK_DAMPING_RANGE[0])
        else:
            lam *= 4.0
            if lam > IK_DAMPING_RANGE[1]:
                break
        costs.append(cost)
    return representative(q_rad, q_start, lower, upper), float(np.sqrt(cost)), J


def polish(model: RobotModel, q: Sequence[float], quat_desired: Sequence[float],
           p_desired: Sequence[float], task: Task) -> Optional[np.ndarray]:
    """
    Refine an IK solution by undamped Newton steps; return it, or None if it does not converge.

    The step is the minimum-norm least-squares one (a redundant arm moves least). Converges
    quadratically from the damped solver's 1e-5 to ``POLISHED_TOLERANCE`` in two or three
    steps at a regular configuration.
    """
    q = np.array(q, dtype=float)
    for _ in range(POLISH_ITERATIONS):
        r, J = _pose_residual(model, q, quat_desired, p_desired, task)
        if np.linalg.norm(r) < POLISHED_TOLERANCE:
            return q
        q = q + np.linalg.lstsq(J, r, rcond=None)[0]
    return None


def _onto_goal(model: RobotModel, x: np.ndarray, quat_desired: Sequence[float],
               p_desired: Sequence[float], task: Task, lower: np.ndarray,
               upper: np.ndarray) -> np.ndarray:
    """Take ``x`` back onto the goal by two minimum-norm Newton steps, within the limits."""
    for _ in range(2):
        r, J = _pose_residual(model, x, quat_desired, p_desired, task)
        x = np.clip(x + np.linalg.lstsq(J, r, rcond=None)[0], lower, upper)
    return x


POSTURE_ITERATIONS = 60  # null-space steps of posture(), at most
POSTURE_MAX_STEP_RAD = 0.1  # the longest null-space step (any joint)
POSTURE_HALVINGS = 12  # of a step that does not lower the posture cost, before giving up
POSTURE_STEP_RAD = 1e-7  # posture() stops once a step moves no joint more than this
POSTURE_BAND_WEIGHT = 1e4  # of the joint-limit bands in the posture cost, x the others


def posture(model: RobotModel, q: Sequence[float], quat_desired: Sequence[float],
            p_desired: Sequence[float], task: Task, q_measured: Sequence[float],
            q_preferred: Sequence[float], weight: float,
            margin_rad: float = 0.0) -> Optional[np.ndarray]:
    """
    Slide an IK solution along the self-motion of a redundant arm to its best posture.

    Among the configurations that reach the goal, the one reached from ``q`` by steps in the
    null space of J that minimise

        c(q) = 1/2 sum_j w_j ((q_j - q_measured,j)^2 + weight (q_j - q_preferred,j)^2)
               + 1/2 POSTURE_BAND_WEIGHT ||x(q)||^2

    ``w`` the :func:`travel_weights`, ``x`` the depth in the joint-limit bands of width
    ``margin_rad`` (section 2 of docs/lyapunov.md): nearest the measured configuration in the
    time the joints take to travel there, then the preferred posture, and out of the bands
    where the self-motion allows. Each step is the Newton step of ``c`` within the
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
    w = travel_weights(model)
    lower = np.array(model.position_lower, dtype=float)
    upper = np.array(model.position_upper, dtype=float)
    limited = _limits(model)[2]
    inner_lo = np.where(limited, lower + margin_rad, -np.inf)
    inner_hi = np.where(limited, upper - margin_rad, np.inf)

    def depth(x: np.ndarray) -> np.ndarray:  # signed depth in the bands (0 outside them)
        return np.minimum(x - inner_lo, 0.0) + np.maximum(x - inner_hi, 0.0)

    def cost(x: np.ndarray) -> float:
        return 0.5 * (float(np.sum(w * ((x - q_now) ** 2 + weight * (x - q_pref) ** 2)))
                      + POSTURE_BAND_WEIGHT * float(np.sum(depth(x) ** 2)))

    _, J = _pose_residual(model, q, quat_desired, p_desired, task)
    rows = J.shape[0]
    if rows >= J.shape[1]:
        return polish(model, q, quat_desired, p_desired, task)
    c_now = cost(q)
    for _ in range(POSTURE_ITERATIONS):
        _, J = _pose_residual(model, q, quat_desired, p_desired, task)
        Z = np.linalg.svd(J)[2][rows:].T  # the self-motion's directions at q
        band = depth(q)
        grad = w * ((q - q_now) + weight * (q - q_pref)) + POSTURE_BAND_WEIGHT * band
        hessian = w * (1.0 + weight) + POSTURE_BAND_WEIGHT * (band != 0.0)
        step = -Z @ np.linalg.solve(Z.T @ (hessian[:, None] * Z), Z.T @ grad)
        largest = float(np.max(np.abs(step)))
        if largest < POSTURE_STEP_RAD:
            break
        if largest > POSTURE_MAX_STEP_RAD:  # the self-motion is curved: short steps
            step *= POSTURE_MAX_STEP_RAD / largest
        for _ in range(POSTURE_HALVINGS):
            q_try = _onto_goal(model, np.clip(q + step, lower, upper), quat_desired, p_desired,
                               task, lower, upper)
            c_try = cost(q_try)
            if c_try < c_now:
                break
            step *= 0.5
        else:
            break  # no step along the self-motion lowers c: a local minimum
        q, c_now = q_try, c_try
    return polish(model, q, quat_desired, p_desired, task)


REGULAR_ITERATIONS = 30  # steps of regular_posture(), at most (each at most 0.1 rad)
REGULAR_MARGIN = 1.01  # ... until sigma_min is this x SINGULAR_SIGMA_MIN
REGULAR_STALL = 1e-4  # ... and a step that raises sigma_min by less than this ends the climb
SIGMA_STEP_RAD = 1e-6  # the central difference of sigma_min's gradient


def regular_posture(model: RobotModel, q: Sequence[float], quat_desired: Sequence[float],
                    p_desired: Sequence[float], task: Task,
                    margin_rad: float = 0.0) -> Optional[np.ndarray]:
    """
    Slide a near-singular solution of a redundant arm along its self-motion until it is regular.

    Steepest ascent of :func:`sigma_min` within the null space of J: its gradient by central
    differences, projected onto the self-motion, a step at most ``POSTURE_MAX_STEP_RAD`` long
    (any joint), taken back onto the goal, halved until ``sigma_min`` rises there within the
    limits, still on the goal (``RESIDUAL_TOLERANCE``: a step clipped at a limit may leave it)
    and out of the joint-limit bands (``margin_rad``). Returns the first configuration whose
    ``sigma_min`` reaches ``REGULAR_MARGIN x SINGULAR_SIGMA_MIN``, polished and within the
    limits, or None if none does within ``REGULAR_ITERATIONS`` steps, or a step raises
    ``sigma_min`` by less than ``REGULAR_STALL`` (a plateau: the climb would cost the goal
    check for nothing). :func:`posture` stops at the posture nearest the measured
    configuration, which may lie in a near-singular stretch of the self-motion that a short
    slide leaves (docs/lyapunov.md, section 9).
    """
    q = np.array(q, dtype=float)
    lower, upper, limited = _limits(model)

    def done(x: np.ndarray) -> Optional[np.ndarray]:
        x = polish(model, x, quat_desired, p_desired, task)
        if x is None or np.any(x < lower) or np.any(x > upper):
            return None
        return x

    target = REGULAR_MARGIN * SINGULAR_SIGMA_MIN
    sigma = sigma_min(model, q, task)
    eye = np.eye(q.size) * SIGMA_STEP_RAD
    for _ in range(REGULAR_ITERATIONS):
        if sigma >= target:
            return done(q)
        _, J = _pose_residual(model, q, quat_desired, p_desired, task)
        rows = J.shape[0]
        if rows >= J.shape[1]:
            return None  # no self-motion to slide along
        Z = np.linalg.svd(J)[2][rows:].T
        gradient = np.array([sigma_min(model, q + e, task) - sigma_min(model, q - e, task)
                             for e in eye]) / (2.0 * SIGMA_STEP_RAD)
        step = Z @ (Z.T @ gradient)
        largest = float(np.max(np.abs(step)))
        if largest <= 0.0:
            return None
        step *= POSTURE_MAX_STEP_RAD / largest
        for _ in range(POSTURE_HALVINGS):
            q_try = _onto_goal(model, np.clip(q + step, lower, upper), quat_desired, p_desired,
                               task, lower, upper)
            residual = float(np.linalg.norm(
                _pose_residual(model, q_try, quat_desired, p_desired, task)[0]))
            sigma_try = sigma_min(model, q_try, task)
            if (sigma_try > sigma and residual < RESIDUAL_TOLERANCE
                    and not _in_band(q_try, lower, upper, limited, margin_rad)):
                break
            step *= 0.5
        else:
            return None  # sigma_min is at a local maximum along the self-motion, or in a band
        if sigma_try - sigma < REGULAR_STALL and sigma_try < target:
            return None
        q, sigma = q_try, sigma_try
    return done(q) if sigma >= target else None


MAX_STARTS = 12  # IK starts per check: measured q, mid-range, then seeded random ones
START_NUDGE_RAD = 1e-3  # every start is moved this much on each joint: off an exact singularity


def sampling_box(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """Return the box random starts are drawn from: the limits, [-pi, pi] for no stops."""
    lower, upper, _ = _limits(model)
    return (np.where(np.isfinite(lower), lower, -pi), np.where(np.isfinite(upper), upper, pi))


def starts(model: RobotModel, q_measured: Optional[Sequence[float]],
           seed: int = 0) -> Iterator[np.ndarray]:
    """
    Yield IK starts without end: the measured q, the middle of the ranges, then random ones.

    The measured q (the branch the regulator most likely ends on; the middle of the ranges if
    None), then the middle of the ranges, then configurations drawn uniformly within the
    limits (seeded: the same seed gives the same starts). A full-turn joint's start needs no
    shift by whole turns: :func:`solve_ik` moves it freely and wraps it at the end. Each start
    is nudged by ``START_NUDGE_RAD`` off an exact singularity (such as the wrist's q = 0).
    """
    lo, hi = sampling_box(model)
    rng = np.random.default_rng(seed)
    middle = 0.5 * (lo + hi)
    yield (middle if q_measured is None else np.asarray(q_measured, dtype=float)) + (
        START_NUDGE_RAD)
    yield middle + START_NUDGE_RAD
    while True:
        yield rng.uniform(lo, hi) + START_NUDGE_RAD


def representative(q: np.ndarray, near: np.ndarray, lower: np.ndarray,
                   upper: np.ndarray, margin_rad: float = 0.0) -> np.ndarray:
    """
    Move each full-turn joint by whole turns to the angle within its range nearest ``near``.

    An angle at least ``margin_rad`` from both limits is preferred: a full-turn joint has no
    joint-limit band, and a q* next to its stop leaves no room for an overshoot. A joint
    without stops (URDF ``continuous``) takes the angle nearest ``near``. A bounded joint is
    left as it is.
    """
    out = np.array(q, dtype=float)
    for j in range(out.size):
        span = upper[j] - lower[j]
        if not np.isfinite(span):
            out[j] = q[j] + 2.0 * pi * np.round((near[j] - q[j]) / (2.0 * pi))
        elif span >= FULL_TURN_RAD:
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
SAME_SOLUTION_RAD = 1e-3  # two IK solutions this close (every joint) are one branch
HOP_RAD = 0.3  # spread of the starts about the closest miss (each joint, standard deviation)


class Search(NamedTuple):
    """What :func:`search_goal_configuration` found, and how hard it looked."""

    q_star: Optional[np.ndarray]  # None: no start reached the goal within the limits
    sigma_min: float  # of the task Jacobian at q_star, as sigma_min() (nan without one)
    starts: int  # IK starts tried (the warm start included)
    best_q: np.ndarray  # the configuration of the smallest residual found
    best_residual: float  # its residual (m and rad)

    @property
    def regular(self) -> bool:
        """Tell whether q* was found at a regular configuration (A2 holds there)."""
        return self.q_star is not None and self.sigma_min >= SINGULAR_SIGMA_MIN


def search_goal_configuration(model: RobotModel, q_measured: Optional[Sequence[float]],
                              quat_desired: Sequence[float], p_desired: Sequence[float],
                              task: Task, margin_rad: float = 0.0,
                              starts_range: tuple[int, int] = CONFIGURATION_STARTS,
                              seed: int = 0,
                              q_warm: Optional[Sequence[float]] = None,
                              q_preferred: Optional[Sequence[float]] = None,
                              posture_weight: float = 0.0) -> Search:
    """
    Look for q*, a joint configuration within the limits that reaches the goal (a :class:`Search`).

    q* reaches the goal to the model's precision (``POLISHED_TOLERANCE``, :func:`polish`).
    The goal-configuration potential (docs/lyapunov.md, section 5) pulls towards it.

    :func:`solve_ik` runs from the :func:`starts` (a robot has several IK branches, so at
    least ``starts_range[0]`` of them, and more, up to ``starts_range[1]``, until a regular
    solution outside the joint-limit bands is found). While none has reached the goal past
    ``starts_range[0]``, every other start is drawn about the closest miss so far (normal,
    ``HOP_RAD`` on each joint): a branch in a narrow corner of the limits is rarely hit by a
    uniform draw, but often by a hop from a configuration that nearly reached it.

    Each solution is polished, its full-turn joints moved by whole turns to the angle nearest
    the measured one, but ``margin_rad`` from their stops when a whole turn allows (the joint
    box is convex: the way there stays within the limits). Among them it prefers the regular
    ones (:func:`sigma_min` ``>= SINGULAR_SIGMA_MIN``), then those outside the joint-limit bands
    (``margin_rad``), then the nearest to ``q_measured`` (in the :func:`travel_weights`'
    distance: the time the joints take to travel there). A goal reached only near a
    singularity still gets the least singular q* found: A2 does not hold there, which the goal
    check reports, but the goal is reached. Deterministic.

    ``q_warm`` (the last goal's q*, for a stream of goals) is tried first: a solution from it
    that is regular, within the limits, outside the bands and within ``WARM_STEP_RAD`` of it on
    every joint is returned at once. So a goal that moves keeps one IK branch, and each of its
    goals costs a few iterations instead of a dozen searches.

    A redundant arm reaches a goal along a whole self-motion: each solution is slid along it
    to its best posture (:func:`posture`: nearest ``q_measured``, then ``q_preferred``, by
    default the middle of the ranges, with ``posture_weight``, and out of the bands), so q*
    fixes the elbow where the arm already is, and on up ``sigma_min`` if it is near-singular
    there (:func:`regular_posture`; docs/lyapunov.md, section 9).
    """
    lower, upper, limited = _limits(model)
    lo, hi = sampling_box(model)
    q_now = 0.5 * (lo + hi) if q_measured is None else np.asarray(q_measured, dtype=float)
    q_pref = np.asarray(model.middle_of_ranges() if q_preferred is None else q_preferred,
                        dtype=float)
    weights = travel_weights(model)

    def travel(q: np.ndarray) -> float:  # the distance from the arm, in the travel's time
        return float(np.sqrt(np.sum(weights * (q - q_now) ** 2)))
    best_try: list = [np.asarray(q_now, dtype=float), np.inf]  # the smallest residual found
    tried: list = []  # the IK solutions taken further, one per branch

    def accept(q: np.ndarray, residual: float,
               J: np.ndarray) -> Optional[tuple[tuple, np.ndarray, float]]:
        """Return (its score, q polished and moved to its representative, sigma_min), or None."""
        if residual < best_try[1]:
            best_try[:] = [q, residual]
        if residual >= RESIDUAL_TOLERANCE:
            return None
        key = representative(q, q_now, lower, upper)
        if any(np.max(np.abs(key - other)) < SAME_SOLUTION_RAD for other in tried):
            return None  # a branch already taken further
        tried.append(key)
        q = polish(model, q, quat_desired, p_desired, task)
        if q is None:
            return None
        q = representative(q, q_now, lower, upper, margin_rad)
        if J.shape[0] < J.shape[1]:
            q = posture(model, q, quat_desired, p_desired, task, q_now, q_pref, posture_weight,
                        margin_rad)
            if q is None:
                return None
            q = representative(q, q_now, lower, upper, margin_rad)  # it may have slid
            if sigma_min(model, q, task) < SINGULAR_SIGMA_MIN:  # a short slide may leave it
                regular = regular_posture(model, q, quat_desired, p_desired, task, margin_rad)
                if regular is not None:
                    regular = representative(regular, q_now, lower, upper, margin_rad)
                    if np.all(regular >= lower) and np.all(regular <= upper):
                        q = regular
        if np.any(q < lower) or np.any(q > upper):
            return None
        sigma = sigma_min(model, q, task)
        in_band = _in_band(q, lower, upper, limited, margin_rad)
        return (sigma < SINGULAR_SIGMA_MIN, in_band, travel(q)), q, sigma

    count = 0
    if q_warm is not None:
        warm = np.asarray(q_warm, dtype=float)
        count += 1
        found = accept(*solve_ik(model, warm, quat_desired, p_desired, task))
        if found is not None and not any(found[0][:2]) and np.max(
                np.abs(found[1] - warm)) <= WARM_STEP_RAD:
            return Search(found[1], found[2], count, found[1], 0.0)
    best = None
    hop = np.random.default_rng([seed, 1])  # the nearby starts' own stream
    for k, q_start in enumerate(starts(model, q_now, seed)):
        if k >= starts_range[1] or (k >= starts_range[0] and best is not None
                                    and not any(best[0][:2])):
            break
        if best is None and k >= starts_range[0] and k % 2:  # near the closest miss
            q_start = np.clip(best_try[0] + hop.normal(0.0, HOP_RAD, q_now.size), lo, hi)
        count += 1
        found = accept(*solve_ik(model, q_start, quat_desired, p_desired, task))
        if found is not None and (best is None or found[0] < best[0]):
            best = found
    if best is None:
        return Search(None, float('nan'), count, np.asarray(best_try[0]), float(best_try[1]))
    return Search(best[1], best[2], count, best[1], 0.0)


def goal_configuration(model: RobotModel, q_measured: Optional[Sequence[float]],
                       quat_desired: Sequence[float], p_desired: Sequence[float], task: Task,
                       margin_rad: float = 0.0,
                       starts_range: tuple[int, int] = CONFIGURATION_STARTS,
                       seed: int = 0,
                       q_warm: Optional[Sequence[float]] = None,
                       q_preferred: Optional[Sequence[float]] = None,
                       posture_weight: float = 0.0) -> Optional[np.ndarray]:
    """Return q* of :func:`search_goal_configuration` (same arguments), or None if none."""
    return search_goal_configuration(model, q_measured, quat_desired, p_desired, task,
                                     margin_rad, starts_range, seed, q_warm, q_preferred,
                                     posture_weight).q_star


def configuration_velocity(model: RobotModel, q_star: Sequence[float],
                           nu_desired: Sequence[float], task: Task) -> np.ndarray:
    """
    Return qdot*_d with J(q*) qdot*_d = nu_d: the joint velocity of a moving goal at q*.

    ``nu_desired`` is the goal's task velocity in the task's rows (``[v; omega]``, ``omega``
    or ``v``, base frame). Least squares: the minimum-norm solution for a redundant arm. It
    runs in the worker, so the tick never inverts a Jacobian (docs/lyapunov.md, section 7).
    """
    _, _, rows = model.kinematics(list(q_star))
    J = Task(task).rows(np.array(rows))
    return np.linalg.lstsq(J, np.asarray(nu_desired, dtype=float), rcond=None)[0]

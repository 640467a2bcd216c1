"""
Check a goal against the paper's assumptions A1 (reachable) and A2 (no self-motion there).

A damped-least-squares inverse kinematics on the URDF model looks for a joint configuration
within the limits that reaches the goal. It starts from the measured q (the branch the
regulator most likely ends on), then from other configurations, within a wall-time budget;
joints whose range spans a full turn are wrapped, not clamped. At the solution, the smallest
singular value of J_o (orientation task) or J_G (pose task) tells whether it is singular. The
regulator itself never uses this: it is advice for the user, given when a goal arrives.
"""
from math import atan2, pi, sqrt
import time
from typing import Optional, Sequence

import numpy as np

from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.model import RobotModel

SINGULAR_SIGMA_MIN = 0.05  # sigma_min(J) below this at the goal: reported singular (A2)
RESIDUAL_TOLERANCE = 1e-4  # IK residual (m and rad) below this: the goal is reached (A1)


def _pose_residual(model: RobotModel, q: np.ndarray, q_desired: Sequence[float],
                   p_desired: Sequence[float], task: Task) -> tuple[np.ndarray, np.ndarray]:
    """Residual (rotation vector of q_d * conj(q), and p_d - p for the pose) and its J."""
    p, R, rows = model.kinematics(q.tolist())
    eta_e, e = quat.orientation_error(quat.from_rotation_matrix(R), q_desired)
    if eta_e < 0.0:
        eta_e, e = -eta_e, (-e[0], -e[1], -e[2])
    s = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    rot = np.array(e) * (2.0 * atan2(s, eta_e) / s) if s > 1e-12 else np.zeros(3)
    J = np.array(rows)
    if task is Task.POSE:
        return np.concatenate((np.subtract(p_desired, p), rot)), J
    return rot, J[3:]


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


def check_goal(model: RobotModel, q_measured: Optional[Sequence[float]],
               q_desired: Sequence[float], p_desired: Sequence[float], task: Task,
               budget_s: float = 0.005, seed: int = 0) -> str:
    """
    Return a warning if the goal breaks assumption A1 or A2, or '' if it is fine.

    Tries the measured q (nudged off an exact singularity), then the middle of the joint
    ranges, then random configurations within the limits, until one reaches the goal or
    ``budget_s`` of wall time is spent. A goal reached only at a singular configuration
    violates A2; a goal no start reaches may violate A1 (it is not proven unreachable).
    """
    deadline = time.perf_counter() + budget_s
    lower = np.maximum(np.array(model.position_lower), -pi)
    upper = np.minimum(np.array(model.position_upper), pi)
    rng = np.random.default_rng(seed)
    starts = [np.zeros(model.n) if q_measured is None else np.asarray(q_measured, float),
              0.5 * (lower + upper)]
    best = None
    singular = None
    while True:
        q_start = starts.pop(0) if starts else rng.uniform(lower, upper)
        q, residual, J = solve_ik(model, q_start + 1e-3, q_desired, p_desired, task)
        if best is None or residual < best[1]:
            best = (q, residual)
        if residual < RESIDUAL_TOLERANCE:
            sigma_min = float(np.linalg.svd(J, compute_uv=False)[-1])
            if sigma_min >= SINGULAR_SIGMA_MIN:
                return ''
            singular = (q, sigma_min)
        if time.perf_counter() > deadline:
            break
    if singular is not None:
        q_text = [round(float(x), 4) for x in singular[0]]
        return (f'it is reached at a singular configuration q = {q_text} (sigma_min(J) = '
                f'{singular[1]:.3g} < {SINGULAR_SIGMA_MIN}): assumption A2 of the paper does '
                'not hold; the regulator may drift along the self-motion')
    q_text = [round(float(x), 4) for x in best[0]]
    return (f'no joint configuration within the limits was found that reaches it (best IK '
            f'residual {best[1]:.3g} at q = {q_text}): assumption A1 may not hold')

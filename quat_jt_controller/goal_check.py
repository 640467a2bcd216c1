"""
Check a goal against the paper's assumptions A1 (reachable) and A2 (no self-motion there).

A damped-least-squares inverse kinematics on the URDF model looks for a joint configuration
within the limits that reaches the goal. It starts from the measured q (the branch the
regulator most likely ends on), then from the middle of the ranges, then from seeded random
configurations; joints whose range spans a full turn are wrapped, not clamped. The work is
bounded by a number of starts and of iterations, never by wall time, so the same start and goal
give the same verdict on any host. At the solution, the smallest singular value of J_o
(orientation task), J_G (pose task) or J_p (position task) tells whether it is singular. The
position task's residual is p_d - p alone: its self-motion is larger, and q* is the solution
nearest the measured joints along it (:func:`posture`).

The verdict is advice for the user. The same inverse kinematics also gives, on request, the
goal configuration q* that the goal-configuration term pulls towards
(:func:`goal_configuration`, docs/lyapunov.md section 5). It costs milliseconds, so the
controller runs it in :class:`GoalCheckWorker`, a separate process, never on the control thread.
"""
from dataclasses import dataclass
import json
from math import pi
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from typing import Callable, NamedTuple, Optional, Sequence

import numpy as np

from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import Task
from quat_jt_controller.model import RobotModel, SINGULAR_SIGMA_MIN
from quat_jt_runtime.realtime import start_at_normal_scheduling

RESIDUAL_TOLERANCE = 1e-4  # IK residual (m and rad) below this: the goal is reached (A1)
# q* is polished by Newton steps to this residual (m and rad), the model's precision, or refused:
# the task and goal-configuration potentials must share their minimum exactly
POLISHED_TOLERANCE = 1e-10
POLISH_ITERATIONS = 12


def _pose_residual(model: RobotModel, q: np.ndarray, q_desired: Sequence[float],
                   p_desired: Sequence[float], task: Task) -> tuple[np.ndarray, np.ndarray]:
    """Residual (rotation vector of q_d * conj(q) and/or p_d - p, per task) and its J."""
    p, R, rows = model.kinematics(q.tolist())
    if task is Task.POSITION:
        return np.subtract(p_desired, p), np.array(rows)[:3]
    rot = np.array(quat.rotation_vector(*quat.orientation_error(quat.from_rotation_matrix(R),
                                                                q_desired)))
    J = np.array(rows)
    if task is Task.POSE:
        return np.concatenate((np.subtract(p_desired, p), rot)), J
    return rot, J[3:]


def _sigma_min(model: RobotModel, q: np.ndarray, task: Task) -> float:
    """Return the smallest singular value of the task Jacobian at ``q``."""
    _, _, rows = model.kinematics(q.tolist())
    J = Task(task).rows(np.array(rows))
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


def check_goal(model: RobotModel, q_measured: Optional[Sequence[float]],
               q_desired: Sequence[float], p_desired: Sequence[float], task: Task,
               max_starts: int = MAX_STARTS, seed: int = 0) -> str:
    """
    Return a warning if the goal breaks assumption A1 or A2, or '' if it is fine.

    Tries the measured q (nudged off an exact singularity), then the middle of the joint
    ranges, then random configurations within the limits (seeded), until one reaches the goal
    at a regular configuration or ``max_starts`` starts are spent. A goal reached only at a
    singular configuration violates A2; a goal no start reaches may violate A1 (it is not
    proven unreachable). Deterministic: the same arguments give the same verdict.
    """
    lower = np.maximum(np.array(model.position_lower), -pi)
    upper = np.minimum(np.array(model.position_upper), pi)
    rng = np.random.default_rng(seed)
    starts = [np.zeros(model.n) if q_measured is None else np.asarray(q_measured, float),
              0.5 * (lower + upper)]
    best = None
    singular = None
    for _ in range(max_starts):
        q_start = starts.pop(0) if starts else rng.uniform(lower, upper)
        q, residual, J = solve_ik(model, q_start + 1e-3, q_desired, p_desired, task)
        if best is None or residual < best[1]:
            best = (q, residual)
        if residual < RESIDUAL_TOLERANCE:
            sigma_min = float(np.linalg.svd(J, compute_uv=False)[-1])
            if sigma_min >= SINGULAR_SIGMA_MIN:
                return ''
            singular = (q, sigma_min)
    if singular is not None:
        q_text = [round(float(x), 4) for x in singular[0]]
        return (f'it is reached at a singular configuration q = {q_text} (sigma_min(J) = '
                f'{singular[1]:.3g} < {SINGULAR_SIGMA_MIN}): assumption A2 of the paper does '
                'not hold; the regulator may drift along the self-motion')
    q_text = [round(float(x), 4) for x in best[0]]
    return (f'no joint configuration within the limits was found that reaches it (best IK '
            f'residual {best[1]:.3g} at q = {q_text}): assumption A1 may not hold')


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

    ``nu_desired`` is the goal's task velocity in the task's rows (``[v; omega]``, ``omega``
    or ``v``, base frame). Least squares: the minimum-norm solution for a redundant arm. It
    runs in the worker, so the tick never inverts a Jacobian (docs/lyapunov.md, section 7).
    """
    _, _, rows = model.kinematics(list(q_star))
    J = Task(task).rows(np.array(rows))
    return np.linalg.lstsq(J, np.asarray(nu_desired, dtype=float), rcond=None)[0]


class Posture(NamedTuple):
    """How q* is chosen along a redundant arm's self-motion (:func:`posture`)."""

    preferred_rad: Optional[Sequence[float]] = None  # None: the middle of the ranges
    weight: float = 0.0


@dataclass(frozen=True)
class ModelSpec:
    """What the worker process needs to build the same RobotModel."""

    urdf_xml: str
    base_link: str
    tip_link: str
    joint_names: tuple[str, ...]
    task: Task


RESTART_BACKOFF_S = (1.0, 2.0, 4.0, 8.0, 16.0, 30.0)  # after the 1st, 2nd, ... death in a row


class GoalCheckWorker:
    """
    :func:`check_goal` in a separate process, fed the newest goal only, restarted if it dies.

    The worker is ``python -m quat_jt_controller.goal_check`` (niced), talking JSON lines over
    its stdin/stdout; it exits when its stdin closes, so it never outlives its parent. It runs
    in a session of its own and ignores SIGINT: a terminal's Ctrl-C reaches only the node,
    which then closes it. A reader thread waits on its output (blocked in I/O, it holds no lock
    the tick needs). :meth:`submit` never blocks: if a check is running, the goal waits as the
    next one and a newer goal replaces it, so a flood of goals costs one check at a time and
    the newest goal is always checked. :meth:`poll` returns finished verdicts.

    If the worker dies, :meth:`take_failure` says so once, :attr:`available` is False, and
    :meth:`poll` starts a new worker after a back-off (``RESTART_BACKOFF_S``, reset by a verdict
    from the new one); the goal that was running or waiting is checked by the new one. Call
    :meth:`close` at the end.
    """

    def __init__(self, spec: ModelSpec, clock: Callable[[], float] = time.monotonic) -> None:
        self._spec = spec
        self._clock = clock
        self._done: queue.SimpleQueue = queue.SimpleQueue()
        self._requests: dict[int, tuple[object, dict]] = {}  # id -> (key, request) sent
        self._configurations: dict[object, Optional[list[float]]] = {}
        self._velocities: dict[object, list[float]] = {}
        self._next_id = 0
        self._running: Optional[int] = None
        self._next: Optional[tuple[object, dict]] = None
        self._deaths_in_a_row = 0
        self._restart_at: Optional[float] = None
        self._failure: Optional[str] = None
        self._last_exit = ''
        self.restarts = 0
        self._closed = False
        self._start_process()

    @property
    def available(self) -> bool:
        """Tell whether a worker process is up (False from its death until its restart)."""
        return self._restart_at is None

    @property
    def ready(self) -> bool:
        """Tell whether the worker has built its model and answers checks at once."""
        return self._ready and self.available

    @property
    def unavailable_reason(self) -> str:
        """Say why checks are unavailable, and when the worker restarts ('' if available)."""
        if self._restart_at is None:
            return ''
        wait_s = max(0.0, self._restart_at - self._clock())
        return f'{self._last_exit}; restarting in {wait_s:.1f} s'

    def _start_process(self) -> None:
        self._ready = False  # until the new worker says it has built its model
        # SIGINT blocked from its first instruction (a blocked mask survives exec) until it
        # ignores it (_serve), and out of the terminal's process group: Ctrl-C is the node's.
        # Here a SIGINT only waits until the mask is restored.
        # Started from a real-time thread (a restart, from the tick's executor), it still
        # begins with normal scheduling: it must never compete with the loop.
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            self._proc = start_at_normal_scheduling(lambda: subprocess.Popen(
                [sys.executable, '-m', 'quat_jt_controller.goal_check'],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=None, text=True,
                bufsize=1, start_new_session=True))
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        spec = self._spec
        self._send({'urdf_xml': spec.urdf_xml, 'base_link': spec.base_link,
                    'tip_link': spec.tip_link, 'joint_names': list(spec.joint_names),
                    'task': Task(spec.task).value})
        threading.Thread(target=self._read, args=(self._proc,), name='goal_check_reader',
                         daemon=True).start()

    def _send(self, obj: dict) -> bool:
        try:
            self._proc.stdin.write(json.dumps(obj) + '\n')
            self._proc.stdin.flush()
            return True
        except (BrokenPipeError, OSError, ValueError):
            return False  # the reader sees the end of its output and reports the exit

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            try:
                self._done.put(json.loads(line))
            except ValueError:
                pass
        self._done.put({'exited': proc})

    def submit(self, key: object, q_measured: Optional[Sequence[float]],
               q_desired: Sequence[float], p_desired: Sequence[float],
               configuration_margin_rad: Optional[float] = None,
               nu_desired: Optional[Sequence[float]] = None,
               posture: Posture = Posture()) -> None:
        """
        Queue a check; ``key`` comes back with its verdict (e.g. the goal object).

        With ``configuration_margin_rad`` (not None) the worker also looks for the goal
        configuration (:func:`goal_configuration` with that joint-limit margin); take it with
        :meth:`take_configuration` once ``key`` has come back from :meth:`poll`. With
        ``nu_desired`` too (the goal's task velocity), also its joint velocity
        (:func:`configuration_velocity`), with :meth:`take_configuration_velocity`.
        ``posture`` chooses q* along a redundant arm's self-motion.
        """
        request = {'q_measured': None if q_measured is None else [float(x) for x in q_measured],
                   'q_desired': [float(x) for x in q_desired],
                   'p_desired': [float(x) for x in p_desired],
                   'configuration_margin': configuration_margin_rad,
                   'nu_desired': None if nu_desired is None else [float(x) for x in nu_desired],
                   'preferred_configuration': None if posture.preferred_rad is None else
                   [float(x) for x in posture.preferred_rad],
                   'posture_weight': float(posture.weight)}
        self._next = (key, request)
        if self._running is None and self.available:
            self._start_next()

    def _start_next(self) -> None:
        key, request = self._next
        self._next = None
        self._next_id += 1
        self._requests[self._next_id] = (key, request)
        self._running = self._next_id
        self._send({'id': self._next_id, **request})

    @property
    def busy(self) -> bool:
        """Tell whether a check is running or waiting."""
        return self._running is not None or self._next is not None

    def poll(self) -> list[tuple[object, str]]:
        """Return ``[(key, verdict)]`` of the checks finished since the last call."""
        out = []
        while not self._done.empty():
            reply = self._done.get()
            if 'exited' in reply:
                if reply['exited'] is self._proc and not self._closed:
                    self._on_exit()
                continue
            if reply.get('ready'):
                self._ready = True
                continue
            key = self._requests.pop(reply.get('id'), (None, None))[0]
            if reply.get('id') == self._running:
                self._running = None
            self._deaths_in_a_row = 0
            if reply.get('configuration') is not None and key is not None:
                try:
                    self._configurations[key] = reply['configuration']
                    if reply.get('configuration_velocity') is not None:
                        self._velocities[key] = reply['configuration_velocity']
                except TypeError:  # an unhashable key: nobody can take it
                    pass
            out.append((key, str(reply.get('verdict', ''))))
        if self._restart_at is not None and self._clock() >= self._restart_at:
            self._restart_at = None
            self.restarts += 1
            self._start_process()
        if self._running is None and self._next is not None and self.available:
            self._start_next()
        return out

    def _on_exit(self) -> None:
        """Hold the dead worker's check for the next one, and schedule the restart."""
        code = self._proc.poll()  # no wait on the control thread: its output has closed
        if self._running is not None and self._next is None:  # re-check it after the restart
            self._next = self._requests.get(self._running)
        self._requests.clear()
        self._running = None
        backoff_s = RESTART_BACKOFF_S[min(self._deaths_in_a_row, len(RESTART_BACKOFF_S) - 1)]
        self._deaths_in_a_row += 1
        self._restart_at = self._clock() + backoff_s
        self._last_exit = ('the goal-check worker exited'
                           + ('' if code is None else f' (exit code {code})'))
        self._failure = (f'{self._last_exit}: goal checks and goal configurations are '
                         f'unavailable; restarting it in {backoff_s:g} s')

    def take_failure(self) -> Optional[str]:
        """Return (once) what happened to the worker since the last call, or None."""
        failure, self._failure = self._failure, None
        return failure

    def take_configuration(self, key: object) -> Optional[list[float]]:
        """Return (once) the goal configuration found for ``key``, or None if none was."""
        try:
            return self._configurations.pop(key, None)
        except TypeError:  # an unhashable key never has one
            return None

    def take_configuration_velocity(self, key: object) -> Optional[list[float]]:
        """Return (once) the joint velocity of ``key``'s configuration, or None if none."""
        try:
            return self._velocities.pop(key, None)
        except TypeError:  # an unhashable key never has one
            return None

    def close(self) -> None:
        """Stop the worker (closing its stdin ends it); idempotent."""
        self._closed = True
        self._next = None
        self._restart_at = None
        if self._proc.poll() is None:
            try:
                self._proc.stdin.close()
            except OSError:
                pass
            try:
                self._proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()


def _serve() -> None:
    """Worker process: a spec line, then one verdict line per request line, until EOF."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node stops it (closes its stdin)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked since its start
    try:
        os.nice(10)  # advice only: leave the CPU to the 1 kHz nodes
    except OSError:
        pass
    lines = iter(sys.stdin)
    spec = json.loads(next(lines))
    model = RobotModel(spec['urdf_xml'], spec['base_link'], spec['tip_link'],
                       spec['joint_names'])
    task = Task(spec['task'])
    sys.stdout.write(json.dumps({'ready': True}) + '\n')  # checks are answered at once now
    sys.stdout.flush()
    q_last: Optional[list[float]] = None  # the last q*: the warm start of the next search
    for line in lines:
        request = json.loads(line)
        configuration = velocity = None
        try:
            margin = request.get('configuration_margin')
            if margin is not None:
                q_star = goal_configuration(
                    model, request['q_measured'], request['q_desired'], request['p_desired'],
                    task, float(margin), q_warm=q_last,
                    q_preferred=request.get('preferred_configuration'),
                    posture_weight=float(request.get('posture_weight', 0.0)))
                configuration = q_last = None if q_star is None else q_star.tolist()
                if q_star is not None and request.get('nu_desired') is not None:
                    velocity = configuration_velocity(model, q_star, request['nu_desired'],
                                                      task).tolist()
            # A q* is a regular configuration within the limits that reaches the goal: A1 and
            # A2 hold, and the full check is not needed.
            verdict = '' if configuration is not None else check_goal(
                model, request['q_measured'], request['q_desired'], request['p_desired'], task)
        except Exception as exc:  # noqa: B902 - reported to the node, which logs it
            verdict = f'the goal check failed: {exc!r}'
        sys.stdout.write(json.dumps({'id': request['id'], 'verdict': verdict,
                                     'configuration': configuration,
                                     'configuration_velocity': velocity}) + '\n')
        sys.stdout.flush()


if __name__ == '__main__':
    _serve()

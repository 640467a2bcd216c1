"""
Check a goal against the paper's assumptions A1 (reachable) and A2 (no self-motion there).

:func:`check_goal` runs the inverse kinematics of :mod:`quat_jt_controller.inverse_kinematics` from
a fixed number of starts: a goal no start reaches may break A1; a goal reached only where the
smallest singular value of J_o (orientation task), J_G (pose task) or J_p (position task) is small
breaks A2 (its position rows in units of the arm's length: ``RobotModel.task_sigma_min``). The
verdict is advice for the user. :class:`GoalCheckWorker` runs it, and on request the goal
configuration q* (:func:`~quat_jt_controller.inverse_kinematics.goal_configuration`), in a
separate process (:func:`_serve`, JSON lines over its stdin and stdout), never on the control
thread.
"""
from dataclasses import dataclass
import json
import sys
import time
from typing import Callable, NamedTuple, Optional, Sequence

from quat_jt_controller.control_law import Task
from quat_jt_controller.inverse_kinematics import configuration_velocity, MAX_STARTS
from quat_jt_controller.inverse_kinematics import RESIDUAL_TOLERANCE, search_goal_configuration
from quat_jt_controller.inverse_kinematics import Search, SINGULAR_SIGMA_MIN, solve_ik, starts
from quat_jt_controller.model import GRAVITY_RESERVE_SHARE, RobotModel
from quat_jt_runtime.payload import Payload
from quat_jt_runtime.worker import (answer, Launcher, quiet_worker, SupervisedWorker,
                                    WorkerOwner)


def singular_warning(q: Sequence[float], sigma_min: float) -> str:
    """Return the warning for a goal reached only at the near-singular ``q`` (A2)."""
    q_text = [round(float(x), 4) for x in q]
    return (f'it is reached only near a singular configuration q = {q_text} (sigma_min(J) = '
            f'{sigma_min:.3g} < {SINGULAR_SIGMA_MIN}; its position rows, if any, per unit of '
            "the arm's length): assumption A2 of the paper does not hold; the regulator may "
            'drift along the self-motion')


def unreached_warning(best_q: Sequence[float], best_residual: float, starts: int) -> str:
    """Return the warning for a goal no IK start reached within the limits (A1)."""
    q_text = [round(float(x), 4) for x in best_q]
    return (f'no joint configuration within the limits was found that reaches it from {starts} '
            f'IK starts (best residual {best_residual:.3g} m and rad at q = {q_text}): '
            'assumption A1 may not hold')


def heavy_warning(model: RobotModel, q: Sequence[float]) -> str:
    """
    Return a warning if gravity at ``q`` takes more than the design's reserve of an effort.

    ``gain_design`` reserves ``GRAVITY_RESERVE_SHARE`` of each joint's effort limit for
    gravity; past it the regulator has less than its budget, and past the effort limit the
    clamped torque cannot hold the arm there at all. '' if no joint is that loaded.
    """
    gravity = [abs(g) for g in model.gravity(list(q))]
    heavy = [f'{name} {g:.3g} of {e:.3g} N m' for name, g, e
             in zip(model.joint_names, gravity, model.effort_limits)
             if 0.0 < e < float('inf') and g > GRAVITY_RESERVE_SHARE * e]  # 0: no limit
    if not heavy:
        return ''
    q_text = [round(float(x), 4) for x in q]
    return (f'it is reached at q = {q_text}, where gravity takes more than '
            f'{GRAVITY_RESERVE_SHARE:g} x the effort limit ({", ".join(heavy)}): the torque may '
            'saturate and the arm may not hold that pose')


def check_goal(model: RobotModel, q_measured: Optional[Sequence[float]],
               quat_desired: Sequence[float], p_desired: Sequence[float], task: Task,
               max_starts: int = MAX_STARTS, seed: int = 0) -> str:
    """
    Return a warning if the goal breaks assumption A1 or A2, or '' if it is fine.

    A goal whose first regular configuration found (the measured q is the first start, so
    near the arm) is one where gravity takes more of an effort limit than the design reserves
    for it gets :func:`heavy_warning`.

    Tries the IK :func:`~quat_jt_controller.inverse_kinematics.starts` (the measured q, the
    middle of the joint ranges, then seeded random configurations within the limits) until one
    reaches the goal at a regular configuration or ``max_starts`` starts are spent. A goal
    reached only at a singular configuration violates A2; a goal no start reaches may violate
    A1 (it is not proven unreachable). Deterministic: the same arguments give the same verdict.
    """
    best = None
    singular = None
    for _, q_start in zip(range(max_starts), starts(model, q_measured, seed)):
        q, residual, J = solve_ik(model, q_start, quat_desired, p_desired, task)
        if best is None or residual < best[1]:
            best = (q, residual)
        if residual < RESIDUAL_TOLERANCE:
            sigma = model.task_sigma_min(J, Task(task).has_position)
            if sigma >= SINGULAR_SIGMA_MIN:
                return heavy_warning(model, q)  # '' unless gravity loads it past the reserve
            if singular is None or sigma > singular[1]:
                singular = (q, sigma)
    if singular is not None:
        return singular_warning(*singular)
    return unreached_warning(best[0], best[1], max_starts)


class Posture(NamedTuple):
    """How q* is chosen along a redundant arm's self-motion (``inverse_kinematics.posture``)."""

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


class GoalCheckWorker(WorkerOwner):
    """
    :func:`check_goal` in a separate process, fed the newest goal only, restarted if it dies.

    The worker is ``python -m quat_jt_controller.goal_check`` (niced), talking JSON lines over
    its stdin/stdout (written by a ``LineWriter`` thread: a write never waits on the pipe); it
    exits when its stdin closes, so it never outlives its parent. It runs in a session of its
    own and ignores SIGINT: a terminal's Ctrl-C reaches only the node, which then closes it. A
    reader thread waits on its output (blocked in I/O, it holds no lock the tick needs).
    :meth:`submit` never blocks: if a check is running, the goal waits as the next one and a
    newer goal replaces it, so a flood of goals costs one check at a time and the newest goal
    is always checked. :meth:`poll` returns finished verdicts.

    The process is a ``SupervisedWorker``'s (``quat_jt_runtime.worker``): started by the
    node's ``Launcher`` process (``launcher``, or one of its own), as :meth:`poll` runs on the
    node's loop, which a process started there would hold up for milliseconds. If the worker
    dies, ``take_failure`` says so once, ``available`` is False, and :meth:`poll` asks
    for a new worker after a back-off (``RESTART_BACKOFF_S``, reset by a verdict from the new
    one); the goal that was running or waiting is checked by the new one. Call :meth:`close`
    at the end.
    """

    def __init__(self, spec: ModelSpec, clock: Callable[[], float] = time.monotonic,
                 launcher: Optional[Launcher] = None) -> None:
        # each worker's first line: encoded once, so that a restart from the loop's thread
        # only queues it (a whole robot's URDF is 100 to 200 KiB)
        spec_line = json.dumps({
            'urdf_xml': spec.urdf_xml, 'base_link': spec.base_link, 'tip_link': spec.tip_link,
            'joint_names': list(spec.joint_names), 'task': Task(spec.task).value})
        self._requests: dict[int, tuple[object, dict]] = {}  # id -> (key, request) sent
        self._configurations: dict[object, Optional[list[float]]] = {}
        self._velocities: dict[object, list[float]] = {}
        self._next_id = 0
        self._running: Optional[int] = None
        self._next: Optional[tuple[object, dict]] = None
        self._worker = SupervisedWorker(
            'quat_jt_controller.goal_check', spec_line, 'the goal-check worker',
            'goal checks and goal configurations are unavailable', launcher, clock)

    def submit(self, key: object, q_measured: Optional[Sequence[float]],
               q_desired: Sequence[float], p_desired: Sequence[float],
               configuration_margin_rad: Optional[float] = None,
               nu_desired: Optional[Sequence[float]] = None,
               posture: Posture = Posture(), payload: Payload = Payload()) -> None:
        """
        Queue a check; ``key`` comes back with its verdict (e.g. the goal object).

        With ``configuration_margin_rad`` (not None) the worker also looks for the goal
        configuration (:func:`goal_configuration` with that joint-limit margin); take it with
        :meth:`take_configuration` once ``key`` has come back from :meth:`poll`. With
        ``nu_desired`` too (the goal's task velocity), also its joint velocity
        (:func:`configuration_velocity`), with :meth:`take_configuration_velocity`.
        ``posture`` chooses q* along a redundant arm's self-motion; ``payload`` is the one the
        tip carries now (the worker's model takes it before the check: a goal the arm may not
        hold up with it is warned about).
        """
        request = {'q_measured': None if q_measured is None else [float(x) for x in q_measured],
                   'q_desired': [float(x) for x in q_desired],
                   'p_desired': [float(x) for x in p_desired],
                   'configuration_margin': configuration_margin_rad,
                   'nu_desired': None if nu_desired is None else [float(x) for x in nu_desired],
                   'preferred_configuration': None if posture.preferred_rad is None else
                   [float(x) for x in posture.preferred_rad],
                   'posture_weight': float(posture.weight),
                   'payload': [float(payload.mass_kg), *(float(c) for c in payload.com_m)]}
        self._next = (key, request)
        if self._running is None and self.available:
            self._start_next()

    def _start_next(self) -> None:
        key, request = self._next
        self._next = None
        self._next_id += 1
        self._requests[self._next_id] = (key, request)
        self._running = self._next_id
        self._worker.send(json.dumps({'id': self._next_id, **request}))

    @property
    def busy(self) -> bool:
        """Tell whether a check is running or waiting."""
        return self._running is not None or self._next is not None

    def poll(self) -> list[tuple[object, str]]:
        """Return ``[(key, verdict)]`` of the checks finished since the last call."""
        out = []
        replies, died = self._worker.poll()
        for reply in replies:
            if not isinstance(reply, dict):
                continue
            key = self._requests.pop(reply.get('id'), (None, None))[0]
            if reply.get('id') == self._running:
                self._running = None
            if reply.get('configuration') is not None and key is not None:
                try:
                    self._configurations[key] = reply['configuration']
                    if reply.get('configuration_velocity') is not None:
                        self._velocities[key] = reply['configuration_velocity']
                except TypeError:  # an unhashable key: nobody can take it
                    pass
            out.append((key, str(reply.get('verdict', ''))))
        if died:  # the check it ran is held for the next worker
            if self._running is not None and self._next is None:
                self._next = self._requests.get(self._running)
            self._requests.clear()
            self._running = None
        if self._running is None and self._next is not None and self.available:
            self._start_next()
        return out

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
        self._next = None
        self._worker.close()


def configuration_verdict(search: Search) -> str:
    """
    Return the goal check's verdict from the search for q* ('' if A1 and A2 hold).

    A regular q* within the limits reaches the goal: A1 and A2 hold, and no further check is
    needed. A q* only near a singularity breaks A2. Without q*, the goal may break A1, and the
    goal-configuration term has nothing to pull towards for this goal.
    """
    if search.regular:
        return ''
    if search.q_star is not None:
        return singular_warning(search.q_star, search.sigma_min)
    return (unreached_warning(search.best_q, search.best_residual, search.starts)
            + '; no goal configuration q*: the goal-configuration term does not act on it')


def _serve() -> None:
    """Worker process: a spec line, then one verdict line per request line, until EOF."""
    quiet_worker()
    lines = iter(sys.stdin)
    first = next(lines, None)
    if first is None:  # the node closed the input before sending the model: nothing to do
        return
    spec = json.loads(first)
    model = RobotModel(spec['urdf_xml'], spec['base_link'], spec['tip_link'],
                       spec['joint_names'])
    task = Task(spec['task'])
    if not answer({'ready': True}):  # checks are answered at once now (the node is gone)
        return
    q_last: Optional[list[float]] = None  # the last q*: the warm start of the next search
    for line in lines:
        request = json.loads(line)
        configuration = velocity = None
        try:
            mass_kg, *com_m = request.get('payload') or (0.0, 0.0, 0.0, 0.0)
            if (mass_kg, tuple(com_m)) != (model.payload_kg, model.payload_com_tip_m):
                model.set_payload(mass_kg, com_m)
            margin = request.get('configuration_margin')
            if margin is None:
                verdict = check_goal(model, request['q_measured'], request['q_desired'],
                                     request['p_desired'], task)
            else:
                search = search_goal_configuration(
                    model, request['q_measured'], request['q_desired'], request['p_desired'],
                    task, float(margin), q_warm=q_last,
                    q_preferred=request.get('preferred_configuration'),
                    posture_weight=float(request.get('posture_weight', 0.0)))
                verdict = configuration_verdict(search)
                q_star = search.q_star
                configuration = q_last = None if q_star is None else q_star.tolist()
                if q_star is not None and request.get('nu_desired') is not None:
                    velocity = configuration_velocity(model, q_star, request['nu_desired'],
                                                      task).tolist()
        except Exception as exc:  # noqa: B902 - reported to the node, which logs it
            verdict = f'the goal check failed: {exc!r}'
        if not answer({'id': request['id'], 'verdict': verdict, 'configuration': configuration,
                       'configuration_velocity': velocity}):
            return


if __name__ == '__main__':
    _serve()

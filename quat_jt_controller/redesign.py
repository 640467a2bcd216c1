"""
Gains designed again for the rotor inertia the motion shows (docs/gain_design.md, section 6).

``design_gains`` sizes the gains for the inertia the URDF and the armature told give each
joint. Where a joint's drive reflects a rotor inertia nobody told, the regulator finds it
while the arm moves (``armature_estimate``) and puts it in ``M(q)``, which sets the damping
right; the stiffness stays the one sized for the light joint, and such an arm crawls
(docs/reach.md, "Rotor inertia nobody told"). Here the controller designs the gains again,
with ``design_gains``' own rules (``gain_design.design``), the robot and options the file was
designed with, and the rotor inertia found:

- :class:`InertiaWatch` says when: at a look (every ``LOOK_S``), the inertia a design would
  now take for some joint is more than ``GROWTH_FACTOR`` times the one its gains were designed
  for (the first time: the joint shows more than twice the inertia of its model), its
  estimate settled or still rising; and which joints' estimates have settled (within
  ``SETTLED_SHARE`` of what they were ``SETTLED_S`` before), which the controller says;
- the design takes ``DESIGN_SHARE`` of what was found on every joint, no more: the gains are
  then sized for a joint lighter than the one the motion shows, as in the campaign's column
  "told 0.05" (a rotor inertia told at half the plant's), which reaches as often as the one
  told right (measured, not proved), and an estimate up to twice too high still gives a
  design for no more than the real joint;
- :func:`redesign` runs the design, and returns the live parameters that change. The
  controller node runs it in a worker process and sets them, through its parameters (checked,
  logged, ``ros2 param get`` shows them), as a user's ``ros2 param set`` would
  (``gain_redesign`` false: never).

Each design multiplies the inertia some joint is designed for by more than ``GROWTH_FACTOR``,
within ``armature_estimation_limit``: a few designs at most. Each is a change of the gains,
after which docs/lyapunov.md's argument holds again (section 13). ROS-free; ``python -m
quat_jt_controller.redesign`` is the node's worker (a request line on stdin, an answer line
on stdout).
"""
from collections import deque
import json
import sys
import time
from typing import Any, Callable, Mapping, Optional, Sequence

from quat_jt_runtime.worker import (answer, Launcher, quiet_worker, SupervisedWorker,
                                    WORKER_CLOSE_WAIT_S, WorkerOwner)

# an estimate within this share of what it was SETTLED_S before has settled: 2.5 of the
# estimate's time constants (armature_estimate.ADOPT_TIME_S)
SETTLED_SHARE = 0.05
SETTLED_S = 0.5
LOOK_S = 0.25  # the estimate is looked at this often, each look against one SETTLED_S before
DESIGN_SHARE = 0.5  # of the rotor inertia found, what the design takes
# a design again when it would design a joint for more than this x the inertia its gains were
# designed for: the first time, for a joint that shows more than twice its model's inertia
# (its model plus DESIGN_SHARE of the rest above 1.5 x its model)
GROWTH_FACTOR = 1.5
# Parameters the design reads, or the user chooses, that a design again does not set
KEPT = frozenset(('potential', 'gravity_compensation', 'friction_compensation',
                  'preferred_configuration', 'posture_weight', 'goal_velocity_gain',
                  'gain_redesign'))


class InertiaWatch:
    """
    When the gains are due a design for the rotor inertia found, and which estimates settled.

    ``told`` is the armature the controller was told (kg m^2 per joint); ``designed`` the one
    the gains in force were designed with, ``told`` until :meth:`designed_with`.
    """

    def __init__(self, told: Sequence[float], start_s: float = 0.0) -> None:
        self.told = tuple(float(a) for a in told)
        self.designed = self.told
        self._then_s = start_s
        self._looks: deque[tuple[float, tuple[float, ...]]] = deque()  # (time s, estimate)

    def settled(self, now_s: float, found: Sequence[float]) -> Optional[list[int]]:
        """
        Return the joints whose estimate ``found`` has settled; None between two looks.

        A look every ``LOOK_S``: settled are the joints found heavier than told (> 0) whose
        estimate is within ``SETTLED_SHARE`` of what the last look at least ``SETTLED_S``
        before saw (half a look early counts: the caller's timer is not exact). Until a look
        is that old, none.
        """
        if now_s - self._then_s < LOOK_S:
            return None
        self._then_s = now_s
        looks, oldest_s = self._looks, now_s - SETTLED_S + 0.5 * LOOK_S
        while len(looks) > 1 and looks[1][0] <= oldest_s:
            looks.popleft()  # looks[1] is old enough: looks[0] is not the one to compare with
        before = looks[0][1] if looks and looks[0][0] <= oldest_s else ()
        looks.append((now_s, tuple(found)))
        return [j for j, (e, b) in enumerate(zip(found, before))
                if e > 0.0 and abs(e - b) <= SETTLED_SHARE * e]

    def due(self, found: Sequence[float],
            own_inertia: Sequence[float]) -> Optional[tuple[float, ...]]:
        """
        Return the armature to design the gains with, if some joint asks for one.

        ``own_inertia`` is ``M_jj(q)`` per joint with the estimate ``found`` in
        (``RobotModel.own_inertias``). A joint would be designed with its armature told plus
        ``DESIGN_SHARE`` of what was found (never less than it was designed with). Due when
        that is more than ``GROWTH_FACTOR`` times the inertia its gains were designed for, for
        some joint; then every joint takes it. The estimate need not have settled: one still
        rising to its value (the estimator adopts a fit over ``ADOPT_TIME_S``, at most
        doubling an inertia per solve) is below it, and ``DESIGN_SHARE`` of it a joint
        lighter than the real one; the next look asks again once it has grown by
        ``GROWTH_FACTOR``. Waiting for it to settle held a joint that started late (one a
        friction held until its learned push freed it) on gains sized for its light model
        for a second or more (docs/reach.md, "A design for an estimate still rising"). None
        when no joint asks for a design.
        """
        told, designed = self.told, self.designed
        armature = list(designed)
        due = False
        for j, found_j in enumerate(found):
            model_j = own_inertia[j] - found_j  # the links and the armature told
            armature[j] = max(designed[j], told[j] + DESIGN_SHARE * found_j)
            before = model_j + designed[j] - told[j]  # the inertia designed for
            if model_j + armature[j] - told[j] > GROWTH_FACTOR * before:
                due = True
        return tuple(armature) if due else None

    def designed_with(self, armature: Sequence[float]) -> None:
        """Record that the gains in force were designed with ``armature`` (or tried)."""
        self.designed = tuple(float(a) for a in armature)


def redesign(urdf_xml: str, values: Mapping[str, Any],
             armature: Sequence[float]) -> dict[str, Any]:
    """
    Design the gains again with ``armature``; return the live parameters that change.

    ``values`` are the controller's parameters in force, by ROS name: the robot
    (``base_link``, ``tip_link``, ``joints``, ``task``, ``state_rate``), the payload, the
    friction estimates (``friction_compensation``), ``preferred_configuration``, ``potential``
    and ``design_options`` (the design_gains options no other parameter holds). What the user
    chooses or the design reads (``KEPT``) is not returned. Raises ValueError (a design that
    fails, or bad options) or ModelError.
    """
    from quat_jt_controller import control_law as cl
    from quat_jt_controller.gain_cli import parse_design_options
    from quat_jt_controller.gain_design import design
    from quat_jt_controller.model import RobotModel

    model = RobotModel(urdf_xml, values['base_link'], values['tip_link'],
                       list(values['joints']), [float(a) for a in armature],
                       float(values.get('payload_mass', 0.0)),
                       list(values.get('payload_com', (0.0, 0.0, 0.0))))
    options = parse_design_options(list(values.get('design_options', ())), model.n)
    preferred = values.get('preferred_configuration')
    result = design(model, cl.Task(values['task']), float(values['state_rate']),
                    friction_nm=values.get('friction_compensation') or None,
                    preferred_configuration_rad=list(preferred) if preferred else None,
                    **options)
    new = result.parameters(str(values.get('potential', 'tanh')))
    return {name: value for name, value in new.items()
            if name not in KEPT and value != _plain(values.get(name))}


def _plain(value: Any) -> Any:
    """Return ``value`` as the design writes it: a list for any array, plain numbers."""
    if isinstance(value, (str, bytes, bool, int, float)) or value is None:
        return value
    if hasattr(value, 'item') and not hasattr(value, '__len__'):  # a numpy scalar
        return value.item()
    return [_plain(v) for v in value]  # a tuple, a list, rclpy's array.array


class DesignWorker(WorkerOwner):
    """
    :func:`redesign` in a process of its own, one design at a time, never on the loop.

    The process (``python -m quat_jt_controller.redesign``, niced, out of the terminal's
    process group, SIGINT ignored) is a ``SupervisedWorker``'s (``quat_jt_runtime.worker``):
    started by the node's ``Launcher`` process (``launcher``, or one of its own) as the node
    starts, sent the URDF, and started again after a back-off when it dies, as the goal-check
    worker is; the node never starts a process while its loop runs (docs/benchmark.md, "A
    worker started again"). It imports what a design needs (Pinocchio) as it starts, niced,
    and then says it is ``ready``. :meth:`submit` queues one request line (the parameters
    and the armature) for the worker's writer thread (``LineWriter``) and returns; a reader
    thread waits for the answer line, which :meth:`poll` returns once: ``{'parameters':
    {...}}``, or ``{'error': text}`` (a design that failed, a worker that died during it, or
    one asked for while no worker is up: refused at once, with the reason). :meth:`poll` also
    starts the next worker when its back-off is over; ``take_failure`` says once that a
    worker died (``WorkerOwner``). Call :meth:`close` at the end: it closes the process's
    input, which ends it.
    """

    def __init__(self, urdf_xml: str, launcher: Optional[Launcher] = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._busy = False
        self._refusal: Optional[dict] = None  # the answer to a design asked for in vain
        # once per worker: each design reads it
        self._worker = SupervisedWorker(
            'quat_jt_controller.redesign', json.dumps({'urdf_xml': urdf_xml}),
            'the design worker', 'the gains cannot be designed again until it is back',
            launcher, clock)

    @property
    def busy(self) -> bool:
        """Tell whether a design is running (or its answer not yet taken)."""
        return self._busy

    def submit(self, values: Mapping[str, Any], armature: Sequence[float]) -> None:
        """Ask for a design with ``armature`` on the parameters ``values`` (by ROS name)."""
        if self._busy:
            raise RuntimeError('a design is running')
        self._busy = True
        if not self._worker.available:
            self._refusal = {'error': self._worker.unavailable_reason}
            return
        self._worker.send(json.dumps({
            'armature': [float(a) for a in armature],
            'values': {name: _plain(v) for name, v in values.items()}}))

    def poll(self) -> Optional[dict]:
        """Return the answer of the design that finished since the last call, or None."""
        replies, died = self._worker.poll()
        reply = None
        if self._refusal is not None:
            reply, self._refusal = self._refusal, None
        elif replies:  # one design at a time: one answer
            reply = replies[-1]
        elif died and self._busy:  # its design is lost with it
            reply = {'error': self._worker.last_exit}
        if reply is None:
            return None
        self._busy = False
        return reply

    def close(self) -> None:
        """End the process: a design still running is stopped, an idle worker ends itself."""
        self._worker.close(0.0 if self._busy else WORKER_CLOSE_WAIT_S)
        if self._busy and self._refusal is None:
            self._refusal = {'error': self._worker.unavailable_reason}


def _serve() -> None:
    """
    Worker process: one answer line (``parameters`` or ``error``) per request line.

    It first imports what a design needs and says ``{'ready': true}``. Its first input line is
    the URDF (``{'urdf_xml': ...}``, no answer); each later line a request (``armature``,
    ``values``).
    """
    quiet_worker()
    # what a design needs (Pinocchio among it), imported now, while the node starts, rather
    # than at the first design: that one then answers as fast as the next
    from quat_jt_controller import gain_cli, gain_design  # noqa: F401
    if not answer({'ready': True}):  # the node is gone
        return
    urdf_xml = ''
    for line in sys.stdin:  # until the node closes it
        try:
            request = json.loads(line)
            if 'urdf_xml' in request:
                urdf_xml = request['urdf_xml']
                continue
            reply = {'parameters': redesign(urdf_xml, request['values'],
                                            request['armature'])}
        except Exception as exc:  # noqa: B902 - reported to the node, which logs it
            reply = {'error': f'{type(exc).__name__}: {exc}'}
        if not answer(reply):
            return


if __name__ == '__main__':
    _serve()

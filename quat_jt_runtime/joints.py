"""Joints of a URDF: which can move, and choosing the controlled ones by name (one way)."""
from typing import Optional, Sequence
from xml.etree import ElementTree

MOVABLE_TYPES = ('revolute', 'continuous', 'prismatic')


def movable_joints(urdf_xml: str) -> list[str]:
    """
    Names of the revolute, continuous and prismatic joints of a URDF, in document order.

    The one definition of 'movable joint' in this package: the model (Pinocchio), the
    simulator (PyBullet) and the simulator node all default their joint lists to it. Raises
    ValueError if the text is not XML.
    """
    try:
        root = ElementTree.fromstring(urdf_xml)
    except ElementTree.ParseError as exc:
        raise ValueError(f'the URDF is not valid XML: {exc}') from exc
    return [j.get('name') for j in root.iter('joint') if j.get('type') in MOVABLE_TYPES]


def fixed_joints(urdf_xml: str, names: Sequence[str]) -> str:
    """
    Return the URDF with the joints ``names`` made fixed: each locked at zero.

    A joint at zero places its child link at the joint's origin, which is what a fixed joint
    with the same origin does. Raises ValueError if the text is not XML or a name is not a
    joint of it.
    """
    try:
        root = ElementTree.fromstring(urdf_xml)
    except ElementTree.ParseError as exc:
        raise ValueError(f'the URDF is not valid XML: {exc}') from exc
    wanted = set(names)
    for joint in root.iter('joint'):
        if joint.get('name') in wanted and joint.get('type') in MOVABLE_TYPES:
            joint.set('type', 'fixed')
            wanted.discard(joint.get('name'))
    if wanted:
        raise ValueError(f'joints {sorted(wanted)} are not movable joints of the URDF')
    return ElementTree.tostring(root, encoding='unicode')


def select_joints(requested: Optional[Sequence[str]], movable: Sequence[str],
                  error: type = ValueError) -> list[str]:
    """
    Return the joints to use, in the caller's order; default all ``movable`` joints.

    Raises ``error`` naming the problem: an unknown or non-movable joint, a repeated one, none.
    """
    names = list(movable) if requested is None else [str(n) for n in requested]
    unknown = [n for n in names if n not in movable]
    if unknown:
        raise error(f'joints {unknown} are not movable joints of the URDF (it has '
                    f'{list(movable)})')
    if len(set(names)) != len(names):
        raise error(f'joint names repeat: {names}')
    if not names:
        raise error('no joints selected')
    return names


class StateLayout:
    """
    Pick the controlled joints out of joint states whose name lists come in any order.

    The index map of a name list is built once and cached (a sensor_msgs/JointState usually
    repeats the same list every tick). :meth:`extract` raises ValueError saying why a state is
    unusable: a controlled joint missing, a name repeated, lengths that differ, NaN or Inf.
    """

    def __init__(self, joint_names: Sequence[str]) -> None:
        self.joint_names = tuple(joint_names)
        self._last_names: Optional[list[str]] = None
        self._last: object = None
        self._cache: dict[tuple[str, ...], object] = {}

    def _index(self, names: Sequence[str]) -> object:
        """Return the list of indices, or the reason (str) why this name list is unusable."""
        if names == self._last_names:
            return self._last
        key = tuple(names)
        index = self._cache.get(key)
        if index is None:
            if len(set(key)) != len(key):
                repeated = sorted({n for n in key if key.count(n) > 1})
                index = f'joint names repeat {repeated}: {list(key)}'
            else:
                where = {name: i for i, name in enumerate(key)}
                missing = [j for j in self.joint_names if j not in where]
                index = (f'missing controlled joint(s) {missing}: have {list(key)}, need '
                         f'{list(self.joint_names)}' if missing
                         else [where[j] for j in self.joint_names])
            if len(self._cache) < 64:
                self._cache[key] = index
        self._last_names = list(names)
        self._last = index
        return index

    def extract(self, names: Sequence[str], position: Sequence[float],
                velocity: Sequence[float]) -> tuple[list[float], list[float]]:
        """Return (q, qdot) of the controlled joints, in ``joint_names`` order."""
        index = self._index(names)
        if isinstance(index, str):
            raise ValueError(index)
        if len(position) != len(names) or len(velocity) != len(names):
            raise ValueError(f'{len(names)} names but {len(position)} positions and '
                             f'{len(velocity)} velocities (positions and velocities are '
                             'required)')
        q = [position[i] for i in index]
        qdot = [velocity[i] for i in index]
        total = sum(q) + sum(qdot)
        if total - total != 0.0:
            raise ValueError(f'non-finite position or velocity: q = {q}, qdot = {qdot}')
        return q, qdot


# Watchdog defaults of the controller (state_timeout, max_state_age), chosen with
# experiments/soak.py on a loaded host (docs/ros.md, 'Watchdog timeouts'): 0.1 s tripped in
# normal running there.
DEFAULT_STATE_TIMEOUT_S = 0.5
DEFAULT_MAX_STATE_AGE_S = 0.5


def stamp_problem(stamp_ns: int, now_ns: int, max_age_ns: int) -> str:
    """
    Say why a joint state's stamp is unusable ('' if it is fine), against the node's clock.

    Unusable: no stamp (zero), older than ``max_age_ns``, or that far in the future (another
    clock). ``max_age_ns`` 0 turns the check off; ``now_ns`` 0 (a simulated clock not yet
    received) skips it.
    """
    if not max_age_ns or not now_ns:
        return ''
    if stamp_ns == 0:
        return 'header.stamp is zero (not stamped); set max_state_age to 0 to accept such states'
    age_ns = now_ns - stamp_ns
    if age_ns > max_age_ns:
        return f'stamped {age_ns * 1e-9:.3f} s ago (max_state_age {max_age_ns * 1e-9:g} s)'
    if age_ns < -max_age_ns:
        return (f'stamped {-age_ns * 1e-9:.3f} s in the future (max_state_age '
                f'{max_age_ns * 1e-9:g} s): another clock?')
    return ''


class StaleState(ValueError):
    """A joint state rejected by its stamp (unstamped, too old, or in the future)."""


class StateCheck:
    """
    A joint state's joints and stamp checked, in one call: the controller's tick input.

    Calling it returns (q, qdot) of the controlled joints, or raises ValueError saying why no
    command may be computed from the state (:class:`StaleState` if it is the stamp).
    """

    def __init__(self, joint_names: Sequence[str], max_age_s: float) -> None:
        self._layout = StateLayout(joint_names)
        self._max_age_ns = int(max_age_s * 1e9)

    def __call__(self, names: Sequence[str], position: Sequence[float],
                 velocity: Sequence[float], stamp_ns: int,
                 now_ns: int) -> tuple[list[float], list[float]]:
        """Return (q, qdot); raise ValueError (StaleState for the stamp) naming the problem."""
        q, qdot = self._layout.extract(names, position, velocity)
        problem = stamp_problem(stamp_ns, now_ns, self._max_age_ns)
        if problem:
            raise StaleState(problem)
        return q, qdot

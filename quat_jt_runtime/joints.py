"""
Joints of a URDF and of joint states.

Which joints of a URDF can move, choosing the controlled ones by name (one way), and the
controller's tick input from a joint state: the controlled joints picked by name, the stamp
checked, continuous joints unwrapped, and the velocities estimated when a driver sends none.
"""
from collections import deque
from math import exp, inf, isfinite, isinf, pi
from typing import Optional, Sequence
from xml.etree import ElementTree

MOVABLE_TYPES = ('revolute', 'continuous', 'prismatic')
ROTATING_TYPES = ('revolute', 'continuous')
# A hand ends the default chain (default_links): a link on it from which two or more branches
# of rotating joints leave (fingers), all it carries lighter than this share of the links the
# chain moves above it, and no more rotating joints on the chain below it than above
HAND_MASS_SHARE = 0.25


def movable_joints(urdf_xml: str) -> list[str]:
    """
    Names of the revolute, continuous and prismatic joints of a URDF, in document order.

    The one definition of 'movable joint' in this package: the model (Pinocchio), the
    simulator (PyBullet) and the simulator node all default their joint lists to it. Raises
    ValueError if the text is not XML.
    """
    return [j.get('name') for j in _parsed(urdf_xml).iter('joint')
            if j.get('type') in MOVABLE_TYPES]


def fixed_joints(urdf_xml: str, names: Sequence[str]) -> str:
    """
    Return the URDF with the joints ``names`` made fixed: each locked at zero.

    A joint at zero places its child link at the joint's origin, which is what a fixed joint
    with the same origin does. Raises ValueError if the text is not XML or a name is not a
    joint of it.
    """
    root = _parsed(urdf_xml)
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


def _parsed(urdf_xml: str) -> ElementTree.Element:
    try:
        return ElementTree.fromstring(urdf_xml)
    except ElementTree.ParseError as exc:
        raise ValueError(f'the URDF is not valid XML: {exc}') from exc


def _joint_rows(root: ElementTree.Element) -> list[tuple[str, str, str, str]]:
    """(name, type, parent link, child link) of each joint of a parsed URDF."""
    return [(j.get('name'), j.get('type'), j.find('parent').get('link'),
             j.find('child').get('link')) for j in root.findall('joint')]


def link_masses(root: ElementTree.Element) -> dict[str, float]:
    """
    Return each link's ``<inertial><mass value>`` (kg; 0 without one) of a parsed URDF.

    Raises ValueError naming the link if a mass is not a number.
    """
    masses = {}
    for link in root.findall('link'):
        node = link.find('inertial/mass')
        try:
            masses[link.get('name')] = float(node.get('value', 0.0)) if node is not None else 0.0
        except ValueError as exc:
            raise ValueError(f'link {link.get("name")!r}: the mass is not a number '
                             f'({exc})') from None
    return masses


def masses_below(root: ElementTree.Element,
                 masses: Optional[dict[str, float]] = None) -> dict[str, float]:
    """
    Return per link the mass (kg) of every link below it in a parsed URDF's tree, its own out.

    ``masses``: :func:`link_masses` of ``root``, if already read. Raises ValueError as it does.
    """
    masses = link_masses(root) if masses is None else masses
    children: dict[str, list[str]] = {}
    for _, _, parent, child in _joint_rows(root):
        children.setdefault(parent, []).append(child)
    below: dict[str, float] = {}

    def carried(link: str) -> float:
        if link not in below:
            below[link] = 0.0  # seen: a malformed URDF's loop ends here
            below[link] = sum(masses.get(c, 0.0) + carried(c) for c in children.get(link, []))
        return below[link]

    for link in masses:
        carried(link)
    return below


def joint_rows(urdf_xml: str) -> list[tuple[str, str, str, str]]:
    """
    Return (name, type, parent link, child link) of each joint of a URDF, in document order.

    Raises ValueError if the text is not XML.
    """
    return _joint_rows(_parsed(urdf_xml))


def default_links(urdf_xml: str, base_link: Optional[str] = None) -> tuple[str, str]:
    """
    Return ``(base_link, tip_link)``: the root link, and the end of the longest rotating chain.

    :func:`default_chain_end` gives the tip; the base is ``base_link``, default the root link.
    """
    base_link, tip_link, _ = default_chain_end(urdf_xml, base_link)
    return base_link, tip_link


def default_chain_end(urdf_xml: str,
                      base_link: Optional[str] = None) -> tuple[str, str, Optional[str]]:
    """
    Return ``(base_link, tip_link, hand_link)``: the default chain, and the hand that ends it.

    The tip is the child link of the last revolute or continuous joint on the path from the
    base (``base_link``, default the root link) with the most such joints; on a tie the one
    found first breadth-first (the shallower, then the first in document order). A joint
    coupled to others by ``<mimic>`` (one that mimics, or one mimicked: a gripper's fingers,
    which move together, not as the regulator's free coordinates) does not count, so a
    gripper of them adds nothing to the chain and the tip stays at the wrist; a linkage inside
    an arm does not cut it short either. A gripper's prismatic fingers do not count; a
    revolute jaw that nothing mimics does (give the tip link then).

    A hand of independent fingers ends the chain at the wrist above it (``hand_link`` is the
    link the fingers leave from; None where there is none): the first link on the path with
    two or more branches of counted joints below it, all it carries (its own mass left out)
    lighter than ``HAND_MASS_SHARE`` of the links the path moves above it, and no more
    counted joints on the path below it than above. A torso's arms are as heavy as what
    carries them, or longer: they do not end it. Raises ValueError if the URDF has no single
    root link (and no base is given), if the base is not a link of it, or if no revolute or
    continuous joint lies below the base.
    """
    root = _parsed(urdf_xml)
    coupled = set()
    for joint in root.findall('joint'):
        mimic = joint.find('mimic')
        if mimic is not None:
            coupled.update((joint.get('name'), mimic.get('joint')))
    joints = _joint_rows(root)
    links = [ln.get('name') for ln in root.findall('link')]
    if not links:
        raise ValueError('the URDF has no <link> (an empty <robot>: a xacro file of macros '
                         'only? give the URDF xacro expands it to)')
    if base_link is None:
        children = {c for _, _, _, c in joints}
        roots = [ln for ln in links if ln not in children]
        if len(roots) != 1:
            raise ValueError(f'the URDF has {len(roots)} root links {roots}; give the base '
                             'link')
        base_link = roots[0]
    elif base_link not in links:
        raise ValueError(f'link {base_link!r} is not in the URDF')
    by_parent: dict[str, list[tuple[bool, str]]] = {}
    for name, kind, parent, child in joints:
        counted = kind in ROTATING_TYPES and name not in coupled
        by_parent.setdefault(parent, []).append((counted, child))
    best = (0, base_link)
    queue = [(base_link, 0, base_link)]
    while queue:
        link, count, tip = queue.pop(0)
        if count > best[0]:
            best = (count, tip)
        for counted, child in by_parent.get(link, []):
            queue.append((child, count + counted, child if counted else tip))
    if best[0] == 0:
        raise ValueError(f'no revolute or continuous joint below link {base_link!r}'
                         + (' but those coupled by <mimic>' if coupled else '')
                         + '; give the tip link')
    tip_link, hand_link = _above_a_hand(root, by_parent, base_link, best[1], best[0])
    return base_link, tip_link, hand_link


def fixed_end(urdf_xml: str, link: str) -> str:
    """
    Return the link at the end of the single chain of fixed joints below ``link``.

    ``link`` itself where no fixed joint, or more than one joint of any type, leaves it. A
    position task regulates a point; the child link of an arm's last joint often lies on that
    joint's axis (a finger's last link, a leg's calf), where that joint cannot move it, while
    the fingertip or foot fixed below it is the point meant.
    """
    below: dict[str, list[tuple[str, str]]] = {}
    for _, kind, parent, child in _joint_rows(_parsed(urdf_xml)):
        below.setdefault(parent, []).append((kind, child))
    seen = {link}
    while len(below.get(link, [])) == 1 and below[link][0][0] == 'fixed':
        link = below[link][0][1]
        if link in seen:  # a loop is no tree: stop where it closes
            break
        seen.add(link)
    return link


def _above_a_hand(root: ElementTree.Element, below: dict[str, list[tuple[bool, str]]],
                  base_link: str, tip_link: str, on_path: int) -> tuple[str, Optional[str]]:
    """
    Return ``(tip_link, hand_link)``: the wrist above a hand on the path, or the tip.

    ``below`` maps a link to ``(counted, child)`` per joint under it (``default_chain_end``'s
    tree); ``on_path`` is the number of counted joints from ``base_link`` to ``tip_link``.
    """
    mass = link_masses(root)
    carried_kg = masses_below(root, mass)
    above = {child: (counted, parent)
             for parent, children in below.items() for counted, child in children}
    rotating: dict[str, bool] = {}  # link: a counted joint below it

    def turns_below(link: str) -> bool:
        if link not in rotating:
            rotating[link] = any(counted or turns_below(child)
                                 for counted, child in below.get(link, []))
        return rotating[link]

    path = [tip_link]
    while path[-1] != base_link:
        path.append(above[path[-1]][1])
    path.reverse()
    moved_kg, counted_above, wrist = 0.0, 0, None
    for link in path[1:]:
        if above[link][0]:
            counted_above, wrist = counted_above + 1, link
        moved_kg += mass.get(link, 0.0)
        fingers = sum(1 for free, child in below.get(link, []) if free or turns_below(child))
        if (wrist is not None and fingers >= 2
                and carried_kg.get(link, 0.0) < HAND_MASS_SHARE * moved_kg
                and on_path - counted_above <= counted_above):
            return wrist, link
    return tip_link, None


def chain_joints(urdf_xml: str, base_link: str, tip_link: str) -> list[str]:
    """
    Return the movable joints from ``base_link`` to ``tip_link``, base first.

    Raises ValueError if either is not a link of the URDF, or ``tip_link`` is not below
    ``base_link``.
    """
    root = _parsed(urdf_xml)
    links = {ln.get('name') for ln in root.findall('link')}
    for name in (base_link, tip_link):
        if name not in links:
            raise ValueError(f'link {name!r} is not in the URDF')
    by_child = {c: (name, kind, parent) for name, kind, parent, c in _joint_rows(root)}
    out = []
    link = tip_link
    while link != base_link:
        if link not in by_child:
            raise ValueError(f'link {tip_link!r} is not below link {base_link!r}')
        name, kind, link = by_child[link]
        if kind in MOVABLE_TYPES:
            out.append(name)
    return out[::-1]


class ForeignState(ValueError):
    """A joint state that names none of the controlled joints: another publisher's."""


class StateLayout:
    """
    Pick the controlled joints out of joint states whose name lists come in any order.

    The index map of a name list is built once and cached (a sensor_msgs/JointState usually
    repeats the same list every tick). :meth:`extract` raises ValueError saying why a state is
    unusable: a controlled joint missing, a name repeated, lengths that differ, NaN or Inf;
    :class:`ForeignState` where it names none of the controlled joints (a gripper's driver
    publishing on the same topic).
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
                if len(missing) == len(self.joint_names):  # another publisher's: a tuple
                    index = (f'names none of the controlled joints: {list(key)}',)
                else:
                    index = (f'missing controlled joint(s) {missing}: have {list(key)}, need '
                             f'{list(self.joint_names)}' if missing
                             else [where[j] for j in self.joint_names])
            if len(self._cache) < 64:
                self._cache[key] = index
        self._last_names = list(names)
        self._last = index
        return index

    def extract(self, names: Sequence[str], position: Sequence[float],
                velocity: Sequence[float],
                velocity_required: bool = True) -> tuple[list[float], Optional[list[float]]]:
        """
        Return (q, qdot) of the controlled joints, in ``joint_names`` order.

        With ``velocity_required`` False, a state without velocities (an empty list) gives
        qdot None, and a NaN velocity is passed on as NaN: ros2_control's
        joint_state_broadcaster publishes NaN for a joint whose hardware has no velocity state
        interface, so NaN there means "not measured", for the caller to estimate. A velocity
        list of another length, or an infinite velocity, is still refused.
        """
        index = self._index(names)
        if isinstance(index, str):
            raise ValueError(index)
        if isinstance(index, tuple):
            raise ForeignState(index[0])
        if len(position) != len(names) or (len(velocity) != len(names) and (
                velocity_required or len(velocity))):
            raise ValueError(f'{len(names)} names but {len(position)} positions and '
                             f'{len(velocity)} velocities (positions are required, and '
                             + ('velocities' if velocity_required else 'velocities, if any')
                             + ', one per name)')
        q = [position[i] for i in index]
        total = sum(q)
        if total - total != 0.0:
            raise ValueError(f'non-finite position: q = {q}')
        if not len(velocity):
            return q, None
        qdot = [velocity[i] for i in index]
        total = sum(qdot)
        if total - total != 0.0 and (velocity_required or any(isinf(v) for v in qdot)):
            raise ValueError(f'non-finite velocity: qdot = {qdot}'
                             + ('' if velocity_required else
                                ' (NaN marks a velocity not measured; Inf is refused)'))
        return q, qdot


# The joint-state rates the controller and the gain design accept (Hz): ros2_control's usual
# 100 Hz up to the 1 kHz of a torque-controlled arm
STATE_RATE_RANGE_HZ = (100.0, 1000.0)
DEFAULT_STATE_RATE_HZ = 1000.0


def check_state_rate(rate_hz: float, name: str = 'state_rate') -> float:
    """Return ``rate_hz`` as a float, or raise ValueError naming it if outside the range."""
    low, high = STATE_RATE_RANGE_HZ
    try:
        rate = float(rate_hz)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a number of Hz, got {rate_hz!r}') from None
    if not low <= rate <= high:  # NaN fails too
        raise ValueError(f'{name} {rate_hz!r} Hz is outside [{low:g}, {high:g}] Hz')
    return rate


def wrapped(angle: float) -> float:
    """Return ``angle`` moved by whole turns into [-pi, pi)."""
    return (angle + pi) % (2.0 * pi) - pi


class VelocityEstimator:
    """
    Joint velocities from positions and their times, for states that carry none.

    Each new position gives the finite difference ``(q_k - q_k-1) / (t_k - t_k-1)``; the
    estimate follows it through a first-order low-pass of time constant ``T``, discretised
    exactly for the interval ``h`` between the two states: ``v += (1 - exp(-h / T)) (d - v)``.
    With ``T`` one period of the state rate the estimate lags the true velocity by about one
    period (half a period of the difference, ``e^-1 / (1 - e^-1)`` = 0.58 of the filter), and
    a position step of one count (quantisation) moves it by at most ``0.63 count / h``, then
    decays.

    The first state, and the first after a gap longer than ``max_gap_s``, give 0 and restart
    the difference. A state whose time is not after the last one's (a repeat or an older one)
    leaves the estimate as it is.
    """

    def __init__(self, n: int, time_constant_s: float, max_gap_s: float) -> None:
        if not time_constant_s > 0.0 or not max_gap_s > 0.0:
            raise ValueError(f'time_constant_s {time_constant_s} and max_gap_s {max_gap_s} '
                             'must be > 0')
        self.n = n
        self.time_constant_s = float(time_constant_s)
        self._max_gap_ns = int(max_gap_s * 1e9)
        self._v = [0.0] * n
        self._last_q: Optional[list[float]] = None
        self._last_ns = 0

    def reset(self) -> None:
        """Forget the last position: the next state restarts the estimate at 0."""
        self._last_q = None
        self._v = [0.0] * self.n

    def update(self, q: Sequence[float], t_ns: int) -> list[float]:
        """Return the velocity estimate after the positions ``q`` measured at ``t_ns`` (a copy)."""
        last = self._last_q
        gap_ns = t_ns - self._last_ns
        if last is None or gap_ns > self._max_gap_ns:
            self._v = [0.0] * self.n
        elif gap_ns <= 0:
            return list(self._v)
        else:
            h = gap_ns * 1e-9
            alpha = 1.0 - exp(-h / self.time_constant_s)
            v = self._v
            for j in range(self.n):
                v[j] += alpha * ((q[j] - last[j]) / h - v[j])
        self._last_q = list(q)
        self._last_ns = t_ns
        return list(self._v)


# The longest window of WindowedVelocityEstimator, in states (16 ms at 1 kHz)
VELOCITY_WINDOW_STATES = 16


class WindowedVelocityEstimator:
    """
    Joint velocities from an encoder's positions, on the longest window they allow.

    The end-fit first-order adaptive window (Janabi-Sharifi, Hayward and Chen, IEEE Trans.
    Control Systems Technology 8(6), 2000): a joint's velocity is the slope of the line from
    the newest position back to the one ``m`` states before, for the largest ``m`` (at most
    ``window``) such that this line and every shorter one pass within the joint's
    ``resolution_rad`` (one count) of each position in between. At rest or at a steady speed
    the window grows and a step of one count moves the estimate by ``count / (m h)``, not by
    the ``0.63 count / h`` of the one-period low-pass of :class:`VelocityEstimator`; where the
    joint accelerates the window shrinks, down to the last difference (``m`` = 1), so the lag
    stays at most what the count allows. A joint whose newest position is within one count of
    every state of the window reads 0: a joint at rest explains those counts, as one hopping
    between two counts about a goal between them (the end-fit line would read
    ``count / (m h)`` on each hop, and the damping turn that into a torque that shakes at
    rest); a creep slower than a count a window reads 0 with it. A joint of resolution 0
    (exact positions) gets the last difference. Times are the states' own, so an irregular rate
    is allowed for. Plain floats: on the tick's path, numpy's call overhead on a few joints
    costs more.

    As :class:`VelocityEstimator`: the first state, and the first after a gap longer than
    ``max_gap_s``, give 0; a state whose time is not after the last one's leaves the estimate
    as it is.
    """

    def __init__(self, resolution_rad: Sequence[float], max_gap_s: float,
                 window: int = VELOCITY_WINDOW_STATES) -> None:
        resolution = [float(r) for r in resolution_rad]
        if not all(isfinite(r) and r >= 0.0 for r in resolution):
            raise ValueError(f'resolution_rad must be finite and >= 0, got {resolution}')
        if not max_gap_s > 0.0 or window < 1:
            raise ValueError(f'max_gap_s {max_gap_s} must be > 0 and window {window} >= 1')
        self.n = len(resolution)
        # within one count, and a hair more: a position exactly one count off the line fits
        self._band = [r * (1.0 + 1e-9) for r in resolution]
        self._max_gap_ns = int(max_gap_s * 1e9)
        self._q: deque = deque(maxlen=window + 1)  # the states' positions, newest first
        self._t_s: deque = deque(maxlen=window + 1)  # ... and their times
        self._last_ns = 0
        self._v = [0.0] * self.n

    def reset(self) -> None:
        """Forget the positions: the next state restarts the estimate at 0."""
        self._q.clear()
        self._t_s.clear()
        self._v = [0.0] * self.n

    def update(self, q: Sequence[float], t_ns: int) -> list[float]:
        """Return the velocity estimate after the positions ``q`` measured at ``t_ns`` (a copy)."""
        if self._q and t_ns - self._last_ns > self._max_gap_ns:
            self.reset()
        elif self._q and t_ns <= self._last_ns:
            return list(self._v)
        states, times = self._q, self._t_s
        states.appendleft(list(q))
        times.appendleft(t_ns * 1e-9)
        self._last_ns = t_ns
        k = len(states) - 1  # the longest window the states allow now
        newest, now = states[0], times[0]
        back_s = [now - times[i] for i in range(1, k + 1)]  # to the state i back
        v = self._v
        for j in range(self.n):
            band, x = self._band[j], newest[j]
            for i in range(1, k + 1):
                if not -band <= x - states[i][j] <= band:
                    break  # a count or more from the newest: it may move
            else:
                v[j] = 0.0  # at rest as far as the counts tell (and the first state)
                continue
            # a line of slope s passes within the band of the state i back if s lies between
            # (rise_i - band) / back_i and (rise_i + band) / back_i; window m needs that of
            # every state inside it (i < m): the running bounds of the states before
            low, high, slope_j = -inf, inf, 0.0
            for i in range(k):
                back = back_s[i]
                rise = x - states[i + 1][j]
                slope = rise / back
                if not low <= slope <= high:
                    break  # the first misfit ends the window (window 1 always fits)
                slope_j = slope
                bound = (rise - band) / back
                if bound > low:
                    low = bound
                bound = (rise + band) / back
                if bound < high:
                    high = bound
            v[j] = slope_j
        return list(v)


def velocity_estimator(
        n: int, rate_hz: float, resolution_rad: Optional[Sequence[float]] = None,
) -> 'VelocityEstimator | WindowedVelocityEstimator':
    """
    Return the velocity estimator for states without velocities, as the controller uses it.

    Positions of no given resolution: :class:`VelocityEstimator`, of time constant one period
    of ``rate_hz``; an encoder's (``resolution_rad``, one count per joint, any > 0):
    :class:`WindowedVelocityEstimator`. Either restarts after ten periods without a state.
    """
    rate = check_state_rate(rate_hz)
    if resolution_rad is not None and len(resolution_rad) != n:
        raise ValueError(f'position_resolution: expected {n} values, got {len(resolution_rad)}')
    if resolution_rad is not None and any(r != 0.0 for r in resolution_rad):
        return WindowedVelocityEstimator(resolution_rad, 10.0 / rate)
    return VelocityEstimator(n, 1.0 / rate, 10.0 / rate)


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
    command may be computed from the state (:class:`StaleState` if it is the stamp). Names may
    come in any order and with other joints (a gripper's). A state without velocities (an
    empty ``velocity``, as some drivers publish, or NaN for a joint, as ros2_control's
    joint_state_broadcaster publishes where the hardware has no velocity interface) gets them
    from :func:`velocity_estimator` (for ``position_resolution``, a count per joint, 0:
    exact), on the states' stamps, or on the time they arrived when they are not stamped;
    :attr:`estimating` says so of the last state, and :attr:`unmeasured` names the joints
    whose velocities came as NaN (empty where none came at all). The angles of the joints
    flagged ``continuous`` (no stops) are unwrapped: a driver that reports them within
    (-pi, pi] gives a q that does not jump by a turn.
    """

    def __init__(self, joint_names: Sequence[str], max_age_s: float,
                 rate_hz: float = DEFAULT_STATE_RATE_HZ,
                 continuous: Optional[Sequence[bool]] = None,
                 position_resolution: Optional[Sequence[float]] = None) -> None:
        rate = check_state_rate(rate_hz)
        self._layout = StateLayout(joint_names)
        self._max_age_ns = int(max_age_s * 1e9)
        n = len(self._layout.joint_names)
        self._continuous = [j for j, c in enumerate(continuous or ()) if c]
        if continuous is not None and len(continuous) != n:
            raise ValueError(f'continuous: expected {n} flags, got {len(continuous)}')
        self._last_q: Optional[list[float]] = None
        # a gap of more than 10 periods restarts the estimate (a lost connection, a pause)
        self._estimator = velocity_estimator(n, rate, position_resolution)
        self.estimating = False  # the last state came without velocities, or with NaN ones
        self.unmeasured: tuple[str, ...] = ()  # ... the joints whose velocities were NaN
        self._missing: list[int] = []  # ... their indices

    def __call__(self, names: Sequence[str], position: Sequence[float],
                 velocity: Sequence[float], stamp_ns: int,
                 now_ns: int) -> tuple[list[float], list[float]]:
        """Return (q, qdot); raise ValueError (StaleState for the stamp) naming the problem."""
        q, qdot = self._layout.extract(names, position, velocity, velocity_required=False)
        problem = stamp_problem(stamp_ns, now_ns, self._max_age_ns)
        if problem:
            raise StaleState(problem)
        if self._continuous:
            last = self._last_q
            if last is not None:
                for j in self._continuous:
                    q[j] = last[j] + wrapped(q[j] - last[j])
            self._last_q = q
        if qdot is None:
            self.estimating, self.unmeasured, self._missing = True, (), []
            return q, self._estimator.update(q, stamp_ns or now_ns)
        total = sum(qdot)
        if total != total:  # NaN: velocities the hardware does not measure (no Inf here)
            self.estimating = True
            estimate = self._estimator.update(q, stamp_ns or now_ns)
            missing = [j for j, v in enumerate(qdot) if v != v]
            for j in missing:
                qdot[j] = estimate[j]
            if missing != self._missing:  # the same joints, state after state: named once
                self._missing = missing
                self.unmeasured = tuple(self._layout.joint_names[j] for j in missing)
        elif self.estimating:  # velocities again: the next state without starts afresh
            self.estimating, self.unmeasured, self._missing = False, (), []
            self._estimator.reset()
        return q, qdot

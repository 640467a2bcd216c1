"""
Extensions of the regulator that stay in the energy-shaping frame (docs/lyapunov.md).

The law of Eq. (22) becomes

    tau = J^T Q(eta_e, e)^T grad U_a(y_tilde) - grad U_lim(q) - grad U_c(q) - K_v qdot + g(q)
          + tau_fc

* ``U_lim``, the joint-limit potential (docs/lyapunov.md, section 2): zero away from the limits,
  ``1/2 k_j x^2`` at a depth ``x`` into a band of width ``margin`` inside each limit of a joint
  whose range is less than a full turn. C1; its gradient pushes the joint out of the band.
* ``U_c``, the goal-configuration potential (section 5): once a goal configuration ``q*``
  within the limits is known (the goal check's inverse kinematics, in a worker process), a
  joint-space term that is zero within ``radius`` of ``q*`` in every joint and pulls towards
  ``q*`` outside, with at most ``T_j`` N m (Huber profile). The joint box is convex, so this
  leads the long way round a joint's stop instead of into it. Within the radius only the
  paper's transpose-Jacobian term acts; with radius 0 both share their minimum at ``q*``.
* The cubic damping (section 6): ``-k_v qdot min(qdot^2, v_m^2) / v_c^2`` on top of ``K_v``.
* The large-error term of ``U_a`` (section 3): ``k_L B(||e||)`` with
  ``B'(s) = s^2 / sqrt(1 + delta^2 - s^2)``, so that ``Q^T grad`` keeps its size up to a few
  degrees from 180 degrees instead of fading like ``eta_e``; computed in ``control_law``.
* Damping towards a streamed goal's velocity (section 7): the joint damping acts on
  ``qdot - g_v qdot*_d`` instead of ``qdot``, ``qdot*_d`` the velocity of the goal
  configuration (from the goal-check worker: the stream's task velocity mapped through
  J(q*), never an inverse in the tick), ``g_v`` in [0, 1]. Zero for a fixed goal.
* ``tau_fc``, Coulomb friction compensation (section 4): per joint
  ``phi(y_tilde) (f_j + a_j) t_p [max(0, t_v t_p) + 1 - |t_v|]``, ``t_p = tanh(tau_p,j /
  (0.001 (f_j + a_max,j)))`` the direction of the potential torque ``tau_p``, ``t_v =
  tanh(qdot_j / v_eps)``: at rest and while the joint moves the way the potential pushes it,
  ``f_j + a_j`` that way; a joint moving against it (an overshoot) is left to its friction.
  All of it fades to zero inside a small error band (``phi``), so an estimate above the true
  friction cannot feed a limit cycle at the goal. Its size never
  exceeds ``f_j + a_j``, which is what keeps dV/dt <= -qdot^T K_v qdot against a Coulomb
  friction of at least that. ``a_j`` in ``[0, a_max,j]`` is the learned part of the estimate
  (:func:`learn_friction`): it grows while the joint is stuck outside the error band, which
  happens only while ``f_j + a_j`` is below the friction that holds it, and leaks away inside
  the band.

All are off by default (:class:`Shaping` ()), which gives the paper's law exactly. Plain
floats: the functions here run in the 1 kHz tick.
"""
from dataclasses import dataclass
from functools import cached_property
from math import isfinite, pi, sqrt, tanh
from typing import Optional, Sequence

from quat_jt_runtime.errors import checked_vector, QuatJtError

# A joint whose URDF range is at least this long turns freely: it gets no limit term.
FULL_TURN_RAD = 2.0 * pi - 1e-6
# t_p = tanh(tau_p / (TORQUE_BAND_FRACTION f)): the breakaway reaches 76% of f when the
# potential torque is 0.1% of f, and changes sign smoothly (C-infinity) through tau_p = 0.
TORQUE_BAND_FRACTION = 0.001
# Width of the fade of the large-error term at 180 degrees, in eta_e (docs/lyapunov.md, 3).
LARGE_ERROR_DELTA = 0.1
# The cubic damping turns linear above the URDF velocity limit, or above this without one.
DEFAULT_SPEED_CAP_RAD_S = 2.0 * pi


class ShapingError(QuatJtError):
    """An invalid extension parameter; the message names the parameter and the value."""


def _nonnegative(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ShapingError(f'{name} must be a number, got {value!r}') from None
    if not isfinite(v) or v < 0.0:
        raise ShapingError(f'{name} must be finite and >= 0, got {v}')
    return v


def _positive(name: str, value: float) -> float:
    v = _nonnegative(name, value)
    if v <= 0.0:
        raise ShapingError(f'{name} must be finite and > 0, got {v}')
    return v


MAX_POSTURE_WEIGHT = 100.0  # of the preferred posture against the distance to the arm


def _at_most(name: str, value: float, ceiling: float) -> float:
    if value > ceiling:
        raise ShapingError(f'{name} must be at most {ceiling:g}, got {value}')
    return value


def _per_joint(name: str, values: Optional[Sequence[float]], n: int,
               nonnegative: bool = True) -> tuple[float, ...]:
    """
    Return ``n`` finite values (>= 0 if ``nonnegative``).

    None is the default: zeros for a gain, () for a posture (``nonnegative`` False), as is an
    empty posture.
    """
    if values is None or (not nonnegative and len(values) == 0):
        return (0.0,) * n if nonnegative else ()
    return checked_vector(name, values, n, ShapingError, lower=0.0 if nonnegative else None,
                          per_joint=True)


@dataclass(frozen=True)
class Shaping:
    """
    The extensions, validated and immutable: a snapshot of their own beside the Gains.

    Units: ``joint_limit_margin_rad`` rad (band width inside each limit), ``joint_limit_gain``
    N m/rad per joint (stiffness in the band; 0 = no limit term for that joint),
    ``large_error_gain`` N m (``k_L``; 0 = off), ``friction_compensation_nm`` N m per joint
    (Coulomb estimates; 0 = off), ``friction_velocity_rad_s`` rad/s (``v_eps``),
    ``friction_error_band`` (``||e||`` below which the breakaway fades out) and
    ``friction_position_band_m`` m (the same for ``||p_d - p||``, pose task).
    ``configuration_gain`` N m per joint (``T_j``, the most the goal-configuration term asks
    of joint j; 0 = off) and ``configuration_radius_rad`` rad (its dead zone, also the width of
    its ramp). Empty per-joint tuples mean zeros.
    """

    joint_limit_margin_rad: float = 0.0
    joint_limit_gain: tuple[float, ...] = ()
    large_error_gain: float = 0.0
    friction_compensation_nm: tuple[float, ...] = ()
    friction_velocity_rad_s: float = 0.05
    friction_error_band: float = 0.004
    friction_position_band_m: float = 0.0005
    configuration_gain: tuple[float, ...] = ()
    configuration_radius_rad: float = 0.05
    configuration_ramp_rad: float = 0.25
    damping_speed_rad_s: tuple[float, ...] = ()
    # g_v: the joint damping acts on qdot - g_v qdot*_d of a streamed goal; 0 = off
    goal_velocity_gain: float = 0.0
    # a_max per joint, N m: the most the friction estimate may learn at rest (0 = no learning)
    friction_learning_limit_nm: tuple[float, ...] = ()
    # s: a_max is learned in this time while stuck, and leaks with it inside the band
    friction_learning_time_s: float = 1.0
    # the goal check's choice of q* along a redundant arm's self-motion
    # (inverse_kinematics.posture):
    # nearest the measured q, then this posture (rad per joint; empty: the middle of the
    # ranges) with this weight. Not read by the tick.
    preferred_configuration_rad: tuple[float, ...] = ()
    posture_weight: float = 0.0

    @classmethod
    def create(cls, n_joints: int, joint_limit_margin: float = 0.0,
               joint_limit_gain: Optional[Sequence[float]] = None,
               large_error_gain: float = 0.0,
               friction_compensation: Optional[Sequence[float]] = None,
               friction_velocity: float = 0.05, friction_error_band: float = 0.004,
               friction_position_band: float = 0.0005,
               configuration_gain: Optional[Sequence[float]] = None,
               configuration_radius: float = 0.05, configuration_ramp: float = 0.25,
               damping_speed: Optional[Sequence[float]] = None,
               goal_velocity_gain: float = 0.0,
               friction_learning_limit: Optional[Sequence[float]] = None,
               friction_learning_time: float = 1.0,
               preferred_configuration: Optional[Sequence[float]] = None,
               posture_weight: float = 0.0) -> 'Shaping':
        """Validate and build; raise ShapingError naming the bad value."""
        if _nonnegative('goal_velocity_gain', goal_velocity_gain) > 1.0:
            raise ShapingError(f'goal_velocity_gain must be in [0, 1], got {goal_velocity_gain}')
        return cls(
            joint_limit_margin_rad=_nonnegative('joint_limit_margin', joint_limit_margin),
            joint_limit_gain=_per_joint('joint_limit_gain', joint_limit_gain, n_joints),
            large_error_gain=_nonnegative('large_error_gain', large_error_gain),
            friction_compensation_nm=_per_joint('friction_compensation', friction_compensation,
                                                n_joints),
            friction_velocity_rad_s=_positive('friction_velocity', friction_velocity),
            friction_error_band=_positive('friction_error_band', friction_error_band),
            friction_position_band_m=_positive('friction_position_band',
                                               friction_position_band),
            configuration_gain=_per_joint('configuration_gain', configuration_gain, n_joints),
            configuration_radius_rad=_nonnegative('configuration_radius', configuration_radius),
            configuration_ramp_rad=_positive('configuration_ramp', configuration_ramp),
            damping_speed_rad_s=_per_joint('damping_speed', damping_speed, n_joints),
            goal_velocity_gain=float(goal_velocity_gain),
            friction_learning_limit_nm=_per_joint('friction_learning_limit',
                                                  friction_learning_limit, n_joints),
            friction_learning_time_s=_positive('friction_learning_time',
                                               friction_learning_time),
            preferred_configuration_rad=_per_joint('preferred_configuration',
                                                   preferred_configuration, n_joints,
                                                   nonnegative=False),
            posture_weight=_at_most('posture_weight', _nonnegative('posture_weight',
                                                                   posture_weight),
                                    MAX_POSTURE_WEIGHT))

    def check_size(self, n_joints: int) -> 'Shaping':
        """Return self if the per-joint vectors fit ``n_joints`` (or are empty); else raise."""
        for name, values in (('joint_limit_gain', self.joint_limit_gain),
                             ('friction_compensation', self.friction_compensation_nm),
                             ('configuration_gain', self.configuration_gain),
                             ('damping_speed', self.damping_speed_rad_s),
                             ('friction_learning_limit', self.friction_learning_limit_nm),
                             ('preferred_configuration', self.preferred_configuration_rad)):
            if values and len(values) != n_joints:
                raise ShapingError(f'{name} must have {n_joints} values (one per joint), got '
                                   f'{len(values)}')
        return self

    @cached_property  # read every tick: computed once per snapshot
    def friction_on(self) -> bool:
        """Return True if any joint has a friction estimate or may learn one."""
        return any(f > 0.0 for f in self.friction_compensation_nm) or self.learning_on

    @cached_property  # read every tick: computed once per snapshot
    def learning_on(self) -> bool:
        """Return True if some joint may learn a part of its friction estimate at rest."""
        return any(a > 0.0 for a in self.friction_learning_limit_nm)

    @cached_property  # read every tick: computed once per snapshot
    def friction_table(self) -> tuple[tuple[float, float, float], ...]:
        """Return per joint ``(f, a_max, 0.001 (f + a_max))``: estimate, learnable, scale."""
        n = max(len(self.friction_compensation_nm), len(self.friction_learning_limit_nm))
        f = self.friction_compensation_nm or (0.0,) * n
        a = self.friction_learning_limit_nm or (0.0,) * n
        return tuple((fj, aj, TORQUE_BAND_FRACTION * (fj + aj)) for fj, aj in zip(f, a))

    @cached_property  # read every tick: computed once per snapshot
    def speed_damping_on(self) -> bool:
        """Return True if some joint has the cubic damping term."""
        return any(v > 0.0 for v in self.damping_speed_rad_s)

    @cached_property  # read every tick: computed once per snapshot
    def configuration_on(self) -> bool:
        """Return True if the goal-configuration term can act (some gain > 0)."""
        return any(t > 0.0 for t in self.configuration_gain)

    @cached_property  # read every tick: computed once per snapshot
    def limits_on(self) -> bool:
        """Return True if the joint-limit potential can act (margin and some gain > 0)."""
        return self.joint_limit_margin_rad > 0.0 and any(k > 0.0 for k in self.joint_limit_gain)


@dataclass(frozen=True)
class LimitBand:
    """
    The joint-limit potential of one robot, ready for the tick (docs/lyapunov.md, section 2).

    ``lower_rad``/``upper_rad`` are the inner edges of the bands (the URDF limit moved inwards
    by the margin), ``gain`` the stiffness per joint; joints without a term have gain 0.
    """

    lower_rad: tuple[float, ...]
    upper_rad: tuple[float, ...]
    gain: tuple[float, ...]
    joints: tuple[int, ...]  # indices with a term
    margin_rad: float

    @classmethod
    def create(cls, position_lower: Sequence[float], position_upper: Sequence[float],
               shaping: Shaping) -> Optional['LimitBand']:
        """
        Build the band of a robot with these URDF limits; None if no joint gets a term.

        A joint gets a term if its range is finite and shorter than a full turn and its gain is
        > 0. Raises ShapingError if the margin does not fit inside such a joint's range.
        """
        if not shaping.limits_on:
            return None
        m = shaping.joint_limit_margin_rad
        lo, hi, gain, joints = [], [], [], []
        for j, (low, up) in enumerate(zip(position_lower, position_upper)):
            k = shaping.joint_limit_gain[j]
            limited = isfinite(low) and isfinite(up) and up > low and up - low < FULL_TURN_RAD
            if limited and k > 0.0:
                if 2.0 * m >= up - low:
                    raise ShapingError(
                        f'joint_limit_margin {m} rad leaves no room inside the range '
                        f'[{low}, {up}] of joint {j} (it must be < {0.5 * (up - low):.4g})')
                joints.append(j)
            else:
                k = 0.0
            lo.append(low + m if k > 0.0 else -float('inf'))
            hi.append(up - m if k > 0.0 else float('inf'))
            gain.append(k)
        if not joints:
            return None
        return cls(tuple(lo), tuple(hi), tuple(gain), tuple(joints), m)

    def ending_at(self, q_star: Sequence[float]) -> 'LimitBand':
        """
        Return this band with each inner edge moved out to ``q_star`` where it lies in the band.

        A goal configuration inside a band would otherwise sit where the band pushes the joint
        away: the band and the goal terms would balance off the goal. Ending the band at q* keeps
        its stiffness and its side, so the joint is still pushed back from the stop beyond q*, and
        makes q* a minimum of the whole potential again (docs/lyapunov.md, section 2). Returns
        self if q* lies outside every band.
        """
        lower = tuple(min(lo, q_star[j]) for j, lo in enumerate(self.lower_rad))
        upper = tuple(max(up, q_star[j]) for j, up in enumerate(self.upper_rad))
        if lower == self.lower_rad and upper == self.upper_rad:
            return self
        return LimitBand(lower, upper, self.gain, self.joints, self.margin_rad)

    def add_torque(self, q: Sequence[float], tau: list[float]) -> None:
        """Add -grad U_lim(q) to ``tau`` in place: k x out of the band, 0 outside it."""
        for j in self.joints:
            qj = q[j]
            if qj < self.lower_rad[j]:
                tau[j] += self.gain[j] * (self.lower_rad[j] - qj)
            elif qj > self.upper_rad[j]:
                tau[j] -= self.gain[j] * (qj - self.upper_rad[j])

    def energy(self, q: Sequence[float]) -> float:
        """U_lim(q) = sum 1/2 k_j x_j^2 (J), x_j the depth into the band."""
        total = 0.0
        for j in self.joints:
            x = max(self.lower_rad[j] - q[j], q[j] - self.upper_rad[j], 0.0)
            total += 0.5 * self.gain[j] * x * x
        return total

    def depth(self, q: Sequence[float]) -> list[float]:
        """Depth into each joint's band as a fraction of the margin (0 outside, 1 at a stop)."""
        out = [0.0] * len(q)
        for j in self.joints:
            x = max(self.lower_rad[j] - q[j], q[j] - self.upper_rad[j], 0.0)
            out[j] = x / self.margin_rad
        return out


def fade(y_tilde: Sequence[float], shaping: Shaping) -> float:
    """
    phi(y_tilde): 1 outside the error band, 0 well inside it, C1 in between.

    ``r = max(||e|| / friction_error_band, ||p_d - p|| / friction_position_band)``; phi is 0
    for r <= 1/2, 1 for r >= 1 and the cubic smoothstep in between.
    """
    e = y_tilde[-3:]
    r = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) / shaping.friction_error_band
    if len(y_tilde) == 6:
        p = sqrt(y_tilde[0] ** 2 + y_tilde[1] ** 2 + y_tilde[2] ** 2)
        r = max(r, p / shaping.friction_position_band_m)
    x = 2.0 * r - 1.0
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


def friction_compensation(tau_potential: Sequence[float], qdot: Sequence[float], phi: float,
                          shaping: Shaping, learned_nm: Optional[Sequence[float]] = None,
                          stuck_out: Optional[list[float]] = None) -> list[float]:
    """
    tau_fc per joint: phi (f + a) t_p [max(0, t_v t_p) + 1 - |t_v|], never above f + a in size.

    ``t_p = tanh(tau_p / (0.001 (f + a_max)))`` is the direction of the potential torque
    ``tau_potential``, ``t_v = tanh(qdot / v_eps)``. At rest it pushes with ``f + a`` in the
    direction of the potential (breakaway); a joint moving that way keeps the push (the
    friction of a moving joint compensated); a joint moving against it (past the goal) gets
    no push along its motion, only ``(1 - |t_v|)`` towards the potential, so the friction
    brakes the overshoot. So the compensation does positive work only while the potential
    does. ``phi`` (:func:`fade`) turns all of it off near the goal. ``learned_nm`` is ``a``,
    the part of the estimate learned at rest (:func:`learn_friction`; None = zeros).
    ``stuck_out``, if given, receives ``(1 - |t_v|) |t_p|`` per joint (how stuck and pushed
    each joint is, for :func:`learn_friction`); it is left alone when ``phi`` is 0.
    """
    out = [0.0] * len(qdot)
    if phi <= 0.0:
        return out
    v_eps = shaping.friction_velocity_rad_s
    for j, (f, _, scale) in enumerate(shaping.friction_table):
        if scale <= 0.0:  # no estimate and nothing to learn
            continue
        tv = tanh(qdot[j] / v_eps)
        tp = tanh(tau_potential[j] / scale)
        rest = 1.0 - abs(tv)
        if stuck_out is not None:
            stuck_out[j] = rest * abs(tp)
        size = f if learned_nm is None else f + learned_nm[j]
        along = tv * tp
        out[j] = phi * size * tp * ((along if along > 0.0 else 0.0) + rest)
    return out


def learn_friction(learned_nm: list[float], stuck: Sequence[float], phi: float,
                   shaping: Shaping, dt_s: float) -> None:
    """
    Advance ``a``, the learned part of the friction estimate, by one tick of ``dt_s``, in place.

    ``da/dt = (a_max / T) phi (1 - |t_v|) |t_p| - (1 - phi) a / T`` (``T`` the learning time),
    clipped to ``[0, a_max]``; ``stuck`` is ``(1 - |t_v|) |t_p|`` per joint, as
    :func:`friction_compensation` gave it this tick (unread when ``phi`` is 0). It grows only
    while the joint is at rest (``t_v`` ~ 0) and pushed (``t_p``) outside the error band
    (``phi`` > 0), that is while the compensation is still below the friction that holds the
    joint; it stops growing once the joint breaks away, and leaks away within the band
    (docs/lyapunov.md, section 4).
    """
    rate = dt_s / shaping.friction_learning_time_s
    for j, (_, a_max, _) in enumerate(shaping.friction_table):
        if a_max <= 0.0:
            continue
        a = learned_nm[j]
        grow = a_max * phi * stuck[j] if phi > 0.0 else 0.0
        a += rate * (grow - (1.0 - phi) * a)
        learned_nm[j] = a_max if a > a_max else (a if a > 0.0 else 0.0)


def add_configuration_torque(q: Sequence[float], q_star: Sequence[float], shaping: Shaping,
                             tau: list[float]) -> None:
    """
    Add -grad U_c(q) to ``tau`` in place (docs/lyapunov.md, section 5).

    Per joint, ``x = max(0, |q - q*| - r)``; the torque is ``-sign(q - q*) T min(x / w, 1)``
    (``r`` the radius, ``w`` the ramp).
    """
    r = shaping.configuration_radius_rad
    w = shaping.configuration_ramp_rad
    for j, t in enumerate(shaping.configuration_gain):
        if t <= 0.0:
            continue
        d = q[j] - q_star[j]
        x = abs(d) - r
        if x > 0.0:
            push = t if x >= w else t * x / w
            tau[j] += -push if d > 0.0 else push


def configuration_energy(q: Sequence[float], q_star: Sequence[float], shaping: Shaping) -> float:
    """U_c(q) = sum T_j h(x_j), h(x) = x^2 / (2 w) up to x = w, then x - w / 2 (J)."""
    r = shaping.configuration_radius_rad
    w = shaping.configuration_ramp_rad
    total = 0.0
    for j, t in enumerate(shaping.configuration_gain):
        x = abs(q[j] - q_star[j]) - r
        if t > 0.0 and x > 0.0:
            total += t * (x * x / (2.0 * w) if x <= w else x - 0.5 * w)
    return total


def add_speed_damping(qdot: Sequence[float], kv: Sequence[float], shaping: Shaping,
                      tau: list[float], speed_cap_rad_s: Sequence[float]) -> None:
    """
    Add the cubic part of the damping, -K_v qdot min(qdot^2, v_m^2) / v_c^2, to ``tau``.

    In place. It makes the dissipation function of Eq. (16) F = sum k_v (qdot^2 / 2 +
    qdot^4 / (4 v_c^2)) up to the speed ``v_m`` (``speed_cap_rad_s``, the URDF velocity limit),
    and linear beyond it, so the slope of the damping, which the sampled loop must tolerate,
    stays bounded (docs/lyapunov.md, section 6). Linear near rest, it caps the cruising speed.
    ``v_c`` per joint; 0 = no cubic term on that joint.
    """
    for j, v_c in enumerate(shaping.damping_speed_rad_s):
        if v_c > 0.0:
            v = qdot[j]
            s = min(v * v, speed_cap_rad_s[j] * speed_cap_rad_s[j])
            tau[j] -= kv[j] * v * s / (v_c * v_c)


def from_parameters(values: dict, n_joints: int) -> Shaping:
    """
    Build a Shaping from controller parameters keyed by their ROS names (a config file's).

    Missing names keep their defaults (off). Raises ShapingError naming a bad value.
    """
    d = Shaping()
    return Shaping.create(
        n_joints, joint_limit_margin=values.get('joint_limit_margin', 0.0),
        joint_limit_gain=values.get('joint_limit_gain'),
        large_error_gain=values.get('large_error_gain', 0.0),
        friction_compensation=values.get('friction_compensation'),
        friction_velocity=values.get('friction_velocity', d.friction_velocity_rad_s),
        friction_error_band=values.get('friction_error_band', d.friction_error_band),
        friction_position_band=values.get('friction_position_band',
                                          d.friction_position_band_m),
        configuration_gain=values.get('configuration_gain'),
        configuration_radius=values.get('configuration_radius', d.configuration_radius_rad),
        configuration_ramp=values.get('configuration_ramp', d.configuration_ramp_rad),
        damping_speed=values.get('damping_speed'),
        goal_velocity_gain=values.get('goal_velocity_gain', 0.0),
        friction_learning_limit=values.get('friction_learning_limit'),
        friction_learning_time=values.get('friction_learning_time',
                                          d.friction_learning_time_s),
        preferred_configuration=values.get('preferred_configuration'),
        posture_weight=values.get('posture_weight', d.posture_weight))


def describe(shaping: Shaping) -> str:
    """Return one line saying which extensions are on, for the node's log."""
    parts = []
    if shaping.limits_on:
        parts.append(f'joint-limit band {shaping.joint_limit_margin_rad:g} rad, stiffness '
                     f'{list(shaping.joint_limit_gain)} N m/rad')
    if shaping.large_error_gain > 0.0:
        parts.append(f'large-error term {shaping.large_error_gain:g} N m')
    if shaping.configuration_on:
        parts.append(f'goal-configuration term {list(shaping.configuration_gain)} N m')
    if shaping.speed_damping_on:
        parts.append(f'cubic damping v_c {list(shaping.damping_speed_rad_s)} rad/s')
    if shaping.goal_velocity_gain > 0.0:
        parts.append(f'damping towards a streamed goal velocity, gain '
                     f'{shaping.goal_velocity_gain:g}')
    if shaping.friction_on:
        parts.append(f'friction compensation {list(shaping.friction_compensation_nm)} N m')
    if shaping.posture_weight > 0.0 and shaping.configuration_on:
        parts.append(f'q* nearest the arm, then posture '
                     f'{list(shaping.preferred_configuration_rad) or "mid-range"} with weight '
                     f'{shaping.posture_weight:g} (a redundant arm)')
    if shaping.learning_on:
        parts.append(f'learning up to {list(shaping.friction_learning_limit_nm)} N m more at '
                     f'rest in {shaping.friction_learning_time_s:g} s')
    return '; '.join(parts) if parts else "off (the paper's law)"

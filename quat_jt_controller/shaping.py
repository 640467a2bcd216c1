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
* The settling damping (section 11): ``-psi(y_tilde) alpha M(q) qdot`` near the goal
  (:func:`settling_fade`), which damps the arm's coupled modes; computed in the regulator.
* The large-error term of ``U_a`` (section 3): ``k_L B(||e||)`` with
  ``B'(s) = s^2 / sqrt(1 + delta^2 - s^2)``, so that ``Q^T grad`` keeps its size up to a few
  degrees from 180 degrees instead of fading like ``eta_e``; computed in ``control_law``.
* Damping towards a streamed goal's velocity (section 7): the joint damping acts on
  ``qdot - g_v qdot*_d`` instead of ``qdot``, ``qdot*_d`` the velocity of the goal
  configuration (from the goal-check worker: the stream's task velocity mapped through
  J(q*), never an inverse in the tick), ``g_v`` in [0, 1]. Zero for a fixed goal.
* ``tau_fc``, Coulomb friction compensation (section 4): per joint
  ``phi(y_tilde) t_p [(f_j + r_j a_j) max(0, t_v t_p) + (f_j + a_j) (1 - |t_v|)]`` (``r_j``
  the fade of the learned part along a motion faster than a creep speed), ``t_p = tanh(tau_p,j /
  (0.001 (f_j + a_max,j)))`` the direction of the potential torque ``tau_p``, ``t_v =
  tanh(qdot_j / v_eps)``: at rest and while the joint moves the way the potential pushes it,
  ``f_j + a_j`` that way (the learned ``a_j`` fading out above a creep speed); a joint moving
  against it (an overshoot) is left to its friction.
  All of it fades to zero inside a small error band (``phi``), so an estimate above the true
  friction cannot feed a limit cycle at the goal. Its size never
  exceeds ``f_j + a_j``, which is what keeps dV/dt <= -qdot^T K_v qdot against a Coulomb
  friction of at least that. ``a_j`` in ``[0, a_max,j]`` is the learned part of the estimate
  (:func:`learn_friction`): it grows while the joint stays held, or creeps slower than its
  creep speed, outside the error band with the push not taken by its damping (held by a
  friction, not slowed by its damping), until the compensation moves the joint at that speed
  (past the breakaway, on purpose); it leaks away where the damping takes the push and inside
  the band.

All are off by default (:class:`Shaping` ()), which gives the paper's law exactly. Plain
floats: the functions here run in the 1 kHz tick.
"""
from dataclasses import dataclass, fields
from functools import cached_property
from math import isfinite, pi, sqrt, tanh
from typing import Any, Mapping, Optional, Sequence

import numpy as np

from quat_jt_controller import parameter_table as table
from quat_jt_runtime.errors import QuatJtError
from quat_jt_runtime.param_table import check_all, names

# A joint whose URDF range is at least this long turns freely: it gets no limit term.
FULL_TURN_RAD = 2.0 * pi - 1e-6
# A goal configuration less than this deep in a joint-limit band counts as out of it: the goal
# check's posture cost holds a joint it pulls against a band's wall that little inside
# (inverse_kinematics.posture)
BAND_DEPTH_TOLERANCE_RAD = 1e-3
# t_p = tanh(tau_p / (TORQUE_BAND_FRACTION f)): the breakaway reaches 76% of f when the
# potential torque is 0.1% of f, and changes sign smoothly (C-infinity) through tau_p = 0.
TORQUE_BAND_FRACTION = 0.001
# The learning goes on while a joint held by a friction slides slower than this x v_eps, the
# creep speed, weakening linearly up to it (docs/lyapunov.md, section 4)
CREEP_SPEED_FACTOR = 2.0
# The learned push along the motion fades out linearly from the creep speed to this x v_eps
FADE_SPEED_FACTOR = 8.0
# With a goal configuration q* (the regulator), a joint's creep speed is |q - q*| x this (1/s),
# at least the above and at most this share of its velocity limit, and its fade speed that
# plus the width above, at most FADE_TOP_FRACTION of the limit: a joint far from q* creeps to
# it with the time constant 1 / CREEP_GAIN instead of at a fixed crawl (docs/reach.md, "The
# creep's time constant", says why 1/16 s)
CREEP_GAIN = 16.0
CREEP_TOP_FRACTION = 0.4
FADE_TOP_FRACTION = 0.6
# ... and lower where the push learned on a joint is large for the inertia it sees: so low
# that the push, acting 1 + FADE_DELAY_TICKS ticks before the fade sees the speed it gave,
# stays within the limit (fade_tops), but at least this share of the limit, the creep's top
# in proportion (docs/lyapunov.md, section 4)
FADE_FLOOR_FRACTION = 0.2
FADE_DELAY_TICKS = 1  # the nodes' loop acts on a state one tick old
# The learning low-passes how held a joint is with this fraction of the learning time, and
# learns only once the filtered value is above 1/2 (learn_friction).
HOLD_TIME_FRACTION = 0.2
# ... where a joint slower than this share of its creep speed counts as fully held, one
# between it and the creep speed the less the faster (so a steady creep below the creep speed
# keeps learning; only a turning point's short stop is too brief to count)
HELD_SPEED_SHARE = 0.75
# The share of a sliding joint's push a friction takes, low-passed as how held a joint is,
# from which the friction it meets counts for the learning, and from which it counts whole
# (learn_friction): a swing's short phases, where the acceleration estimate lags, do not
SLIDING_SHARE_FROM = 0.25
SLIDING_SHARE_FULL = 0.5
# The learning's estimate of a joint's acceleration: its velocity minus the velocity's
# low-pass of this time constant, over it (s; Regulator.update)
ACCELERATION_TIME_S = 0.02
# Above this share of its URDF velocity limit a joint's damping rises to the most the sampled
# loop tolerates (the speed guard, with the inertial damping; docs/lyapunov.md, section 6)
SPEED_GUARD_FRACTION = 0.8
# ... and towards a stop, above this share of beta x the room left before the stop's clearance:
# with the guard's damping the approach x'' = -beta x' - s beta^2 x is critically damped at
# s = 1/4, so it comes to rest short of the clearance (docs/lyapunov.md, section 6)
STOP_GUARD_SHARE = 0.25
STOP_CLEARANCE_SHARE = 0.25  # of the joint-limit margin: the room the stop guard keeps
# A joint whose potential torque asks less than what the goal-configuration term's stiffness
# gives at this distance from its rest (rad) learns the slower the less it asks: it sits at its
# own equilibrium, not held away from it by a friction (learn_friction)
LEARNING_ANGLE_RAD = 3e-3
# The cubic damping turns linear above the URDF velocity limit, or above this without one.
DEFAULT_SPEED_CAP_RAD_S = 2.0 * pi
# A URDF velocity limit above this is taken for a placeholder (iCub's and Alex's 100 rad/s,
# Solo's 1000, the hextilt arm's 10,000; the G1's 37 is real): design_gains warns of it, and
# the goal check counts the joint's travel as for a joint without a limit
PLAUSIBLE_SPEED_RAD_S = 60.0


class ShapingError(QuatJtError):
    """An invalid extension parameter; the message names the parameter and the value."""


_default = table.shaping_default  # a field's default is its row's


@dataclass(frozen=True)
class Shaping:
    """
    The extensions, validated and immutable: a snapshot of their own beside the Gains.

    Units: ``joint_limit_margin_rad`` rad (band width inside each limit), ``joint_limit_gain``
    N m/rad per joint (stiffness in the band; 0 = no limit term for that joint),
    ``large_error_gain`` N m (``k_L``; 0 = off), ``friction_compensation_nm`` N m per joint
    (Coulomb estimates; 0 = off), ``friction_velocity_rad_s`` rad/s (``v_eps``),
    ``friction_error_band`` (``||e||`` below which the breakaway fades out) and
    ``friction_position_band_m`` m (the same for ``||p_d - p||``, pose and position tasks).
    ``configuration_gain`` N m per joint (``T_j``, the most the goal-configuration term asks
    of joint j; 0 = off) and ``configuration_radius_rad`` rad (its dead zone, also the width of
    its ramp). Empty per-joint tuples mean zeros. The rules and the defaults are the rows of
    ``parameter_table.SHAPING`` (each row's ``field`` names its attribute).
    """

    joint_limit_margin_rad: float = _default('joint_limit_margin')
    joint_limit_gain: tuple[float, ...] = ()
    large_error_gain: float = _default('large_error_gain')
    friction_compensation_nm: tuple[float, ...] = ()
    friction_velocity_rad_s: float = _default('friction_velocity')
    friction_error_band: float = _default('friction_error_band')
    friction_position_band_m: float = _default('friction_position_band')
    configuration_gain: tuple[float, ...] = ()
    configuration_radius_rad: float = _default('configuration_radius')
    configuration_ramp_rad: float = _default('configuration_ramp')
    damping_speed_rad_s: tuple[float, ...] = ()
    # c_j and beta (1/s): the damping of joint j is max(k_v,j, min(c_j sqrt(M_jj(q)),
    # beta I_j(q))) (docs/lyapunov.md, section 10; empty or zeros: k_v alone)
    inertial_damping: tuple[float, ...] = ()
    inertial_damping_rate_per_s: float = _default('inertial_damping_rate')
    # alpha (1/s): -psi alpha M(q) qdot near the goal (docs/lyapunov.md, section 11; 0 = off)
    settling_damping_rate_per_s: float = _default('settling_damping_rate')
    # per joint, the most rotor inertia beyond the armature told that the regulator may add to
    # M(q) from the motion (kg m^2; armature_estimate.py; 0 = not estimated)
    armature_estimation_limit_kg_m2: tuple[float, ...] = ()
    # design the gains again for the rotor inertia found (redesign.py; not read by the tick)
    gain_redesign: bool = _default('gain_redesign')
    # g_v: the joint damping acts on qdot - g_v qdot*_d of a streamed goal; 0 = off
    goal_velocity_gain: float = _default('goal_velocity_gain')
    # a_max per joint, N m: the most the friction estimate may learn at rest (0 = no learning)
    friction_learning_limit_nm: tuple[float, ...] = ()
    # s: a_max is learned in this time while stuck, and leaks with it inside the band
    friction_learning_time_s: float = _default('friction_learning_time')
    # the goal check's choice of q* along a redundant arm's self-motion
    # (inverse_kinematics.posture):
    # nearest the measured q, then this posture (rad per joint; empty: the middle of the
    # ranges) with this weight. Not read by the tick.
    preferred_configuration_rad: tuple[float, ...] = ()
    posture_weight: float = _default('posture_weight')

    @classmethod
    def create(cls, n_joints: int, **values: Any) -> 'Shaping':
        """
        Validate and build from values keyed by parameter name; raise ShapingError naming one.

        Every row of ``parameter_table.SHAPING`` is checked by its rules (range, finiteness,
        one value per joint), the node's own: a name not given (or None) takes its row's
        default. An empty ``preferred_configuration`` means the middle of the ranges.
        """
        rows = table.SHAPING
        checked = check_all(rows, values, table.shaping_context(n_joints), ShapingError)
        attributes = {f.name for f in fields(cls)}
        return cls(**{spec.attribute: checked[spec.name] for spec in rows
                      if spec.attribute in attributes})

    def check_size(self, n_joints: int) -> 'Shaping':
        """Return self if the per-joint vectors fit ``n_joints`` (or are empty); else raise."""
        for spec in table.SHAPING:
            values = getattr(self, spec.attribute, ())
            if spec.size == 'n' and values and len(values) != n_joints:
                raise ShapingError(f'{spec.name} must have {n_joints} values (one per joint), '
                                   f'got {len(values)}')
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
    def armature_estimation_on(self) -> bool:
        """Return True if some joint's rotor inertia is estimated from the motion."""
        return any(a > 0.0 for a in self.armature_estimation_limit_kg_m2)

    @cached_property  # read every tick: computed once per snapshot
    def friction_table(self) -> tuple[tuple[float, float, float], ...]:
        """Return per joint ``(f, a_max, 0.001 (f + a_max))``: estimate, learnable, scale."""
        n = max(len(self.friction_compensation_nm), len(self.friction_learning_limit_nm))
        f = self.friction_compensation_nm or (0.0,) * n
        a = self.friction_learning_limit_nm or (0.0,) * n
        return tuple((fj, aj, TORQUE_BAND_FRACTION * (fj + aj)) for fj, aj in zip(f, a))

    @cached_property  # read every tick: computed once per snapshot
    def learning_torque_band(self) -> tuple[float, ...]:
        """
        Return per joint ``LEARNING_ANGLE_RAD T_j / w`` (N m; 0 without the term).

        What the goal-configuration term's ramp asks at that distance from ``q*``: a joint
        whose potential torque is well below it is at its own equilibrium.
        """
        w = self.configuration_ramp_rad
        return tuple(LEARNING_ANGLE_RAD * t / w for t in self.configuration_gain)

    @cached_property  # read every tick: computed once per snapshot
    def speed_damping_on(self) -> bool:
        """Return True if some joint has the cubic damping term."""
        return any(v > 0.0 for v in self.damping_speed_rad_s)

    @cached_property  # read every tick: computed once per snapshot
    def inertial_damping_on(self) -> bool:
        """Return True if some joint's damping grows with the inertia it sees."""
        return any(c > 0.0 for c in self.inertial_damping)

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


def fade(y_tilde: Sequence[float], shaping: Shaping, position_only: bool = False) -> float:
    """
    phi(y_tilde): 1 outside the error band, 0 well inside it, C1 in between.

    ``r = max(||e|| / friction_error_band, ||p_d - p|| / friction_position_band)``; phi is 0
    for r <= 1/2, 1 for r >= 1 and the cubic smoothstep in between. ``position_only``:
    ``y_tilde`` is p_d - p alone (the position task), with no e, so r is its position part.
    """
    if position_only:
        r = sqrt(y_tilde[0] ** 2 + y_tilde[1] ** 2 + y_tilde[2] ** 2)
        r /= shaping.friction_position_band_m
    else:
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


def settling_fade(y_tilde: Sequence[float], lam: Sequence[float]) -> float:
    """
    psi(y_tilde) of the settling damping: 1 near the goal, 0 far from it, smooth in between.

    ``r = max_i |lambda_i y_i|`` over the task rows (Eq. 31's argument of tanh); psi is 1 for
    ``r <= 1`` (every row within the linear range of its tanh, where the loop's linearisation
    at the goal holds), 0 for ``r >= 2`` and the cubic smoothstep in between (docs/lyapunov.md,
    section 11). C1 in ``r``; in ``y_tilde`` Lipschitz (through the max and abs).
    """
    r = 0.0
    for y, k in zip(y_tilde, lam):
        x = abs(y * k)
        if x > r:
            r = x
    x = 2.0 - r
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


def friction_compensation(tau_potential: Sequence[float], qdot: Sequence[float], phi: float,
                          shaping: Shaping, learned_nm: Optional[Sequence[float]] = None,
                          stuck_out: Optional[list[float]] = None,
                          damping_nm: Optional[Sequence[float]] = None,
                          unmet_out: Optional[list[float]] = None,
                          creep_rad_s: Optional[Sequence[float]] = None,
                          fade_rad_s: Optional[Sequence[float]] = None,
                          inertial_nm: Optional[Sequence[float]] = None,
                          equilibrium_band_nm: Optional[Sequence[float]] = None,
                          sliding_out: Optional[list[float]] = None) -> list[float]:
    """
    tau_fc per joint: phi t_p [(f + r a) max(0, t_v t_p) + (f + a) (1 - |t_v|)], |.| <= f + a.

    ``t_p = tanh(tau_p / (0.001 (f + a_max)))`` is the direction of the potential torque
    ``tau_potential``, ``t_v = tanh(qdot / v_eps)``. At rest it pushes with ``f + a`` in the
    direction of the potential (breakaway); a joint moving that way keeps the push (the
    friction of a moving joint compensated); a joint moving against it (past the goal) gets
    no push along its motion, only ``(1 - |t_v|)`` towards the potential, so the friction
    brakes the overshoot. So the compensation does positive work only while the potential
    does. ``phi`` (:func:`fade`) turns all of it off near the goal. ``learned_nm`` is ``a``,
    the part of the estimate learned at rest (:func:`learn_friction`; None = zeros).

    The learned ``a`` along the motion is scaled by a ramp of the speed along the push: 1 up
    to the creep speed, 0 from the fade speed on (``creep_rad_s``, ``fade_rad_s`` per joint;
    None: ``CREEP_SPEED_FACTOR v_eps`` and ``FADE_SPEED_FACTOR v_eps``). So a learned push
    that no friction takes drives the joint no faster than the fade speed, however large it
    is; the estimate ``f``, which the user measured, is not faded.

    For the learning, ``unmet_out``, if given, receives per joint the share of the push
    ``u = tau_p + tau_fc`` that the damping torque ``damping_nm`` (the joint damping terms of
    the law, ``-K_v qdot`` and the rest) does not take: ``w = max(0, 1 - |d| / |u|)``, and
    with ``inertial_nm`` (``M(q) qddot``, the torque the joints' acceleration took) neither
    the damping nor the acceleration: ``w = min(1, max(0, 1 - (|d| + sgn(u) (M qddot)_j) /
    |u|))``. In a joint that the push moves freely against its damping (a slow approach) or
    accelerates (a swing) ``w`` is near 0; in one held by stiction it is 1 (no damping, no
    acceleration at rest); one moving against the push gets ``slow w`` (it is not held); with
    ``damping_nm`` None, ``w`` is 1. ``stuck_out``, if
    given, receives ``slow |t_p| w`` (how stuck, pushed and unmoved by the push each joint
    is), ``slow = max(0, 1 - |qdot| / creep)``: a joint creeping slower than its creep speed
    still counts, the less the nearer it is to it; with ``equilibrium_band_nm`` (the
    regulator passes :attr:`Shaping.learning_torque_band` once ``q*`` is known and the
    goal-configuration term pulls), times ``tanh(|tau_p| / b)`` (a joint at its own
    equilibrium is not held away from it). ``sliding_out``, if given (with ``damping_nm``),
    receives per joint the friction a joint sliding along its push, slower than its creep
    speed, meets beyond the estimate: ``max(0, w |u| - f) max(0, t_v t_p) min(1, 4 slow)``
    (N m; 0 at rest, against the push and from the creep speed on), with the same ``tanh``
    factor; :func:`learn_friction` keeps ``a`` up to it. All are left alone when ``phi`` is
    0.
    """
    out = [0.0] * len(qdot)
    if phi <= 0.0:
        return out
    v_eps = shaping.friction_velocity_rad_s
    v_creep = CREEP_SPEED_FACTOR * v_eps
    v_fade = FADE_SPEED_FACTOR * v_eps
    band = (equilibrium_band_nm if (stuck_out is not None or sliding_out is not None)
            and equilibrium_band_nm else ())
    for j, (f, _, scale) in enumerate(shaping.friction_table):
        if scale <= 0.0:  # no estimate and nothing to learn
            continue
        v = qdot[j]
        tv = tanh(v / v_eps)
        tp = tanh(tau_potential[j] / scale)
        rest = 1.0 - abs(tv)
        along = tv * tp
        if along < 0.0:
            along = 0.0
        size = f * (along + rest)
        if creep_rad_s is not None:
            v_creep = creep_rad_s[j]
            v_fade = fade_rad_s[j]
        if learned_nm is not None and learned_nm[j] > 0.0:
            speed = v if tp > 0.0 else -v  # along the push
            if speed <= v_creep:
                size += learned_nm[j] * (along + rest)
            elif speed < v_fade:
                size += learned_nm[j] * (along * (v_fade - speed) / (v_fade - v_creep) + rest)
            else:
                size += learned_nm[j] * rest
        out[j] = phi * size * tp
        if stuck_out is not None or unmet_out is not None or sliding_out is not None:
            slow = 1.0 - abs(v) / v_creep
            if slow < 0.0:
                slow = 0.0
            w = 1.0
            if sliding_out is not None:
                sliding_out[j] = 0.0
            if damping_nm is not None:
                signed = tau_potential[j] + out[j]
                push = abs(signed)
                left = push - abs(damping_nm[j])
                if inertial_nm is not None:  # what the acceleration took, along the push
                    left -= inertial_nm[j] if signed > 0.0 else -inertial_nm[j]
                w = left / push if left > 0.0 and push > 0.0 else 0.0
                if w > 1.0:  # decelerated against the push by more than the damping
                    w = 1.0
                if qdot[j] * signed < 0.0:  # moving against the push: it is not held
                    w *= slow
                if sliding_out is not None:  # what a friction takes of a sliding joint's
                    met = w * push - f  # push, up to 3/4 of its creep speed, less up to it
                    if met > 0.0 and slow > 0.0:
                        short = slow / (1.0 - HELD_SPEED_SHARE)
                        sliding_out[j] = met * along * (short if short < 1.0 else 1.0)
            equilibrium = (tanh(abs(tau_potential[j]) / band[j]) if band and band[j] > 0.0
                           else 1.0)  # at its own equilibrium: not held away from it
            if stuck_out is not None:
                stuck_out[j] = slow * abs(tp) * w * equilibrium
            if sliding_out is not None and equilibrium < 1.0:
                sliding_out[j] *= equilibrium
            if unmet_out is not None:
                unmet_out[j] = w
    return out


def creep_speeds(q: Sequence[float], q_star: Optional[Sequence[float]], shaping: Shaping,
                 creep_top: Sequence[float], fade_top: Sequence[float],
                 creep_out: list[float], fade_out: list[float]) -> None:
    """
    Fill each joint's creep and fade speeds (rad/s) for :func:`friction_compensation`.

    The creep speed is ``CREEP_GAIN |q - q*|`` (0 with no ``q*``), at least
    ``CREEP_SPEED_FACTOR v_eps`` and at most ``creep_top`` (at most ``CREEP_TOP_FRACTION`` of
    the velocity limit, lower where :func:`fade_tops` lowers it: then it may be below
    ``CREEP_SPEED_FACTOR v_eps``); the fade speed is ``(FADE_SPEED_FACTOR -
    CREEP_SPEED_FACTOR) v_eps`` above it, at most ``fade_top`` (at most ``FADE_TOP_FRACTION``
    of the limit, above the creep's top).
    """
    v_eps = shaping.friction_velocity_rad_s
    v0 = CREEP_SPEED_FACTOR * v_eps
    extra = (FADE_SPEED_FACTOR - CREEP_SPEED_FACTOR) * v_eps
    for j in range(len(creep_out)):
        v = 0.0 if q_star is None else abs(q[j] - q_star[j]) * CREEP_GAIN
        c = v0 if v < v0 else v
        top = creep_top[j]
        c = c if c < top else top
        creep_out[j] = c
        top = fade_top[j]
        fade_out[j] = c + extra if c + extra < top else top


def fade_tops(learned_nm: Sequence[float], seen_inertia: Sequence[float], tick_s: float,
              speed_cap_rad_s: Sequence[float], creep_top_out: list[float],
              fade_top_out: list[float]) -> None:
    """
    Fill each joint's tops of the creep and fade speeds (rad/s) for :func:`creep_speeds`.

    The fade top is ``v_lim - (1 + FADE_DELAY_TICKS) a_j dt / I_j``: from it, the learned
    push ``a_j`` on the inertia the joint sees (``I_j = 1 / (M(q)^-1)_jj``), with nothing to
    take it, acting for a tick and for the tick of delay before the fade sees the speed it
    gave, lands at the limit ``v_lim`` (``speed_cap_rad_s``). It is at most
    ``FADE_TOP_FRACTION`` and at least ``FADE_FLOOR_FRACTION`` of the limit (the floor, not
    the bound, where ``a_j`` is larger than ``design_gains`` lets it be, or ``I_j`` is not
    positive and finite); the creep's top is ``CREEP_TOP_FRACTION / FADE_TOP_FRACTION`` of it.
    ``tick_s`` is the ``dt`` it assumes: the regulator passes the longest recent time between
    states (``Regulator.update``), so a burst of close states does not raise the tops. A joint
    that has learned little keeps the tops at their largest; one that has learned much for its
    inertia creeps and is pushed more slowly (docs/lyapunov.md, section 4).
    """
    share = CREEP_TOP_FRACTION / FADE_TOP_FRACTION
    ticks = 1.0 + FADE_DELAY_TICKS
    for j in range(len(fade_top_out)):
        v_lim = speed_cap_rad_s[j]
        floor = FADE_FLOOR_FRACTION * v_lim
        top = FADE_TOP_FRACTION * v_lim
        inertia = seen_inertia[j]
        if inertia > 0.0 and isfinite(inertia):
            room = v_lim - ticks * learned_nm[j] * tick_s / inertia
            top = top if room > top else room
        else:  # no inertia to bound it by: the least
            top = floor
        top = top if top > floor else floor
        fade_top_out[j] = top
        creep_top_out[j] = share * top


def learn_friction(learned_nm: list[float], stuck: Sequence[float], phi: float,
                   shaping: Shaping, dt_s: float,
                   unmet: Optional[Sequence[float]] = None,
                   held: Optional[list[float]] = None,
                   sliding: Optional[Sequence[float]] = None,
                   slid: Optional[list[float]] = None) -> None:
    """
    Advance ``a``, the learned part of the friction estimate, by one tick of ``dt_s``, in place.

    ``da/dt = (a_max / T) phi s - [(1 - phi) + phi (1 - w)^2 / c] a / T`` (``T`` the learning
    time, ``c = HOLD_TIME_FRACTION``), clipped to ``[0, a_max]``. ``stuck`` (``slow |t_p| w``,
    ``slow = max(0, 1 - |qdot| / v_cr)``) and ``unmet`` (``w``) are per joint as
    :func:`friction_compensation` gave them this tick (unread when ``phi`` is 0; ``unmet``
    None: ``w`` = 1). ``held``, if given, is ``h`` per joint, advanced here in place: how held
    the joint is, ``min(w, stuck / (1 - HELD_SPEED_SHARE))`` (``w`` up to 3/4 of the creep
    speed with ``|t_p|`` = 1, less up to it), low-passed with the time constant ``c T``;
    ``s`` is ``stuck`` times a ramp of ``h`` from 0 at ``h = 1/2`` to 1 at ``3/4``, so a
    joint must stay held for a while (about ``0.7 c T``) before anything is learned, which the
    turning point of a swing does not, and learns less as it nears its creep speed.
    Without ``held``, ``s`` is ``stuck``.

    ``sliding`` (N m per joint, :func:`friction_compensation`'s ``sliding_out``) is the
    friction a joint sliding along its push meets beyond the estimate, ``m``; ``slid`` (per
    joint, in place, with ``sliding``) is ``g``, the share ``w`` of a sliding joint's push a
    friction takes (0 where ``m`` is 0), low-passed as ``h`` is. ``a`` is pulled up to
    ``m_s = r_s(g) min(m, a_max)`` in ``c T`` (times ``phi``), and the leak where the damping
    takes the push acts only on what ``a`` has above ``m_s``; ``r_s`` rises from 0 at ``g =
    SLIDING_SHARE_FROM`` to 1 at ``SLIDING_SHARE_FULL``. So a joint that a friction slows,
    sliding, learns it until it slides at its creep speed (``m`` is 0 from there on), where
    before it kept a share of it that left it crawling; a swing's short phases, where the
    acceleration estimate lags the joint and ``w`` is briefly wrong, do not count.

    So ``a`` grows only while a joint stays at rest or creeps, pushed and not moved by the push
    against its damping, outside the error band (``phi`` > 0): while the compensation does not
    yet move it at its creep speed against the friction that holds it. It holds while a
    friction takes the push of a moving joint (``w`` ~ 1), leaks in
    ``c T`` while the damping takes it (``w`` ~ 0: nothing to compensate), the slower the
    more of the push a friction takes, and in ``T`` within the band (docs/lyapunov.md,
    section 4).
    """
    rate = dt_s / shaping.friction_learning_time_s
    hold_rate = rate / HOLD_TIME_FRACTION
    if hold_rate > 1.0:
        hold_rate = 1.0
    for j, (_, a_max, _) in enumerate(shaping.friction_table):
        if a_max <= 0.0:
            continue
        a = learned_nm[j]
        if phi > 0.0:
            s = stuck[j]
            if held is not None:
                x = s / (1.0 - HELD_SPEED_SHARE)  # held: w up to 3/4 of the creep speed
                if unmet is not None and unmet[j] < x:
                    x = unmet[j]
                elif x > 1.0:
                    x = 1.0
                h = held[j] + hold_rate * (x - held[j])
                held[j] = h
                if h < 0.75:  # not stuck for long enough: s = 0 below h = 1/2
                    s = s * (4.0 * h - 2.0) if h > 0.5 else 0.0
            m = 0.0  # the friction met, sliding, as far as it counts
            if sliding is not None and slid is not None:
                x = unmet[j] if unmet is not None and sliding[j] > 0.0 else 0.0
                g = slid[j] + hold_rate * (x - slid[j])
                slid[j] = g
                if g > SLIDING_SHARE_FROM:
                    m = sliding[j] if sliding[j] < a_max else a_max
                    if g < SLIDING_SHARE_FULL:
                        m *= (g - SLIDING_SHARE_FROM) / (SLIDING_SHARE_FULL - SLIDING_SHARE_FROM)
            # leaks in T within the band, in HOLD_TIME_FRACTION T where the damping takes the
            # push (there down to the friction met)
            leak = (1.0 - phi) * a
            if unmet is not None:
                taken = 1.0 - unmet[j]
                leak += phi * taken * taken / HOLD_TIME_FRACTION * (a - m if a > m else 0.0)
            a += rate * (a_max * phi * s - leak)
            if m > a:  # up to the friction a sliding joint meets, in c T
                a += hold_rate * phi * (m - a)
        else:
            if held is not None:
                held[j] -= hold_rate * held[j]
            if slid is not None:
                slid[j] -= hold_rate * slid[j]
            a -= rate * a
        learned_nm[j] = a_max if a > a_max else (a if a > 0.0 else 0.0)


def add_configuration_torque(q: Sequence[float], q_star: Sequence[float], shaping: Shaping,
                             tau: list[float], shares: Optional[Sequence[float]] = None
                             ) -> None:
    """
    Add -grad (sum_j s_j U_c,j)(q) to ``tau`` in place (docs/lyapunov.md, section 5).

    Per joint, ``x = max(0, |q - q*| - r)``; the torque is ``-sign(q - q*) T min(x / w, 1)``
    (``r`` the radius, ``w`` the ramp), times the joint's share ``s_j`` (in [0, 1]: the term
    fading in; all 1 if None).
    """
    r = shaping.configuration_radius_rad
    w = shaping.configuration_ramp_rad
    for j, t in enumerate(shaping.configuration_gain):
        if t <= 0.0:
            continue
        if shares is not None:
            t *= shares[j]
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


def from_parameters(values: Mapping[str, Any], n_joints: int) -> Shaping:
    """
    Build a Shaping from controller parameters keyed by their ROS names (a config file's).

    The names that are no extension parameter are left to the others. Missing names keep their
    defaults (off). Raises ShapingError naming a bad value.
    """
    extensions = set(names(table.SHAPING))
    return Shaping.create(n_joints, **{k: v for k, v in values.items() if k in extensions})


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
    if shaping.inertial_damping_on:
        parts.append(f'damping at least min(c sqrt(M_jj(q)), beta I_j(q)), c '
                     f'{list(shaping.inertial_damping)}, beta '
                     f'{shaping.inertial_damping_rate_per_s:g} 1/s')
    if shaping.settling_damping_rate_per_s > 0.0:
        parts.append(f'settling damping {shaping.settling_damping_rate_per_s:g} M(q) qdot near '
                     f'the goal')
    if shaping.armature_estimation_on:
        parts.append(f'rotor inertia found from the motion, up to '
                     f'{list(shaping.armature_estimation_limit_kg_m2)} kg m^2, in M(q)')
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
                     f'rest or creeping in {shaping.friction_learning_time_s:g} s')
    return '; '.join(parts) if parts else "off (the paper's law)"


def fast_damping_modes(minv: Sequence[Sequence[float]], damping: Sequence[float],
                       beta: float) -> Optional[list[tuple[float, list[float]]]]:
    """
    Return the modes of ``M(q)^-1 D`` faster than ``beta`` and how much of each to take away.

    ``D = diag(damping)`` is the inertial damping of docs/lyapunov.md, section 10. Each
    entry of ``M^-1 D`` on its diagonal is at most ``beta``, but ``M(q)`` couples the joints
    and a mode can be faster: the sampled, delayed loop rings on it (docs/reach.md, "the
    modes of the damping"). ``A = D^(1/2) M^-1 D^(1/2)`` has the rates of ``M^-1 D`` as its
    eigenvalues; for each eigenpair ``(w, u)`` with ``w > beta``, ``y = D^(1/2) u``, the
    damping ``D - sum (1 - beta / w) y y^T`` has the same modes, each at ``min(w, beta)``:
    still positive definite, so still a dissipation. Returns ``[(1 - beta / w, y)]``, or None
    when the row sums of ``|A|`` (Gershgorin) already keep every mode within ``beta``, as on
    an arm whose joints are weakly coupled: no eigenvalue problem then. None too where
    ``M^-1`` or the damping is not finite (a singular ``M(q)``): the tick's finite check then
    decides, never an exception here. The tick (Regulator.update) and the design's model of
    it (gain_analysis.damping_matrix) both call it.
    """
    n = len(damping)
    root = [sqrt(d) for d in damping]
    for j in range(n):
        row = minv[j]
        total = 0.0
        for k in range(n):
            m = row[k]
            total += root[k] * (m if m > 0.0 else -m)
        total *= root[j]  # the row sum of |A|
        if not isfinite(total):
            return None
        if total > beta:
            break
    else:
        return None
    r = np.array(root)
    a = r[:, None] * np.array(minv) * r
    if not np.isfinite(a).all():
        return None
    try:
        w, u = np.linalg.eigh(a)
    except np.linalg.LinAlgError:  # no convergence: keep the diagonal damping this tick
        return None
    out = []
    for i in range(n - 1, -1, -1):  # eigh sorts them ascending
        if w[i] <= beta:
            break
        out.append((1.0 - beta / float(w[i]), (r * u[:, i]).tolist()))
    return out or None

"""
The control tick, written once: joint state in, clamped joint torque out (Eq. 22).

    tau = J^T Q(eta_e, e)^T grad U_a(y_tilde) - K_v qdot + g(q),  clamped to the effort limits

With the extensions (the :class:`~quat_jt_controller.shaping.Shaping` snapshot, ``shaping.py``,
docs/lyapunov.md) it is

    tau = J^T Q^T grad U_a - grad U_lim(q) - K_v(q) qdot - psi alpha M(q) qdot + g(q) + tau_fc,
    clamped

(``K_v(q)``: ``K_v`` with its cubic part and, per joint, at least ``min(c_j sqrt(M_jj(q)),
beta I_j(q))``, each mode of ``M(q)^-1 K_v(q)`` faster than ``beta`` brought down to it,
docs/lyapunov.md, section 10; ``psi alpha M(q)``: the settling damping near the goal,
section 11.)

:class:`Regulator` owns the robot model, the task, the effort limits and immutable snapshots of
the gains (:class:`~quat_jt_controller.control_law.Gains`) and of the goal (:class:`Goal`).
:meth:`Regulator.update` is the tick: kinematics, output error (Eqs. 8-10), the law of the
chosen potential (Eq. 24/32, orientation task Eq. 37/38, position task the position rows of
Eq. 24/32), gravity, the finite check and the
clamp. The controller node, the reference and sampled loops, the benchmark and the tests all
call it, so what is simulated and timed is what ships. ROS-free, and numpy-free in the tick
but where a mode of the damping is capped (an eigenvalue problem of the joints' size).

A parameter or goal change builds a new immutable object and swaps one reference; a tick reads
each reference once, so it never sees half an update.
"""
from dataclasses import dataclass
from math import inf, isfinite, sqrt
from typing import NamedTuple, Optional, Sequence

from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.armature_estimate import ArmatureEstimator
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_runtime.payload import Payload

Vector3 = tuple[float, float, float]
MAX_LEARNING_STEP_S = 0.01  # a longer gap between ticks advances the friction learning by this
# The period the fade tops assume (shaping.fade_tops) is the longest recent time step (at most
# the above), kept x this per tick: a burst of close states does not shorten it at once
TICK_MEMORY = 0.999
# A q* far from the last one (a step of up to T_j on every joint), or a T_j raised live (from
# the term in force), fades in over this, so that a heavy joint's step does not jolt a light
# one past its velocity limit through the coupling of M(q) before the damping sees the motion,
# nor the heavy joints' rise to their cruise carry it there (docs/lyapunov.md, section 5)
CONFIGURATION_FADE_IN_S = 0.25


@dataclass(frozen=True)
class Goal:
    """
    A constant desired pose (p_d, R_d) in the base frame, Eq. (2)-(3).

    ``q_desired_base`` is the unit quaternion (eta_d, eps_d) of R_d, scalar first (Eq. 6);
    ``p_desired_base`` the tip position in m (Eq. 9), ignored by the orientation task. The
    position task ignores the quaternion (:meth:`at_position` sets the identity).
    """

    q_desired_base: quat.Quaternion
    p_desired_base: Vector3 = (0.0, 0.0, 0.0)

    @classmethod
    def from_xyzw(cls, x: float, y: float, z: float, w: float,
                  p_desired_base: Sequence[float] = (0.0, 0.0, 0.0)) -> 'Goal':
        """
        Validate a goal given in ROS order; raise ValueError saying what is wrong.

        The quaternion is checked as tf2 does (finite, |norm^2 - 1| <= 0.01) and normalised;
        the position must be finite.
        """
        xyzw = (x, y, z, w)
        if not all(isfinite(c) for c in xyzw):
            raise ValueError(f'quaternion (x, y, z, w) = {xyzw} has a non-finite component')
        try:
            q = quat.validate_unit(quat.from_xyzw(x, y, z, w))
        except ValueError as exc:
            raise ValueError(f'{exc}: (x, y, z, w) = {xyzw}') from None
        p = (float(p_desired_base[0]), float(p_desired_base[1]), float(p_desired_base[2]))
        if not all(isfinite(c) for c in p):
            raise ValueError(f'non-finite position {p}')
        return cls(q, p)

    @classmethod
    def at_position(cls, p_desired_base: Sequence[float]) -> 'Goal':
        """
        Validate a position goal (the position task); raise ValueError if it is not finite.

        The orientation is not part of the goal: the quaternion is the identity, unread.
        """
        p = tuple(float(c) for c in p_desired_base)
        if len(p) != 3 or not all(isfinite(c) for c in p):
            raise ValueError(f'position {p} must be 3 finite values')
        return cls((1.0, 0.0, 0.0, 0.0), p)

    def describe(self, with_position: bool = True, with_orientation: bool = True) -> str:
        """Return the goal for a log line, in ROS order, rounded (the parts the task reads)."""
        parts = []
        if with_orientation:
            parts.append(f'quaternion (x, y, z, w) {tuple(round(c, 4) for c in self.xyzw())}')
        if with_position:
            parts.append(f'position {tuple(round(c, 4) for c in self.p_desired_base)} m')
        return ', '.join(parts)

    def xyzw(self) -> tuple[float, float, float, float]:
        """Return the quaternion in ROS order (x, y, z, w)."""
        return quat.to_xyzw(self.q_desired_base)


class TickOutput(NamedTuple):
    """What one tick gives: the command and what feedback and diagnostics need."""

    tau_nm: list[float]  # clamped to the effort limits; zeros if the law was not finite
    y_tilde: tuple[float, ...]  # e (3), [p_d - p; e] (6) or p_d - p (3, position), Eq. (8)
    eta_e: float  # scalar part of q_d * conj(q), after Eq. (13); 1 for the position task
    p_tip_base: list[float]  # measured tip position, m
    R_tip_base: list[list[float]]  # measured tip rotation
    saturated: bool  # an entry was clamped
    finite: bool  # False: the law gave NaN/Inf (e.g. from extreme gains); tau_nm is zero
    # -grad of the potentials (U_a and U_lim), N m: what moves the robot towards the goal
    tau_potential_nm: tuple[float, ...] = ()
    # what y_tilde holds; None: the orientation or pose task, told by its size
    task: Optional[cl.Task] = None

    @property
    def orientation_error(self) -> tuple[float, ...]:
        """Return e of Eq. (10); zeros for the position task, which has none."""
        return tuple(cl.orientation_part(self.y_tilde, self.task))

    @property
    def orientation_error_norm(self) -> float:
        """||e|| of Eq. (10); 0 for the position task."""
        e = cl.orientation_part(self.y_tilde, self.task)
        return sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])

    @property
    def position_error_norm_m(self) -> float:
        """||p_d - p|| of Eq. (9); 0 for the orientation task."""
        if len(self.y_tilde) == 3 and self.task is not cl.Task.POSITION:
            return 0.0
        p = self.y_tilde
        return sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])


class Law(NamedTuple):
    """The law in force, swapped whole: the gains, the extensions and their limit band."""

    gains: cl.Gains
    shaping: sh.Shaping
    band: Optional[sh.LimitBand]


class Target(NamedTuple):
    """What the regulator drives to, swapped whole: the goal and its q* (None until known)."""

    goal: Optional[Goal]
    q_star: Optional[tuple[float, ...]] = None


def _limits(model: RobotModel, effort_limits_nm: Optional[Sequence[float]]) -> list[float]:
    """Per-joint clamp; a missing, zero or non-finite URDF limit means no clamp."""
    values = model.effort_limits if effort_limits_nm is None else effort_limits_nm
    if len(values) != model.n:
        raise ValueError(f'expected {model.n} effort limits, got {len(values)}')
    return [float(v) if isfinite(v) and v > 0.0 else float('inf') for v in values]


def _settling_gain(y_tilde: Sequence[float], gains: cl.Gains, shaping: sh.Shaping) -> float:
    """Return ``psi(y_tilde) alpha`` of the settling damping (1/s; 0 where it is off)."""
    alpha = shaping.settling_damping_rate_per_s
    return alpha * sh.settling_fade(y_tilde, gains.lam) if alpha > 0.0 else 0.0


def _guard_damping(minv: Sequence[Sequence[float]], qdot: Sequence[float], tau: list[float],
                   guarded: list, beta: float) -> None:
    """
    Damp the guarded joints' excess together, through M(q) (in place; docs/lyapunov.md, s. 6).

    ``G`` the guarded joints, ``A = (M^-1)_GG``, ``s_j = over_j / qdot_j`` in (0, 1] the share
    of each speed above its guard: ``tau_G`` gets ``-beta S^(1/2) A^-1 S^(1/2) qdot_G`` on top
    of the inertial damping. A joint guarded alone gets ``-beta I_j over_j``,
    ``I_j = 1 / A_jj``: the damping the sampled loop tolerates on that joint, on its excess.
    Several coupled joints guarded at once each decelerate at about ``beta`` x their excess,
    as one alone would; ``beta I_j`` on each apart couples through ``A`` to the edge of what
    the loop tolerates. ``A^-1`` is positive definite, so it is a dissipation.
    """
    g = len(guarded)
    root = [sqrt(over / qdot[j]) for j, over, _ in guarded]
    # Cholesky of A (symmetric positive definite), then A x = S^(1/2) qdot_G
    low = [[0.0] * g for _ in range(g)]
    for a in range(g):
        ja = guarded[a][0]
        for b in range(a + 1):
            jb = guarded[b][0]
            acc = minv[ja][jb]
            for c in range(b):
                acc -= low[a][c] * low[b][c]
            low[a][b] = sqrt(acc) if a == b else acc / low[b][b]
    x = [0.0] * g
    for a in range(g):
        acc = root[a] * qdot[guarded[a][0]]
        for c in range(a):
            acc -= low[a][c] * x[c]
        x[a] = acc / low[a][a]
    for a in range(g - 1, -1, -1):
        acc = x[a]
        for c in range(a + 1, g):
            acc -= low[c][a] * x[c]
        x[a] = acc / low[a][a]
    for a, (j, _, _) in enumerate(guarded):
        tau[j] -= beta * root[a] * x[a]


def _cancel_push(minv: Sequence[Sequence[float]], tau: list[float], guarded: list) -> None:
    """
    Take from each joint within a stop's clearance the push the others give it (in place).

    The other joints' torques ``tau_i`` (gravity apart: its compensation cancels it)
    accelerate joint j by ``a_j = sum_i!=j (M^-1)_ji tau_i`` through M(q). Where the stop
    guard acts on j within the clearance and ``a_j`` drives j on towards its stop, ``tau_j``
    gets ``-a_j I_j(q)``, ``I_j = 1 / (M^-1)_jj``, which cancels that acceleration. It opposes
    ``qdot_j`` and is zero at rest: a dissipation (docs/lyapunov.md, section 6). On the way
    (outside the clearance) nothing is taken: that added its gain to the guard's damping and
    made coupled guarded joints ripple (docs/reach.md, "the speed guard through M(q)").
    """
    if not any(within for _, _, within in guarded):
        return  # the speed guard alone, on the way: nothing to take, no copy
    pushed = list(tau)  # the torques before any cancellation
    for j, over, within in guarded:
        if not within:
            continue
        row = minv[j]
        a = -row[j] * pushed[j]
        for m, t in zip(row, pushed):
            a += m * t
        if a * over > 0.0:  # it drives the joint on towards its stop
            tau[j] -= a / row[j]


class Regulator:
    """
    The transpose-Jacobian unit-quaternion regulator of Eq. (22) for one robot and task.

    :param model: the robot (URDF), joints in the order of q, qdot and tau.
    :param task: ``orientation`` (y = e, J = J_o), ``pose`` (y = [p_d - p; e], J = J_G) or
        ``position`` (y = p_d - p, J = J_p).
    :param gains: the initial gains; sizes must fit the task and the joints.
    :param effort_limits_nm: clamp per joint; default the URDF's. Pass ``[inf] * n`` for the
        ideal loop of the paper's analysis (no saturation).
    :param goal: the initial goal; None until :meth:`set_goal` or :meth:`hold`.
    :param shaping: the extensions (``shaping.Shaping``); default all off, the
        paper's law.

    Two snapshots, each one reference swapped whole: the law ``(gains, shaping, limit band)``
    and the target ``(goal, goal configuration q* or None)``. A tick reads each once.
    """

    def __init__(self, model: RobotModel, task: cl.Task, gains: cl.Gains,
                 effort_limits_nm: Optional[Sequence[float]] = None,
                 goal: Optional[Goal] = None, shaping: Optional[sh.Shaping] = None) -> None:
        self.model = model
        self.task = cl.Task(task)
        self.n = model.n
        self.effort_limits_nm = _limits(model, effort_limits_nm)
        self._zero = [0.0] * self.n
        # where the cubic damping turns linear: the URDF velocity limits (2 pi rad/s if none)
        self._speed_cap = [v if isfinite(v) and v > 0.0 else sh.DEFAULT_SPEED_CAP_RAD_S
                           for v in model.velocity_limits]
        self._check_gains(gains)
        shaping = sh.Shaping() if shaping is None else shaping
        self._law = Law(gains, shaping, self._band(shaping))
        self._target = Target(goal)
        # qdot*_d of a streamed goal (rad/s), or None: independent of the goal, which a stream
        # replaces at every sample while its velocity stays
        self._goal_joint_velocity: Optional[tuple[float, ...]] = None
        # a, the part of the friction estimate learned at rest (N m per joint): the one state
        # the tick keeps, advanced only by ticks given a time step (shaping.learn_friction)
        self._learned_friction_nm = [0.0] * self.n
        # this tick's slow |t_p| w and w (the share of the push the damping does not
        # take), and the damping torque they are computed from: for the learning, filled in place
        self._stuck = [0.0] * self.n
        self._unmet = [0.0] * self.n
        self._sliding = [0.0] * self.n  # the friction a sliding joint meets (learn_friction)
        self._damping = [0.0] * self.n
        self._creep = [0.0] * self.n  # the creep speed per joint (rad/s), for the learning
        self._fade = [0.0] * self.n  # ... and the fade speed of the learned push (rad/s)
        self._creep_top = [sh.CREEP_TOP_FRACTION * v for v in self._speed_cap]  # their tops
        # the speed guard: above this (rad/s, a share of the URDF velocity limit; none without
        # one) a joint's damping rises to beta I_j(q), the most the sampled loop tolerates
        self._guard = [sh.SPEED_GUARD_FRACTION * v if isfinite(v) and v > 0.0 else inf
                       for v in model.velocity_limits]
        # ... and towards a stop, above what that damping stops in the room left (rad/s):
        # STOP_GUARD_SHARE x beta x the distance to the stop less its clearance
        self._stop_lower = tuple(model.position_lower)  # -inf / inf: no stop
        self._stop_upper = tuple(model.position_upper)
        self._caps = [0.0] * self.n  # beta I_j(q) this tick
        self._own = [0.0] * self.n  # M_jj(q) this tick (with the inertial damping)
        self._seen = [0.0] * self.n  # ... and 1 / (M(q)^-1)_jj
        self._tick_s = 0.0  # the period the fade tops assume (s; TICK_MEMORY)
        # per joint, the share of U_c in force (CONFIGURATION_FADE_IN_S), and whether some
        # share is below 1
        self._lead_in = [1.0] * self.n
        self._fading = False
        self._lead_in_q_star: Optional[tuple[float, ...]] = None  # the q* it last saw
        self._lead_in_shaping: Optional[sh.Shaping] = None  # ... and the shaping it last used
        self._fade_top = [sh.FADE_TOP_FRACTION * v for v in self._speed_cap]
        self._held = [0.0] * self.n  # how stuck each joint has stayed (learn_friction's h)
        self._slid = [0.0] * self.n  # how much friction each has slid against (... its g)
        # the learning's acceleration estimate: qdot's low-pass (rad/s) and
        # (qdot - low-pass) / ACCELERATION_TIME_S (rad/s^2), advanced by the ticks given a step
        self._qdot_slow = [0.0] * self.n
        self._qddot = [0.0] * self.n
        self._accel_seeded = False  # the filter starts at the first tracked qdot
        # the rotor inertia the motion shows beyond the armature told (armature_estimate.py),
        # and the last tick's torque beyond gravity, which the plant got (N m; None: none yet)
        self._armature = ArmatureEstimator(self.n)
        self._net_nm: Optional[list[float]] = None
        if any(model.armature_estimate):  # a new regulator starts from the model told
            model.set_armature_estimate(self._zero)
        self._armature_in_model = False  # this regulator put an estimate in the model
        # the limit band ending at q* (LimitBand.ending_at), cached for (band, q*): derived
        self._band_at_goal: tuple = (None, None, None)

    # -- snapshots ------------------------------------------------------------------------
    @property
    def gains(self) -> cl.Gains:
        """Return the gains in force (immutable)."""
        return self._law.gains

    @property
    def shaping(self) -> sh.Shaping:
        """Return the extensions in force (immutable)."""
        return self._law.shaping

    @property
    def limit_band(self) -> Optional[sh.LimitBand]:
        """Return the joint-limit potential in force, or None if it is off."""
        return self._law.band

    def _check_gains(self, gains: cl.Gains) -> None:
        if len(gains.kp) != self.task.dim or len(gains.lam) != self.task.dim:
            raise cl.GainsError(f'kp and lambda must have {self.task.dim} values for the '
                                f'{self.task.value} task')
        if len(gains.kv) != self.n:
            raise cl.GainsError(f'kv must have {self.n} values')

    def _band(self, shaping: sh.Shaping) -> Optional[sh.LimitBand]:
        return sh.LimitBand.create(self.model.position_lower, self.model.position_upper,
                                   shaping.check_size(self.n))

    def set_gains(self, gains: cl.Gains) -> None:
        """Swap in new gains, whole; raise GainsError if their sizes do not fit."""
        self._check_gains(gains)
        self._law = self._law._replace(gains=gains)

    def check_shaping(self, shaping: sh.Shaping) -> sh.Shaping:
        """Return ``shaping`` if it fits this robot; raise ShapingError saying why not."""
        self._band(shaping)
        for name, lo, hi, v in zip(self.model.joint_names, self.model.position_lower,
                                   self.model.position_upper,
                                   shaping.preferred_configuration_rad):
            if not lo <= v <= hi:
                raise sh.ShapingError(f'preferred_configuration: {name} = {v} is outside its '
                                      f'limits [{lo:g}, {hi:g}]')
        return shaping

    def check_payload(self, payload: Payload, q: Sequence[float]) -> Payload:
        """
        Return ``payload`` if the arm can hold it up at ``q``; raise ModelError saying why not.

        With it in ``g(q)`` (the payload in force taken out), no joint may need more than its
        effort limit at ``q``: a mass beyond that (a typo of a hundred kilograms) would drive
        every joint to its limit at once, and the arm could not hold it anyway. One ``g(q)``
        and one Jacobian: cheap enough for a parameter callback on the control thread. Goals
        whose pose it cannot be held in are the goal check's (``heavy_warning``). With
        ``gravity_compensation`` off the drives hold the weight, not our torque: not checked.
        """
        if not self.gains.gravity_compensation:
            return payload
        model = self.model
        # (m, m c) of the new payload less the one in force, through Y(q)
        old = model.payload
        delta = [payload.mass_kg * a - old.mass_kg * b
                 for a, b in zip((1.0, *payload.com_m), (1.0, *old.com_m))]
        needed = [g + sum(y * d for y, d in zip(row, delta))
                  for g, row in zip(model.gravity(q), model.payload_regressor(q).tolist())]
        for name, tau, limit in zip(model.joint_names, needed, self.effort_limits_nm):
            if abs(tau) > limit:
                raise ModelError(
                    f'payload_mass {payload.mass_kg:g} kg at payload_com {list(payload.com_m)} '
                    f'cannot be held up where the arm is: {name} would need {abs(tau):.3g} N m '
                    f'of its {limit:g} N m effort limit against gravity')
        return payload

    def set_payload(self, payload: Payload) -> None:
        """
        Carry ``payload`` at the tip from the next tick (``RobotModel.set_payload``).

        Its weight goes into the gravity compensation g(q), its mass into M(q) and the
        damping built on it. The learned friction is kept: it adapts to what is left.
        """
        self.model.set_payload(payload.mass_kg, payload.com_m)

    def set_shaping(self, shaping: sh.Shaping) -> None:
        """
        Swap in new extensions (and their limit band), whole; raise ShapingError if unfit.

        The friction learned so far is kept within the new limits (zero where none).
        """
        self.check_shaping(shaping)
        band = self._band(shaping)
        limits = shaping.friction_learning_limit_nm or (0.0,) * self.n
        self._learned_friction_nm = [min(a, a_max) for a, a_max in
                                     zip(self._learned_friction_nm, limits)]
        self._held = [h if a_max > 0.0 else 0.0 for h, a_max in zip(self._held, limits)]
        self._slid = [g if a_max > 0.0 else 0.0 for g, a_max in zip(self._slid, limits)]
        self._accel_seeded = False  # the filter may have stood still while the learning was off
        self._armature.restart()  # ... and the estimate's filters with it
        self._keep_armature_estimate(shaping.armature_estimation_limit_kg_m2 or self._zero)
        self._law = self._law._replace(shaping=shaping, band=band)

    def _keep_armature_estimate(self, limits: Sequence[float]) -> None:
        """Keep the rotor inertia estimated within ``limits`` (forgotten if all are 0)."""
        est = self._armature
        if not any(a > 0.0 for a in limits):
            est.reset()
            self._net_nm = None
        else:
            est.estimate = [min(e, top) for e, top in zip(est.estimate, limits)]
        # only the regulator that put an estimate in the model changes it (ClosedLoop's two
        # share one model)
        if self._armature_in_model and tuple(est.estimate) != self.model.armature_estimate:
            self.model.set_armature_estimate(est.estimate)

    @property
    def armature_estimate(self) -> tuple[float, ...]:
        """
        Return the rotor inertia found beyond the armature told (kg m^2 per joint), in M(q).

        Zeros until the motion shows some, or with ``armature_estimation_limit`` zero
        (``armature_estimate.ArmatureEstimator``).
        """
        return tuple(self._armature.estimate)

    @property
    def friction_held(self) -> tuple[float, ...]:
        """
        Return ``h`` per joint: how long each has stayed held by a friction, as the learning sees.

        In ``[0, 1]``; above 1/2 the joint has been held (pushed, its push taken neither by its
        damping nor by its acceleration) for about ``0.14 T`` (``shaping.learn_friction``).
        Zeros while nothing is learned.
        """
        return tuple(self._held)

    @property
    def learned_friction_nm(self) -> tuple[float, ...]:
        """Return ``a``, the part of the friction estimate learned at rest so far (N m)."""
        return tuple(self._learned_friction_nm)

    @property
    def goal(self) -> Optional[Goal]:
        """Return the goal in force (immutable), or None before the first."""
        return self._target.goal

    @property
    def goal_configuration(self) -> Optional[tuple[float, ...]]:
        """Return q* of the goal in force (rad), or None if none is known."""
        return self._target.q_star

    @property
    def goal_joint_velocity(self) -> Optional[tuple[float, ...]]:
        """Return qdot*_d of the stream in force (rad/s), or None for a fixed goal."""
        return self._goal_joint_velocity

    def set_goal(self, goal: Goal) -> None:
        """Swap in a new goal, whole; its goal configuration is unknown until given."""
        self._target = Target(goal)

    def set_goal_configuration(self, goal: Goal, q_star: Optional[Sequence[float]]) -> bool:
        """
        Give q*, a joint configuration within the limits that reaches ``goal`` (rad).

        Taken only if ``goal`` is still the goal in force (it may have been replaced while q*
        was being computed); returns whether it was taken.
        """
        target = self._target
        if goal is not target.goal:
            return False
        if q_star is not None and len(q_star) != self.n:
            raise ValueError(f'expected {self.n} joint positions, got {len(q_star)}')
        self._target = target._replace(
            q_star=None if q_star is None else tuple(float(x) for x in q_star))
        return True

    def set_goal_joint_velocity(self, qdot_desired: Optional[Sequence[float]]) -> None:
        """
        Give qdot*_d, the joint velocity of a streamed goal's configuration (rad/s).

        The damping then acts on ``qdot - g_v qdot*_d`` (``shaping.goal_velocity_gain``);
        None makes the goal fixed again (docs/lyapunov.md, section 7).
        """
        if qdot_desired is not None and len(qdot_desired) != self.n:
            raise ValueError(f'expected {self.n} joint velocities, got {len(qdot_desired)}')
        self._goal_joint_velocity = (None if qdot_desired is None else
                                     tuple(float(x) for x in qdot_desired))

    def pose(self, q: Sequence[float]) -> Goal:
        """Return the measured tip pose at ``q`` as a Goal (scalar-first quaternion, eta >= 0)."""
        p, R = self.model.forward_kinematics(q)
        return Goal(quat.from_rotation_matrix(R), (p[0], p[1], p[2]))

    def hold(self, q: Sequence[float]) -> Goal:
        """Make the pose measured at ``q`` the goal (hold still where the robot is), q* = q."""
        goal = self.pose(q)
        self._target = Target(goal, tuple(float(x) for x in q))
        return goal

    def _advance_lead_in(self, q_star: Optional[tuple[float, ...]], shaping: sh.Shaping,
                         step_s: float) -> None:
        """
        Fade U_c in over CONFIGURATION_FADE_IN_S (ticks with a time step only).

        Each joint's share restarts from 0 for a q* further than the ramp from the last one in
        some joint (or the first); a q* that moves less (a streamed goal's) keeps them. A gain
        ``T_j`` raised live keeps the term in force where it was, ``s_j T_j`` (its share
        scaled by the old gain over the new), and rises from there: neither a step up nor a
        drop to nothing (a design again, ``redesign.py``, raises them at rest). While no q* is
        in force (a new goal's, until the goal check gives it) the shares fall at the rate
        they rise, so a q* that comes back near the last one after a gap returns at the
        shares the gap left.
        """
        rate = step_s / CONFIGURATION_FADE_IN_S
        shares = self._lead_in
        n = self.n
        if q_star is None:
            for j in range(n):
                share = shares[j] - rate
                shares[j] = share if share > 0.0 else 0.0
            self._fading = True
            return
        before = self._lead_in_shaping
        if shaping is not before:  # a new set of parameters (immutable): compare T_j once
            if before is not None:
                for j, (t, t_old) in enumerate(zip(shaping.configuration_gain,
                                                   before.configuration_gain)):
                    if t > t_old:
                        shares[j] *= max(t_old, 0.0) / t
                        self._fading = True
            self._lead_in_shaping = shaping
        last = self._lead_in_q_star
        if q_star is not last:
            ramp_rad = shaping.configuration_ramp_rad
            if last is None or any(abs(a - b) > ramp_rad for a, b in zip(q_star, last)):
                for j in range(n):
                    shares[j] = 0.0
                self._fading = True
            self._lead_in_q_star = q_star
        if self._fading:
            fading = False
            for j in range(n):
                share = shares[j] + rate
                if share < 1.0:
                    shares[j] = share
                    fading = True
                else:
                    shares[j] = 1.0
            self._fading = fading

    def _band_at(self, band: Optional[sh.LimitBand],
                 q_star: Optional[tuple[float, ...]]) -> Optional[sh.LimitBand]:
        """Return the band in force for the target: ``band``, ending at q* if q* is in it."""
        if band is None or q_star is None:
            return band
        cached = self._band_at_goal
        if cached[0] is band and cached[1] is q_star:
            return cached[2]
        ended = band.ending_at(q_star)
        self._band_at_goal = (band, q_star, ended)
        return ended

    def goal_in_band(self) -> tuple[int, ...]:
        """
        Return the joints whose goal configuration q* lies in the joint-limit band.

        Deeper than ``BAND_DEPTH_TOLERANCE_RAD``, as the goal check counts it: a q* it slid
        against a band's wall is out of it.
        """
        band, q_star = self._law.band, self._target.q_star
        if band is None or q_star is None:
            return ()
        tol = sh.BAND_DEPTH_TOLERANCE_RAD
        return tuple(j for j in band.joints
                     if not band.lower_rad[j] - tol <= q_star[j] <= band.upper_rad[j] + tol)

    # -- the law ----------------------------------------------------------------------------
    def error(self, q: Sequence[float], goal: Optional[Goal] = None):
        """
        Return ``(y_tilde, eta_e, rows, p, R)`` at ``q`` towards ``goal`` (default: in force).

        ``rows`` is the Jacobian of the task, J_o (orientation), J_G (pose) or J_p
        (position), Eq. (12).
        """
        goal = self._target.goal if goal is None else goal
        p, R, J = self.model.kinematics(q)
        y, eta_e = cl.output_error(p, R, goal.p_desired_base, goal.q_desired_base, self.task)
        return y, eta_e, self.task.rows(J), p, R

    def update(self, q: Sequence[float], qdot: Sequence[float], dt_s: float = 0.0) -> TickOutput:
        """
        One control tick at the measured ``(q, qdot)``: Eq. (22) + g(q), checked and clamped.

        With the extensions of :attr:`shaping`: + the joint-limit, large-error and
        goal-configuration terms of the potential, the cubic and inertial damping, the speed
        guard and the settling damping (docs/lyapunov.md, sections 6, 10 and 11), + friction
        compensation
        (``shaping.py``). Reads the law and the target once each. A goal must have been set
        (or :meth:`hold`). If the law gives a non-finite torque the command is zero and
        ``finite`` is False.
        ``dt_s``, the time since the last tick (s; at most ``MAX_LEARNING_STEP_S`` counts),
        advances the friction learned at rest; 0 (a re-evaluation, the ideal loop's stages)
        leaves it as it is.
        """
        gains, shaping, band = self._law
        goal, q_star = self._target
        band = self._band_at(band, q_star)
        qdot_goal = self._goal_joint_velocity
        step = dt_s if dt_s < MAX_LEARNING_STEP_S else MAX_LEARNING_STEP_S  # what counts
        estimating = dt_s > 0.0 and shaping.armature_estimation_on
        if dt_s > 0.0 and (shaping.learning_on or estimating):  # the acceleration estimate
            self._track_acceleration(qdot, dt_s)
            kept = self._tick_s * TICK_MEMORY  # ... and the period its fade tops assume
            self._tick_s = step if step > kept else kept
        y, eta_e, rows, p, R = self.error(q, goal)
        n = self.n
        tau_p = cl.potential_torque(rows, y, eta_e, gains, shaping.large_error_gain, self.task)
        if band is not None:
            band.add_torque(q, tau_p)
        if shaping.configuration_on:
            if dt_s > 0.0:
                self._advance_lead_in(q_star, shaping, step)
            if q_star is not None:
                sh.add_configuration_torque(q, q_star, shaping, tau_p, self._lead_in)
        kv = gains.kv
        tau = [tau_p[j] - kv[j] * qdot[j] for j in range(n)]
        if shaping.speed_damping_on:
            sh.add_speed_damping(qdot, kv, shaping, tau, self._speed_cap)
        g_v = (shaping.goal_velocity_gain if qdot_goal is not None else 0.0)
        if g_v > 0.0:  # damping on qdot - g_v qdot*_d
            for j in range(n):
                tau[j] += kv[j] * g_v * qdot_goal[j]
        own = None  # M_jj(q), where the inertial damping computed it
        guarded = None  # (j, speed over the guard, within the stop's clearance) where it acts
        minv = None  # M(q)^-1, with the inertial damping
        if shaping.inertial_damping_on:  # docs/lyapunov.md, section 10: on the same velocity
            caps = self._caps
            own = self._own
            beta = shaping.inertial_damping_rate_per_s
            stop_rate = sh.STOP_GUARD_SHARE * beta
            clearance = sh.STOP_CLEARANCE_SHARE * shaping.joint_limit_margin_rad
            damping, minv = self._inertial_damping(q, kv, shaping, caps, own, self._seen)
            damped = qdot if g_v <= 0.0 else [qdot[j] - g_v * qdot_goal[j] for j in range(n)]
            for j, d in enumerate(damping):
                if d > kv[j]:
                    tau[j] -= (d - kv[j]) * damped[j]
                # the speed guard, docs/lyapunov.md s. 6: above 0.8 v_lim, or what the cap
                # stops in the room left before the stop it moves to
                v = qdot[j]
                room = (self._stop_upper[j] - q[j] if v > 0.0
                        else q[j] - self._stop_lower[j]) - clearance
                guard = self._guard[j]
                if stop_rate * room < guard:
                    guard = stop_rate * room if room > 0.0 else 0.0
                over = v - guard if v > guard else (v + guard if v < -guard else 0.0)
                if over != 0.0:
                    if guarded is None:
                        guarded = []
                    guarded.append((j, over, room <= 0.0))
            modes = sh.fast_damping_modes(minv, damping, beta)
            if modes is not None:  # each mode of M^-1 D at most beta, K_v included
                for c, y in modes:
                    along = 0.0
                    for j in range(n):
                        along += y[j] * damped[j]
                    along *= c
                    for j in range(n):
                        tau[j] += along * y[j]
            if guarded is not None:
                _guard_damping(minv, qdot, tau, guarded, beta)
        settled = None  # (psi alpha, v, M(q) v) of the settling damping, if it acts
        k = _settling_gain(y, gains, shaping)  # docs/lyapunov.md, section 11
        if k > 0.0:
            v = qdot if g_v <= 0.0 else [qdot[j] - g_v * qdot_goal[j] for j in range(n)]
            m_v = self.model.inertial_torque(q, v)  # M(q) v
            for j in range(n):
                tau[j] -= k * m_v[j]
            settled = (k, v, m_v)
        if shaping.friction_on:
            phi = sh.fade(y, shaping, self.task is cl.Task.POSITION)
            if phi > 0.0:  # else the compensation is zero (near the goal)
                learning = shaping.learning_on
                damping = self._damping if learning else None
                if learning:  # the damping terms so far: tau = tau_p + damping
                    for j in range(n):
                        damping[j] = tau[j] - tau_p[j]
                    if settled is not None:  # the other joints' share of the settling
                        k, v, m_v = settled  # damping is no damping of this joint: it may
                        if own is None:  # push either way; its own, -k M_jj v_j, is
                            own = self.model.own_inertias(q)
                        for j in range(n):
                            damping[j] += k * (m_v[j] - own[j] * v[j])
                creep = fade = inertial = None
                if learning:  # the creep and fade speeds, the creep from q* if known
                    creep, fade = self._creep, self._fade
                    if self._tick_s > 0.0:  # their tops, lower where much is learned
                        seen = (self._seen if shaping.inertial_damping_on
                                else self.model.inertias(q)[1])
                        sh.fade_tops(self._learned_friction_nm, seen, self._tick_s,
                                     self._speed_cap, self._creep_top, self._fade_top)
                    sh.creep_speeds(q, q_star, shaping, self._creep_top, self._fade_top,
                                    creep, fade)
                    inertial = self.model.inertial_torque(q, self._qddot)
                fc = sh.friction_compensation(
                    tau_p, qdot, phi, shaping, self._learned_friction_nm if learning else None,
                    self._stuck, damping, self._unmet, creep, fade, inertial,
                    shaping.learning_torque_band if q_star is not None else None,
                    self._sliding if learning else None)
                for j in range(n):
                    tau[j] += fc[j]
        if guarded is not None:
            _cancel_push(minv, tau, guarded)
        g = None
        if gains.gravity_compensation:
            g = self.model.gravity(q)
            for j in range(n):
                tau[j] += g[j]
        total = 0.0
        for t in tau:
            total += t
        if total - total != 0.0:  # NaN or Inf somewhere (inf - inf is NaN)
            if estimating:  # the plant gets no torque of ours
                self.torque_withheld()
            return TickOutput(list(self._zero), y, eta_e, p, R, False, False, tuple(self._zero),
                              self.task)
        if shaping.learning_on and dt_s > 0.0:  # only from a finite tick: never poisoned
            sh.learn_friction(self._learned_friction_nm, self._stuck, phi, shaping, step,
                              self._unmet, self._held, self._sliding, self._slid)
        saturated = cl.saturate(tau, self.effort_limits_nm)
        if estimating:
            self._estimate_armature(q, qdot, tau, g, dt_s, shaping, own)
        return TickOutput(tau, y, eta_e, p, R, saturated, True, tuple(tau_p), self.task)

    def _estimate_armature(self, q: Sequence[float], qdot: Sequence[float], tau: list[float],
                           g: Optional[list[float]], dt_s: float, shaping: sh.Shaping,
                           own: Optional[list[float]]) -> None:
        """
        Advance the rotor inertia estimate by a tick; put a new one in M(q) (armature_estimate).

        The torque of the last tick beyond gravity is what the plant got while it moved to
        this ``qdot`` (the filtered acceleration tracked this tick, over ``dt_s``); this
        tick's ``tau`` (clamped) less ``g`` is kept for the next. After a gap longer than
        ``MAX_LEARNING_STEP_S`` the filters start again. The Coriolis torques are taken at the
        low-passed ``qdot``, as the torque is low-passed.
        """
        est = self._armature
        if dt_s > MAX_LEARNING_STEP_S:  # states lost: the acceleration filter jumps
            self.torque_withheld()
        net = self._net_nm
        if net is not None and est.track(net, qdot, shaping.friction_velocity_rad_s, dt_s):
            model = self.model
            slow = self._qdot_slow
            est.sample(self._qddot, model.inertial_torque(q, self._qddot, slow),
                       model.armature_estimate, slow, shaping.friction_velocity_rad_s)
            if est.solve_due:
                if own is None:
                    own = model.own_inertias(q)
                if est.solve(own, shaping.armature_estimation_limit_kg_m2):
                    model.set_armature_estimate(est.estimate)
                    self._armature_in_model = True
        if net is None:
            net = self._net_nm = list(tau)
        if g is None:
            net[:] = tau
        else:
            for j, t in enumerate(tau):
                net[j] = t - g[j]

    def torque_withheld(self) -> None:
        """
        Say that the last tick's torque does not reach the plant (a command not published).

        The rotor inertia estimate reads the last torque as what the plant got: its filters
        start again (its fits and its value are kept) and take no sample for their warm-up
        (``armature_estimate.WARM_UP_S``). Nothing else reads it.
        """
        self._armature.restart()
        self._net_nm = None

    def _track_acceleration(self, qdot: Sequence[float], dt_s: float) -> None:
        """
        Advance the learning's filtered derivative of ``qdot`` by one tick (docs/lyapunov.md, 4).

        ``qddot = (qdot - s) / ACCELERATION_TIME_S``, ``s`` the low-pass of ``qdot`` before this
        tick: a steady ramp's slope at any step. Seeded at ``qdot`` (``qddot`` 0) on its first
        tick and after :meth:`set_shaping`; a non-finite ``qdot`` is skipped, never kept.
        """
        total = 0.0
        for v in qdot:
            total += v
        if total - total != 0.0:  # NaN or Inf: the tick will say so; the filter stays
            return
        slow, qddot = self._qdot_slow, self._qddot
        if not self._accel_seeded:
            slow[:] = qdot
            qddot[:] = self._zero
            self._accel_seeded = True
            return
        tau = sh.ACCELERATION_TIME_S
        k = dt_s / tau if dt_s < tau else 1.0
        for j, v in enumerate(qdot):
            change = v - slow[j]
            qddot[j] = change / tau  # a steady ramp's slope, at any k
            slow[j] += k * change

    def linear_damping(self, q: Sequence[float]) -> list[float]:
        """
        Return the linear damping per joint at ``q`` (N m s/rad), as :meth:`update` applies it.

        ``K_v``, or with ``inertial_damping`` ``max(k_v,j, min(c_j sqrt(M_jj(q)), beta
        I_j(q)))``, ``I_j(q) = 1 / (M(q)^-1)_jj``, less the diagonal of what the cap on the
        modes faster than ``beta`` takes away (docs/lyapunov.md, section 10); the cubic
        part and the settling damping near the goal (section 11, which couples the joints:
        :meth:`settling_damping` gives its diagonal) apart.
        """
        gains, shaping, _ = self._law
        if not shaping.inertial_damping_on:
            return list(gains.kv)
        damping, minv = self._inertial_damping(q, gains.kv, shaping)
        modes = sh.fast_damping_modes(minv, damping, shaping.inertial_damping_rate_per_s)
        for c, y in modes or ():
            for j in range(self.n):
                damping[j] -= c * y[j] * y[j]
        return damping

    def settling_damping(self, q: Sequence[float], y_tilde: Sequence[float]) -> list[float]:
        """
        Return the diagonal of the settling damping at ``q`` (N m s/rad): ``psi alpha M_jj(q)``.

        ``psi`` of ``y_tilde`` (``shaping.settling_fade``), ``alpha`` the
        ``settling_damping_rate`` in force; zeros where it is off (docs/lyapunov.md, 11).
        """
        gains, shaping, _ = self._law
        k = _settling_gain(y_tilde, gains, shaping)
        if k <= 0.0:
            return list(self._zero)
        return [k * m for m in self.model.own_inertias(q)]

    def _inertial_damping(self, q: Sequence[float], kv: Sequence[float],
                          shaping: sh.Shaping,
                          caps_out: Optional[list[float]] = None,
                          own_out: Optional[list[float]] = None,
                          seen_out: Optional[list[float]] = None
                          ) -> tuple[list[float], list[list[float]]]:
        """
        ``max(k_v,j, min(c_j sqrt(M_jj(q)), beta I_j(q)))`` per joint (N m s/rad), and M(q)^-1.

        ``caps_out``, if given, receives ``beta I_j(q)`` per joint, ``own_out`` ``M_jj(q)``,
        ``seen_out`` ``I_j(q) = 1 / (M(q)^-1)_jj``.
        """
        own, seen, minv = self.model.inertias_and_inverse(q)
        if own_out is not None:
            own_out[:] = own
        if seen_out is not None:
            seen_out[:] = seen
        beta = shaping.inertial_damping_rate_per_s
        out = []
        for j, c in enumerate(shaping.inertial_damping):
            b = c * sqrt(own[j])
            cap = beta * seen[j]
            if caps_out is not None:
                caps_out[j] = cap
            b = b if b < cap else cap
            out.append(b if b > kv[j] else kv[j])
        return out, minv

    def potential_energy(self, q: Sequence[float]) -> float:
        """
        Return the total potential at ``q`` (J), docs/lyapunov.md.

        U_a(y_tilde(q)) of Eq. (23) or (31) (+ the large-error term), + U_lim(q) + U_c(q) of
        the extensions in force.
        """
        gains, shaping, band = self._law
        goal, q_star = self._target
        band = self._band_at(band, q_star)
        u = cl.potential_energy(self.error(q, goal)[0], gains, shaping.large_error_gain,
                                self.task)
        if band is not None:
            u += band.energy(q)
        if q_star is not None and shaping.configuration_on:
            u += sh.configuration_energy(q, q_star, shaping)
        return u

    def lyapunov(self, q: Sequence[float], qdot: Sequence[float]) -> float:
        """V = 1/2 qdot^T M(q) qdot + the total potential, Eq. (27) / (34), docs/lyapunov.md."""
        M = self.model.mass_matrix(q)
        kinetic = 0.5 * sum(qdot[i] * M[i, j] * qdot[j]
                            for i in range(self.n) for j in range(self.n))
        return float(kinetic) + self.potential_energy(q)

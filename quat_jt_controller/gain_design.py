"""
Gains from the robot, by rules: the paper's open problem (docs/gain_design.md).

Section 5 of the paper regrets "the lack of a procedure for tuning their gains", and Section 6
leaves gain tuning open.

From the URDF (kinematics, inertias, effort and velocity limits) with the drives' rotor
inertia (the model's armature, on the diagonal of M(q)), the task, the control rate and the
Coulomb friction estimates, :func:`design` computes K_p, K_v and Lambda (one set that
serves both potentials, so ``potential`` can be switched live) and the extensions
(``shaping.Shaping``): joint-limit band, goal-configuration term, cubic damping, friction
compensation. In short:

1. budget per joint: a share of the effort limit left after gravity and friction compensation
   (the estimate and the part the regulator may learn at rest, ``friction_learning_limit``);
2. K_p from the tanh law's a-priori bound |tau_j| <= ||J_p[:, j]|| ||k_p|| + 1/2 ||k_o||
   (|Q| <= 1/2 on the orientation rows; a revolute column of J_o is a unit vector), kept
   within the part of the budget left to the task potential;
3. Lambda from where the tanh force should saturate; K_v for critical damping of the
   linearised loop at the geometric mean of the two potentials' stiffnesses, from M(q) at
   representative configurations, raised where the damping (with its cubic part) would not
   hold the potentials' largest push at ``SPEED_MARGIN`` x the URDF velocity limit;
4. the sampled loop linearised at those configurations must have spectral radius < 1, for
   both potentials, with every delay asked for plus one more tick (``DELAY_MARGIN``), and at
   ``GAIN_MARGIN`` x the gains; the stiffness of the limit band, of the goal-configuration
   ramp, the slope of the cubic damping and that of the friction compensation's braking are
   checked the same way, per joint, on the inertia the joint sees, ``1 / (M^-1)_jj``.

The sampled-loop analysis is in ``gain_analysis``, the parameter files in ``gain_output``, the
command line in ``gain_cli``. ROS-free. ``python -m quat_jt_controller.gain_design --help``
(``ros2 run quat_jt_controller design_gains`` under colcon) writes a parameter file in the format
of config/*_controller.yaml.
"""
from dataclasses import dataclass, field, replace
from math import isfinite, pi, sqrt
import sys
from typing import Optional, Sequence

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import parameter_table as table
from quat_jt_controller.gain_analysis import (
    carried_speed, checked_delays, configuration_stiffness, cruising_speed, damping_at,
    joint_spectral_radius, joint_stiffness, largest_stable_damping, median_damping_ratio, QO,
    seen_inertia, settling_rate, sigma_min, time_to_goal_s, worst_rho)
from quat_jt_controller.model import GRAVITY_RESERVE_SHARE, RobotModel
from quat_jt_controller.shaping import (
    DEFAULT_SPEED_CAP_RAD_S, FADE_DELAY_TICKS, FADE_FLOOR_FRACTION, FULL_TURN_RAD,
    PLAUSIBLE_SPEED_RAD_S, Shaping)
from quat_jt_runtime.joints import check_state_rate
from quat_jt_runtime.param_table import row

TORQUE_SHARE = 0.8  # of what gravity and friction compensation leave; the rest: damping
UNHELD_SHARE_MAX = 0.5  # of the survey's configurations where gravity exceeds the effort: refused
GUIDE_OVER_TASK = 2.0  # the goal-configuration term must overcome the task term at a stop
LIMIT_OVER_TASK = 1.5  # the limit band at the stop holds at least 1.5 x the task term's bound,
# and up to what K_v brakes at SPEED_MARGIN x the velocity limit (within the budget)
LAMBDA_ORIENTATION = 4.0  # tanh(4 ||e||) = 0.96 at ||e|| = 0.5 (60 degrees)
POSITION_SATURATION_M = 0.1  # tanh(lambda_p 0.1 m) = 0.96
DAMPING_RATIO = sqrt(0.5)  # of the tanh law's linearised loop (the quadratic's: x sqrt(lambda))
# Where the sampled loop caps K_v, the stiffness is lowered until the tanh law keeps this much
DAMPING_RATIO_MIN = 0.5
# The ratio the inertial damping holds where the arm is heavy: the least the design accepts.
# More slows the creep of a joint that the friction learning moves (docs/gain_design.md).
INERTIAL_DAMPING_RATIO = DAMPING_RATIO_MIN
CRUISE_FRACTION = 0.6  # of the URDF velocity limit: the speed far from the goal (default)
# ... and the most that steady speed may be, whatever the cruise aimed at: the push far from
# the goal meets the damping (linear and cubic) at or below this share of the limit
SPEED_MARGIN = 0.8
# ... where K_v is raised to hold it, at most to this share of b_max: near rest a light joint
# keeps much of the delay margin its own (small) K_v leaves; the cubic part brakes the rest
SPEED_DAMPING_SHARE = 0.75
# The speed the other joints' pushes give a joint through M(q) (gain_analysis.carried_speed,
# an overestimate) is held at or below this share of its velocity limit: a joint lighter than
# the arm that carries it gets more damping (up to SPEED_DAMPING_SHARE x b_max) and, towards
# the linear pace push / K_v it had (near the goal K_v alone damps), a larger
# goal-configuration gain; not more damping than its budget can push at that pace
CARRIED_SPEED_SHARE = 1.0
CARRY_STEP = 1.02  # ... raised where that asks for this much more K_v than the joint has
CARRY_PASSES = 30  # ... in at most this many passes of the design loop
NEGLIGIBLE_CUBIC = 100.0  # a v_c this many times the velocity limit: no cubic term
CRUISE_STEP = 1.1  # the goal-configuration gain of a joint slower than that grows by this
DEFAULT_VELOCITY = DEFAULT_SPEED_CAP_RAD_S  # rad/s, for a joint whose URDF gives no velocity limit
DAMPER_SAFETY = 0.5  # of the largest damping the sampled loop tolerates on a joint
LIMIT_MARGIN_MAX_RAD = 0.25
LIMIT_MARGIN_FRACTION = 0.1  # of the smallest half range of a limited joint
GUIDE_RADIUS_RAD = 0.0  # > 0: a dead zone around q* where only the paper's term acts
GUIDE_RAMP_RAD = 0.25  # the goal-configuration term's ramp w, unless --approach-time asks less
FRICTION_VELOCITY_RAD_S = 0.075  # v_eps of the compensation (docs/reach.md says why 0.075)
FRICTION_ERROR_BAND = 0.004  # ||e||; a little below the 0.005 the wrist is asked to reach
FRICTION_POSITION_BAND_M = 0.0005
# At rest the regulator may learn this much more than the estimate (x the estimate), in
# FRICTION_LEARNING_TIME_S: a friction up to (1 + this) x the estimate is still broken
FRICTION_LEARNING = 2.0
# ... and with no estimate (0), a share (--friction-effort-share) of the joint's
# effort limit: a friction nobody measured up to this much is still broken (docs/lyapunov.md,
# section 4). On by default: without it no arm but the wrist reaches with a friction of 1% of
# its effort limits that nobody measured (docs/gain_design.md, "The learning on by default").
FRICTION_EFFORT_SHARE = 0.03
DEFAULT_FRICTION_EFFORT_SHARE = FRICTION_EFFORT_SHARE
FRICTION_LEARNING_TIME_S = 1.0
# ... and on a joint without one, at most what changes its speed by this share of its limit in
# one tick: the learned push fades out from a speed 1 + FADE_DELAY_TICKS times that much below
# the limit, at least FADE_FLOOR_FRACTION of it (shaping.fade_tops)
TICK_SPEED_SHARE = (1.0 - FADE_FLOOR_FRACTION) / (1.0 + FADE_DELAY_TICKS)
# A joint that accelerates faster than this on its effort limit and the inertia it sees, with
# no armature given, is taken for a URDF without its drive's rotor inertia (a warning)
PLAUSIBLE_ACCELERATION_RAD_S2 = 5000.0
SUGGESTED_ARMATURE = 0.1  # kg m^2, what a geared drive of a ~1 m arm reflects, as an example
# The regulator may find at most the rotor inertia that the joint's effort limit accelerates
# this fast (rad/s^2; m/s^2 on a slide), beyond the armature told (armature_estimate.py)
ESTIMATED_ARMATURE_ACCELERATION_RAD_S2 = 10.0
SAMPLES = 24  # representative regular configurations for M(q), J(q)
SURVEY = 400  # random configurations for the largest g(q) and lever ||J_p[:, j]||
REGULAR_SIGMA_MIN = 0.1
# The representative configurations are looked for among at most this many random ones. If
# fewer than SAMPLES reach REGULAR_SIGMA_MIN (a small arm: sigma_min mixes metres and
# radians), the best ones are taken, down to REGULAR_RELATIVE x the largest sigma_min found.
REGULAR_TRIES = 2000
REGULAR_RELATIVE = 0.5
MASSLESS_KG_M2 = 1e-9  # the smallest eigenvalue of M(q) at or below this: M is singular
SINGULAR_EVERYWHERE = 1e-6  # the largest sigma_min below this: the task is out of reach
SHRINK = 0.8  # gains are scaled by this until the sampled loop is stable
# The damping acts on qdot - g_v qdot*_d of a streamed goal: all of it (an exogenous input to
# the loop, which changes none of its gains; docs/lyapunov.md, section 7)
GOAL_VELOCITY_GAIN = 1.0
# alpha of the settling damping alpha M(q) near the goal: chosen on this grid (1/s), the
# smallest whose slowest mode decays at least SETTLING_NEAR_BEST x as fast as the best's
SETTLING_RATES_PER_S = tuple(0.25 * i for i in range(81))
SETTLING_NEAR_BEST = 0.98
# Of the preferred posture against the distance to the measured joints, in the choice of a
# redundant arm's q* (inverse_kinematics.posture): nearest first, the posture breaks near-ties
POSTURE_WEIGHT = 0.1


@dataclass
class Design:
    """The designed gains and extensions, with the figures behind them (docs/gain_design.md)."""

    task: cl.Task
    joints: tuple[str, ...]
    base_link: str
    tip_link: str
    rate_hz: float
    kp: tuple[float, ...]
    kv: tuple[float, ...]
    lam: tuple[float, ...]
    shaping: Shaping
    figures: dict = field(default_factory=dict)
    armature: tuple[float, ...] = ()  # kg m^2 per joint, in M(q) of the design (the model's)
    payload_kg: float = 0.0  # the tip link's payload, in g(q) and M(q) of the design
    payload_com_tip_m: tuple[float, ...] = (0.0, 0.0, 0.0)  # where it is, in tip_link's frame
    # design_gains' options no other parameter holds, as it takes them (design_options)
    options: tuple[str, ...] = ()

    def gains(self, potential: str = 'tanh') -> cl.Gains:
        """Return the K_p, K_v, Lambda of the design as validated Gains for ``potential``."""
        return cl.Gains.create(potential, self.kp, self.kv, self.lam, self.task,
                               len(self.joints))

    def parameters(self, potential: str = 'tanh') -> dict:
        """Return the controller's live parameters of the design, by ROS parameter name."""
        values = {'potential': potential, 'kp': list(self.kp), 'kv': list(self.kv),
                  'lambda': list(self.lam), 'gravity_compensation': True}
        for spec in table.SHAPING:  # each extension from its Shaping attribute
            if hasattr(self.shaping, spec.attribute):
                value = getattr(self.shaping, spec.attribute)
                values[spec.name] = list(value) if isinstance(value, tuple) else value
        return values

    def structure(self) -> dict:
        """
        Return the read-only parameters of the design, by ROS parameter name.

        The robot, the task and the rate it was designed for; the URDF and the state checks at
        their defaults (a parameter file shows them).
        """
        defaults = {name: row(table.STRUCTURE, name).default
                    for name in ('robot_description', 'state_timeout', 'max_state_age')}
        return {'task': self.task.value, 'joints': list(self.joints),
                'armature': list(self.armature or [0.0] * len(self.joints)),
                'payload_mass': self.payload_kg, 'payload_com': list(self.payload_com_tip_m),
                'base_link': self.base_link, 'tip_link': self.tip_link, **defaults,
                'state_rate': self.rate_hz,
                'publish_rate_divider': max(1, int(round(self.rate_hz / 100.0))),
                'design_options': list(self.options)}


def _sample(model: RobotModel, rng: np.random.Generator, fraction: float) -> np.ndarray:
    lower = np.maximum(np.array(model.position_lower), -pi)
    upper = np.minimum(np.array(model.position_upper), pi)
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    return rng.uniform(mid - fraction * half, mid + fraction * half)


def _mass_matrix(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """M(q), or ValueError naming the joints that move no inertia (M singular)."""
    M = np.array(model.mass_matrix(q.tolist()))
    if np.linalg.eigvalsh(M)[0] > MASSLESS_KG_M2:
        return M
    light = [model.joint_names[j] for j in np.flatnonzero(np.diag(M) <= MASSLESS_KG_M2)]
    raise ValueError(f'M(q) is singular at q = {np.round(q, 3).tolist()}: joints '
                     f'{light or list(model.joint_names)} move no inertia there (links without '
                     "<inertial> in the URDF?); give the drives' rotor inertia (--armature) or "
                     'leave such joints out (--joints)')


def survey(model: RobotModel, task: cl.Task, seed: int = 0) -> dict:
    """
    Return what the rules need from the robot, measured on seeded random configurations.

    ``gravity_max`` and ``lever_max`` (the largest ||J_p[:, j]||, m) over SURVEY
    configurations within the limits (``gravity``: each one's |g(q)|, SURVEY x n);
    ``configurations``: SAMPLES regular ones (sigma_min of the task Jacobian >=
    REGULAR_SIGMA_MIN) within 90% of the ranges, with their task Jacobians and M(q), among at
    most REGULAR_TRIES random ones; if fewer are found, the best ones down to REGULAR_RELATIVE
    x the largest sigma_min (``regular_sigma_min`` the threshold used); ``inertia_min`` the
    smallest inertia a joint sees over all of them, ``1 / (M^-1)_jj`` (the others free to
    move; up to several times below M_jj on a coupled arm).
    """
    rng = np.random.default_rng(seed)
    n = model.n
    gravity, lever, inertia_min = [], np.zeros(n), np.full(n, np.inf)
    for _ in range(SURVEY):
        q = _sample(model, rng, 1.0)
        _, _, J = model.kinematics(q.tolist())
        gravity.append(np.abs(model.gravity(q.tolist())))
        lever = np.maximum(lever, np.linalg.norm(np.array(J)[:3], axis=0))
        inertia_min = np.minimum(inertia_min, seen_inertia(_mass_matrix(model, q)))
    regular, others = [], []
    for _ in range(REGULAR_TRIES):
        q = _sample(model, rng, 0.9)
        _, _, J = model.kinematics(q.tolist())
        rows = task.rows(np.array(J))
        sigma = sigma_min(rows)
        (regular if sigma >= REGULAR_SIGMA_MIN else others).append((sigma, q, rows))
        if len(regular) == SAMPLES:
            break
    threshold = REGULAR_SIGMA_MIN
    if len(regular) < SAMPLES:
        best = max(sigma for sigma, _, _ in regular + others)
        if best < SINGULAR_EVERYWHERE:
            raise ValueError(
                f'the {task.value} task Jacobian is singular at each of {REGULAR_TRIES} random '
                f'configurations of joints {list(model.joint_names)} (largest sigma_min '
                f'{best:.3g}): these joints cannot move {model.tip_link!r} in every direction '
                f'of the {task.value} task; choose another task, tip link or joints')
        threshold = REGULAR_RELATIVE * best
        others.sort(key=lambda c: -c[0])
        regular += [c for c in others if c[0] >= threshold][:SAMPLES - len(regular)]
    configs = []
    for _, q, rows in regular:
        M = _mass_matrix(model, q)
        inertia_min = np.minimum(inertia_min, seen_inertia(M))
        configs.append((q, rows, M))
    gravity = np.array(gravity)
    return {'gravity_max': gravity.max(axis=0), 'gravity': gravity,
            'lever_max': lever, 'inertia_min': inertia_min,
            'configurations': configs, 'regular_sigma_min': threshold}


def task_torque_bound(lever_max: np.ndarray, kp: Sequence[float], task: cl.Task,
                      large_error_gain: float = 0.0) -> np.ndarray:
    """
    A-priori bound of the tanh law's potential torque per joint (docs/gain_design.md, 2).

    |tau_j| <= ||J_p[:, j]|| ||k_p||_2 + 1/2 (||k_o||_2 + k_L): |tanh| <= 1 per row,
    ||Q_o^T w|| <= ||w|| / 2, a revolute column of J_o has norm 1; each term where the task
    has those rows. The quadratic law obeys the same bound on the orientation rows
    (||e|| <= 1) and on the position rows while ||p_d - p|| <= sqrt(3) m.
    """
    task = cl.Task(task)
    kp = np.asarray(kp, dtype=float)
    bound = np.zeros(lever_max.size)
    if task.has_orientation:
        bound = bound + QO * (float(np.linalg.norm(kp[-3:])) + large_error_gain)
    if task.has_position:
        bound = bound + lever_max * float(np.linalg.norm(kp[:3]))
    return bound


def _damping(configs, kp: np.ndarray, lam: np.ndarray, extra: np.ndarray,
             task: cl.Task = cl.Task.POSE) -> np.ndarray:
    """
    K_v per joint: damping ratio DAMPING_RATIO for the tanh law's stiffness (median).

    ``extra`` is the joint stiffness the goal-configuration term adds at the goal (N m/rad).
    """
    values = []
    for _, rows, M in configs:
        k_t = np.diag(joint_stiffness(rows, kp * lam, task)) + extra
        values.append(2.0 * DAMPING_RATIO * np.sqrt(np.diag(M) * k_t))
    return np.median(values, axis=0)


def _inertial_damping(configs, slope: np.ndarray, extra: np.ndarray,
                      task: cl.Task = cl.Task.POSE) -> np.ndarray:
    """
    Return ``c`` per joint: the damping ``c_j sqrt(M_jj(q))`` of INERTIAL_DAMPING_RATIO.

    ``c_j = 2 zeta sqrt(k_j)``, ``k_j`` the joint's median stiffness at the goal (the task's
    slope ``slope`` and the goal-configuration term's ``extra``): where the arm is heavier
    than the K_v that the lightest configuration allows can damp, the damping keeps the ratio
    zeta (the tick caps it at ``beta I_j(q)``, :func:`inertial_damping_rate`).
    """
    k = np.median([np.diag(joint_stiffness(rows, slope, task)) for _, rows, _ in configs],
                  axis=0) + extra
    return 2.0 * INERTIAL_DAMPING_RATIO * np.sqrt(k)


def _round_up(value: float) -> float:
    """Return ``value`` to 4 significant figures, never below it (a floor stays met)."""
    rounded = float(f'{value:.4g}')
    return rounded if rounded >= value else float(f'{value * (1.0 + 5e-4):.4g}')


def _joint_unstable(inertia: float, stiffness: float, kv: float, b_max: float, delays,
                    dt_s: float) -> bool:
    """
    Return True if a joint's spring is unstable on its least inertia with either damping.

    There the tick damps with ``k_v`` or, with the inertial damping, up to ``b_max``
    (``beta I_min``): both ends are checked (:func:`joint_spectral_radius`, with the margins).
    """
    return max(joint_spectral_radius(inertia, stiffness, kv, delays, dt_s),
               joint_spectral_radius(inertia, stiffness, b_max, delays, dt_s)) >= 1.0


def inertial_damping_rate(delays: Sequence[int], dt_s: float) -> float:
    """
    Return ``beta`` (1/s): DAMPER_SAFETY x the damping per kg m^2 the sampled loop tolerates.

    The largest damping ``D`` with ``v_k+1 = v_k - dt D / I v_k-d`` stable is proportional to
    ``I`` (:func:`largest_stable_damping`), so its ratio to ``I`` is one number for the rate
    and the delays (with the margin of one tick more); ``b_max,j`` is this times ``I_min,j``.
    """
    return DAMPER_SAFETY * largest_stable_damping(1.0, checked_delays(delays), dt_s)


def _cruising_guide(configs, kp: np.ndarray, lam: np.ndarray, bound: np.ndarray,
                    push_max: np.ndarray, cruise: np.ndarray, b_max: np.ndarray,
                    task: cl.Task = cl.Task.POSE,
                    kv_floor: Optional[np.ndarray] = None,
                    ramp_rad: float = GUIDE_RAMP_RAD) -> np.ndarray:
    """
    Return the goal-configuration gains T_j: GUIDE_OVER_TASK x the task bound, or more.

    A joint whose push far from the goal, ``bound + T``, would drive it slower than ``cruise``
    against its damping K_v (which grows with the ramp's stiffness T / w) gets a larger T, up
    to what its budget leaves, ``push_max - bound``. So a strong joint is not held to the pace
    that the task bound, set by the weakest joint, gives it (the Panda's 87 N m shoulder
    beside its 12 N m wrist). ``kv_floor``: the least K_v per joint (default none);
    ``ramp_rad`` the term's ramp w.
    """
    guide = GUIDE_OVER_TASK * bound
    ceiling = np.maximum(push_max - bound, guide)
    floor = np.zeros(len(bound)) if kv_floor is None else kv_floor
    for _ in range(60):
        kv = np.minimum(np.maximum(_damping(configs, kp, lam, guide / ramp_rad, task),
                                   floor), b_max)
        slow = ((bound + guide) / kv < cruise) & (guide < ceiling)
        if not slow.any():
            break
        guide = np.where(slow, np.minimum(guide * CRUISE_STEP, ceiling), guide)
    return guide


def approach_ramp(cruise_rad_s: np.ndarray, prismatic: Sequence[bool],
                  approach_time_s: Optional[float] = None) -> float:
    """
    Return the goal-configuration term's ramp ``w`` (rad): GUIDE_RAMP_RAD, or less if asked.

    Near ``q*`` a joint that cruises at ``v`` against the damping that holds it there
    approaches ``q*`` at about the rate ``v / w``, overdamped or at a damping ratio of 0.71
    alike (docs/gain_design.md, section 5, "The ramp"): the linear approach's time constant is
    ``w / v``. With ``approach_time_s`` the ramp is at most that time at the slowest cruise of a
    revolute joint (a slide's ramp would be metres); None keeps GUIDE_RAMP_RAD. Rounded to 3
    significant digits, as the file writes it.
    """
    if approach_time_s is None:
        return GUIDE_RAMP_RAD
    if not (isfinite(approach_time_s) and approach_time_s > 0.0):
        raise ValueError(f'approach_time_s must be finite and > 0, got {approach_time_s}')
    rotating = ~np.asarray(prismatic, dtype=bool)
    if not rotating.any():
        return GUIDE_RAMP_RAD
    return min(GUIDE_RAMP_RAD,
               float(f'{approach_time_s * float(np.min(cruise_rad_s[rotating])):.3g}'))


def holding_damping(push_nm: np.ndarray, kv: np.ndarray, b_max: np.ndarray,
                    ceiling_rad_s: np.ndarray, speed_cap_rad_s: np.ndarray,
                    share: float = SPEED_DAMPING_SHARE) -> np.ndarray:
    """
    Return K_v per joint, raised where needed so the damping holds ``push_nm`` at the ceiling.

    The cubic damping's slope, ``k_v (1 + 3 v^2 / v_c^2)`` up to ``v_m`` (``speed_cap_rad_s``),
    may reach ``b_max`` at most (docs/gain_design.md, section 5), so at a speed ``v = a v_m``
    it brakes with at most ``v (k_v + a^2 (b_max - k_v) / 3)``: a fifth of ``b_max v`` at
    ``a = 0.8`` if ``k_v`` is small. Where that is below the push, the linear part must carry
    more: ``k_v = (push / v - a^2 b_max / 3) / (1 - a^2 / 3)``, at most ``share b_max`` (a
    push within :func:`holding_limit` needs no more).
    """
    a2 = np.minimum(ceiling_rad_s / speed_cap_rad_s, 1.0) ** 2
    needed = (push_nm / ceiling_rad_s - a2 * b_max / 3.0) / (1.0 - a2 / 3.0)
    return np.minimum(np.maximum(kv, needed), np.maximum(kv, share * b_max))


def holding_limit(b_max: np.ndarray, ceiling_rad_s: np.ndarray, speed_cap_rad_s: np.ndarray,
                  share: float = SPEED_DAMPING_SHARE) -> np.ndarray:
    """
    Return the largest push per joint the damping can hold at the ceiling (N m).

    With ``k_v = share b_max`` and the cubic part at its slope limit (:func:`holding_damping`):
    ``v (k_v + a^2 (b_max - k_v) / 3)`` at ``v`` = the ceiling, ``a = v / v_m``.
    """
    a2 = np.minimum(ceiling_rad_s / speed_cap_rad_s, 1.0) ** 2
    kv = share * b_max
    return ceiling_rad_s * (kv + a2 * (b_max - kv) / 3.0)


def design(model: RobotModel, task: cl.Task, rate_hz: float = 1000.0,
           effort_limits_nm: Optional[Sequence[float]] = None,
           friction_nm: Optional[Sequence[float]] = None, delays: Sequence[int] = (1,),
           seed: int = 0, friction_learning: float = FRICTION_LEARNING,
           cruise_fraction: float = CRUISE_FRACTION,
           preferred_configuration_rad: Optional[Sequence[float]] = None,
           friction_effort_share: float = DEFAULT_FRICTION_EFFORT_SHARE,
           approach_time_s: Optional[float] = None) -> Design:
    """
    Compute gains and extensions for ``model`` and ``task`` (docs/gain_design.md).

    ``effort_limits_nm`` default the URDF's; ``friction_nm`` are the Coulomb estimates per
    joint (default zeros: no friction compensation); ``delays`` the ticks of delay the
    sampled loop must be stable with; ``friction_learning`` how much more than the estimate
    (x the estimate) the regulator may learn at rest, and on a joint without an estimate
    ``friction_effort_share`` of its effort limit (at most what changes its speed by
    ``TICK_SPEED_SHARE`` of its velocity limit in one tick); ``cruise_fraction`` of the velocity
    limits the speed far from the goal that the goal-configuration gain is raised towards and
    the cubic damping holds (``_cruising_guide``); ``preferred_configuration_rad`` the
    posture a redundant arm's q* leans to (default: the middle of the ranges);
    ``approach_time_s`` shortens the goal-configuration ramp to at most that time at the
    slowest joint's cruise (:func:`approach_ramp`; default None: 0.25 rad). Raises
    ValueError if a joint has no
    torque left, or if the goal-configuration term of a joint cannot stay above the task
    term's bound (it would no longer lead that joint round its stop).
    """
    task = cl.Task(task)
    n = model.n
    rate_hz = check_state_rate(rate_hz, 'rate_hz')
    dt_s = 1.0 / rate_hz
    effort = np.array(model.effort_limits if effort_limits_nm is None else effort_limits_nm,
                      dtype=float)
    friction = np.zeros(n) if friction_nm is None else np.array(friction_nm, dtype=float)
    if effort.size != n or friction.size != n:
        raise ValueError(f'expected {n} effort limits and friction values')
    stuck = np.flatnonzero(np.array(model.position_upper) <= np.array(model.position_lower))
    if stuck.size:  # revolute joints without <limit lower upper> have [0, 0]
        raise ValueError(
            f'joints {[model.joint_names[j] for j in stuck]} have an empty range '
            f'({[(model.position_lower[j], model.position_upper[j]) for j in stuck]} in the '
            'URDF, upper <= lower; a <limit> without lower and upper gives 0 and 0): they '
            'cannot move; give them their limits in the URDF, or leave them out (--joints)')
    unlimited = ~np.isfinite(effort) | (effort <= 0.0)
    if unlimited.any():  # the budget is a share of the effort limit: none, no design
        raise ValueError(
            f'joints {[model.joint_names[j] for j in np.flatnonzero(unlimited)]} have no '
            f'effort limit ({effort[unlimited].tolist()} N m; 0 or absent in a URDF means none '
            "given): the gains are sized within the drives' limits, so give them "
            '(--effort-limits, one per joint)')
    data = survey(model, task, seed)
    configs = data['configurations']
    lever = data['lever_max'] if task.has_position else np.zeros(n)
    if not 0.0 < cruise_fraction <= 1.0:
        raise ValueError(f'cruise_fraction must be in (0, 1], got {cruise_fraction}')
    if preferred_configuration_rad is not None:
        preferred = np.array(preferred_configuration_rad, dtype=float)
        lower, upper = np.array(model.position_lower), np.array(model.position_upper)
        if (preferred.size != n or not np.all(np.isfinite(preferred))
                or np.any(preferred < lower) or np.any(preferred > upper)):
            raise ValueError(f'the preferred configuration {preferred.tolist()} must be {n} '
                             'finite values within the joint limits '
                             f'{list(zip(model.position_lower, model.position_upper))}')
    if not np.isfinite(friction_learning) or friction_learning < 0.0:
        raise ValueError(f'friction_learning must be finite and >= 0, got {friction_learning}')
    if not np.isfinite(friction_effort_share) or not 0.0 <= friction_effort_share < 0.5:
        raise ValueError('friction_effort_share must be in [0, 0.5), got '
                         f'{friction_effort_share}')
    inertia = data['inertia_min']
    velocity = np.array(model.velocity_limits, dtype=float)
    velocity = np.where(np.isfinite(velocity) & (velocity > 0), velocity, DEFAULT_VELOCITY)
    # a joint with an estimate learns relative to it; one without, a share of its effort, at
    # most what changes its speed by TICK_SPEED_SHARE x its velocity limit in one tick on the
    # least inertia it sees: the learned push fades out from a speed far enough below the limit
    # (docs/lyapunov.md, section 4, says what this bounds and what it does not)
    per_tick = TICK_SPEED_SHARE * velocity * inertia / dt_s
    learning = np.where(friction > 0.0, friction_learning * friction,
                        np.minimum(friction_effort_share * effort, per_tick))
    unheld = (data['gravity'] > effort).mean(axis=0)
    if np.any(unheld > UNHELD_SHARE_MAX):
        weak = np.flatnonzero(unheld > UNHELD_SHARE_MAX)
        raise ValueError(
            'the arm cannot hold itself up in most of its configurations: joints '
            f'{[model.joint_names[j] for j in weak]} need more than their effort limits '
            f'{effort[weak].tolist()} against gravity in '
            f'{[round(100.0 * unheld[j]) for j in weak]}% of {SURVEY} random configurations '
            f'within the limits (up to {np.round(data["gravity_max"][weak], 3).tolist()} N m): '
            'check the effort limits of the URDF, and that gravity is along -z of the base '
            f'link {model.base_link!r} (give --base-link a level link). An arm that a spring '
            "or a counterweight holds up (the PR2's) needs that in its URDF: this design and "
            "the controller's g(q) take the drives to carry the arm's weight")
    # gravity is spoken for, up to GRAVITY_RESERVE_SHARE of the effort (gravity_warnings)
    reserve = np.minimum(data['gravity_max'], GRAVITY_RESERVE_SHARE * effort)
    budget = TORQUE_SHARE * (effort - reserve - friction - learning)
    if np.any(budget <= 0.0):  # friction, learned or estimated, took the rest of the effort
        short = np.flatnonzero(budget <= 0.0)
        raise ValueError(f'no torque left for the potential on joints '
                         f'{[model.joint_names[j] for j in short]}: '
                         f'effort {effort.tolist()}, reserved for gravity '
                         f'{np.round(reserve, 3).tolist()} (the largest over {SURVEY} '
                         f'configurations within the limits, at most {GRAVITY_RESERVE_SHARE:g} '
                         'x the effort), friction and its learnable share '
                         f'{np.round(friction + learning, 3).tolist()}: check the friction '
                         'estimates (--friction), what may be learned on top of them '
                         '(--friction-learning, --friction-effort-share) and the effort '
                         'limits')
    # Speed rule: never ask a joint for more than its damping can hold at SPEED_MARGIN x its
    # velocity limit (holding_limit; b_max: the largest damping the sampled loop tolerates on
    # its smallest inertia, halved); K_v is raised below (holding_damping) where the cubic
    # part alone cannot. A joint without a URDF velocity limit: b_max x DEFAULT_VELOCITY.
    b_max = np.array([DAMPER_SAFETY * largest_stable_damping(inertia[j],
                                                             checked_delays(delays), dt_s)
                      for j in range(n)])
    # b_max per kg m^2, for the inertial damping: the tick brings every mode of its damping,
    # coupled through M(q), down to it, so the damping alone is stable with the margins
    beta = inertial_damping_rate(delays, dt_s)
    limited_speed = np.array([isfinite(v) and v > 0.0 for v in model.velocity_limits])
    ceiling = np.where(limited_speed, SPEED_MARGIN * velocity, velocity)
    push_max = np.minimum(budget, np.where(limited_speed,
                                           holding_limit(b_max, ceiling, velocity),
                                           b_max * velocity))
    cap = push_max / (1.0 + GUIDE_OVER_TASK)  # what the task potential may ask of a joint

    # K_p: the largest gains within the a-priori bound (pose: the largest k_p k_o).
    unit_o = QO * sqrt(3.0)  # bound per unit isotropic k_o
    if task is cl.Task.ORIENTATION:
        k_o, k_p = float(np.min(cap) / unit_o), 0.0
    elif task is cl.Task.POSITION:
        unit_p = lever * sqrt(3.0)
        k_o, k_p = 0.0, float(np.min(cap[unit_p > 0] / unit_p[unit_p > 0]))
    else:
        unit_p = lever * sqrt(3.0)
        best = (0.0, 0.0, 0.0)
        for k_o_try in np.linspace(0.0, float(np.min(cap)) / unit_o, 2001)[1:]:
            room = cap - unit_o * k_o_try
            if np.any(room < 0.0):
                break
            k_p_try = float(np.min(room[unit_p > 0] / unit_p[unit_p > 0]))
            if k_o_try * k_p_try > best[0]:
                best = (k_o_try * k_p_try, k_o_try, k_p_try)
        k_o, k_p = best[1], best[2]
    lam_o = LAMBDA_ORIENTATION
    lam_p = 4.0 / POSITION_SATURATION_M
    kp = np.array(([k_p] * 3 if task.has_position else [])
                  + ([k_o] * 3 if task.has_orientation else []))
    lam = np.array(([lam_p] * 3 if task.has_position else [])
                   + ([lam_o] * 3 if task.has_orientation else []))

    # The goal-configuration term (GUIDE_OVER_TASK x the task bound, over a ramp) adds joint
    # stiffness at q*; K_v damps the sum. The sampled-loop check: shrink Lambda (down to 1),
    # then K_p, until every representative configuration is stable with every delay (and the
    # margins), for both potentials, and no joint whose damping the loop caps is left with a
    # damping ratio below DAMPING_RATIO_MIN; a joint whose own mass-spring-damper (smallest
    # inertia) is unstable gets a smaller goal-configuration gain.
    cruise = cruise_fraction * velocity
    ramp = approach_ramp(cruise, model.prismatic, approach_time_s)
    guide_cap = np.full(n, np.inf)  # per joint: lowered where the capped damping is too weak
    # The position rows leave a joint whose axis passes through the tip (a wrist roll) with
    # little or no task torque; the goal-configuration term alone holds it. Its terms are
    # sized as if the task asked of it what the orientation rows would: the weakest share.
    floor = 0.0 if task.has_orientation else float(np.min(cap))
    # K_v per joint at least this: where the other joints' pushes would carry it too fast
    kv_floor = np.zeros(n)
    carry_most = SPEED_DAMPING_SHARE * b_max
    rotating = ~np.array(model.prismatic)  # a slide is not carried (docs/gain_design.md)
    pace, carry_passes = None, 0
    rho = {}
    for _ in range(200):
        bound = np.maximum(task_torque_bound(lever, kp, task), floor)
        # a joint whose K_v the carried speed raised gets T_j towards the linear pace it had
        # (its approach near the goal, at the rate T_j / (w K_v), about as fast), as its
        # budget allows
        aim = (cruise if pace is None
               else np.where(kv_floor > 0.0, np.maximum(cruise, pace), cruise))
        guide = np.minimum(_cruising_guide(configs, kp, lam, bound, push_max, aim, b_max,
                                           task, kv_floor, ramp),
                           np.maximum(guide_cap, GUIDE_OVER_TASK * bound))
        kv = np.minimum(np.maximum(_damping(configs, kp, lam, guide / ramp, task),
                                   kv_floor), b_max)
        for j in range(n):
            while _joint_unstable(inertia[j], guide[j] / ramp, kv[j], b_max[j],
                                  delays, dt_s):
                guide[j] *= SHRINK
        extra = guide / ramp
        kv = np.minimum(np.maximum(_damping(configs, kp, lam, extra, task), kv_floor), b_max)
        kv = np.where(limited_speed, holding_damping(bound + guide, kv, b_max, ceiling,
                                                     velocity), kv)
        carried = carried_speed(configs, kv, bound + guide)
        if pace is None:  # the linear pace (push / K_v) before any raise
            pace = np.divide(bound + guide, kv, out=np.zeros(n), where=kv > 0.0)
        # ... as far as the joint's push can grow with it (within push_max) at that pace
        wanted = np.minimum(np.minimum(kv * carried / (CARRIED_SPEED_SHARE * velocity),
                                       carry_most),
                            np.divide(push_max, pace, out=np.full(n, np.inf), where=pace > 0.0))
        carried_fast = (wanted > CARRY_STEP * np.maximum(kv, kv_floor)) & rotating
        if carried_fast.any() and carry_passes < CARRY_PASSES:  # more damping, then again
            kv_floor = np.where(carried_fast, wanted, kv_floor)
            carry_passes += 1
            continue
        inertial = _inertial_damping(configs, kp * lam, extra, task)
        rho = worst_rho(configs, kp, kv, lam, extra, delays, dt_s, task, inertial, beta)
        zeta = median_damping_ratio(configs, kp * lam, kv, extra, task, inertial, beta)
        if max(rho.values()) < 1.0 and zeta.min() >= DAMPING_RATIO_MIN:
            break
        # A joint whose damping the loop caps, under-damped because of its own
        # goal-configuration stiffness: lower that joint's term, not every task row.
        own = ((zeta < DAMPING_RATIO_MIN) & (kv >= b_max * (1.0 - 1e-9))
               & (guide > GUIDE_OVER_TASK * bound * (1.0 + 1e-9)))
        # whatever is lowered next, the carried speeds are estimated anew from no floor
        kv_floor, pace, carry_passes = np.zeros(n), None, 0
        if max(rho.values()) < 1.0 and own.any():
            guide_cap = np.where(own, guide * SHRINK, guide_cap)
            continue
        if lam.min() > 1.0:
            lam = np.maximum(lam * SHRINK, 1.0)
        else:
            kp = kp * SHRINK
    else:
        raise ValueError(f'no stable gains found (spectral radius {rho})')
    weak = [model.joint_names[j] for j in range(n) if guide[j] <= bound[j]]
    if weak:
        raise ValueError(
            f'the goal-configuration term of {weak} fell to {np.round(guide, 4).tolist()} N m, '
            f'at or below the task bound {np.round(bound, 4).tolist()} N m, to keep the sampled '
            'loop stable: it could not lead those joints round their stops. Give the loop more '
            'room (a higher --rate, fewer --delays) or a robot with more inertia on them')

    # Joint-limit band and goal-configuration term, checked per joint on its smallest inertia.
    # At the stop the band holds the task term's bound with a margin, and what the joint's K_v
    # brakes at the speed ceiling, within its budget: a joint that the others carry into its
    # band is stopped there, and one that starts inside is pushed out no faster than the
    # ceiling once K_v balances it (docs/gain_design.md, section 5).
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    limited = np.isfinite(lower) & np.isfinite(upper) & (upper - lower < FULL_TURN_RAD)
    margin = 0.0
    limit_gain = np.zeros(n)
    if np.any(limited):
        half = 0.5 * float(np.min((upper - lower)[limited]))
        margin = round(min(LIMIT_MARGIN_MAX_RAD, LIMIT_MARGIN_FRACTION * half), 3)
        for j in np.flatnonzero(limited):
            stop_nm = max(LIMIT_OVER_TASK * bound[j],
                          min(budget[j], SPEED_MARGIN * velocity[j] * kv[j]))
            k = min(stop_nm, effort[j] - reserve[j]) / margin
            while _joint_unstable(inertia[j], k, kv[j], b_max[j], delays, dt_s):
                k *= SHRINK
            limit_gain[j] = k

    # Cubic damping: linear near rest, it holds the cruising speed far from the goal; its
    # slope k_v (1 + 3 v^2 / v_c^2) must not exceed b_max up to the velocity limit.
    push = bound + guide  # the most the potentials ask of a joint, far from the goal
    damping_speed = np.zeros(n)
    for j in range(n):
        if push[j] / kv[j] <= cruise[j] or b_max[j] <= kv[j]:
            continue  # linear damping alone keeps it slow enough, or nothing more is stable
        v_c = max(sqrt(cruise[j] ** 3 / (push[j] / kv[j] - cruise[j])),
                  velocity[j] * sqrt(3.0 * kv[j] / (b_max[j] - kv[j])))
        if v_c < NEGLIGIBLE_CUBIC * velocity[j]:  # else it brakes < 1e-4 of k_v v: none
            damping_speed[j] = v_c
    terminal = cruising_speed(push, kv, damping_speed, velocity)  # where K_v alone damps
    kp_r = tuple(float(f'{v:.4g}') for v in kp)
    kv_r = tuple(float(f'{v:.4g}') for v in kv)
    lam_r = tuple(float(f'{v:.4g}') for v in lam)
    # c from the values as written, a little above the ratio, so the floor survives rounding
    guide_r = guide.round(3)
    inertial = (1.0 + 1e-3) * _inertial_damping(configs, np.array(kp_r) * np.array(lam_r),
                                                guide_r / ramp, task)
    inertial = np.array([_round_up(v) for v in inertial])
    beta_r = float(f'{beta:.4g}')  # as written
    # The settling damping alpha M near the goal: the alpha that makes the slowest coupled
    # mode decay (nearly) fastest, its median over the configurations (docs/gain_design.md)
    settling, decay_before, decay_after = settling_rate(
        configs, np.array(kp_r) * np.array(lam_r), np.array(kv_r), guide_r / ramp,
        SETTLING_RATES_PER_S, SETTLING_NEAR_BEST, task, inertial, beta_r)
    shaping = Shaping.create(
        n, joint_limit_margin=margin, joint_limit_gain=limit_gain.round(3).tolist(),
        friction_compensation=friction.tolist(), friction_velocity=FRICTION_VELOCITY_RAD_S,
        friction_learning_limit=learning.tolist(),
        friction_learning_time=FRICTION_LEARNING_TIME_S,
        friction_error_band=FRICTION_ERROR_BAND,
        friction_position_band=FRICTION_POSITION_BAND_M,
        configuration_gain=guide_r.tolist(), configuration_radius=GUIDE_RADIUS_RAD,
        configuration_ramp=ramp, damping_speed=damping_speed.round(3).tolist(),
        inertial_damping=inertial.tolist(),
        inertial_damping_rate=beta_r,
        settling_damping_rate=settling,
        armature_estimation_limit=[float(f'{v:.4g}') for v in
                                   effort / ESTIMATED_ARMATURE_ACCELERATION_RAD_S2],
        gain_redesign=True,
        goal_velocity_gain=GOAL_VELOCITY_GAIN,
        preferred_configuration=(model.middle_of_ranges() if preferred_configuration_rad is None
                                 else preferred_configuration_rad),
        posture_weight=POSTURE_WEIGHT)
    extra = configuration_stiffness(shaping)
    inertial = np.array(shaping.inertial_damping)
    beta = shaping.inertial_damping_rate_per_s
    # ... and the median cruise over the configurations, with the inertial damping there
    typical = np.median([cruising_speed(push, kv, damping_speed, velocity,
                                        damping_at(kv, inertial, beta, M))
                         for _, _, M in configs], axis=0)
    final = worst_rho(configs, np.array(kp_r), np.array(kv_r), np.array(lam_r), extra,
                      delays, dt_s, task, inertial, beta, settling)
    if max(final.values()) >= 1.0:  # alpha M tipped the sampled loop over: none, then
        settling, decay_after = 0.0, decay_before
        shaping = replace(shaping, settling_damping_rate_per_s=0.0)
        final = worst_rho(configs, np.array(kp_r), np.array(kv_r), np.array(lam_r), extra,
                          delays, dt_s, task, inertial, beta)
    ratios = {'quadratic': median_damping_ratio(configs, np.array(kp_r), np.array(kv_r), extra,
                                                task, inertial, beta),
              'tanh': median_damping_ratio(configs, np.array(kp_r) * np.array(lam_r),
                                           np.array(kv_r), extra, task, inertial, beta)}
    figures = {
        'effort_limits_nm': effort, 'gravity_max_nm': data['gravity_max'],
        'gravity_reserve_nm': reserve,
        'friction_nm': friction, 'budget_nm': budget, 'task_bound_nm': bound,
        'guide_nm': guide, 'limit_at_stop_nm': limit_gain * margin,
        'lever_max_m': data['lever_max'], 'inertia_min': inertia,
        'spectral_radius': final, 'delays': tuple(delays),
        'damping_ratio': ratios, 'terminal_speed_rad_s': np.array(terminal),
        'carried_speed_rad_s': carried_speed(configs, np.array(kv_r), bound + guide_r),
        'damping_max_nms': b_max, 'carry_damping_nms': kv_floor,
        'prismatic': np.array(model.prismatic),
        'velocity_limits_rad_s': velocity, 'friction_learning': friction_learning,
        'cruise_fraction': cruise_fraction,
        'regular_sigma_min': data['regular_sigma_min'],
        'warnings': (friction_warnings(model, friction, learning)
                     + gravity_warnings(model, effort, data['gravity'])
                     + inertia_warnings(model, effort, inertia)
                     + speed_warnings(model)
                     + learning_warnings(model, friction, learning,
                                         friction_effort_share * effort)
                     + guide_warnings(model, guide, bound)),
        'speed_ceiling_rad_s': np.where(limited_speed, ceiling, np.inf),
        'typical_speed_rad_s': typical,
        'time_to_goal_s': time_to_goal_s(typical, configs, np.array(kp_r),
                                         np.array(kv_r), np.array(lam_r), extra, dt_s,
                                         task=task, inertial=inertial, rate_per_s=beta,
                                         settling_per_s=settling),
        'settling_decay_per_s': (decay_before, decay_after),
        'friction_effort_share': friction_effort_share,
    }
    return Design(task, model.joint_names, model.base_link, model.tip_link, rate_hz, kp_r,
                  kv_r, lam_r, shaping, figures, model.armature, model.payload_kg,
                  model.payload_com_tip_m,
                  options_argv(effort_limits_nm, delays, friction_learning,
                               friction_effort_share, cruise_fraction, approach_time_s))


def options_argv(effort_limits_nm: Optional[Sequence[float]], delays: Sequence[int],
                 friction_learning: float, friction_effort_share: float,
                 cruise_fraction: float, approach_time_s: Optional[float]) -> tuple[str, ...]:
    """
    Return the options of a design that no parameter holds, as design_gains takes them.

    Those at design_gains' defaults are left out (``gain_cli.parse_design_options`` reads the
    rest back); a number is written so that it reads back the same.
    """
    argv: list[str] = []
    if effort_limits_nm is not None:
        argv += ['--effort-limits', *(repr(float(e)) for e in effort_limits_nm)]
    if tuple(int(d) for d in delays) != (1,):
        argv += ['--delays', *(str(int(d)) for d in delays)]
    for flag, value, default in (('--friction-learning', friction_learning, FRICTION_LEARNING),
                                 ('--friction-effort-share', friction_effort_share,
                                  DEFAULT_FRICTION_EFFORT_SHARE),
                                 ('--cruise-fraction', cruise_fraction, CRUISE_FRACTION)):
        if float(value) != default:
            argv += [flag, repr(float(value))]
    if approach_time_s is not None:
        argv += ['--approach-time', repr(float(approach_time_s))]
    return tuple(argv)


def guide_warnings(model: RobotModel, guide: np.ndarray, bound: np.ndarray) -> list[str]:
    """
    Warn of joints whose goal-configuration gain the sampled loop held below GUIDE_OVER_TASK.

    ``T_j`` stays above the task bound (the design fails otherwise), so the term still leads
    the joint round its stops (docs/lyapunov.md, section 5), but where the two terms pull it
    opposite ways its net push is less than the task bound.
    """
    low = [f'{model.joint_names[j]} ({guide[j] / bound[j]:.2f} x)'
           for j in range(len(guide)) if guide[j] < GUIDE_OVER_TASK * bound[j] * (1.0 - 1e-9)]
    if not low:
        return []
    return [f'the goal-configuration term is held below {GUIDE_OVER_TASK:g} x the task bound on '
            f'{", ".join(low)} to keep the sampled loop stable on the least inertia those '
            'joints see: where it and the task term pull them opposite ways, they move slowly. '
            'Their rotor inertia (--armature), if the URDF leaves it out, gives the loop room']


def gravity_warnings(model: RobotModel, effort: np.ndarray,
                     gravity: np.ndarray) -> list[str]:
    """
    Warn of joints whose gravity torque takes more than GRAVITY_RESERVE_SHARE of their effort.

    ``gravity`` is |g(q)| at the survey's configurations (SURVEY x n). The budget reserves
    only that share for gravity, so such an arm is designed rather than refused; where a
    joint needs more, the regulator has less than its budget, and past the effort limit the
    clamped torque cannot hold the arm up. ``goal_check`` warns of goals there.
    """
    heavy = gravity > GRAVITY_RESERVE_SHARE * effort
    over = gravity > effort
    names = [f'{model.joint_names[j]} (up to {gravity[:, j].max():.3g} N m of its '
             f'{effort[j]:.3g}; more than {GRAVITY_RESERVE_SHARE:g} x it in '
             f'{100.0 * heavy[:, j].mean():.0f}% of the configurations, more than all of it in '
             f'{100.0 * over[:, j].mean():.0f}%)'
             for j in np.flatnonzero(heavy.any(axis=0))]
    if not names:
        return []
    return [f'gravity takes more than {GRAVITY_RESERVE_SHARE:g} x the effort limit somewhere '
            f'within the limits ({SURVEY} random configurations): {", ".join(names)}. The '
            f'design reserves {GRAVITY_RESERVE_SHARE:g} x the effort limit for gravity; where '
            'a joint needs more the torque saturates and the arm may sag, and the goal check '
            "warns of such goals. Check the URDF's effort limits, and that gravity is along "
            f'-z of the base link {model.base_link!r} (--base-link a level link)']


def inertia_warnings(model: RobotModel, effort: np.ndarray, inertia: np.ndarray) -> list[str]:
    """
    Warn of joints whose inertia is implausibly small for a geared drive, with no armature.

    A joint that its effort limit would accelerate faster than PLAUSIBLE_ACCELERATION_RAD_S2
    on the smallest inertia it sees, ``1 / (M^-1)_jj``, is most likely a URDF without the
    rotor inertia its drive reflects (gear ratio squared times the rotor's); the damping the
    sampled loop tolerates on it is then far below what the real joint takes.
    """
    if any(a > 0.0 for a in model.armature):
        return []
    fast = [f'{name} ({e / i:.3g} rad/s^2 on {i:.3g} kg m^2)'
            for name, e, i in zip(model.joint_names, effort, inertia)
            if e / i > PLAUSIBLE_ACCELERATION_RAD_S2]
    if not fast:
        return []
    return [f'implausibly light for a geared drive: {", ".join(fast)} on the effort limit. '
            "The URDF's inertias likely leave out the drives' rotor inertia, and the gains are "
            'sized for that light a joint (slow, weakly damped). Give the rotor inertia with '
            f'--armature (e.g. --armature {SUGGESTED_ARMATURE:g} kg m^2 per joint)']


def speed_warnings(model: RobotModel) -> list[str]:
    """
    Warn of URDF velocity limits no drive has: placeholders, and none at all.

    The speed rule and the speed guard hold a joint to 0.8 of its URDF limit; a placeholder
    (above PLAUSIBLE_SPEED_RAD_S) holds nothing back, so a light joint that the others carry
    may be thrown into its stops (iCub's arm, docs/reach.md, "the stop guard"). A joint without
    a limit (0 in the URDF, or a continuous joint without one) is designed for
    DEFAULT_VELOCITY, and the speed guard leaves it alone.
    """
    pairs = list(zip(model.joint_names, model.velocity_limits))
    fast = [f'{name} ({v:g} rad/s)' for name, v in pairs
            if isfinite(v) and v > PLAUSIBLE_SPEED_RAD_S]
    none = [name for name, v in pairs if not (isfinite(v) and v > 0.0)]
    warnings = []
    if fast:
        warnings.append(
            f'velocity limits no drive has: {", ".join(fast)}, likely placeholders. The speeds '
            'are held to 0.8 of the URDF limits, so on these joints nothing holds them back '
            'but the damping, and a light joint the others carry may be thrown into its '
            "stops. Give the drives' real velocity limits in the URDF")
    if none:
        warnings.append(
            f'no velocity limit in the URDF (0 or none): {", ".join(none)}. They are designed '
            f'to cruise at a share of {DEFAULT_VELOCITY:.3g} rad/s, and the speed guard does '
            "not hold them back; a drive that faults on speed may. Give the drives' velocity "
            'limits in the URDF')
    return warnings


def learning_warnings(model: RobotModel, friction: np.ndarray, learning: np.ndarray,
                      asked: np.ndarray) -> list[str]:
    """
    Warn of joints without an estimate whose learnable friction is held below the share asked.

    On a joint without a friction estimate the regulator may learn ``asked`` (the effort
    share), at most what changes the joint's speed by ``TICK_SPEED_SHARE`` of its limit in one
    tick on the least inertia it sees. Where that is less, a friction above it is never
    broken: the joint stops short of the goal, and /diagnostics says "likely friction".
    """
    short = [f'{name} to {a:.3g} N m (not {want:.3g})'
             for name, f, a, want in zip(model.joint_names, friction, learning, asked)
             if f <= 0.0 and isfinite(want) and a < (1.0 - 1e-9) * want]
    if not short:
        return []
    return ['the friction the regulator may learn at rest is held down on joints too light '
            f'for it: {", ".join(short)}, so that releasing it cannot jump the joint past its '
            'velocity limit in one tick. A larger friction holds the joint short of the goal. '
            'Give the '
            "drives' rotor inertia with --armature, or measure the friction and give it with "
            '--friction']


def friction_warnings(model: RobotModel, friction: np.ndarray,
                      learning: np.ndarray) -> list[str]:
    """
    Return warnings on friction estimates the robot's data do not support (none if they do).

    The data are the URDF's ``<dynamics friction>`` values. The compensation at rest reaches
    the estimate plus what it may learn; above the true friction it would push a joint that
    friction no longer holds (docs/lyapunov.md, section 4). A URDF with no friction value
    gives nothing to check against; that is said once.
    """
    data = np.array(model.friction_nm, dtype=float)
    if not np.any(data > 0.0):
        if np.any(friction > 0.0):
            return ['the URDF gives no <dynamics friction>: the friction estimates cannot be '
                    "checked against the robot's data (measure the breakaway torque per joint)"]
        return []
    out = []
    for j, name in enumerate(model.joint_names):
        if friction[j] > data[j]:
            out.append(f'{name}: the friction estimate {friction[j]:g} N m is above the '
                       f"URDF's {data[j]:g} N m: an over-estimate drives a joint that friction "
                       'no longer holds; lower it')
        elif data[j] > 0.0 and friction[j] + learning[j] > 2.0 * data[j]:
            out.append(f'{name}: the estimate {friction[j]:g} N m + {learning[j]:g} N m '
                       f"learnable at rest exceeds twice the URDF's {data[j]:g} N m")
    return out


def main(argv: Optional[list] = None) -> int:
    """Run the command line, ``design_gains`` (``gain_cli.main``)."""
    from quat_jt_controller.gain_cli import main as cli_main  # the CLI imports this module
    return cli_main(argv)


if __name__ == '__main__':
    sys.exit(main())

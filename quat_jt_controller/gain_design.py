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

ROS-free. ``python -m quat_jt_controller.gain_design --help`` (``ros2 run quat_jt_controller
design_gains`` under colcon) writes a parameter file in the format of config/*_controller.yaml.
"""
import argparse
from dataclasses import dataclass, field
from math import isfinite, pi, sqrt
from pathlib import Path
import shlex
import sys
import textwrap
from typing import Callable, NoReturn, Optional, Sequence
from xml.etree import ElementTree

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import parameter_table as table
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_controller.shaping import FULL_TURN_RAD, Shaping
from quat_jt_runtime.joints import check_state_rate, STATE_RATE_RANGE_HZ
from quat_jt_runtime.param_table import Kind, names, row, yaml_lines, yaml_value

TORQUE_SHARE = 0.8  # of what gravity and friction compensation leave; the rest: damping
GUIDE_OVER_TASK = 1.2  # the goal-configuration term must overcome the task term at a stop
LIMIT_OVER_TASK = 1.5  # the limit band at the stop holds 1.5 x the task term's bound
LAMBDA_ORIENTATION = 4.0  # tanh(4 ||e||) = 0.96 at ||e|| = 0.5 (60 degrees)
POSITION_SATURATION_M = 0.1  # tanh(lambda_p 0.1 m) = 0.96
DAMPING_RATIO = sqrt(0.5)  # of the tanh law's linearised loop (the quadratic's: x sqrt(lambda))
# Where the sampled loop caps K_v, the stiffness is lowered until the tanh law keeps this much
DAMPING_RATIO_MIN = 0.5
CRUISE_FRACTION = 0.6  # of the URDF velocity limit: the speed far from the goal (default)
# ... and the most that steady speed may be, whatever the cruise aimed at: the push far from
# the goal meets the damping (linear and cubic) at or below this share of the limit
SPEED_MARGIN = 0.8
# ... where K_v is raised to hold it, at most to this share of b_max: near rest a light joint
# keeps much of the delay margin its own (small) K_v leaves; the cubic part brakes the rest
SPEED_DAMPING_SHARE = 0.75
NEGLIGIBLE_CUBIC = 100.0  # a v_c this many times the velocity limit: no cubic term
CRUISE_STEP = 1.1  # the goal-configuration gain of a joint slower than that grows by this
DEFAULT_VELOCITY = 2.0 * pi  # rad/s, for a joint whose URDF gives no velocity limit
DAMPER_SAFETY = 0.5  # of the largest damping the sampled loop tolerates on a joint
LIMIT_MARGIN_MAX_RAD = 0.25
LIMIT_MARGIN_FRACTION = 0.1  # of the smallest half range of a limited joint
GUIDE_RADIUS_RAD = 0.0  # > 0: a dead zone around q* where only the paper's term acts
GUIDE_RAMP_RAD = 0.25
FRICTION_VELOCITY_RAD_S = 0.075  # the xArm6 wrist creeps at ~2 v_eps while it learns
FRICTION_ERROR_BAND = 0.004  # ||e||; a little below the 0.005 the wrist is asked to reach
FRICTION_POSITION_BAND_M = 0.0005
# At rest the regulator may learn this much more than the estimate (x the estimate), in
# FRICTION_LEARNING_TIME_S: a friction up to (1 + this) x the estimate is still broken
FRICTION_LEARNING = 2.0
# ... and with no estimate (0), when asked (--friction-effort-share), a share of the joint's
# effort limit: a friction nobody measured up to this much is still broken (docs/lyapunov.md,
# section 4). This is the share measured; the default is none: on the Panda's ideal plant the
# learning left torque sign changes at the end of most cases (docs/gain_design.md).
FRICTION_EFFORT_SHARE = 0.03
DEFAULT_FRICTION_EFFORT_SHARE = 0.0
FRICTION_LEARNING_TIME_S = 1.0
# A joint that accelerates faster than this on its effort limit and the inertia it sees, with
# no armature given, is taken for a URDF without its drive's rotor inertia (a warning)
PLAUSIBLE_ACCELERATION_RAD_S2 = 5000.0
SUGGESTED_ARMATURE = 0.1  # kg m^2, what a geared drive of a ~1 m arm reflects, as an example
SAMPLES = 24  # representative regular configurations for M(q), J(q)
SURVEY = 400  # random configurations for the largest g(q) and lever ||J_p[:, j]||
REGULAR_SIGMA_MIN = 0.1
# The representative configurations are looked for among at most this many random ones. If
# fewer than SAMPLES reach REGULAR_SIGMA_MIN (a small arm: sigma_min mixes metres and
# radians), the best ones are taken, down to REGULAR_RELATIVE x the largest sigma_min found.
REGULAR_TRIES = 2000
REGULAR_RELATIVE = 0.5
SINGULAR_EVERYWHERE = 1e-6  # the largest sigma_min below this: the task is out of reach
SHRINK = 0.8  # gains are scaled by this until the sampled loop is stable
DELAY_MARGIN = 1  # the loop must also be stable with this many ticks more than asked for
GAIN_MARGIN = 1.5  # ... and with the gains (stiffness and damping) this many times larger
# The damping acts on qdot - g_v qdot*_d of a streamed goal: all of it (an exogenous input to
# the loop, which changes none of its gains; docs/lyapunov.md, section 7)
GOAL_VELOCITY_GAIN = 1.0
# Of the preferred posture against the distance to the measured joints, in the choice of a
# redundant arm's q* (inverse_kinematics.posture): nearest first, the posture breaks near-ties
POSTURE_WEIGHT = 0.1
QO = 0.5  # |Q| on the orientation rows (Eq. 15)
ENGINES = ('pybullet', 'mujoco')  # the simulator's engine parameter (sim_yaml)


def _dynamics_matrix(M: np.ndarray, K: np.ndarray, D: np.ndarray, delay_ticks: int,
                     dt_s: float) -> np.ndarray:
    """State matrix of M qddot = -K q - D qdot, sampled, torque from ``delay_ticks`` ago."""
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    size = 2 * n * (delay_ticks + 1)  # [q_k, v_k, q_k-1, v_k-1, ..., q_k-d, v_k-d]
    A = np.zeros((size, size))
    old = 2 * n * delay_ticks
    A[n:2 * n, n:2 * n] = np.eye(n)
    A[n:2 * n, old:old + n] -= dt_s * Minv @ K
    A[n:2 * n, old + n:old + 2 * n] -= dt_s * Minv @ D
    A[:n, :n] = np.eye(n)
    A[:n, :] += dt_s * A[n:2 * n, :]  # q_k+1 = q_k + dt v_k+1 (semi-implicit Euler)
    for j in range(1, delay_ticks + 1):
        A[2 * n * j:2 * n * (j + 1), 2 * n * (j - 1):2 * n * j] = np.eye(2 * n)
    return A


def spectral_radius(M: np.ndarray, K: np.ndarray, D: np.ndarray, delay_ticks: int = 1,
                    dt_s: float = 1e-3) -> float:
    """
    Spectral radius of the sampled, delayed loop M qddot = -K q - D qdot (zero-order hold).

    The plant is integrated with semi-implicit Euler (as PyBullet does) at ``dt_s``; the
    torque applied in step k is computed from the state of step k - ``delay_ticks``. Below 1:
    locally stable; the slowest mode decays with the time constant -dt / ln(rho).
    """
    A = _dynamics_matrix(np.atleast_2d(M), np.atleast_2d(K), np.atleast_2d(D), delay_ticks,
                         dt_s)
    return float(np.abs(np.linalg.eigvals(A)).max())


def joint_stiffness(jacobian: np.ndarray, slope: Sequence[float],
                    task: cl.Task = cl.Task.POSE) -> np.ndarray:
    """
    K_q = J^T Q^T diag(slope) Q J at the goal (eta_e = 1, e = 0): Q = diag(I, I/2) (Eq. 15).

    ``slope`` is k_p (quadratic, Eq. 23) or k_p lambda (log-cosh, Eq. 31), one per task row;
    ``jacobian`` has one row per task coordinate (J_o, J_G = [J_p; J_o] or J_p). Q is 1/2 on
    the orientation rows, the last three unless ``task`` is the position task (Q = I).
    """
    J = np.asarray(jacobian, dtype=float)
    q_diag = np.ones(J.shape[0])
    if cl.Task(task).has_orientation:
        q_diag[-3:] = QO
    QJ = q_diag[:, None] * J
    return QJ.T @ np.diag(np.asarray(slope, dtype=float)) @ QJ


def linearized_spectral_radius(model: RobotModel, q_goal_rad: Sequence[float], gains: cl.Gains,
                               delay_ticks: int = 1, dt_s: float = 1e-3,
                               mass_matrix: Optional[np.ndarray] = None,
                               task: cl.Task = cl.Task.POSE,
                               shaping: Optional[Shaping] = None) -> float:
    """
    Spectral radius of the regulator's loop linearised at a goal, sampled and delayed.

    At y_tilde = 0 (eta_e = 1) Eq. (24) / (32) minus g(q) is tau = -K_q dq - K_v qdot with
    K_q of :func:`joint_stiffness`, slopes k_p (quadratic) or k_p lambda (log-cosh). Of the
    extensions (``shaping``) only the goal-configuration term without a dead zone adds
    stiffness there (:func:`configuration_stiffness`; q* = the goal); the others are zero
    near the goal. See :func:`spectral_radius`.
    """
    _, _, J = model.kinematics(list(q_goal_rad))
    task = cl.Task(task)
    rows = task.rows(np.array(J))
    slope = np.array(gains.kp)
    if gains.potential is cl.Potential.TANH:
        slope = slope * np.array(gains.lam)
    M = model.mass_matrix(list(q_goal_rad)) if mass_matrix is None else mass_matrix
    K = joint_stiffness(rows, slope, task)
    if shaping is not None and shaping.configuration_on:
        K = K + np.diag(configuration_stiffness(shaping))
    return spectral_radius(M, K, np.diag(gains.kv), delay_ticks, dt_s)


def time_constant_s(rho: float, dt_s: float = 1e-3) -> float:
    """Time constant of a discrete mode of modulus ``rho`` (inf if not decaying)."""
    return -dt_s / np.log(rho) if rho < 1.0 else float('inf')


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
                'base_link': self.base_link, 'tip_link': self.tip_link, **defaults,
                'state_rate': self.rate_hz,
                'publish_rate_divider': max(1, int(round(self.rate_hz / 100.0)))}


def _sample(model: RobotModel, rng: np.random.Generator, fraction: float) -> np.ndarray:
    lower = np.maximum(np.array(model.position_lower), -pi)
    upper = np.minimum(np.array(model.position_upper), pi)
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    return rng.uniform(mid - fraction * half, mid + fraction * half)


def _sigma_min(rows: np.ndarray) -> float:
    return float(np.linalg.svd(rows, compute_uv=False)[-1])


def survey(model: RobotModel, task: cl.Task, seed: int = 0) -> dict:
    """
    Return what the rules need from the robot, measured on seeded random configurations.

    ``gravity_max`` and ``lever_max`` (the largest ||J_p[:, j]||, m) over SURVEY
    configurations within the limits; ``configurations``: SAMPLES regular ones (sigma_min of
    the task Jacobian >= REGULAR_SIGMA_MIN) within 90% of the ranges, with their task
    Jacobians and M(q), among at most REGULAR_TRIES random ones; if fewer are found, the
    best ones down to REGULAR_RELATIVE x the largest sigma_min (``regular_sigma_min`` the
    threshold used); ``inertia_min`` the smallest inertia a joint sees over all of them,
    ``1 / (M^-1)_jj`` (the others free to move; up to several times below M_jj on a coupled
    arm).
    """
    rng = np.random.default_rng(seed)
    n = model.n
    g_max, lever, inertia_min = np.zeros(n), np.zeros(n), np.full(n, np.inf)
    for _ in range(SURVEY):
        q = _sample(model, rng, 1.0)
        _, _, J = model.kinematics(q.tolist())
        g_max = np.maximum(g_max, np.abs(model.gravity(q.tolist())))
        lever = np.maximum(lever, np.linalg.norm(np.array(J)[:3], axis=0))
        inertia_min = np.minimum(inertia_min, seen_inertia(model.mass_matrix(q.tolist())))
    regular, others = [], []
    for _ in range(REGULAR_TRIES):
        q = _sample(model, rng, 0.9)
        _, _, J = model.kinematics(q.tolist())
        rows = task.rows(np.array(J))
        sigma = _sigma_min(rows)
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
        M = model.mass_matrix(q.tolist())
        inertia_min = np.minimum(inertia_min, seen_inertia(M))
        configs.append((q, rows, M))
    return {'gravity_max': g_max, 'lever_max': lever, 'inertia_min': inertia_min,
            'configurations': configs, 'regular_sigma_min': threshold}


def seen_inertia(M: np.ndarray) -> np.ndarray:
    """Return ``1 / (M^-1)_jj``: the inertia joint j sees when the other joints move freely."""
    return 1.0 / np.diag(np.linalg.inv(M))


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


def _median_damping_ratio(configs, slope: np.ndarray, kv: np.ndarray,
                          extra: np.ndarray, task: cl.Task = cl.Task.POSE) -> np.ndarray:
    """Median over the configurations of k_v / (2 sqrt(M_jj k_jj)), per joint."""
    zeta = [kv / (2.0 * np.sqrt(np.diag(M) * (np.diag(joint_stiffness(rows, slope, task))
                                              + extra)))
            for _, rows, M in configs]
    return np.median(zeta, axis=0)


def _worst_rho(configs, kp, kv, lam, extra, delays, dt_s, task=cl.Task.POSE) -> dict:
    """
    Worst spectral radius per potential over the configurations, with the margins.

    DELAY_MARGIN more ticks of delay than asked for, and GAIN_MARGIN x the gains.
    """
    cases = _margin_cases(delays)
    worst = {}
    for potential, slope in (('quadratic', kp), ('tanh', kp * lam)):
        rho = 0.0
        for _, rows, M in configs:
            K = joint_stiffness(rows, slope, task) + np.diag(extra)
            for scale, d in cases:
                rho = max(rho, spectral_radius(M, scale * K, scale * np.diag(kv), d, dt_s))
        worst[potential] = rho
    return worst


def _cruising_guide(configs, kp: np.ndarray, lam: np.ndarray, bound: np.ndarray,
                    push_max: np.ndarray, cruise: np.ndarray, b_max: np.ndarray,
                    task: cl.Task = cl.Task.POSE) -> np.ndarray:
    """
    Return the goal-configuration gains T_j: GUIDE_OVER_TASK x the task bound, or more.

    A joint whose push far from the goal, ``bound + T``, would drive it slower than ``cruise``
    against its damping K_v (which grows with the ramp's stiffness T / w) gets a larger T, up
    to what its budget leaves, ``push_max - bound``. So a strong joint is not held to the pace
    that the task bound, set by the weakest joint, gives it (the Panda's 87 N m shoulder
    beside its 12 N m wrist).
    """
    guide = GUIDE_OVER_TASK * bound
    ceiling = np.maximum(push_max - bound, guide)
    for _ in range(60):
        kv = np.minimum(_damping(configs, kp, lam, guide / GUIDE_RAMP_RAD, task), b_max)
        slow = ((bound + guide) / kv < cruise) & (guide < ceiling)
        if not slow.any():
            break
        guide = np.where(slow, np.minimum(guide * CRUISE_STEP, ceiling), guide)
    return guide


def cruising_speed(push_nm: np.ndarray, kv: np.ndarray, damping_speed_rad_s: np.ndarray,
                   speed_cap_rad_s: np.ndarray) -> np.ndarray:
    """
    Return the steady speed per joint where the damping meets a constant ``push_nm``.

    The damping is the regulator's (``shaping.add_speed_damping``): ``k_v v (1 + min(v, v_m)^2
    / v_c^2)``, ``v_m`` = ``speed_cap_rad_s``, no cubic part where ``v_c`` is 0. It rises
    monotonically with ``v``; the speed is found by bisection.
    """
    out = np.zeros(len(push_nm))
    for j, (push, k, v_c, v_m) in enumerate(zip(push_nm, kv, damping_speed_rad_s,
                                                speed_cap_rad_s)):
        lo_v, hi_v = 0.0, push / k
        for _ in range(60):
            v = 0.5 * (lo_v + hi_v)
            f = k * v * (1.0 + (min(v, v_m) / v_c) ** 2 if v_c > 0.0 else 1.0)
            lo_v, hi_v = (v, hi_v) if f < push else (lo_v, v)
        out[j] = 0.5 * (lo_v + hi_v)
    return out


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


def configuration_stiffness(shaping: Shaping) -> np.ndarray:
    """Joint stiffness (N m/rad) of the goal-configuration term at q* (0 with a dead zone)."""
    if shaping.configuration_radius_rad > 0.0 or not shaping.configuration_gain:
        return np.zeros(len(shaping.configuration_gain))
    return np.array(shaping.configuration_gain) / shaping.configuration_ramp_rad


def _joint_stable(inertia: float, stiffness: float, damping: float, delays, dt_s) -> float:
    """Worst spectral radius of one joint's mass-spring-damper, with the margins."""
    return max(spectral_radius(np.array([[inertia]]), np.array([[scale * stiffness]]),
                               np.array([[scale * damping]]), d, dt_s)
               for scale, d in _margin_cases(delays))


def _checked_delays(delays) -> tuple[int, ...]:
    """Return the delays asked for, plus DELAY_MARGIN ticks more than the largest."""
    return tuple(sorted(set(delays) | {max(delays) + DELAY_MARGIN}))


def _margin_cases(delays) -> list[tuple[float, int]]:
    """Return the (gain scale, delay) pairs checked: 1x up to one tick more, 1.5x as asked."""
    return ([(1.0, d) for d in _checked_delays(delays)]
            + [(GAIN_MARGIN, d) for d in delays])


def _largest_stable_damping(inertia: float, delays, dt_s) -> float:
    """Return the largest D with v_k+1 = v_k - dt D / I v_k-d stable for every delay."""
    lo, hi = 0.0, 2.0 * inertia / dt_s
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _damper_stable(inertia, mid, delays, dt_s) < 1.0 else (lo, mid)
    return lo


def _damper_stable(inertia: float, damping: float, delays, dt_s) -> float:
    """Spectral radius of v_k+1 = v_k - dt D / I v_k-d: a joint's speed under damping alone."""
    worst = 0.0
    for d in delays:
        A = np.zeros((d + 1, d + 1))
        A[0, 0] = 1.0
        A[0, d] -= dt_s * damping / inertia
        for i in range(1, d + 1):
            A[i, i - 1] = 1.0
        worst = max(worst, float(np.abs(np.linalg.eigvals(A)).max()))
    return worst


def design(model: RobotModel, task: cl.Task, rate_hz: float = 1000.0,
           effort_limits_nm: Optional[Sequence[float]] = None,
           friction_nm: Optional[Sequence[float]] = None, delays: Sequence[int] = (1,),
           seed: int = 0, friction_learning: float = FRICTION_LEARNING,
           cruise_fraction: float = CRUISE_FRACTION,
           preferred_configuration_rad: Optional[Sequence[float]] = None,
           friction_effort_share: float = DEFAULT_FRICTION_EFFORT_SHARE) -> Design:
    """
    Compute gains and extensions for ``model`` and ``task`` (docs/gain_design.md).

    ``effort_limits_nm`` default the URDF's; ``friction_nm`` are the Coulomb estimates per
    joint (default zeros: no friction compensation); ``delays`` the ticks of delay the
    sampled loop must be stable with; ``friction_learning`` how much more than the estimate
    (x the estimate) the regulator may learn at rest, and on a joint without an estimate
    ``friction_effort_share`` of its effort limit (at most what its damping takes at the
    velocity limit); ``cruise_fraction`` of the velocity
    limits the speed far from the goal that the goal-configuration gain is raised towards and
    the cubic damping holds (``_cruising_guide``); ``preferred_configuration_rad`` the
    posture a redundant arm's q* leans to (default: the middle of the ranges). Raises
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
    # a joint with an estimate learns relative to it; one without, a share of its effort
    learning = np.where(friction > 0.0, friction_learning * friction,
                        friction_effort_share * effort)
    budget = TORQUE_SHARE * (effort - data['gravity_max'] - friction - learning)
    if np.any(budget <= 0.0):
        raise ValueError(f'no torque left for the potential on joints '
                         f'{[model.joint_names[j] for j in np.flatnonzero(budget <= 0.0)]}: '
                         f'effort {effort.tolist()}, gravity up to '
                         f'{np.round(data["gravity_max"], 3).tolist()}')
    # Speed rule: never ask a joint for more than its damping can hold at SPEED_MARGIN x its
    # velocity limit (holding_limit; b_max: the largest damping the sampled loop tolerates on
    # its smallest inertia, halved); K_v is raised below (holding_damping) where the cubic
    # part alone cannot. A joint without a URDF velocity limit: b_max x DEFAULT_VELOCITY.
    inertia = data['inertia_min']
    velocity = np.array(model.velocity_limits, dtype=float)
    velocity = np.where(np.isfinite(velocity) & (velocity > 0), velocity, DEFAULT_VELOCITY)
    b_max = np.array([DAMPER_SAFETY * _largest_stable_damping(inertia[j],
                                                              _checked_delays(delays), dt_s)
                      for j in range(n)])
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
    guide_cap = np.full(n, np.inf)  # per joint: lowered where the capped damping is too weak
    # The position rows leave a joint whose axis passes through the tip (a wrist roll) with
    # little or no task torque; the goal-configuration term alone holds it. Its terms are
    # sized as if the task asked of it what the orientation rows would: the weakest share.
    floor = 0.0 if task.has_orientation else float(np.min(cap))
    for _ in range(200):
        bound = np.maximum(task_torque_bound(lever, kp, task), floor)
        guide = np.minimum(_cruising_guide(configs, kp, lam, bound, push_max, cruise, b_max,
                                           task),
                           np.maximum(guide_cap, GUIDE_OVER_TASK * bound))
        kv = np.minimum(_damping(configs, kp, lam, guide / GUIDE_RAMP_RAD, task), b_max)
        for j in range(n):
            while _joint_stable(inertia[j], guide[j] / GUIDE_RAMP_RAD, kv[j], delays,
                                dt_s) >= 1.0:
                guide[j] *= SHRINK
        extra = guide / GUIDE_RAMP_RAD
        kv = np.minimum(_damping(configs, kp, lam, extra, task), b_max)
        kv = np.where(limited_speed, holding_damping(bound + guide, kv, b_max, ceiling,
                                                     velocity), kv)
        rho = _worst_rho(configs, kp, kv, lam, extra, delays, dt_s, task)
        zeta = _median_damping_ratio(configs, kp * lam, kv, extra, task)
        if max(rho.values()) < 1.0 and zeta.min() >= DAMPING_RATIO_MIN:
            break
        # A joint whose damping the loop caps, under-damped because of its own
        # goal-configuration stiffness: lower that joint's term, not every task row.
        own = ((zeta < DAMPING_RATIO_MIN) & (kv >= b_max * (1.0 - 1e-9))
               & (guide > GUIDE_OVER_TASK * bound * (1.0 + 1e-9)))
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
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    limited = np.isfinite(lower) & np.isfinite(upper) & (upper - lower < FULL_TURN_RAD)
    margin = 0.0
    limit_gain = np.zeros(n)
    if np.any(limited):
        half = 0.5 * float(np.min((upper - lower)[limited]))
        margin = round(min(LIMIT_MARGIN_MAX_RAD, LIMIT_MARGIN_FRACTION * half), 3)
        for j in np.flatnonzero(limited):
            k = min(LIMIT_OVER_TASK * bound[j], effort[j] - data['gravity_max'][j]) / margin
            while _joint_stable(inertia[j], k, kv[j], delays, dt_s) >= 1.0:
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
    terminal = cruising_speed(push, kv, damping_speed, velocity)
    # The effort share of what may be learned is held to the damping torque (linear and cubic)
    # at the joint's velocity limit: a fully learned over-compensation alone, with no friction
    # left to take it, drives the joint no faster than that limit.
    at_limit = kv * velocity * (1.0 + np.divide(velocity ** 2, damping_speed ** 2,
                                                out=np.zeros(n), where=damping_speed > 0.0))
    learning_limit = np.where(friction > 0.0, learning, np.minimum(learning, at_limit))
    shaping = Shaping.create(
        n, joint_limit_margin=margin, joint_limit_gain=limit_gain.round(3).tolist(),
        friction_compensation=friction.tolist(), friction_velocity=FRICTION_VELOCITY_RAD_S,
        friction_learning_limit=learning_limit.tolist(),
        friction_learning_time=FRICTION_LEARNING_TIME_S,
        friction_error_band=FRICTION_ERROR_BAND,
        friction_position_band=FRICTION_POSITION_BAND_M,
        configuration_gain=guide.round(3).tolist(), configuration_radius=GUIDE_RADIUS_RAD,
        configuration_ramp=GUIDE_RAMP_RAD, damping_speed=damping_speed.round(3).tolist(),
        goal_velocity_gain=GOAL_VELOCITY_GAIN,
        preferred_configuration=(model.middle_of_ranges() if preferred_configuration_rad is None
                                 else preferred_configuration_rad),
        posture_weight=POSTURE_WEIGHT)
    kp_r = tuple(float(f'{v:.4g}') for v in kp)
    kv_r = tuple(float(f'{v:.4g}') for v in kv)
    lam_r = tuple(float(f'{v:.4g}') for v in lam)
    extra = configuration_stiffness(shaping)
    final = _worst_rho(configs, np.array(kp_r), np.array(kv_r), np.array(lam_r), extra,
                       delays, dt_s, task)
    ratios = {'quadratic': _median_damping_ratio(configs, np.array(kp_r), np.array(kv_r), extra,
                                                 task),
              'tanh': _median_damping_ratio(configs, np.array(kp_r) * np.array(lam_r),
                                            np.array(kv_r), extra, task)}
    figures = {
        'effort_limits_nm': effort, 'gravity_max_nm': data['gravity_max'],
        'friction_nm': friction, 'budget_nm': budget, 'task_bound_nm': bound,
        'guide_nm': guide, 'limit_at_stop_nm': limit_gain * margin,
        'lever_max_m': data['lever_max'], 'inertia_min': inertia,
        'spectral_radius': final, 'delays': tuple(delays),
        'damping_ratio': ratios, 'terminal_speed_rad_s': np.array(terminal),
        'velocity_limits_rad_s': velocity, 'friction_learning': friction_learning,
        'cruise_fraction': cruise_fraction,
        'regular_sigma_min': data['regular_sigma_min'],
        'warnings': (friction_warnings(model, friction, learning_limit)
                     + inertia_warnings(model, effort, inertia)),
        'speed_ceiling_rad_s': np.where(limited_speed, ceiling, np.inf),
        'time_to_goal_s': time_to_goal_s(np.array(terminal), configs, np.array(kp_r),
                                         np.array(kv_r), np.array(lam_r), extra, dt_s,
                                         task=task),
        'friction_effort_share': friction_effort_share,
    }
    return Design(task, model.joint_names, model.base_link, model.tip_link, rate_hz, kp_r,
                  kv_r, lam_r, shaping, figures, model.armature)


def time_to_goal_s(cruise_rad_s: np.ndarray, configs, kp: np.ndarray, kv: np.ndarray,
                   lam: np.ndarray, extra: np.ndarray, dt_s: float,
                   move_rad: float = 1.0, task: cl.Task = cl.Task.POSE) -> float:
    """
    Return the expected time to a goal ``move_rad`` away in every joint (s), roughly.

    The slowest joint's cruise, ``move_rad / v_j`` at its cruising speed, plus the linearised
    tanh loop's settling, ln(1000) time constants of its slowest mode (an error 1000 x
    smaller: a 0.5 rad error down to ~0.5 mrad), at the median of the representative
    configurations, nominal gains and one tick of delay.
    """
    rhos = sorted(spectral_radius(M, joint_stiffness(rows, kp * lam, task) + np.diag(extra),
                                  np.diag(kv), 1, dt_s) for _, rows, M in configs)
    settle = np.log(1000.0) * time_constant_s(rhos[len(rhos) // 2], dt_s)
    return float(move_rad / np.min(cruise_rad_s) + settle)


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


def _saturation(lam: Sequence[float], task: cl.Task) -> str:
    """Say from which error the tanh force is 96% of K_p (tanh(x) = 0.96 at x = 1.946)."""
    x96 = float(np.arctanh(0.96))
    parts = []
    if task.has_orientation:
        e = x96 / lam[-1]  # ||e|| = sin(theta / 2)
        parts.append(f'{np.degrees(2.0 * np.arcsin(e)):.0f} deg' if e < 1.0
                     else 'no angle (orientation)')
    if task.has_position:
        parts.append(f'{x96 / lam[0]:.2g} m')
    return 'tanh at 96% of K_p from ' + ' / '.join(parts)


def _regular_note(f: dict) -> str:
    """Say which sigma_min the representative configurations have, if not the usual one."""
    threshold = f.get('regular_sigma_min', REGULAR_SIGMA_MIN)
    if threshold >= REGULAR_SIGMA_MIN:
        return ''
    return (f' (sigma_min(J) >= {threshold:.3g}: none of {REGULAR_TRIES} random ones reached '
            f'{REGULAR_SIGMA_MIN:g})')


def _fmt(values) -> str:
    return yaml_value(Kind.DOUBLE_ARRAY, values)


def _live_names(specs) -> str:
    """
    Return the names of ``specs``, a run of names with the same first word as ``prefix_*``.

    ``joint_limit_margin, joint_limit_gain`` is written ``joint_limit_*``.
    """
    out, names_ = [], [spec.name for spec in specs]
    i = 0
    while i < len(names_):
        word = names_[i].split('_')[0]
        j = i
        while j + 1 < len(names_) and names_[j + 1].split('_')[0] == word:
            j += 1
        if j == i:
            out.append(names_[i])
        else:
            parts = [name.split('_') for name in names_[i:j + 1]]
            common = []
            for words in zip(*parts):
                if len(set(words)) > 1:
                    break
                common.append(words[0])
            out.append('_'.join(common) + '_*')
        i = j + 1
    return ', '.join(out)


def to_yaml(d: Design, potential: str = 'tanh', command: str = '',
            robot_description_note: str = '') -> str:
    """
    Return a parameter file for controller_node in the format of config/*_controller.yaml.

    Keyed ``/**:`` + ``ros__parameters:`` so it applies to any node name and namespace. The
    comments give the rule behind each value and the design's own figures.
    """
    f = d.figures
    s = d.shaping
    axes = ', '.join((['x, y, z (N/m)'] if d.task.has_position else [])
                     + (['rx, ry, rz (N m)'] if d.task.has_orientation else []))
    rho = f['spectral_radius']
    zeta = f['damping_ratio']
    header = [
        f'quat_jt_controller: {d.task.value} task, {d.base_link} -> {d.tip_link}, joints '
        f'{", ".join(d.joints)}.',
        'Generated by quat_jt_controller.gain_design (docs/gain_design.md gives each rule):',
        f'  {command or "python -m quat_jt_controller.gain_design ..."}',
        f'Live parameters (ros2 param set): {", ".join(names(table.GAINS))} and the '
        f'extensions ({_live_names(table.SHAPING)}; '
        'docs/lyapunov.md). The rest is read-only.',
        'The design, per joint (N m unless said):',
        f'  effort limits {_fmt(f["effort_limits_nm"])}, largest |g(q)| '
        f'{_fmt(np.round(f["gravity_max_nm"], 4))}, friction estimates '
        f'{_fmt(f["friction_nm"])}, rotor inertia (armature, in M(q)) '
        f'{_fmt(d.armature or [0.0] * len(d.joints))} kg m^2;',
        f'  at rest the regulator may learn {f["friction_learning"]:g} x the estimates more, '
        f'and without an estimate {f.get("friction_effort_share", 0.0):g} x the effort limit (a '
        'friction nobody measured; at most the damping at the velocity limit), in '
        f'{FRICTION_LEARNING_TIME_S:g} s;',
        f'  budget {TORQUE_SHARE:g} x (effort - gravity - friction - learnable friction) = '
        f'{_fmt(f["budget_nm"])}, of which the task potential may ask at most (a-priori '
        f'bound of the tanh law) {_fmt(f["task_bound_nm"])} and the goal-configuration term '
        f'{_fmt(f["guide_nm"])};',
        f'  joint-limit band torque at a stop {_fmt(f["limit_at_stop_nm"])};',
        f'  sampled loop at {d.rate_hz:g} Hz with {"/".join(str(x) for x in f["delays"])} '
        f'tick(s) of delay and {max(f["delays"]) + DELAY_MARGIN}, and at {GAIN_MARGIN:g} x the '
        f'gains, per joint on the inertia it sees (1 / (M^-1)_jj, smallest '
        f'{_fmt(f["inertia_min"])} kg m^2), linearised at {SAMPLES} regular configurations'
        f'{_regular_note(f)}: '
        'worst spectral '
        f'radius {rho["tanh"]:.6f} (tanh), {rho["quadratic"]:.6f} (quadratic) < 1; median '
        f'damping ratios tanh {_fmt(zeta["tanh"])}, quadratic {_fmt(zeta["quadratic"])};',
        f'  cruising speeds far from the goal {_fmt(f["terminal_speed_rad_s"])} rad/s '
        f'(velocity limits {_fmt(f["velocity_limits_rad_s"])}, aimed at '
        f'{f["cruise_fraction"]:g} x them, at most {SPEED_MARGIN:g} x them: K_v is raised where '
        'the cubic damping cannot hold the push there).',
        f'Expected time to a goal: about {f["time_to_goal_s"]:.2g} s for a 1 rad move of every '
        'joint (the slowest cruise, then ln(1000) time constants of the slowest linear mode).',
    ]
    header += [f'WARNING: {w}' for w in f.get('warnings', ())]
    lines = []
    for entry in header:
        indent = '#   ' if entry.startswith('  ') else '# '
        lines += textwrap.wrap(entry.strip(), width=99, initial_indent=indent,
                               subsequent_indent=indent + '  ', break_on_hyphens=False,
                               break_long_words=False)
    comments = {
        'task': 'read-only',
        'potential': "'tanh' (Eq. 32/38) or 'quadratic' (Eq. 24/37); one set serves both",
        'kp': f'K_p, {axes}: a-priori torque bound within the budget',
        'kv': f'K_v, N m s/rad: damping ratio {DAMPING_RATIO:.2f} (tanh), from M(q), or '
              'more to hold the speed',
        'lambda': f'Lambda: {_saturation(d.lam, d.task)}',
        'gravity_compensation': '+ g(q) from the URDF',
        'joint_limit_margin': 'rad, band inside each limit (joints with less than a full turn)',
        'joint_limit_gain': f'N m/rad: {LIMIT_OVER_TASK:g} x the task bound at the stop',
        'large_error_gain': 'N m; 0: the goal-configuration term carries large errors',
        'friction_compensation': 'N m, the Coulomb estimates (0 = off)',
        'friction_learning_limit': 'N m, the most learned at rest on top (0 = none)',
        'friction_learning_time': 's, to learn it while stuck; it leaks as fast near the goal',
        'friction_velocity': 'rad/s, v_eps of f tanh(qdot / v_eps)',
        'friction_error_band': '||e|| where the compensation fades out',
        'friction_position_band': 'm, the same for ||p_d - p||',
        'configuration_gain': f'N m: {GUIDE_OVER_TASK:g} x the task bound, more on a joint it '
                              'would leave slow',
        'configuration_radius': 'rad, dead zone around q*',
        'configuration_ramp': 'rad, the torque rises over this',
        'damping_speed': 'rad/s, v_c of the cubic damping (0 = none)',
        'goal_velocity_gain': "damping towards a streamed goal's velocity (0 = off)",
        'preferred_configuration': "rad, the posture a redundant arm's q* leans to",
        'posture_weight': 'of that posture against the distance to the arm (no effect without '
                          'self-motion)',
        'armature': 'kg m^2, rotor inertia per joint, in M(q) of the design',
        'robot_description': "URDF XML; '' = the bundled wrist" + (
            f' ({robot_description_note})' if robot_description_note else ''),
        'state_timeout': 's without valid joint_states -> zero torque (once)',
        'max_state_age': 's; older, future or unstamped states are rejected; 0 = off',
        'state_rate': 'Hz, the joint_states rate designed for (--rate)',
        'publish_rate_divider': 'feedback topics at 100 Hz',
    }
    # The task first (it sizes the gains), the live rows (the design's, or their defaults),
    # then the read-only rows the design gives.
    structure = d.structure()
    context = {'task': d.task, 'dim': d.task.dim, 'n': len(d.joints),
               'preferred_configuration': s.preferred_configuration_rad}
    live = tuple(table.GAINS) + tuple(table.SHAPING)
    values = {spec.name: spec.default_value(context) for spec in live}
    values.update(d.parameters(potential))
    values.update(structure)
    first = row(table.STRUCTURE, 'task')
    rows = (first, *live, *(spec for spec in table.STRUCTURE
                            if spec is not first and spec.name in structure))
    lines += ['/**:  # any node name and namespace', '  ros__parameters:']
    lines += yaml_lines(rows, values, comments)
    return '\n'.join(lines) + '\n'


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (the problem, then where the usage is), status 2."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` on one line and exit with status 2."""
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def _number(low: float, high: float = float('inf'), low_open: bool = True,
            integer: bool = False) -> Callable[[str], float]:
    """Return an argparse type: a finite number in (low, high] (or [low, high])."""
    kind = 'an integer' if integer else 'a finite number'
    interval = f'{"(" if low_open else "["}{low:g}, {high:g}{"]" if isfinite(high) else ")"}'

    def parse(text: str) -> float:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not {kind}') from None
        if not (isfinite(value) and (value > low if low_open else value >= low)
                and value <= high):
            raise argparse.ArgumentTypeError(f'{text} is not {kind} in {interval}')
        return value
    return parse


def _real(text: str) -> float:
    """Return an argparse type's float (NaN and infinities too: a range check follows)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None


def _check_per_joint(parser: argparse.ArgumentParser, model: RobotModel,
                     args: argparse.Namespace) -> None:
    """Refuse (status 2) a per-joint list of the wrong length, or a posture outside the limits."""
    names = list(model.joint_names)
    for option in ('effort_limits', 'friction', 'preferred_configuration', 'initial_positions',
                   'sim_coulomb', 'sim_viscous'):
        values = getattr(args, option)
        if values is not None and len(values) != model.n:
            parser.error(f'--{option.replace("_", "-")}: {len(values)} '
                         f'value{"" if len(values) == 1 else "s"} for the {model.n} joints '
                         f'{names}')
    limits = list(zip(model.position_lower, model.position_upper))
    for option in ('preferred_configuration', 'initial_positions'):
        values = getattr(args, option)
        outside = [name for name, v, (lo, hi) in zip(names, values or (), limits)
                   if not lo <= v <= hi]
        if outside:
            parser.error(f'--{option.replace("_", "-")}: {values} puts {outside} outside the '
                         f'joint limits {limits}')


def main(argv: Optional[list] = None) -> int:
    """
    ``ros2 run quat_jt_controller design_gains`` / ``python -m ...gain_design``.

    A bad argument (a number, a file, a joint, a link, a list's length) is one line on stderr
    and status 2, as argparse's own; gains that cannot be designed for the robot, or a file
    that cannot be written, one line and status 1.
    """
    from quat_jt_runtime.resources import default_urdf_xml

    positive, non_negative = _number(0.0), _number(0.0, low_open=False)
    parser = _Parser(
        prog='design_gains', description='Compute K_p, K_v, Lambda and the '
        'extensions of the regulator from the robot (docs/gain_design.md).')
    parser.add_argument('--urdf', type=Path, help='URDF file (default: the bundled wrist)')
    parser.add_argument('--base-link', default='base_link',
                        help='the frame of the goals (default: base_link, the wrist)')
    parser.add_argument('--tip-link', default='tool0',
                        help='the link whose pose is regulated (default: tool0, the wrist)')
    parser.add_argument('--joints', nargs='+', help='controlled joints (default: all movable)')
    parser.add_argument('--task', choices=[t.value for t in cl.Task], default='orientation',
                        help="'orientation' (y = e, Eqs. 37/38), 'pose' (y = [p_d - p; e], "
                             "Eqs. 24/32) or 'position' (y = p_d - p: any reachable point, e.g. "
                             'on an arm of 4 or 5 joints)')
    parser.add_argument('--effort-limits', type=positive, nargs='+',
                        help='N m per joint (default: the URDF effort limits)')
    parser.add_argument('--armature', type=_real, nargs='+',
                        help='rotor inertia the drives add about their joints, kg m^2: one '
                        'value for every joint, or one per joint (default 0). Added to the '
                        "diagonal of the URDF's M(q); written to the file as the controller's "
                        'armature')
    parser.add_argument('--rate', type=_real, default=1000.0,
                        help='the control rate (of joint_states and commands), Hz, in '
                        f'[{STATE_RATE_RANGE_HZ[0]:g}, {STATE_RATE_RANGE_HZ[1]:g}]; the '
                        'sampled loop is checked at it (default 1000)')
    parser.add_argument('--friction', type=non_negative, nargs='+',
                        help='Coulomb friction estimates, N m per joint (default: none)')
    parser.add_argument('--friction-learning', type=non_negative, default=FRICTION_LEARNING,
                        help='how much more than the estimates the regulator may learn at '
                        f'rest, x the estimates (default {FRICTION_LEARNING:g}; 0 = none)')
    parser.add_argument('--friction-effort-share', type=_number(0.0, 0.5, low_open=False),
                        default=DEFAULT_FRICTION_EFFORT_SHARE,
                        help='what the regulator may learn at rest on a joint without a '
                        'friction estimate, as a share of its effort limit: a friction nobody '
                        f'measured ({FRICTION_EFFORT_SHARE:g} measured; default '
                        f'{DEFAULT_FRICTION_EFFORT_SHARE:g}, none)')
    parser.add_argument('--delays', type=_number(0.0, low_open=False, integer=True), nargs='+',
                        default=[1], help='ticks of delay the sampled loop must be stable with')
    parser.add_argument('--cruise-fraction', type=_number(0.0, 1.0), default=CRUISE_FRACTION,
                        help='the speed far from the goal, as a fraction of the URDF velocity '
                        'limits: a strong joint gets a goal-configuration gain that drives it '
                        f'this fast, within its budget (default {CRUISE_FRACTION:g})')
    parser.add_argument('--preferred-configuration', type=_number(-float('inf')), nargs='+',
                        help="rad per joint: the posture a redundant arm's goal configuration "
                        'leans to (default: the middle of the ranges)')
    parser.add_argument('--potential', choices=[p.value for p in cl.Potential],
                        default='tanh', help='the potential the file selects')
    parser.add_argument('--robot-note', default='',
                        help='a note on robot_description for the file')
    parser.add_argument('--out', type=Path, help='write here (default: stdout)')
    sim = parser.add_argument_group(
        'simulator config', 'also write a wrist_sim_node parameter file for the same joints')
    sim.add_argument('--sim-out', type=Path, help='write it here')
    sim.add_argument('--initial-positions', type=_number(-float('inf')), nargs='+',
                     help='rad per joint, where the robot starts at rest (default: the middle '
                     'of the ranges)')
    sim.add_argument('--sim-coulomb', type=non_negative, nargs='+',
                     help='the simulated Coulomb friction, N m per joint (default: none)')
    sim.add_argument('--sim-viscous', type=non_negative, nargs='+',
                     help='the simulated viscous friction, N m s/rad per joint (default: none)')
    sim.add_argument('--sim-armature', type=non_negative, nargs='+',
                     help="the simulated rotor inertia, kg m^2 (default: --armature's)")
    sim.add_argument('--sim-engine', choices=ENGINES, default=ENGINES[0],
                     help=f'the physics engine of the simulator (default {ENGINES[0]})')
    args = parser.parse_args(argv)
    try:
        check_state_rate(args.rate, '--rate')
    except ValueError as exc:
        parser.error(str(exc))
    try:
        urdf = args.urdf.read_text() if args.urdf else default_urdf_xml()
    except (OSError, UnicodeDecodeError) as exc:
        parser.error(f'--urdf {args.urdf}: {getattr(exc, "strerror", None) or exc}')
    try:  # before the URDF parser, which prints its own lines for what is not XML
        root = ElementTree.fromstring(urdf).tag
    except ElementTree.ParseError as exc:
        parser.error(f'--urdf {args.urdf}: not XML ({exc})')
    if root != 'robot':
        parser.error(f'--urdf {args.urdf}: not a URDF (its root element is <{root}>, not '
                     '<robot>)')
    try:
        model = RobotModel(urdf, args.base_link, args.tip_link, args.joints)
    except ModelError as exc:
        parser.error(f'{exc} (--urdf {args.urdf or "<the bundled wrist>"})')
    try:  # one value for every joint or one per joint, each finite and >= 0
        if args.armature is not None:
            model = RobotModel(urdf, args.base_link, args.tip_link, args.joints,
                               per_joint_values(args.armature, model.n, '--armature'))
        sim_armature = per_joint_values(args.sim_armature, model.n, '--sim-armature')
    except (ModelError, ValueError) as exc:
        parser.error(str(exc))
    _check_per_joint(parser, model, args)
    try:
        result = design(model, cl.Task(args.task), args.rate, args.effort_limits,
                        args.friction, tuple(args.delays),
                        friction_learning=args.friction_learning,
                        friction_effort_share=args.friction_effort_share,
                        cruise_fraction=args.cruise_fraction,
                        preferred_configuration_rad=args.preferred_configuration)
        command = shlex.join(['python', '-m', 'quat_jt_controller.gain_design']
                             + _public_argv(sys.argv[1:] if argv is None else argv))
        text = to_yaml(result, args.potential, command, args.robot_note)
        sim_text = (sim_yaml(model, args.rate, args.initial_positions, args.sim_coulomb,
                             args.sim_viscous, command, args.robot_note,
                             model.armature if sim_armature is None else sim_armature,
                             args.sim_engine)
                    if args.sim_out else None)  # both checked before either is written
    except ValueError as exc:  # the robot leaves no gains that meet the design's checks
        print(f'design_gains: error: no design: {exc}', file=sys.stderr)
        return 1
    for warning in result.figures['warnings']:
        print(f'design_gains: WARNING: {warning}', file=sys.stderr)
    try:
        if args.out:
            args.out.write_text(text)
            print(f'wrote {args.out}', file=sys.stderr)
        else:
            sys.stdout.write(text)
        if args.sim_out:
            args.sim_out.write_text(sim_text)
            print(f'wrote {args.sim_out}', file=sys.stderr)
    except OSError as exc:
        print(f'design_gains: error: cannot write {exc.filename}: {exc.strerror}',
              file=sys.stderr)
        return 1
    return 0


def sim_yaml(model: RobotModel, rate_hz: float,
             initial_positions_rad: Optional[Sequence[float]],
             coulomb_nm: Optional[Sequence[float]],
             viscous_nm_s_per_rad: Optional[Sequence[float]],
             command: str = '', robot_description_note: str = '',
             armature: Optional[Sequence[float]] = None, engine: str = ENGINES[0]) -> str:
    """
    Return a parameter file for wrist_sim_node in the format of config/*_sim.yaml.

    The joints are the design's; the others of the URDF (a gripper's fingers) are held where
    they are by the simulator. The start defaults to the middle of the ranges, the friction to
    none, the rotor inertia (``armature``) to the model's. Raises ValueError on a list of the
    wrong length or a start outside the limits.
    """
    n = model.n
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    start = (0.5 * (np.maximum(lower, -pi) + np.minimum(upper, pi))
             if initial_positions_rad is None else np.array(initial_positions_rad, float))
    coulomb = np.zeros(n) if coulomb_nm is None else np.array(coulomb_nm, float)
    viscous = (np.zeros(n) if viscous_nm_s_per_rad is None
               else np.array(viscous_nm_s_per_rad, float))
    rotor = np.array(model.armature if armature is None else armature, float)
    if engine not in ENGINES:
        raise ValueError(f'engine must be one of {list(ENGINES)}, got {engine!r}')
    for name, values in (('--initial-positions', start), ('--sim-coulomb', coulomb),
                         ('--sim-viscous', viscous), ('--sim-armature', rotor)):
        if values.size != n or not np.all(np.isfinite(values)):
            raise ValueError(f'{name}: expected {n} finite values, got {values.tolist()}')
    if np.any(rotor < 0.0):
        raise ValueError(f'--sim-armature: values must be >= 0, got {rotor.tolist()}')
    if np.any(start < lower) or np.any(start > upper):
        raise ValueError(f'--initial-positions {start.tolist()} are outside the limits')
    _, _, J = model.kinematics(start.tolist())
    sigma = _sigma_min(np.array(J))
    note = f'  # {robot_description_note}' if robot_description_note else ''
    lines = [
        *textwrap.wrap(f'wrist_sim_node for {model.base_link} -> {model.tip_link}, joints '
                       f'{", ".join(model.joint_names)}.', width=97, initial_indent='# ',
                       subsequent_indent='#   ', break_on_hyphens=False),
        '# Generated by quat_jt_controller.gain_design with the controller config:',
        *textwrap.wrap(command or 'python -m quat_jt_controller.gain_design ...',
                       width=95, initial_indent='#   ', subsequent_indent='#     ',
                       break_on_hyphens=False, break_long_words=False),
        '# Joints of the URDF not listed here are held by the simulator where they are (at 0).',
        '# Floats are written as floats: ROS 2 parameters are strictly typed (1 is not 1.0).',
        '/**:  # any node name and namespace',
        '  ros__parameters:',
        f"    robot_description: ''{note}",
        f'    joints: [{", ".join(model.joint_names)}]',
        f'    initial_positions: {_fmt(np.round(start, 4))}  # rad, at rest; sigma_min(J) '
        f'{sigma:.3g}',
        f'    rate_hz: {int(round(rate_hz))}',
        '    use_gui: false                   # true opens the PyBullet window',
        '    publish_clock: false             # real-time pacing',
        '    lockstep_timeout: 0.05',
        '    max_real_time_factor: 0.0',
        f'    viscous_friction: {_fmt(viscous)}  # N m s/rad',
        f'    coulomb_friction: {_fmt(coulomb)}  # N m (stiction level)',
        f'    armature: {_fmt(rotor)}  # kg m^2, rotor inertia per joint (engine mujoco)',
        f'    engine: {engine}                 # or '
        + ' or '.join(e for e in ENGINES if e != engine),
        '    command_timeout: 0.5             # s without a valid command -> zero torque',
        '    enforce_velocity_limits: true    # the URDF velocity limits, as a drive holds them',
        '    hold_until_first_command: true   # brakes on until the first command',
        "    stats_file: ''",
    ]
    return '\n'.join(lines) + '\n'


def per_joint_values(values: Optional[Sequence[float]], n: int,
                     name: str) -> Optional[list[float]]:
    """Return one value per joint: ``values`` as given, or its one value ``n`` times."""
    if values is None:
        return None
    if len(values) == 1:
        return [float(values[0])] * n
    if len(values) != n:
        raise ValueError(f'{name}: give one value for every joint or {n} (one per joint), got '
                         f'{len(values)}: {list(values)}')
    return [float(v) for v in values]


def _public_argv(argv: Sequence[str]) -> list[str]:
    """Return ``argv`` with the pybullet_data folder written as <pybullet_data>."""
    try:
        import pybullet_data
        folder = pybullet_data.getDataPath()
    except ImportError:  # a controller-only install has no simulator
        folder = None
    return [a.replace(folder, '<pybullet_data>') if folder else a for a in argv]


if __name__ == '__main__':
    sys.exit(main())

"""
Stall detection for /diagnostics: at rest, away from the goal, and why.

The regulator's Lyapunov function only decreases (docs/lyapunov.md), so the robot can come to
rest before the goal: against a joint limit, where the potential's torque is below the
friction (estimated, or with no estimate below a plausible level), near a singular
configuration, or near a 180-degree orientation error (where the paper's torque fades). It can
also crawl towards the goal slower than the rest speed, where the potential's torque is weak
against the damping: a slow approach, told apart from a joint held by a friction by what the
joint does under its push (:meth:`StallDetector.diagnose`).
:class:`StallDetector` is fed every tick with the tick's output (``TickOutput``) and q/qdot,
but evaluates only every ``period_s`` (10 Hz: no SVD per tick). If the joints are at rest and
the error is above tolerance for more than ``hold_s`` it reports a WARN naming the likely
causes. ROS-free.
"""
from math import isfinite, nan
from typing import NamedTuple, Optional, Sequence

import numpy as np

from quat_jt_controller.diagnostics import NEAR_180_ETA_E, OK, Status, WARN
from quat_jt_controller.model import RobotModel, SINGULAR_SIGMA_MIN
from quat_jt_controller.regulator import Regulator, TickOutput
from quat_jt_runtime.payload import Payload

PERIOD_S = 0.1  # evaluation period (10 Hz)
HOLD_S = 0.5  # at rest and off the goal for longer than this: a stall
REST_SPEED_RAD_S = 0.02  # max |qdot| below this: at rest
ORIENTATION_TOLERANCE = 0.01  # ||e|| above this: off the goal
POSITION_TOLERANCE_M = 0.001  # ||p_d - p|| above this: off the goal (pose, position tasks)
NEAR_LIMIT_RAD = 0.05  # a joint this close to a URDF limit (or inside the band) is at a limit
# With no friction estimate, a potential torque below this share of a joint's effort limit
# (or below what the joint may learn, if more) is within a geared drive's plausible friction
PLAUSIBLE_FRICTION_SHARE = 0.05
# A weak joint whose potential torque is at least this share of the largest weak one is pushed
# (the smaller ones may be moved or held by the others through the inertia's coupling)
PUSHED_SHARE = 0.1
# A pushed joint moving along its push with its damping taking at least this share of the
# push, K_v |qdot| >= share |tau_p|, moves freely (a slow approach); else it is held
MOVING_DAMPING_SHARE = 0.5
# A joint that has learned this share of its a_max has learned all it may
LEARNED_FULL_SHARE = 0.999
# With no estimate and the learning on, a weak joint the learning has seen held for less than
# this (its h, Regulator.friction_held) is not held by a friction (shaping.learn_friction)
HELD_LEARNING = 0.5
# The torque held at rest is named the weight of an untold payload where a payload's g(q)
# (RobotModel.payload_regressor: 4 unknowns, of which 3 act in one pose) fits all but this
# share of it (the norm of the rest over its own) ...
PAYLOAD_FIT_RESIDUAL = 0.2
# ... on an arm with at least this many joints (more equations than the pose's unknowns) ...
PAYLOAD_FIT_JOINTS = 5
# ... where the fitted torque is at least this share of some joint's effort limit
PAYLOAD_FIT_EFFORT_SHARE = 0.01


class PayloadFit(NamedTuple):
    """A payload's ``g(q)`` fitted to a torque held at rest (:func:`fit_payload`)."""

    extra_kg: float  # the mass the model lacks at the tip (< 0: it has too much)
    extra_moment_kg_m: tuple[float, ...]  # ... and its first moment, tip frame (min-norm)
    unexplained: float  # the norm of what the fit leaves, over the held torque's; nan: none
    held_nm: tuple[float, ...]  # the torque held beyond the model's g(q)

    @property
    def significant(self) -> bool:
        """Return True if the fit explains the held torque (``PAYLOAD_FIT_RESIDUAL``)."""
        return self.unexplained <= PAYLOAD_FIT_RESIDUAL


def negligible_torque(tau_nm: Sequence[float], effort_limits_nm: Sequence[float]) -> bool:
    """
    Return True if every joint's ``tau_nm`` is below ``PAYLOAD_FIT_EFFORT_SHARE`` of its limit.

    A joint whose URDF gives no usable effort limit (0, not finite) counts with the largest
    usable one; an arm with none at all, against 1 N m.
    """
    usable = [e for e in effort_limits_nm if isfinite(e) and e > 0.0]
    fallback = max(usable) if usable else 1.0
    return all(abs(t) < PAYLOAD_FIT_EFFORT_SHARE * (e if isfinite(e) and e > 0.0 else fallback)
               for t, e in zip(tau_nm, effort_limits_nm))


def fit_payload(model: RobotModel, q: Sequence[float], tau_nm: Sequence[float],
                R: Optional[np.ndarray] = None, J: Optional[np.ndarray] = None) -> PayloadFit:
    """
    Fit the payload the model lacks to the torque ``tau_nm`` held at rest at ``q``.

    At rest the torque beyond the model's ``g(q)`` holds what the model leaves out. A point
    payload's ``g(q)`` is ``Y(q) [m; m c]`` (``RobotModel.payload_regressor``): least squares
    give ``(m, m c)``; one pose shows 3 of the 4 (a lever along gravity makes no torque), and
    the first moment returned is the smallest that fits. ``R``, ``J``: the tip's at ``q``
    (base frame), if already computed.
    """
    held = np.array(tau_nm, dtype=float) - np.array(model.gravity(list(q)))
    if R is None or J is None:
        _, R, J = model.kinematics(list(q))
    Y = model.payload_regressor_at(np.asarray(R), np.asarray(J))
    theta = np.linalg.lstsq(Y, held, rcond=None)[0]
    norm = float(np.linalg.norm(held))
    unexplained = float(np.linalg.norm(held - Y @ theta)) / norm if norm > 0.0 else nan
    return PayloadFit(float(theta[0]), tuple(float(x) for x in theta[1:]), unexplained,
                      tuple(held.tolist()))


def identify_payload(regulator: Regulator, q: Sequence[float], qdot: Sequence[float],
                     tau_nm: Sequence[float]) -> tuple[Optional[Payload], str]:
    """
    Return the payload the tip carries as the torque ``tau_nm`` held at rest shows it, and why.

    The arm must have ``PAYLOAD_FIT_JOINTS`` joints or more, be at rest at ``q`` (``qdot``
    below ``REST_SPEED_RAD_S``), and have gravity compensation on. The torque beyond the
    model's ``g(q)`` is fitted by a payload at the tip (:func:`fit_payload`), on top of the one
    in force. Below ``PAYLOAD_FIT_EFFORT_SHARE`` of every effort limit
    (:func:`negligible_torque`), the payload in force is kept. The answer is None, with the
    reason, where the fit leaves more than ``PAYLOAD_FIT_RESIDUAL`` of that torque (a friction
    or a contact holds it, not a weight), makes the tip lighter than nothing or puts the mass
    farther away than the arm is long. One pose shows the centre of mass across gravity only:
    that component stays what it was (the message says so). ``Controller.identify_payload``
    (the node's ``~/identify_payload``) and the reach experiment call it.
    """
    model = regulator.model
    if model.n < PAYLOAD_FIT_JOINTS:
        return None, (f'an arm of {model.n} joints shows too little of a payload at its tip '
                      'to tell its mass from its lever: set payload_mass and payload_com')
    if not regulator.gains.gravity_compensation:
        return None, ('gravity_compensation is off: the drives hold the weight, and the held '
                      'torque says nothing of it')
    fastest = max(abs(v) for v in qdot)
    if fastest >= REST_SPEED_RAD_S:
        return None, (f'the arm is moving ({fastest:.3g} rad/s; at rest is below '
                      f'{REST_SPEED_RAD_S:g}): identify the payload with the arm at rest')
    _, R, J = model.kinematics(list(q))  # once: the fit's regressor and the lever's axis
    R = np.array(R)
    fit = fit_payload(model, q, tau_nm, R, np.array(J))
    mass = model.payload_kg + fit.extra_kg
    if negligible_torque(fit.held_nm, model.effort_limits):
        return model.payload, ("the model's g(q) holds the arm here (what it holds beyond is "
                               f'below {PAYLOAD_FIT_EFFORT_SHARE:g} of each effort limit): '
                               f'{model.payload.describe(model.tip_link)} kept')
    if not fit.significant:
        return None, (f'the torque held beyond g(q) ({max(abs(t) for t in fit.held_nm):.3g} N m '
                      'at most) is not a weight at the tip: a payload fits '
                      f'{100.0 * (1.0 - min(fit.unexplained, 1.0)):.0f}% of it (a friction or a '
                      'contact holds the arm); nothing changed')
    if mass <= 0.0:
        return None, (f'the held torque asks for a tip {-fit.extra_kg:.3g} kg lighter than the '
                      f'model, lighter than its payload of {model.payload_kg:g} kg: check the '
                      "URDF's masses; nothing changed")
    # the first moment this pose shows, and along gravity (unseen here) the lever in force
    up = R.T @ model.gravity_base_m_s2
    up /= np.linalg.norm(up)
    moment = model.payload_kg * np.array(model.payload_com_tip_m) + fit.extra_moment_kg_m
    com = (moment - up * (up @ moment)) / mass + up * (up @ model.payload_com_tip_m)
    if np.linalg.norm(com) > model.length_m:
        return None, (f'the held torque asks for {mass:.3g} kg at {np.round(com, 3).tolist()} '
                      f'm, farther from the tip than the arm is long ({model.length_m:.3g} m): '
                      'not a payload; nothing changed')
    payload = Payload.create(mass, com.tolist())
    return payload, (f'identified at rest: {payload.describe(model.tip_link)} '
                     f'({fit.extra_kg:+.3g} kg; the fit leaves {100.0 * fit.unexplained:.0f}% '
                     'of the held torque). One pose shows the centre of mass across gravity '
                     'only: identify again in another orientation of the tip, or set '
                     'payload_com')


class StallDetector:
    """
    Watch the ticks of one :class:`Regulator` for a stall; report it as a diagnostic status.

    Call :meth:`feed` on every tick (cheap: it returns at once between evaluations) and
    :meth:`status` when publishing diagnostics.
    """

    def __init__(self, regulator: Regulator, period_s: float = PERIOD_S,
                 hold_s: float = HOLD_S) -> None:
        self.regulator = regulator
        self.period_s = period_s
        self.hold_s = hold_s
        self._next_s = -float('inf')
        self._since_s: Optional[float] = None
        self.stalled_for_s = 0.0
        self.causes: list[str] = []
        self.error_norm = nan
        self.position_error_m = nan
        self.sigma_min = nan

    def feed(self, t_s: float, q: Sequence[float], qdot: Sequence[float],
             out: TickOutput) -> None:
        """Take one tick (``t_s`` any monotonic clock, s); evaluate every ``period_s``."""
        if t_s < self._next_s:
            return
        self._next_s = t_s + self.period_s
        self.error_norm = out.orientation_error_norm
        self.position_error_m = out.position_error_norm_m
        at_rest = max(abs(v) for v in qdot) < REST_SPEED_RAD_S
        off_goal = (self.error_norm > ORIENTATION_TOLERANCE
                    or self.position_error_m > POSITION_TOLERANCE_M)
        if not (at_rest and off_goal and out.finite):
            self._since_s = None
            self.stalled_for_s = 0.0
            self.causes = []
            return
        if self._since_s is None:
            self._since_s = t_s
        self.stalled_for_s = t_s - self._since_s
        self.causes = self.diagnose(q, out, qdot) if self.stalled else []

    @property
    def stalled(self) -> bool:
        """Return True while at rest off the goal for longer than ``hold_s``."""
        return self._since_s is not None and self.stalled_for_s > self.hold_s

    def diagnose(self, q: Sequence[float], out: TickOutput,
                 qdot: Optional[Sequence[float]] = None) -> list[str]:
        """
        Return the likely causes of a stall at ``q`` (called at most at 10 Hz).

        It costs a Jacobian, an SVD, a g(q) and an n x 4 least-squares fit.

        ``qdot`` (rad/s; None: at rest) tells a joint held by a friction from one still
        moving along its weak push (:meth:`_weak_push`).
        """
        reg = self.regulator
        model, shaping = reg.model, reg.shaping
        _, R, J = model.kinematics(list(q))
        J = np.array(J)
        causes = self._payload(q, out, np.array(R), J)
        near = max(NEAR_LIMIT_RAD, shaping.joint_limit_margin_rad)
        for j, name in enumerate(model.joint_names):
            lo, hi = model.position_lower[j], model.position_upper[j]
            for side, limit, gap in (('lower', lo, q[j] - lo), ('upper', hi, hi - q[j])):
                if isfinite(limit) and gap < near:
                    causes.append(f'{name} at {q[j]:.3f} rad is {max(gap, 0.0):.3f} rad from '
                                  f'its {side} limit {limit:g} rad')
        if out.tau_potential_nm:  # each joint's own damping, the settling damping's included
            damping = [d + s for d, s in zip(reg.linear_damping(q),
                                             reg.settling_damping(q, out.y_tilde))]
            causes += self._weak_push(out.tau_potential_nm,
                                      (0.0,) * model.n if qdot is None else qdot, damping)
        rows = reg.task.rows(J)
        self.sigma_min = model.task_sigma_min(rows, reg.task.has_position)
        if self.sigma_min < SINGULAR_SIGMA_MIN:
            causes.append(f'near-singular: sigma_min(J) = {self.sigma_min:.3g} < '
                          f'{SINGULAR_SIGMA_MIN}'
                          + (f' (position rows per {model.length_m:.3g} m of arm)'
                             if reg.task.has_position else ''))
        if abs(out.eta_e) < NEAR_180_ETA_E:
            causes.append(f'orientation error near 180 degrees (eta_e = {out.eta_e:.3f})')
        if not causes:
            causes.append('no known cause (a local minimum of the potential)')
        return causes

    def _payload(self, q: Sequence[float], out: TickOutput, R: np.ndarray,
                 J: np.ndarray) -> list[str]:
        """
        Name a weight the model does not carry where it explains the torque held at rest.

        At rest the torque the controller applies beyond its ``g(q)`` holds what its model
        leaves out. A payload's ``g(q)`` is linear in its mass and first moment
        (``RobotModel.payload_regressor``); where the least-squares fit of one leaves less than
        ``PAYLOAD_FIT_RESIDUAL`` of the held torque and asks at least
        ``PAYLOAD_FIT_EFFORT_SHARE`` of an effort limit, the stall is most likely an untold
        payload, or link masses the URDF has wrong: its mass is said (a negative one, no more
        than the model's links and payload weigh: the model is heavier than the arm). A
        friction holds with a torque of any pattern;
        the fit tells the two apart only on an arm with more joints than the pose shows of the
        payload (``PAYLOAD_FIT_JOINTS``). ``R`` and ``J`` are the tip's at ``q`` (base frame).
        """
        reg = self.regulator
        model = reg.model
        if model.n < PAYLOAD_FIT_JOINTS or not reg.gains.gravity_compensation:
            return []
        fit = fit_payload(model, q, out.tau_nm, R, J)
        extra_kg = fit.extra_kg
        if (not fit.significant or negligible_torque(fit.held_nm, model.effort_limits)
                or -extra_kg > model.link_mass_kg + model.payload_kg):  # more than it has
            return []
        if extra_kg > 0.0:
            return [f'the torque held at rest is what {extra_kg:.3g} kg more at the tip '
                    f'({model.tip_link}) would need: a payload the model does not carry (set '
                    f'payload_mass, {extra_kg + model.payload_kg:.3g} kg, and payload_com), or '
                    'link masses the URDF has wrong']
        return [f'the torque held at rest is what {-extra_kg:.3g} kg less at the tip '
                f'({model.tip_link}) would need: the model carries more than the arm (check '
                f'payload_mass, {model.payload_kg:g} kg, and the link masses of the URDF)']

    def _weak_push(self, tau_p: Sequence[float], qdot: Sequence[float],
                   kv: Sequence[float]) -> list[str]:
        """
        Name a friction where it holds a joint, or a slow approach where the push is only weak.

        A joint's push is weak below its friction estimate ``f + a`` (the estimate plus what
        was learned), or, with no estimate, below a plausible friction level:
        PLAUSIBLE_FRICTION_SHARE x its effort limit, or what it may learn at rest (``a_max``)
        if more (docs/lyapunov.md, section 4). Of the weak joints, those pushed (at least
        PUSHED_SHARE x the largest weak torque) are told apart by their motion. With the
        potential's torque ``tau_p`` balanced by the damping alone, ``K_v qdot = tau_p`` (a
        frictionless joint crawling, its inertia's share small at such speeds; ``kv`` the
        linear damping at the joints' configuration, ``Regulator.linear_damping``), so a joint
        moving along its push with ``K_v |qdot| >= MOVING_DAMPING_SHARE |tau_p|`` is moving
        freely: a slow approach, not a friction. A joint at rest, moving against its push, or
        moving along it with less than that share taken by its damping is held: something
        else takes the push, a friction (or a joint-limit or contact force, named apart).
        """
        reg = self.regulator
        model, shaping = reg.model, reg.shaping
        n = model.n
        friction = shaping.friction_compensation_nm or (0.0,) * n
        limits = shaping.friction_learning_limit_nm or (0.0,) * n
        learned = reg.learned_friction_nm
        weak = []
        for j in range(n):
            t = abs(tau_p[j])
            if friction[j] > 0.0:
                level = friction[j] + learned[j]
            else:
                level = max(PLAUSIBLE_FRICTION_SHARE * model.effort_limits[j], limits[j])
            if isfinite(level) and t <= level:
                weak.append((j, level))
        largest = max((abs(tau_p[j]) for j, _ in weak), default=0.0)
        estimated, unmeasured, moving, loose = [], [], [], []
        held = reg.friction_held
        speed = 0.0  # the fastest of the joints moving along their push, rad/s
        for j, level in weak:
            t = tau_p[j]
            if abs(t) <= 0.0 or abs(t) < PUSHED_SHARE * largest:
                continue
            name = model.joint_names[j]
            if qdot[j] * t > 0.0 and kv[j] * abs(qdot[j]) >= MOVING_DAMPING_SHARE * abs(t):
                moving.append(f'{name} |tau| {abs(t):.3g} N m, qdot {qdot[j]:.3g} rad/s')
                speed = max(speed, abs(qdot[j]))
                continue
            if friction[j] <= 0.0 < limits[j] and held[j] < HELD_LEARNING:
                # the learning watched it: its push went into its damping or its acceleration
                loose.append(f'{name} |tau| {abs(t):.3g} N m, qdot {qdot[j]:.3g} rad/s')
                continue
            what = (f'{name} |tau| {abs(t):.3g} N m <= {level:.3g} N m'
                    + (f', qdot {qdot[j]:.3g} rad/s' if qdot[j] != 0.0 else '')
                    + self._learned_text(learned[j], limits[j]))
            (estimated if friction[j] > 0.0 else unmeasured).append(what)
        causes = []
        if estimated:
            causes.append('potential torque below the friction estimate, the joint held ('
                          + ', '.join(estimated) + ')')
        if unmeasured:
            causes.append('likely friction: no friction estimate is set (friction_compensation '
                          '0) and the potential torque is below a plausible friction level '
                          'while the joint is held (' + ', '.join(unmeasured) + '); measure '
                          'the breakaway torque per joint and set friction_compensation, or '
                          'raise friction_learning_limit')
        if loose:
            causes.append("no friction holds the weak joints: the potential's torque is weak "
                          'here (' + ', '.join(loose) + '), and the friction learning saw '
                          'their push go into moving them, not into a friction; the arm is '
                          'settling slowly about the goal; raise kp or allow more time')
        if moving:
            causes.append("a slow approach: the potential's torque is weak here ("
                          + ', '.join(moving) + '); the arm is still moving towards the goal at '
                          f'{speed:.3g} rad/s, slower than the rest speed {REST_SPEED_RAD_S:g} '
                          'rad/s; raise kp, allow more time, or give design_gains --armature '
                          'if its design warned of light links')
        return causes

    @staticmethod
    def _learned_text(a: float, a_max: float) -> str:
        """Say what a held joint has learned of its friction: some, or all it may."""
        if a_max <= 0.0:
            return ''
        if a >= LEARNED_FULL_SHARE * a_max:
            return (f', learned its full {a_max:.3g} N m: the friction exceeds what it may '
                    'learn')
        return f', learned {a:.3g} of {a_max:.3g} N m so far'

    def status(self) -> Status:
        """Return ``(level, message, values)`` for /diagnostics."""
        values = [('stalled', str(self.stalled)),
                  ('stalled_for_s', f'{self.stalled_for_s:.2f}'),
                  ('error_norm', f'{self.error_norm:.6g}'),
                  ('sigma_min', f'{self.sigma_min:.4g}'),
                  ('causes', '; '.join(self.causes))]
        task = self.regulator.task
        if task.has_position:
            values.insert(3, ('position_error_m', f'{self.position_error_m:.6g}'))
        if not self.stalled:
            return OK, 'not stalled', values
        where = ', '.join(
            ([f'||e|| = {self.error_norm:.4g}'] if task.has_orientation else [])
            + ([f'||p_d - p|| = {self.position_error_m * 1e3:.2f} mm'] if task.has_position
               else []))
        return (WARN, f'stalled for {self.stalled_for_s:.1f} s at rest, {where}: '
                + '; '.join(self.causes), values)

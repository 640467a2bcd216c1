"""
Reach any reachable goal from any start: the figures, from the package's configs.

For random (start, goal) pairs, seeded, the regulator of ``config/wrist_controller.yaml``,
``config/xarm6_controller.yaml`` or ``config/panda_controller.yaml`` runs as the nodes run it:
on the PyBullet simulator core, with the friction of ``config/*_sim.yaml``, sampled at 1 kHz,
one tick of delay (``--delay``), clamped to the effort limits (``reference_sim.run_sampled``).
The goal configuration q* reaches the regulator 0.1 s after the goal, as from the node's
goal-check worker.

* wrist (orientation): start and goal joint angles within 90% of the URDF ranges, |q2| >= 0.3
  at the goal; reached if ||e|| < 0.005 over the last 0.1 s of 4 s;
* xArm6 (pose): start and goal within 80% of the ranges (about their middle), the goal away
  from singularities (sigma_min(J_G) >= 0.1); reached if ||p_d - p|| < 1 mm and ||e|| < 0.01
  over the last 0.1 s of 5 s.
* Panda (pose, 7 joints: a redundant arm; the fingers held): as the xArm6, with the goal's
  sigma_min(J_G) >= 0.05 (the issue's bound), then held 2 s more:
  over that last second the fastest joint speed (the self-motion drift) and, at the end,
  max_j |q_j - q*_j| (the elbow where the goal check put it).

A stop is touched if a joint comes within 1e-3 rad of a URDF limit. Failures are listed with
their likely cause (``stall.StallDetector.diagnose`` at the final state).

    python -m experiments.reach_experiment [--robot wrist xarm6 panda]
        [--potential tanh quadratic] [--cases N] [--seed S] [--dds K]
        [--without configuration|friction|limits] [--fraction F] [--duration T]
        [--sim-coulomb-scale S | --sim-coulomb-effort-fraction X] [--estimate-of-sim K]

The plant is never the model: ``--sim-coulomb-scale`` multiplies the simulator's Coulomb
friction of ``config/*_sim.yaml`` (the controller's estimate unchanged),
``--sim-coulomb-effort-fraction`` sets it to a fraction of each URDF effort limit, and
``--estimate-of-sim`` sets the controller's estimate to that multiple of the simulated
friction. The sign changes of each joint's control torque without gravity, ``tau - g(q)``, are
counted over the case's last second: more than one on a joint and the case ends in a limit
cycle.

The cases run in parallel on local processes (``--workers``, default one per CPU) or, given
``--ray-address``, on a Ray cluster (``experiments.runners``); seeded, they give the same
outcomes whichever runner ran them.

Any arm from its URDF plus what a user knows, instead of ``--robot`` (docs/reach.md, "Any arm"):

    python -m experiments.reach_experiment (--urdf FILE | --example-robot NAME)
        [--base-link L] [--tip-link L] [--task pose|orientation|position] [--rate HZ]
        [--condition ideal armature armature-wrong friction armature-friction no-velocities
         encoder payload payload-told armature-payload armature-payload-told]
        [--encoder-bits B] [--no-encoder-told] [--payload-share S]
        [--engine mujoco|pybullet] [--armature A] [--armature-told-scale S]
        [--friction-fraction F] [--delay TICKS] [--cases N] [--potential tanh]

The gains are ``gain_design.design`` on the URDF with the armature the condition tells it and
the rate; the plant is the same URDF in ``--engine`` with the condition's rotor inertia and
untold Coulomb friction, its velocities not clamped (a peak past a URDF velocity limit is
reported as ``|qdot|/limit``), or its states given without velocities (estimated by
``quat_jt_runtime.joints.VelocityEstimator``, as the node does), their positions exact or, in
``encoder``, in whole counts of a ``--encoder-bits`` encoder whose count the controller is
told (``position_resolution``) unless ``--no-encoder-told``. In the payload conditions the
plant's tip carries ``--payload-share`` of the arm's link mass, at most half what it can carry
(``payload_kg``), 5 cm along its z, and the design and the controller are told it
(``payload-told``: ``payload_mass``, ``payload_com``) or not. A markdown table ends the
output: reached, stops touched, velocity limits exceeded, limit cycles, time to goal.

``--dds K`` also runs the first K cases of each robot over DDS with the real nodes
(``local_ros``, lockstep paced at real time, so that the goal-check worker answers in the same
time as on a robot; the goal 2 s after the start): the verdict from the last joint state after
the case's duration.
"""
import argparse
import dataclasses
from dataclasses import dataclass
import functools
import math
import os
from pathlib import Path
import re
import shutil
import sys
import tempfile
import time
from typing import Optional

from experiments import arms
from experiments import runners
import numpy as np
from quat_jt_controller import control_law as cl
from quat_jt_controller import parameter_table as table
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.controller_config import (controller_from_config,
                                                  controller_from_package_config)
from quat_jt_controller.gain_design import CRUISE_FRACTION, SPEED_MARGIN
from quat_jt_controller.goal_check import heavy_warning
from quat_jt_controller.inverse_kinematics import (MAX_STARTS, sampling_box,
                                                   search_goal_configuration)
from quat_jt_controller.model import GRAVITY_RESERVE_SHARE, RobotModel
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled, SampledRun
from quat_jt_controller.regulator import Goal
from quat_jt_controller.stall import identify_payload, StallDetector
from quat_jt_runtime.param_table import names
from quat_jt_runtime.payload import with_payload
from quat_jt_runtime.resources import config_parameters, default_urdf_xml
import yaml

TOUCH_RAD = 1e-3  # closer than this to a URDF limit: the stop was touched
LIMIT_CYCLE_FLIPS_PER_S = 1.0  # more sign changes of tau - g(q) in the last second: a cycle
FLIP_FLOOR = 1e-3  # of the effort limit: smaller torques have no sign (numerical dither)
FINAL_WINDOW_S = 0.1
GRAVITY_CHECK_EVERY = 10  # a failed case's g(q) is checked against the effort limits this often
# The goal-check worker's answer arrives this long after the goal: its search of MAX_STARTS
# IK starts takes 10 to 100 ms on the campaign's arms on this host, up to 4 times that where it
# goes on to 48 (no regular q* out of the bands in MAX_STARTS; the report counts those cases).
# With --q-star-by-starts, this long per MAX_STARTS starts the search took (run_case).
Q_STAR_AFTER_S = 0.1
# A design again (redesign.py) is in force this long after it is due: the node's worker
# designs (Pinocchio imported as it starts); about the median answer on the campaign's arms
# with a campaign beside the worker, less than the worst (docs/benchmark.md, "A design again")
REDESIGN_AFTER_S = 1.0
DDS_GOAL_AFTER_S = 2.0  # over DDS, the goal is sent this long after the start (simulated time)


@dataclass(frozen=True)
class Robot:
    """One robot of the experiment: its files, its case generator and its targets."""

    name: str
    controller_config: str
    sim_config: str
    task: cl.Task
    fraction: float  # of the half range around the middle, for starts and goals
    duration_s: float
    orientation_tol: float
    position_tol_m: float
    # held on after duration_s (reached is judged at duration_s): the drift, the distance to q*
    # and the limit cycles are measured over the last second of the hold
    hold_s: float = 0.0
    goal_sigma_min: float = 0.1  # pose task: the goal's sigma_min(J_G) at least this
    # an arm from its URDF (--urdf, --example-robot): no configs, the design from the URDF
    urdf_path: str = ''
    base_link: str = ''
    tip_link: str = ''
    joints: tuple = ()


ROBOTS = {
    'wrist': Robot('wrist', 'wrist_controller.yaml', 'wrist_sim.yaml',
                   cl.Task.ORIENTATION, 0.9, 4.0, 0.005, math.inf),
    'xarm6': Robot('xarm6', 'xarm6_controller.yaml', 'xarm6_sim.yaml',
                   cl.Task.POSE, 0.8, 5.0, 0.01, 1e-3),
    'panda': Robot('panda', 'panda_controller.yaml', 'panda_sim.yaml',
                   cl.Task.POSE, 0.8, 5.0, 0.01, 1e-3, hold_s=2.0, goal_sigma_min=0.05),
}


def robot_urdf(robot: Robot) -> str:
    """Return the URDF XML of ``robot`` (the xArm6's ships inside pybullet_data)."""
    if robot.urdf_path:
        return Path(robot.urdf_path).read_text()
    if robot.name == 'wrist':
        return default_urdf_xml()
    import pybullet_data
    if robot.name == 'panda':
        return (Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf').read_text()
    return (Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf').read_text()


def load_controller(robot: Robot, potential: Optional[str] = None,
                    overrides: Optional[dict] = None):
    """Return ``(model, gains, shaping)`` of the robot's controller config (+ ``overrides``)."""
    regulator = controller_from_package_config(robot.controller_config, robot_urdf(robot),
                                               potential, overrides)
    return regulator.model, regulator.gains, regulator.shaping


MAX_CASE_TRIES = 1000  # random pairs per case before the arm is said to have too few goals


def cases(model: RobotModel, robot: Robot, count: int, seed: int) -> list:
    """
    Return ``count`` seeded (start, goal) joint configurations, as the targets define them.

    For an arm from its URDF the goal's task rows keep ``goal_sigma_min``, and gravity at the
    goal takes at most the design's reserve of each effort limit (``heavy_warning``: a pose the
    arm may not hold up is not a target). ValueError if too few random goals qualify.
    """
    rng = np.random.default_rng(seed)
    lower, upper = sampling_box(model)  # a joint without stops: one turn
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    lo, hi = mid - robot.fraction * half, mid + robot.fraction * half
    out = []
    for tries in range(1, MAX_CASE_TRIES * count + 1):
        if len(out) == count:
            break
        q0, qg = rng.uniform(lo, hi), rng.uniform(lo, hi)
        if robot.urdf_path:  # any arm: the goal's task rows away from a singularity
            _, _, J = model.kinematics(qg.tolist())
            rows = robot.task.rows(np.array(J))
            if np.linalg.svd(rows, compute_uv=False)[-1] < robot.goal_sigma_min:
                continue
            if heavy_warning(model, qg):  # a pose the arm cannot be sure to hold up
                continue
            out.append((q0, qg))
            continue
        if robot.task is cl.Task.ORIENTATION and abs(qg[1]) < 0.3:
            continue
        if robot.task is cl.Task.POSE:
            _, _, J = model.kinematics(qg.tolist())
            if np.linalg.svd(np.array(J), compute_uv=False)[-1] < robot.goal_sigma_min:
                continue
        out.append((q0, qg))
    if len(out) < count:
        raise ValueError(f'{robot.name}: only {len(out)} of {tries} random goals are regular and '
                         f'held up within the effort limits; {count} cases were asked for')
    return out


def quiet():
    """Silence PyBullet's C-level prints (connection banner, inertia warnings)."""
    from wrist_sim.quiet import c_output_silenced
    return c_output_silenced((1, 2))


@dataclass
class Outcome:
    """One case: reached?, the final errors, and what went wrong if anything."""

    index: int
    reached: bool
    touched: bool
    position_error_m: float
    orientation_error: float
    settled_s: float
    max_speed_rad_s: float
    saturated_ticks: int
    flips_per_s: float  # the most sign changes of tau_j - g_j(q) in the last second
    q_start: np.ndarray
    q_goal: np.ndarray
    q_final: np.ndarray
    final_speed_rad_s: float = math.nan  # the fastest joint over the run's last second
    from_q_star_rad: float = math.nan  # max_j |q_j - q*_j| at the end (nan: no q*)
    cause: str = ''
    speed_ratio: float = math.nan  # max over joints and time of |qdot_j| / velocity limit_j
    # max_j |q*_j - q_start,j| / velocity limit_j: the least time to the goal configuration
    # at the velocity limits, acceleration aside (nan: no q* or no limits)
    travel_s: float = math.nan
    ripple: float = math.nan  # max_j std(tau_j - g_j) in the last second / effort limit_j
    identified_kg: float = math.nan  # the payload set at rest by the identification (nan: none)
    # the rotor inertia found beyond the armature told, per joint, at the end (kg m^2)
    armature_estimate: tuple = ()
    # (time s, the armature designed with) of each design again in force, or its error text
    redesigns: tuple = ()
    warm_touched: bool = False  # a stop touched in the warm-up (run_case's warm_up_s)
    warm_speed_ratio: float = 0.0  # ... and its max |qdot_j| / velocity limit_j
    ik_starts: int = 0  # the IK starts the goal check's search for the case's q* took
    q_star_after_s: float = math.nan  # ... and when q* was given, after the goal (s)


class Redesigns:
    """
    The gains designed again as the node does (``redesign.py``), on a case's simulated time.

    :meth:`step` after each tick: when ``InertiaWatch`` says a design is due, it is made at
    once (``redesign.redesign`` on the parameters in force) and put in force
    ``REDESIGN_AFTER_S`` later, on both of the loop's regulators, through
    ``controller_from_config`` (the parameters checked as the node checks them).
    """

    def __init__(self, loop: ClosedLoop, urdf_xml: str, values: dict) -> None:
        from quat_jt_controller.redesign import InertiaWatch
        self.loop, self.urdf_xml, self.values = loop, urdf_xml, dict(values)
        self.watch = InertiaWatch(loop.model.armature)
        self.pending: Optional[tuple] = None  # (in force at s, armature, regulator)
        self.applied: list = []

    def step(self, t_s: float, q: list) -> None:
        """Look at the estimate, as the node's timer does; put a design in force when due."""
        from quat_jt_controller.redesign import redesign
        if self.pending is not None and t_s >= self.pending[0]:
            _, armature, made = self.pending
            self.pending = None
            for regulator in (self.loop.clamped, self.loop.regulator):
                regulator.set_gains(made.gains)
                regulator.set_shaping(made.shaping)
            self.applied.append((round(t_s, 3), armature))
        found = self.loop.clamped.armature_estimate
        if self.watch.settled(t_s, found) is None or self.pending is not None:
            return  # not a look, or a design on its way
        armature = self.watch.due(found, self.loop.model.own_inertias(q))
        if armature is None:
            return
        self.watch.designed_with(armature)
        try:
            self.values.update(redesign(self.urdf_xml, self.values, armature))
            made = controller_from_config(self.values, self.urdf_xml)
        except ValueError as exc:
            self.applied.append((round(t_s, 3), f'{type(exc).__name__}: {exc}'))
            return
        self.pending = (t_s + REDESIGN_AFTER_S, armature, made)


class PositionsOnly:
    """
    A simulator whose states carry no velocities: the controller gets them estimated.

    As the node does for such joint states (``quat_jt_runtime.joints.JointStateReader``): a
    ``VelocityEstimator`` of time constant one period, restarted after ten periods without a
    state, fed each state's positions and time. With ``resolution_rad`` > 0 the positions
    are an encoder's, rounded to whole counts of that size (``sensed_q_rad``, what the
    controller reads: ``reference_sim.run_sampled``), and with ``told`` the controller is
    told the count (its ``position_resolution``: ``WindowedVelocityEstimator``); ``q_rad``
    stays the plant's, for the errors and speeds the case is judged by.
    """

    def __init__(self, sim, resolution_rad: float = 0.0, told: bool = True) -> None:
        from quat_jt_runtime.joints import velocity_estimator
        if not (math.isfinite(resolution_rad) and resolution_rad >= 0.0):
            raise ValueError(f'resolution_rad must be finite and >= 0, got {resolution_rad}')
        self.sim, self.n, self.dt_s = sim, sim.n, sim.dt_s
        self.resolution_rad = float(resolution_rad)
        self._estimator = velocity_estimator(sim.n, 1.0 / sim.dt_s,
                                             [self.resolution_rad if told else 0.0] * sim.n)
        self._k = 0
        self._v = np.array(self._estimator.update(self.sensed_q_rad.tolist(), 0))

    @property
    def q_rad(self) -> np.ndarray:
        """Return the joint positions, as the plant's."""
        return self.sim.q_rad

    @property
    def sensed_q_rad(self) -> np.ndarray:
        """Return the joint positions as the encoders read them (whole counts)."""
        q = self.sim.q_rad
        if self.resolution_rad == 0.0:
            return q
        return np.round(q / self.resolution_rad) * self.resolution_rad

    @property
    def qdot_rad_s(self) -> np.ndarray:
        """Return the velocities estimated from the sensed positions (not the plant's)."""
        return self._v

    def step(self, tau):
        """Step the plant, then estimate the velocities from the new sensed positions."""
        applied = self.sim.step(tau)
        self._k += 1
        self._v = np.array(self._estimator.update(
            self.sensed_q_rad.tolist(), int(round(self._k * self.dt_s * 1e9))))
        return applied


def encoder_resolution_rad(bits: int) -> float:
    """Return the count of an absolute encoder of ``bits`` bits a turn, rad (0: exact)."""
    if bits == 0:
        return 0.0
    if not 8 <= bits <= 32:
        raise ValueError(f'--encoder-bits must be 0 (exact) or in [8, 32], got {bits}')
    return 2.0 * math.pi / 2 ** bits


def run_case(robot: Robot, model: RobotModel, gains: cl.Gains, shaping: sh.Shaping,
             sim_params: dict, index: int, q0: np.ndarray, qg: np.ndarray,
             delay_ticks: int = 1, q_star_after_s: float = Q_STAR_AFTER_S,
             engine: str = 'pybullet', sim_armature=None, no_velocities: bool = False,
             dt_s: float = 1e-3, encoder_bits: int = 0, encoder_told: bool = True,
             sim_payload_kg: float = 0.0, identify_at_s: float = 0.0,
             design_values: Optional[dict] = None, warm_up_s: float = 0.0,
             q_warm_goal: Optional[np.ndarray] = None,
             q_star_by_starts: bool = False) -> Outcome:
    """
    Run one case on the simulator core (``engine``); classify it.

    ``sim_armature`` is the plant's rotor inertia (kg m^2 per joint; the model's may differ),
    ``no_velocities`` gives the controller estimated velocities (``PositionsOnly``), from
    positions read by encoders of ``encoder_bits`` bits a turn (0: exact), their count told
    to the controller if ``encoder_told``, ``dt_s`` the plant's step and the control period,
    ``sim_payload_kg`` a payload the plant's tip carries (at ``PAYLOAD_COM_TIP_M``; the model's
    may differ). With ``identify_at_s`` > 0, at that time the payload is identified from the
    plant's state and the last torque (``stall.identify_payload``, what the node's
    ``~/identify_payload`` does) and, if one is, set on the controller's model; the run goes
    on from there. ``design_values`` are the controller's parameters (the design's, by ROS
    name): with them and ``gain_redesign``, the gains are designed again as the node does
    (:class:`Redesigns`). With ``warm_up_s`` > 0 the arm works before the case: from ``q0``
    towards ``q_warm_goal``'s pose for that long, then the case's goal from where it is (the
    case's start, in the outcome), its estimates, learned friction and gains kept.
    ``q*`` is given ``q_star_after_s`` after each goal; with ``q_star_by_starts``, that long
    per ``MAX_STARTS`` IK starts its search took (at least that long), as a worker's search
    of more starts answers later.
    """
    from wrist_sim.simulator import RobotSimulator

    def target(q_goal: np.ndarray) -> tuple:  # the goal's pose
        p, R = model.forward_kinematics(q_goal.tolist())
        return quat.from_rotation_matrix(R), p

    def configuration(q_from: np.ndarray, goal: tuple
                      ) -> tuple[Optional[np.ndarray], int, float]:
        """Return q* (None without the term), the IK starts its search took, when given."""
        if not shaping.configuration_on:
            return None, 0, q_star_after_s
        search = search_goal_configuration(
            model, q_from, goal[0], goal[1], robot.task, shaping.joint_limit_margin_rad,
            q_preferred=shaping.preferred_configuration_rad or None,
            posture_weight=shaping.posture_weight)
        after = q_star_after_s
        if q_star_by_starts and search.starts > MAX_STARTS:
            after *= search.starts / MAX_STARTS
        return search.q_star, search.starts, after
    q_d, p_d = target(qg)
    first_goal = target(q_warm_goal) if warm_up_s > 0.0 else (q_d, p_d)
    loop = ClosedLoop(model, gains, robot.task, *first_goal, shaping=shaping)
    with quiet():
        sim = RobotSimulator(with_payload(robot_urdf(robot), model.tip_link, sim_payload_kg,
                                          PAYLOAD_COM_TIP_M),
                             model.joint_names, initial_positions_rad=q0,
                             viscous_nm_s_per_rad=sim_params.get('viscous_friction'),
                             coulomb_nm=sim_params.get('coulomb_friction'),
                             enforce_velocity_limits=sim_params.get('enforce_velocity_limits',
                                                                    True),
                             engine=engine, armature=sim_armature, dt_s=dt_s)
    plant = (PositionsOnly(sim, encoder_resolution_rad(encoder_bits), encoder_told)
             if no_velocities else sim)
    identified_kg = math.nan
    warm = None
    redesigns = (Redesigns(loop, robot_urdf(robot), design_values)
                 if design_values is not None and shaping.gain_redesign else None)

    def from_s(start_s: float):  # the design's look on the case's time
        return None if redesigns is None else (
            lambda t, q: redesigns.step(start_s + t, q))
    try:
        if warm_up_s > 0.0:  # the arm at work before the case: to the warm-up goal
            warm_q_star, _, warm_after = configuration(q0, first_goal)
            warm = run_sampled(loop, plant, warm_up_s, delay_ticks, warm_q_star, warm_after,
                               from_s(0.0))
            q0 = sim.q_rad.copy()  # the case starts where the warm-up left the arm
            goal = Goal(tuple(q_d), tuple(p_d))
            loop.goal = goal
            for regulator in (loop.regulator, loop.clamped):
                regulator.set_goal(goal)
        q_star, ik_starts, after_s = configuration(q0, (q_d, p_d))
        total_s = robot.duration_s + robot.hold_s
        if identify_at_s > 0.0:
            first = run_sampled(loop, plant, identify_at_s, delay_ticks, q_star, after_s,
                                from_s(warm_up_s))
            payload, _ = identify_payload(loop.clamped, sim.q_rad.tolist(),
                                          sim.qdot_rad_s.tolist(), first.tau_nm[-1].tolist())
            if payload is not None and payload != model.payload:  # not just kept
                loop.clamped.set_payload(payload)  # the model the loop's regulators share
                identified_kg = payload.mass_kg
            held = _joined(first, run_sampled(loop, plant, total_s - identify_at_s, delay_ticks,
                                              q_star, 0.0, from_s(warm_up_s + identify_at_s)))
        else:
            held = run_sampled(loop, plant, total_s, delay_ticks, q_star, after_s,
                               from_s(warm_up_s))
    finally:
        sim.close()
    run = held.until(robot.duration_s)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    gap = float(np.minimum(held.q_rad - lower, upper - held.q_rad).min())
    position, orientation = run.final(FINAL_WINDOW_S)
    reached = (run.all_finite and orientation < robot.orientation_tol
               and position < robot.position_tol_m and (warm is None or warm.all_finite))
    dt_s = run.t_s[1] - run.t_s[0]
    qdot = np.abs(np.diff(held.q_rad, axis=0)) / dt_s
    speed = float(qdot.max())
    limits = np.array([v if math.isfinite(v) and v > 0.0 else math.inf
                       for v in model.velocity_limits])
    warmed = (False, 0.0)  # the warm-up's stops and speeds, said apart (the case's are the same)
    if warm is not None:
        warmed = (float(np.minimum(warm.q_rad - lower, upper - warm.q_rad).min()) < TOUCH_RAD,
                  float((np.abs(np.diff(warm.q_rad, axis=0)) / dt_s / limits).max()))
    settle_tol = (robot.position_tol_m if math.isfinite(robot.position_tol_m) else math.inf)
    settled_s = run.settled_at_s(settle_tol, robot.orientation_tol)
    last = held.q_rad[int(np.searchsorted(held.t_s, held.t_s[-1] - 1.0)):]
    rest = last_second_torques(model, held)
    outcome = Outcome(index, reached, gap < TOUCH_RAD, position, orientation, settled_s, speed,
                      held.saturated_ticks, torque_flips_per_s(model, rest),
                      q0, qg, held.q_rad[-1].copy(),
                      final_speed_rad_s=float(np.abs(np.diff(last, axis=0)).max() / dt_s),
                      from_q_star_rad=(math.nan if q_star is None else
                                       float(np.abs(held.q_rad[-1] - q_star).max())),
                      speed_ratio=float((qdot / limits).max()),
                      travel_s=(math.nan if q_star is None else
                                float((np.abs(np.asarray(q_star) - q0) / limits).max())),
                      ripple=torque_ripple(model, rest), identified_kg=identified_kg,
                      armature_estimate=loop.clamped.armature_estimate,
                      redesigns=() if redesigns is None else tuple(redesigns.applied),
                      warm_touched=warmed[0], warm_speed_ratio=warmed[1],
                      ik_starts=ik_starts, q_star_after_s=after_s)
    if not reached:
        outcome.cause = classify(model, loop, shaping, q_star, run)
    if outcome.flips_per_s > LIMIT_CYCLE_FLIPS_PER_S:
        outcome.cause = '; '.join(c for c in (outcome.cause, (
            f'LIMIT CYCLE: {outcome.flips_per_s:.0f} torque sign changes in the last second'))
            if c)
    return outcome


def _joined(first: SampledRun, then: SampledRun) -> SampledRun:
    """Return ``first`` followed by ``then`` (whose times restart at 0) as one run."""
    both = (lambda a, b: None if a is None or b is None else np.concatenate((a, b)))
    return SampledRun(np.concatenate((first.t_s, first.t_s[-1] + then.t_s)),
                      both(first.position_error_m, then.position_error_m),
                      both(first.orientation_error, then.orientation_error),
                      both(first.max_abs_torque_nm, then.max_abs_torque_nm),
                      first.saturated_ticks + then.saturated_ticks,
                      first.all_finite and then.all_finite, both(first.q_rad, then.q_rad),
                      both(first.tau_nm, then.tau_nm))


def last_second_torques(model: RobotModel, run) -> np.ndarray:
    """Return each joint's ``tau - g(q)`` over the case's last second (samples x joints)."""
    k0 = int(np.searchsorted(run.t_s, float(run.t_s[-1]) - 1.0))
    q, tau = run.q_rad[k0:], run.tau_nm[k0:]
    return tau - np.array([model.gravity(qi.tolist()) for qi in q])


def torque_flips_per_s(model: RobotModel, rest_nm: np.ndarray) -> float:
    """
    Return the most sign changes of a joint's ``tau - g(q)`` (``last_second_torques``).

    More than ``LIMIT_CYCLE_FLIPS_PER_S`` in the last second: the case ends in a limit cycle.
    Torques below ``FLIP_FLOOR`` of the effort limit carry no sign (numerical dither at rest).
    """
    floor = FLIP_FLOOR * _efforts(model)
    most = 0
    for j in range(model.n):
        signs = np.sign(rest_nm[:, j])
        signs = signs[np.abs(rest_nm[:, j]) > floor[j]]
        most = max(most, int(np.count_nonzero(np.diff(signs))))
    return float(most)


def torque_ripple(model: RobotModel, rest_nm: np.ndarray) -> float:
    """
    Return the largest standard deviation of a joint's ``tau - g(q)`` in the last second.

    ``rest_nm`` from ``last_second_torques``; as a fraction of the joint's effort limit. In a
    case reached that second is the hold at the goal: how hard the torque shakes there (a
    limit cycle, or the damping acting on the count steps of an encoder's positions), whether
    or not its sign changes.
    """
    return float((rest_nm.std(axis=0) / _efforts(model)).max())


def _efforts(model: RobotModel) -> np.ndarray:
    return np.array([v if math.isfinite(v) else 1.0 for v in model.effort_limits])


def classify(model: RobotModel, loop: ClosedLoop, shaping: sh.Shaping, q_star,
             run) -> str:
    """Name the likely cause of a failed case, as the stall detector would."""
    causes = []
    if shaping.configuration_on and q_star is None:
        causes.append('no goal configuration found (IK)')
    speed = np.abs(np.diff(run.q_rad[-100:], axis=0)).max() / (run.t_s[1] - run.t_s[0])
    if speed > 0.02:
        causes.append(f'still moving at the end (up to {speed:.3f} rad/s): too slow')
    else:
        # the run's own regulator, as the node's detector reads it: what it learned of the
        # friction and how held it saw each joint, at the end of the run (and of its hold_s)
        reg = loop.clamped
        # the mean velocity of the last samples: a crawl tells a slow approach from a hold
        k = min(100, len(run.t_s) - 1)
        qdot = ((run.q_rad[-1] - run.q_rad[-1 - k]) / (run.t_s[-1] - run.t_s[-1 - k])).tolist()
        out = reg.update(run.q_rad[-1].tolist(), qdot)
        found = StallDetector(reg).diagnose(run.q_rad[-1].tolist(), out, qdot)
        causes += ['stalled: ' + c for c in found]
    if loop.clamped.gains.gravity_compensation:  # where gravity alone asked more than a limit
        effort = np.array(loop.clamped.effort_limits_nm)  # the clamp (inf: none)
        ratio = np.array([np.abs(model.gravity(q.tolist())) / effort
                          for q in run.q_rad[::GRAVITY_CHECK_EVERY]])
        j = int(np.argmax(ratio.max(axis=0)))
        if ratio[:, j].max() > 1.0:
            over_s = (np.count_nonzero(ratio[:, j] > 1.0) * GRAVITY_CHECK_EVERY
                      * (run.t_s[1] - run.t_s[0]))
            causes.append(f'on its way the arm passed where it cannot hold itself: '
                          f'{model.joint_names[j]} needed up to {ratio[:, j].max():.3g} x its '
                          'effort limit against gravity (its command clamped there, it sagged) '
                          f'for {over_s:.2f} s')
    return '; '.join(causes)


# The stall diagnosis's words for an untold payload (stall.StallDetector), and its mass
PAYLOAD_CAUSE = re.compile(r'what ([0-9.e+-]+) kg (more|less) at the tip')


def report(robot: Robot, potential: str, outcomes: list, elapsed_s: float,
           cruise_fraction: float = CRUISE_FRACTION) -> str:
    """Return the summary lines of one robot and potential (designed for ``cruise_fraction``)."""
    n = len(outcomes)
    ok = sum(o.reached for o in outcomes)
    touched = sum(o.touched for o in outcomes)
    settled = np.array([o.settled_s for o in outcomes if o.reached])
    pos = np.array([o.position_error_m for o in outcomes])
    ori = np.array([o.orientation_error for o in outcomes])
    target = ' and '.join(
        ([f'< {robot.position_tol_m * 1e3:g} mm'] if robot.task.has_position else [])
        + ([f'||e|| < {robot.orientation_tol:g}'] if robot.task.has_orientation else []))
    lines = [
        f'{robot.name}, {potential}: {ok}/{n} reached ({100.0 * ok / max(n, 1):.1f}%) '
        f'{target} within {robot.duration_s:g} s; stops touched in {touched} cases; '
        f'{sum(o.saturated_ticks > 0 for o in outcomes)} cases with saturated ticks',
    ]
    if settled.size:
        lines.append(f'  time to stay within tolerance: median {np.median(settled):.2f} s, '
                     f'90% {np.percentile(settled, 90):.2f} s, max {settled.max():.2f} s; '
                     f'fastest joint speed up to '
                     f'{max(o.max_speed_rad_s for o in outcomes):.2f} rad/s')
    flips = np.array([o.flips_per_s for o in outcomes])
    cycles = int(np.count_nonzero(flips > LIMIT_CYCLE_FLIPS_PER_S))
    ripple = np.array([o.ripple for o in outcomes])
    lines.append(f'  torque sign changes in the last second (tau - g, worst joint): median '
                 f'{np.median(flips):.2f}, max {flips.max():.2f}; limit cycles (> '
                 f'{LIMIT_CYCLE_FLIPS_PER_S:g}) in {cycles} cases; its ripple (std, worst '
                 f'joint, x its effort limit) median {np.nanmedian(ripple):.1e}, max '
                 f'{np.nanmax(ripple):.1e}')
    travel = np.array([o.travel_s for o in outcomes])
    if np.any(np.isfinite(travel) & (travel > 0.0)):  # what the velocity limits allow
        over = int(np.count_nonzero(travel > robot.duration_s))
        ceiling = int(np.count_nonzero(travel / SPEED_MARGIN > robot.duration_s))
        cruise = int(np.count_nonzero(travel / cruise_fraction > robot.duration_s))
        lines.append(f'  the longest joint travel to q* takes more than {robot.duration_s:g} s '
                     f"at the velocity limits in {over} cases, at the design's speed ceiling "
                     f'({SPEED_MARGIN:g} x the limits) in {ceiling}, at its cruise '
                     f'({cruise_fraction:g} x the limits) in {cruise}')
    starts = np.array([o.ik_starts for o in outcomes])
    if starts.max() > MAX_STARTS:  # when q* came, for the searches of more starts
        given = np.array([o.q_star_after_s for o in outcomes])
        longer = starts > MAX_STARTS
        lines.append(f"  the goal check's search for q* took more than {MAX_STARTS} IK starts "
                     f'(no regular q* out of the bands in {MAX_STARTS}) in '
                     f'{int(np.count_nonzero(longer))} cases, {int(starts.max())} at most: '
                     + (f'q* is given {Q_STAR_AFTER_S:g} s after the goal in every case, where '
                        'a worker answers such a search later'
                        if np.nanmax(given[longer]) <= Q_STAR_AFTER_S else
                        f'q* is given {Q_STAR_AFTER_S:g} s after the goal per {MAX_STARTS} '
                        f'starts there (--q-star-by-starts), {np.nanmax(given):.2f} s at most'))
    if robot.hold_s > 0.0 and ok:  # after settling: the cases reached
        drift = np.array([o.final_speed_rad_s for o in outcomes if o.reached])
        away = np.array([o.from_q_star_rad for o in outcomes if o.reached])
        lines.append(f'  the {ok} reached, held {robot.hold_s:g} s more: fastest joint over the '
                     f'last second median {np.median(drift):.1e}, max {drift.max():.1e} rad/s; '
                     f'at the end, max_j |q_j - q*_j| median {np.nanmedian(away):.1e}, max '
                     f'{np.nanmax(away):.1e} rad (no q* in '
                     f'{int(np.count_nonzero(np.isnan(away)))})')
    finals = ([f'final ||e||: median {np.median(ori):.2e}, max {ori.max():.2e}']
              if robot.task.has_orientation else [])
    if robot.task.has_position:
        finals.append(f'final ||p_d - p||: median {np.median(pos) * 1e3:.3f} mm, max '
                      f'{pos.max() * 1e3:.3f} mm')
    lines.append('  ' + '; '.join(finals) + f' ({elapsed_s:.0f} s)')
    named = [float(m.group(1)) * (1.0 if m.group(2) == 'more' else -1.0)
             for m in (PAYLOAD_CAUSE.search(o.cause) for o in outcomes) if m]
    if named:
        lines.append(f'  the stall diagnosis names a payload the model does not carry in '
                     f'{len(named)} cases: median {np.median(named):.3g} kg (from '
                     f'{min(named):.3g} to {max(named):.3g})')
    identified = [o.identified_kg for o in outcomes if math.isfinite(o.identified_kg)]
    if identified:
        lines.append(f'  a payload identified at rest in {len(identified)} cases: median '
                     f'{np.median(identified):.3g} kg (from {min(identified):.3g} to '
                     f'{max(identified):.3g})')
    found = np.array([o.armature_estimate for o in outcomes if any(o.armature_estimate)])
    if found.size:
        lines.append(f'  rotor inertia found beyond the armature told, at the end, in '
                     f'{len(found)} cases: per joint median '
                     f'{np.round(np.median(found, axis=0), 4).tolist()}, max '
                     f'{np.round(found.max(axis=0), 4).tolist()} kg m^2')
    if any(o.warm_speed_ratio > 0.0 for o in outcomes):
        lines.append(f'  in the warm-ups before the cases: stops touched in '
                     f'{sum(o.warm_touched for o in outcomes)} cases, velocity limit exceeded '
                     f'in {sum(o.warm_speed_ratio > 1.0 for o in outcomes)} (max '
                     f'{max(o.warm_speed_ratio for o in outcomes):.2f})')
    designed = [o.redesigns for o in outcomes if o.redesigns]
    if designed:
        times = [t for r in designed for t, a in r if not isinstance(a, str)]
        failed = [a for r in designed for _, a in r if isinstance(a, str)]
        lines.append(f'  gains designed again for the rotor inertia found in {len(designed)} '
                     f'cases ({len(times)} designs, in force from '
                     + (f'{min(times):.2f} to {max(times):.2f} s' if times else '-')
                     + (f'; {len(failed)} failed, e.g. {failed[0]}' if failed else '') + ')')
    for o in outcomes:
        if (not o.reached or o.touched or o.flips_per_s > LIMIT_CYCLE_FLIPS_PER_S
                or o.speed_ratio > 1.0):
            lines.append(
                f'  case {o.index}: start {np.round(o.q_start, 2).tolist()} goal '
                f'{np.round(o.q_goal, 2).tolist()} end {np.round(o.q_final, 2).tolist()}: '
                + ', '.join(([f'||e|| {o.orientation_error:.3g}']
                             if robot.task.has_orientation else [])
                            + ([f'{o.position_error_m * 1e3:.2f} mm']
                               if robot.task.has_position else []))
                + (', TOUCHED A STOP' if o.touched else '')
                + (f', PAST A VELOCITY LIMIT ({o.speed_ratio:.2f} x)' if o.speed_ratio > 1.0
                   else '')
                + (f'; {o.cause}' if o.cause else ''))
    return '\n'.join(lines)


ABLATIONS = {  # --without: turn one extension off to see what it does
    'configuration': {'configuration_gain': ()},
    'friction': {'friction_compensation_nm': ()},
    'limits': {'joint_limit_gain': ()},
}


@dataclass(frozen=True)
class Plant:
    """How the simulated plant and the controller's friction estimate differ from the configs."""

    coulomb_scale: float = 1.0  # x the simulator config's Coulomb friction
    coulomb_effort_fraction: Optional[float] = None  # or this fraction of each effort limit
    estimate_of_sim: Optional[float] = None  # the estimate = this x the simulated friction

    def describe(self) -> str:
        """Return the plant's difference from the configs, for the report ('' if none)."""
        parts = []
        if self.coulomb_effort_fraction is not None:
            parts.append(f'simulated Coulomb friction {self.coulomb_effort_fraction:g} x the '
                         'effort limits')
        elif self.coulomb_scale != 1.0:
            parts.append(f'simulated Coulomb friction {self.coulomb_scale:g} x the configured one')
        if self.estimate_of_sim is not None:
            parts.append(f'estimate {self.estimate_of_sim:g} x the simulated friction')
        return ', '.join(parts)

    def apply(self, model: RobotModel, sim_params: dict, shaping: sh.Shaping):
        """Return ``(sim_params, shaping)`` for this plant."""
        coulomb = [self.coulomb_scale * f for f in sim_params['coulomb_friction']]
        if self.coulomb_effort_fraction is not None:
            coulomb = [self.coulomb_effort_fraction * e for e in model.effort_limits]
        sim_params = dict(sim_params, coulomb_friction=coulomb)
        if self.estimate_of_sim is not None:  # the learnable part keeps its ratio to it
            estimate = [self.estimate_of_sim * f for f in coulomb]
            old = shaping.friction_compensation_nm or (0.0,) * model.n
            ratio = [a / f if f > 0.0 else 0.0 for a, f in
                     zip(shaping.friction_learning_limit_nm or (0.0,) * model.n, old)]
            shaping = dataclasses.replace(
                shaping, friction_compensation_nm=tuple(estimate),
                friction_learning_limit_nm=tuple(r * e for r, e in zip(ratio, estimate)))
        return sim_params, shaping

    def parameters(self, shaping: sh.Shaping) -> dict:
        """Return the controller parameters :meth:`apply` changed, by ROS name."""
        if self.estimate_of_sim is None:
            return {}
        return {'friction_compensation': list(shaping.friction_compensation_nm),
                'friction_learning_limit': list(shaping.friction_learning_limit_nm)}


@dataclass(frozen=True)
class CaseJob:
    """One case, picklable: what a worker process (or a Ray task) needs to run it."""

    robot: Robot
    # (urdf_xml, base_link, tip_link, joints, armature, payload_kg, payload_com_tip_m)
    model_spec: tuple
    gains: cl.Gains
    shaping: sh.Shaping
    sim_params: dict
    index: int
    q_start: np.ndarray
    q_goal: np.ndarray
    delay_ticks: int = 1
    engine: str = 'pybullet'
    sim_armature: Optional[tuple] = None
    no_velocities: bool = False
    dt_s: float = 1e-3
    encoder_bits: int = 0
    encoder_told: bool = True
    sim_payload_kg: float = 0.0  # at the tip, PAYLOAD_COM_TIP_M in its frame
    identify_at_s: float = 0.0  # > 0: the payload identified at rest then (run_case)
    design_values: Optional[dict] = None  # the parameters a design again reads (run_case)
    warm_up_s: float = 0.0  # > 0: the arm works this long first, towards q_warm_goal's pose
    q_warm_goal: Optional[np.ndarray] = None
    q_star_by_starts: bool = False  # q* given later for a longer search (run_case)


@functools.lru_cache(maxsize=8)
def _model(urdf_xml: str, base_link: str, tip_link: str, joints: tuple,
           armature: tuple, payload_kg: float = 0.0,
           payload_com_tip_m: tuple = (0.0, 0.0, 0.0)) -> RobotModel:
    return RobotModel(urdf_xml, base_link, tip_link, list(joints), list(armature), payload_kg,
                      payload_com_tip_m)


def model_spec(model: RobotModel, urdf_xml: str) -> tuple:
    """Return what rebuilds ``model`` in a worker (``CaseJob.model_spec``)."""
    return (urdf_xml, model.base_link, model.tip_link, tuple(model.joint_names),
            tuple(model.armature), model.payload_kg, model.payload_com_tip_m)


def run_job(job: CaseJob) -> Outcome:
    """Run one ``CaseJob`` (in whichever process the runner chose)."""
    return run_case(job.robot, _model(*job.model_spec), job.gains, job.shaping, job.sim_params,
                    job.index, job.q_start, job.q_goal, job.delay_ticks, engine=job.engine,
                    sim_armature=job.sim_armature, no_velocities=job.no_velocities,
                    dt_s=job.dt_s, encoder_bits=job.encoder_bits,
                    encoder_told=job.encoder_told, sim_payload_kg=job.sim_payload_kg,
                    identify_at_s=job.identify_at_s, design_values=job.design_values,
                    warm_up_s=job.warm_up_s, q_warm_goal=job.q_warm_goal,
                    q_star_by_starts=job.q_star_by_starts)


def run_jobs(jobs: list, label: str, progress=print, workers: Optional[int] = None,
             ray_address: Optional[str] = None) -> list:
    """Run ``jobs`` on the runner asked for (``experiments.runners``); their outcomes, in order."""
    outcomes: list = []

    def report_progress(done: int, total: int) -> None:
        if progress and done % 25 == 0:
            progress(f'  [{label}] {done}/{total} cases', flush=True)
    outcomes = runners.run_all(run_job, jobs, workers, ray_address, report_progress)
    return outcomes


def run_robot(robot: Robot, potential: str, count: int, seed: int, delay_ticks: int = 1,
              progress=print, without: Optional[str] = None,
              plant: Plant = Plant(), overrides: Optional[dict] = None,
              workers: Optional[int] = None, ray_address: Optional[str] = None) -> list:
    """
    Run ``count`` cases of ``robot`` with ``potential``; return their outcomes.

    The cases run on local processes (``workers``, default one per CPU; 1: here, one after
    the other) or on the Ray cluster at ``ray_address``: the same outcomes whichever.
    """
    model, gains, shaping = load_controller(robot, potential, overrides)
    if without:
        shaping = dataclasses.replace(shaping, **ABLATIONS[without])
    sim_params, shaping = plant.apply(model, config_parameters(robot.sim_config), shaping)
    spec = model_spec(model, robot_urdf(robot))
    # a design again reads the file's parameters, as the node would (not with an ablation,
    # which it would undo)
    values = (None if without else {**config_parameters(robot.controller_config),
                                    'potential': potential, **(overrides or {}),
                                    **plant.parameters(shaping)})
    jobs = [CaseJob(robot, spec, gains, shaping, sim_params, i, q0, qg, delay_ticks,
                    design_values=values)
            for i, (q0, qg) in enumerate(cases(model, robot, count, seed))]
    return run_jobs(jobs, f'{robot.name} {potential}', progress, workers, ray_address)


def run_dds(robot: Robot, count: int, seed: int, progress=print) -> str:
    """Run the first ``count`` cases of ``robot`` over DDS (real nodes, lockstep); a report."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    from experiments import local_ros
    from experiments.probe import ProbeNode

    model, _, shaping = load_controller(robot)
    urdf = {} if robot.name == 'wrist' else {'robot_description': robot_urdf(robot)}
    lines = []
    for i, (q0, qg) in enumerate(cases(model, robot, count, seed)):
        p_d, R_d = model.forward_kinematics(qg.tolist())
        q_d = quat.from_rotation_matrix(R_d)
        work = Path(tempfile.mkdtemp(prefix='reach_dds_'))
        domain = 50 + (os.getpid() + i) % 40
        env = local_ros.isolated_env(work, domain)
        sim, ctrl = local_ros.spawn_wrist_pair(
            env, work, sim_params={'initial_positions': q0.tolist(), 'publish_clock': True,
                                   'max_real_time_factor': 1.0, **urdf},
            controller_params={'use_sim_time': True, **urdf},
            controller_config=f'config/{robot.controller_config}',
            sim_config=f'config/{robot.sim_config}')
        probe = ProbeNode('reach_probe', domain)
        states: list = []
        probe.node.create_subscription(JointState, '/joint_states', states.append, 100)
        pub = probe.node.create_publisher(PoseStamped, '/quat_jt_controller/target_pose', 10)

        def spin_until(condition, timeout_s: float) -> bool:
            deadline = time.monotonic() + timeout_s
            while not condition():
                if time.monotonic() > deadline or sim.poll() is not None or \
                        ctrl.poll() is not None:
                    return False
                probe.executor.spin_once(timeout_sec=0.05)
            return True

        def stamp_s() -> float:
            s = states[-1].header.stamp
            return s.sec + 1e-9 * s.nanosec
        try:
            # as a user would: the goal some time after the start, the goal-check worker up
            ok = spin_until(lambda: len(states) > 50 and stamp_s() >= DDS_GOAL_AFTER_S, 60.0)
            msg = PoseStamped()
            msg.header.frame_id = model.base_link
            o, p = msg.pose.orientation, msg.pose.position
            o.x, o.y, o.z, o.w = quat.to_xyzw(q_d)
            if robot.task.has_position:
                p.x, p.y, p.z = (float(v) for v in p_d)
            t0 = stamp_s()
            pub.publish(msg)
            ok = ok and spin_until(lambda: stamp_s() - t0 >= robot.duration_s, 240.0)
            q_end = [states[-1].position[states[-1].name.index(n)] for n in model.joint_names]
            p_end, R_end = model.forward_kinematics(q_end)
            _, e = quat.orientation_error(quat.from_rotation_matrix(R_end), q_d)
            err = math.sqrt(sum(c * c for c in e))
            position = math.dist(p_end, p_d) if robot.task.has_position else 0.0
            verdict = ('reached' if ok and err < robot.orientation_tol
                       and position < robot.position_tol_m else 'NOT reached')
            if verdict == 'reached':
                shutil.rmtree(work, ignore_errors=True)  # else keep the nodes' logs
            lines.append(f'  DDS case {i}: after {robot.duration_s:g} s (simulated) ||e|| = '
                         f'{err:.3g}'
                         + (f', ||p_d - p|| = {position * 1e3:.3f} mm'
                            if robot.task.has_position else '')
                         + f' -> {verdict}' + ('' if verdict == 'reached'
                                               else f' (logs in {work})'))
            progress(lines[-1], flush=True)
        finally:
            local_ros.stop_nodes((sim, ctrl))
            probe.close()
    return '\n'.join(lines)


# The most ticks of delay an experiment takes (the design checks 1 to 3)
MAX_DELAY_TICKS = 10

CONDITIONS = ('ideal', 'armature', 'armature-wrong', 'friction', 'armature-friction',
              'no-velocities', 'encoder', 'payload', 'payload-told', 'armature-payload',
              'armature-payload-told', 'armature-payload-identify', 'armature-untold',
              'armature-untold-friction')
# ... and in 'armature-payload-identify', the payload is identified at rest this late (s; the
# case then runs as long again: judged at twice its duration)
IDENTIFY_AT_S = 5.0
# Where the payload conditions put the payload: 5 cm along the tip link's z, in its frame
PAYLOAD_COM_TIP_M = (0.0, 0.0, 0.05)


@dataclass(frozen=True)
class Condition:
    """A plant of an arm from its URDF and what its controller is told of it."""

    name: str
    plant_armature: float = 0.0  # kg m^2 per joint, simulated
    told_armature: float = 0.0  # kg m^2 per joint, given to the design and the controller
    coulomb_effort_fraction: float = 0.0  # simulated Coulomb friction, x the effort limits
    no_velocities: bool = False
    encoder_bits: int = 0  # the positions read in whole counts of 2 pi / 2^bits (0: exact)
    encoder_told: bool = True  # ... and the controller told the count (position_resolution)
    delay_ticks: int = 1  # the ticks between a state and the torque computed from it applied
    payload_share: float = 0.0  # a payload at the tip, x the arm's link mass (payload_kg)
    payload_told: bool = False  # ... and the design and the controller told it
    identify_at_s: float = 0.0  # > 0: stall.identify_payload at this time, then as long again

    def describe(self) -> str:
        """Return the condition in words, for the table."""
        delay = f', {self.delay_ticks} ticks of delay' if self.delay_ticks != 1 else ''
        return {
            'ideal': 'ideal plant',
            'armature': f'rotor inertia {self.plant_armature:g} kg m^2, given',
            'armature-wrong': f'rotor inertia {self.plant_armature:g} kg m^2, given as '
                              f'{self.told_armature:g}',
            'friction': f'untold Coulomb friction {self.coulomb_effort_fraction:g} x effort',
            'armature-friction': f'rotor inertia {self.plant_armature:g} kg m^2, given, and '
                                 f'untold Coulomb friction {self.coulomb_effort_fraction:g} x '
                                 'effort',
            'no-velocities': 'states without velocities (estimated)',
            'encoder': f'positions from {self.encoder_bits}-bit encoders, no velocities '
                       + ('(estimated, the count told)' if self.encoder_told else
                          '(estimated, the count not told)'),
            'payload': f'untold payload {self.payload_share:g} x link mass',
            'payload-told': f'payload {self.payload_share:g} x link mass, given',
            'armature-payload': f'rotor inertia {self.plant_armature:g} kg m^2, given, and '
                                f'untold payload {self.payload_share:g} x link mass',
            'armature-payload-told': f'rotor inertia {self.plant_armature:g} kg m^2 and '
                                     f'payload {self.payload_share:g} x link mass, given',
            'armature-untold': f'rotor inertia {self.plant_armature:g} kg m^2, untold',
            'armature-untold-friction': f'rotor inertia {self.plant_armature:g} kg m^2 and '
                                        f'Coulomb friction {self.coulomb_effort_fraction:g} x '
                                        'effort, both untold',
            'armature-payload-identify': f'rotor inertia {self.plant_armature:g} kg m^2, given, '
                                         f'untold payload {self.payload_share:g} x link mass, '
                                         f'identified at rest at {self.identify_at_s:g} s '
                                         f'(judged at {2.0 * self.identify_at_s:g} s)',
        }[self.name] + delay


def condition(name: str, armature: float = 0.1, told_scale: float = 0.5,
              friction_fraction: float = 0.01, encoder_bits: int = 17,
              encoder_told: bool = True, delay_ticks: int = 1,
              payload_share: float = 0.1) -> Condition:
    """Return the condition ``name`` (``CONDITIONS``) with these plant figures."""
    encoder_resolution_rad(encoder_bits)  # ValueError names a bad count
    if not (math.isfinite(payload_share) and payload_share >= 0.0):
        raise ValueError(f'--payload-share must be finite and >= 0, got {payload_share}')
    if not 0 <= delay_ticks <= MAX_DELAY_TICKS:
        raise ValueError(f'--delay must be in [0, {MAX_DELAY_TICKS}] ticks, got {delay_ticks}')
    return dataclasses.replace({
        'ideal': Condition('ideal'),
        'armature': Condition('armature', armature, armature),
        'armature-wrong': Condition('armature-wrong', armature, told_scale * armature),
        'friction': Condition('friction', coulomb_effort_fraction=friction_fraction),
        'armature-friction': Condition('armature-friction', armature, armature,
                                       friction_fraction),
        'no-velocities': Condition('no-velocities', no_velocities=True),
        'encoder': Condition('encoder', no_velocities=True, encoder_bits=encoder_bits,
                             encoder_told=encoder_told),
        'payload': Condition('payload', payload_share=payload_share),
        'payload-told': Condition('payload-told', payload_share=payload_share,
                                  payload_told=True),
        'armature-payload': Condition('armature-payload', armature, armature,
                                      payload_share=payload_share),
        'armature-payload-told': Condition('armature-payload-told', armature, armature,
                                           payload_share=payload_share, payload_told=True),
        'armature-untold': Condition('armature-untold', armature, 0.0),
        'armature-untold-friction': Condition('armature-untold-friction', armature, 0.0,
                                              friction_fraction),
        'armature-payload-identify': Condition('armature-payload-identify', armature,
                                               armature, payload_share=payload_share,
                                               identify_at_s=IDENTIFY_AT_S),
    }[name], delay_ticks=delay_ticks)


# An arm's case runs this long after its duration: its limit cycles are counted there (s)
ARM_HOLD_S = 1.0


def arm_robot(name: str, urdf_path: str, base_link: Optional[str], tip_link: Optional[str],
              task: cl.Task, fraction: float = 0.8, duration_s: float = 5.0,
              hold_s: float = ARM_HOLD_S) -> Robot:
    """
    Return the ``Robot`` of an arm from its URDF alone (``experiments.arms`` for the chain).

    The targets are the issue's for any arm: ||e|| < 0.01 and, for a pose task, < 1 mm; for
    the position task < 1 mm only (no orientation is asked for), judged at ``duration_s``.
    Each case then runs ``hold_s`` more, and its torque sign changes are counted in the last
    second of that hold: a limit cycle goes on, while a case that came to rest just before
    ``duration_s`` has its last flips in its approach (the stops and the speeds are checked
    over the whole run). The
    goals' task rows of J keep sigma_min at least a quarter of its median over the arm's
    sampled configurations (a rule for any arm, where a fixed bound in mixed units is not).
    """
    urdf = Path(urdf_path).read_text()
    base, tip, joints = arms.arm_links(urdf, base_link, tip_link,
                                       point=task is cl.Task.POSITION)
    model = RobotModel(urdf, base, tip, joints)
    rng = np.random.default_rng(0)
    lower, upper = sampling_box(model)
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    sigmas = []
    for _ in range(200):
        _, _, J = model.kinematics(rng.uniform(mid - fraction * half, mid + fraction * half)
                                   .tolist())
        rows = task.rows(np.array(J))
        sigmas.append(np.linalg.svd(rows, compute_uv=False)[-1])
    return Robot(name, '', '', task, fraction, duration_s,
                 0.01 if task.has_orientation else math.inf,
                 1e-3 if task.has_position else math.inf, hold_s=hold_s,
                 goal_sigma_min=0.25 * float(np.median(sigmas)), urdf_path=str(urdf_path),
                 base_link=base, tip_link=tip, joints=tuple(joints))


# The configurations payload_capacity_kg samples, seeded
CAPACITY_SURVEY = 400
# A payload condition's payload is at most this share of payload_capacity_kg
CAPACITY_SHARE = 0.5


@functools.lru_cache(maxsize=64)
def payload_capacity_kg(robot: Robot) -> float:
    """
    Return the most the arm's tip can carry at ``PAYLOAD_COM_TIP_M`` within the gravity reserve.

    The largest mass whose weight, on top of the arm's own, asks no joint for more than
    ``GRAVITY_RESERVE_SHARE`` of its URDF effort limit in any of ``CAPACITY_SURVEY`` seeded
    configurations (``RobotModel.payload_regressor``; the sign of the two taken at their
    worst): an arm's rated payload, as its URDF's effort limits give it. 0 where the arm's own
    weight already asks more somewhere (Baxter's and TALOS's shoulders), or where a joint the
    payload loads has no effort limit in the URDF (0).
    """
    model = _model(robot_urdf(robot), robot.base_link, robot.tip_link, tuple(robot.joints),
                   (0.0,) * len(robot.joints))
    lower, upper = sampling_box(model)
    rng = np.random.default_rng(0)
    reserve = GRAVITY_RESERVE_SHARE * np.array(model.effort_limits)
    unit = np.array([1.0, *PAYLOAD_COM_TIP_M])  # 1 kg
    most = math.inf
    for _ in range(CAPACITY_SURVEY):
        q = rng.uniform(lower, upper).tolist()
        own = np.abs(model.gravity(q))
        per_kg = np.abs(model.payload_regressor(q) @ unit)
        lifted = per_kg > 1e-9
        if np.any(lifted):
            most = min(most, float(np.min((reserve[lifted] - own[lifted]) / per_kg[lifted])))
    return max(most, 0.0) if math.isfinite(most) else 0.0


def link_mass_kg(robot: Robot) -> float:
    """Return the mass the arm's joints move (kg; ``RobotModel.link_mass_kg``)."""
    return _model(robot_urdf(robot), robot.base_link, robot.tip_link, tuple(robot.joints),
                  (0.0,) * len(robot.joints)).link_mass_kg


def payload_kg(robot: Robot, cond: 'Condition') -> float:
    """
    Return the plant's payload of ``cond`` on ``robot``, kg.

    Its share of the mass the arm moves (a real arm's rated payload is 20 to 40% of its own:
    a UR5's 5 kg, a Panda's 3 kg), at most ``CAPACITY_SHARE`` of what its URDF's effort limits
    carry within the gravity reserve (``payload_capacity_kg``; 0 for an arm that cannot hold
    itself up everywhere).
    """
    if not cond.payload_share:
        return 0.0
    return min(cond.payload_share * link_mass_kg(robot),
               CAPACITY_SHARE * payload_capacity_kg(robot))


@functools.lru_cache(maxsize=16)
def arm_design(robot: Robot, told_armature: float, rate_hz: float,
               friction_effort_share: Optional[float] = None,
               approach_time_s: Optional[float] = None,
               cruise_fraction: Optional[float] = None, delays: tuple = (1,),
               told_payload_kg: float = 0.0):
    """
    Return ``(model, design)``: ``design_gains``' Python API on the URDF + the armature.

    ``friction_effort_share`` is design_gains' ``--friction-effort-share`` (None: its default),
    ``approach_time_s`` its ``--approach-time`` (None: none), ``cruise_fraction`` its
    ``--cruise-fraction`` (None: its default), ``delays`` its ``--delays`` (ticks),
    ``told_payload_kg`` its ``--payload-mass`` (at ``PAYLOAD_COM_TIP_M``).
    """
    from quat_jt_controller import gain_design
    urdf = robot_urdf(robot)
    model = RobotModel(urdf, robot.base_link, robot.tip_link, list(robot.joints),
                       [told_armature] * len(robot.joints), told_payload_kg,
                       PAYLOAD_COM_TIP_M)
    share = (gain_design.DEFAULT_FRICTION_EFFORT_SHARE if friction_effort_share is None
             else friction_effort_share)
    fraction = gain_design.CRUISE_FRACTION if cruise_fraction is None else cruise_fraction
    return model, gain_design.design(model, robot.task, rate_hz, delays=tuple(delays),
                                     friction_effort_share=share,
                                     approach_time_s=approach_time_s, cruise_fraction=fraction)


def run_arm(robot: Robot, cond: Condition, potential: str, count: int, seed: int,
            rate_hz: float = 1000.0, engine: str = 'mujoco', progress=print,
            workers: Optional[int] = None, ray_address: Optional[str] = None,
            friction_effort_share: Optional[float] = None,
            overrides: Optional[dict] = None,
            approach_time_s: Optional[float] = None,
            cruise_fraction: Optional[float] = None, design_delays: tuple = (1,),
            armature_estimation: bool = True, redesign: bool = True,
            warm_up_s: float = 0.0, q_star_by_starts: bool = False) -> list:
    """
    Run ``count`` cases of an arm from its URDF in condition ``cond``; their outcomes.

    The gains are ``design_gains``' from the URDF, the told armature and the rate; the plant
    is ``engine``'s, without the velocity clamp (a speed past the URDF limit is measured, not
    hidden), with ``cond``'s rotor inertia and Coulomb friction; the control period is
    1 / ``rate_hz``. ``overrides`` replace parameters of the design, by their ROS names
    (validated as the node does; ShapingError or GainsError names a bad one);
    ``armature_estimation`` False turns the design's rotor inertia estimate off (an ablation),
    ``redesign`` False its design again for the rotor inertia found (``gain_redesign``).
    With ``warm_up_s`` > 0 each case starts after that long towards the previous case's goal
    (the last case's for the first; ``run_case``), and with ``q_star_by_starts`` each case's
    ``q*`` comes later in proportion to its search's IK starts past ``MAX_STARTS``.
    ``friction_effort_share``, ``approach_time_s``, ``cruise_fraction`` and ``design_delays``
    (its ``--delays``) are design_gains' options (:func:`arm_design`).
    """
    plant_payload_kg = payload_kg(robot, cond)
    if cond.identify_at_s > 0.0:  # as long again after the identification
        robot = dataclasses.replace(robot, duration_s=robot.duration_s + cond.identify_at_s)
    model, d = arm_design(robot, cond.told_armature, float(rate_hz), friction_effort_share,
                          approach_time_s, cruise_fraction, tuple(design_delays),
                          plant_payload_kg if cond.payload_told else 0.0)
    n = model.n
    gains, shaping = d.gains(potential), d.shaping
    ablated = {**({} if armature_estimation else {'armature_estimation_limit': []}),
               **({} if redesign else {'gain_redesign': False})}
    values = {**d.structure(), **d.parameters(potential), **(overrides or {}), **ablated}
    if overrides or ablated:  # as a node would take the design's file with these values
        overridden = controller_from_config(values, robot_urdf(robot))
        gains, shaping = overridden.gains, overridden.shaping
    sim_params = {'viscous_friction': [0.0] * n,
                  'coulomb_friction': [cond.coulomb_effort_fraction * e
                                       for e in model.effort_limits],
                  'enforce_velocity_limits': False}
    spec = model_spec(model, robot_urdf(robot))  # a payload told: in the model's
    # the goals are those the plant can hold up, its payload in, told or not (cases)
    plant_model = (model if cond.payload_told or not plant_payload_kg else
                   RobotModel(robot_urdf(robot), robot.base_link, robot.tip_link,
                              list(robot.joints), model.armature, plant_payload_kg,
                              PAYLOAD_COM_TIP_M))
    pairs = cases(plant_model, robot, count, seed)
    jobs = [CaseJob(robot, spec, gains, shaping, sim_params, i, q0, qg, cond.delay_ticks, engine,
                    (cond.plant_armature,) * n, cond.no_velocities, 1.0 / rate_hz,
                    cond.encoder_bits, cond.encoder_told, plant_payload_kg, cond.identify_at_s,
                    values, warm_up_s, pairs[i - 1][1], q_star_by_starts)
            for i, (q0, qg) in enumerate(pairs)]
    return run_jobs(jobs, f'{robot.name} {cond.name}', progress, workers, ray_address)


def table_row(robot: Robot, cond: Condition, outcomes: list) -> str:
    """Return the markdown table row of one arm and condition (TABLE_HEADER's columns)."""
    n = len(outcomes)
    ok = sum(o.reached for o in outcomes)
    ratios = np.array([o.speed_ratio for o in outcomes])
    settled = np.array([o.settled_s for o in outcomes if o.reached])
    cycles = sum(o.flips_per_s > LIMIT_CYCLE_FLIPS_PER_S for o in outcomes)
    times = (f'{np.percentile(settled, 10):.2f} / {np.median(settled):.2f} / '
             f'{np.percentile(settled, 90):.2f} / {settled.max():.2f}' if settled.size else '-')
    return (f'| {robot.name} | {cond.describe()} | {ok}/{n} | '
            f'{sum(o.touched for o in outcomes)} | {int(np.sum(ratios > 1.0))} '
            f'(max {np.nanmax(ratios):.2f}) | {cycles} | {times} |')


TABLE_HEADER = (r'| arm | condition | reached | stop touched | velocity limit exceeded (peak '
                r'\|qdot\|/limit) | limit cycles | time to goal s: 10% / median / 90% / max |' '\n'
                '|---|---|---|---|---|---|---|')


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--robot', nargs='+', choices=list(ROBOTS), default=list(ROBOTS))
    parser.add_argument('--potential', nargs='+', choices=[p.value for p in cl.Potential],
                        default=['tanh', 'quadratic'])
    parser.add_argument('--cases', type=int, help='cases per robot and potential (default: '
                        '200 wrist, 100 xArm6)')
    parser.add_argument('--seed', type=int, default=10)
    parser.add_argument('--delay', type=int, default=1,
                        help='ticks between a state and the torque computed from it (default 1)')
    parser.add_argument('--dds', type=int, default=0,
                        help='also run the first this many cases of each robot over DDS (real '
                        'nodes, lockstep)')
    parser.add_argument('--without', choices=list(ABLATIONS),
                        help='turn this extension off (to see what it does)')
    parser.add_argument('--fraction', type=float,
                        help='draw starts and goals within this fraction of the half ranges '
                        '(default: 0.9 wrist, 0.8 xArm6)')
    parser.add_argument('--duration', type=float,
                        help='seconds per case (default: 4 wrist, 5 xArm6)')
    friction = parser.add_mutually_exclusive_group()
    friction.add_argument('--sim-coulomb-scale', type=float, default=1.0,
                          help="multiply the simulator config's Coulomb friction by this (the "
                          "controller's estimate unchanged)")
    friction.add_argument('--sim-coulomb-effort-fraction', type=float,
                          help='simulate a Coulomb friction of this fraction of each URDF '
                          'effort limit')
    parser.add_argument('--estimate-of-sim', type=float,
                        help="set the controller's friction estimate to this multiple of the "
                        'simulated Coulomb friction')
    parser.add_argument('--param', action='append', default=[], metavar='NAME:=VALUE',
                        help='override a controller parameter of the config, ros2-style '
                        "(VALUE in YAML, e.g. 'configuration_gain:=[0, 0, 0]')")
    parser.add_argument('--workers', type=int,
                        help='local processes to run the cases on (default: one per CPU; 1: '
                        'one after the other, here)')
    parser.add_argument('--ray-address',
                        help="run the cases on this Ray cluster (e.g. 'auto'; pip install ray, "
                        "the package's 'campaign' extra) instead of local processes")
    arm = parser.add_argument_group(
        'any arm', 'an arm from its URDF alone, instead of --robot: the gains from '
        "design_gains' Python API, the plant from the same URDF")
    source = arm.add_mutually_exclusive_group()
    source.add_argument('--urdf', type=Path, help='the URDF file of the arm')
    source.add_argument('--example-robot', help='an example-robot-data arm (one of '
                        f'{", ".join(arms.EXAMPLE_ROBOTS)})')
    arm.add_argument('--name', help="the arm's name in the table (default: the example "
                     "robot's, or the URDF file's stem)")
    arm.add_argument('--base-link', help="default: the URDF's root link")
    arm.add_argument('--tip-link', help='default: the child of the last revolute joint of the '
                     'longest chain')
    arm.add_argument('--task', choices=[t.value for t in cl.Task], default='pose')
    arm.add_argument('--condition', nargs='+', choices=CONDITIONS, default=list(CONDITIONS))
    arm.add_argument('--rate', type=float, default=1000.0,
                     help='control and state rate, Hz (the design checks it; default 1000)')
    arm.add_argument('--engine', choices=['mujoco', 'pybullet'], default='mujoco',
                     help='the plant (default mujoco; pybullet simulates no armature)')
    arm.add_argument('--armature', type=float, default=0.1,
                     help='the rotor inertia of the armature conditions, kg m^2 per joint')
    arm.add_argument('--armature-told-scale', type=float, default=0.5,
                     help="'armature-wrong': the design is told this x the rotor inertia")
    arm.add_argument('--friction-fraction', type=float, default=0.01,
                     help="'friction': untold Coulomb friction, x each effort limit")
    arm.add_argument('--payload-share', type=float, default=0.1,
                     help='the payload conditions: a payload at the tip (5 cm along its z), '
                     'this x the mass the arm moves, at most half what the tip can carry '
                     'within the gravity reserve of the URDF effort limits (default 0.1)')
    arm.add_argument('--encoder-bits', type=int, default=17,
                     help="'encoder': the positions in counts of 2 pi / 2^bits (8 to 32, "
                     'or 0 for exact ones; default 17)')
    arm.add_argument('--encoder-told', action=argparse.BooleanOptionalAction, default=True,
                     help="'encoder': the controller is told the count (position_resolution; "
                     'default) or not (--no-encoder-told)')
    arm.add_argument('--friction-effort-share', type=float, default=None,
                     help="design_gains' --friction-effort-share (default: its default)")
    arm.add_argument('--approach-time', type=float, default=None,
                     help="design_gains' --approach-time, s (default: none)")
    arm.add_argument('--cruise-fraction', type=float, default=None,
                     help="design_gains' --cruise-fraction (default: its default)")
    arm.add_argument('--no-armature-estimation', action='store_true',
                     help="turn the design's estimate of the rotor inertia from the motion off "
                     '(armature_estimation_limit zeros), to see what it does')
    arm.add_argument('--warm-up', type=float, default=0.0,
                     help='s: before each case the arm works this long, from its start towards '
                     "the previous case's goal, then the case's goal from where it is: the "
                     'estimates and a design again made on the way are in force (default 0)')
    arm.add_argument('--no-redesign', action='store_true',
                     help="turn the design's design again for the rotor inertia found off "
                     '(gain_redesign false), to see what it does')
    arm.add_argument('--q-star-by-starts', action='store_true',
                     help=f'give each case its q* {Q_STAR_AFTER_S:g} s after the goal per '
                     f'{MAX_STARTS} IK starts its search took, as a worker answers a longer '
                     f'search later (default: {Q_STAR_AFTER_S:g} s in every case)')
    arm.add_argument('--design-delays', type=int, nargs='+', default=[1],
                     help="design_gains' --delays: the ticks of delay the design checks its "
                     'sampled loop with, and one more (default: 1; --delay is the '
                     "plant's)")
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error(f'--workers must be >= 1, got {args.workers}')
    if not 0 <= args.delay <= MAX_DELAY_TICKS:
        parser.error(f'--delay must be in [0, {MAX_DELAY_TICKS}] ticks, got {args.delay}')
    overrides = {}
    for item in args.param:
        name, sep, value = item.partition(':=')
        if not sep:
            parser.error(f'--param takes NAME:=VALUE, got {item!r}')
        overrides[name.strip()] = yaml.safe_load(value)
    known = set(names(table.GAINS)) | set(names(table.SHAPING))
    if not (args.urdf or args.example_robot):  # a package config: its structure too
        known |= set(names(table.STRUCTURE))
    unknown = sorted(set(overrides) - known)
    if unknown:
        parser.error(f'--param: {unknown} are no controller parameters it can set here (those '
                     f'are: {", ".join(sorted(known))}; an arm from its URDF takes its '
                     'armature and rate from --armature and --rate)')
    if args.urdf or args.example_robot:
        return main_arm(parser, args, overrides)
    plant = Plant(args.sim_coulomb_scale, args.sim_coulomb_effort_fraction,
                  args.estimate_of_sim)
    default_cases = {'wrist': 200, 'xarm6': 100, 'panda': 100}
    text = []
    for name in args.robot:
        robot = ROBOTS[name]
        if args.fraction is not None:
            robot = dataclasses.replace(robot, fraction=args.fraction)
        if args.duration is not None:
            robot = dataclasses.replace(robot, duration_s=args.duration)
        for potential in args.potential:
            t0 = time.monotonic()
            outcomes = run_robot(robot, potential, args.cases or default_cases[name],
                                 args.seed, args.delay, without=args.without, plant=plant,
                                 overrides=overrides, workers=args.workers,
                                 ray_address=args.ray_address)
            label = ', '.join(x for x in (
                potential, f'without {args.without}' if args.without else '',
                f'within {robot.fraction:g} of the ranges', plant.describe(),
                ', '.join(f'{k} {v}' for k, v in overrides.items())) if x)
            text.append(report(robot, label, outcomes, time.monotonic() - t0))
            print(text[-1], flush=True)
    for name in args.robot if args.dds else ():
        robot = ROBOTS[name]
        text.append(f'{name} over DDS (nodes in lockstep, tanh, config/'
                    f'{robot.controller_config}):\n' + run_dds(robot, args.dds, args.seed))
    print('\n' + '\n'.join(text))
    return 0


def main_arm(parser: argparse.ArgumentParser, args, overrides: dict) -> int:
    """
    Run the conditions on one arm from its URDF (``--urdf`` or ``--example-robot``).

    ``overrides`` (``--param``) replace parameters of the design, by their ROS names.
    """
    try:
        path = args.urdf or arms.example_robot_urdf(args.example_robot)
        if not Path(path).is_file():
            raise ValueError(f'--urdf {path}: no such file')
        for name, value in (('--armature', args.armature), ('--rate', args.rate),
                            ('--armature-told-scale', args.armature_told_scale),
                            ('--friction-fraction', args.friction_fraction),
                            ('--friction-effort-share', args.friction_effort_share or 0.0),
                            ('--payload-share', args.payload_share)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be finite and >= 0, got {value}')
        encoder_resolution_rad(args.encoder_bits)
        if not all(0 <= d <= MAX_DELAY_TICKS for d in args.design_delays):
            raise ValueError(f'--design-delays must be in [0, {MAX_DELAY_TICKS}] ticks, got '
                             f'{args.design_delays}')
        robot = arm_robot(args.name or args.example_robot or Path(path).stem, str(path),
                          args.base_link, args.tip_link, cl.Task(args.task),
                          args.fraction if args.fraction is not None else 0.8,
                          args.duration if args.duration is not None else 5.0)
    except (ValueError, OSError) as exc:
        parser.error(str(exc))
    rows, text = [], []
    for name in args.condition:
        cond = condition(name, args.armature, args.armature_told_scale, args.friction_fraction,
                         args.encoder_bits, args.encoder_told, args.delay, args.payload_share)
        for potential in args.potential:
            t0 = time.monotonic()
            try:  # design_gains may refuse the arm, and says why (cached: run_arm reuses it)
                arm_design(robot, cond.told_armature, float(args.rate),
                           args.friction_effort_share, args.approach_time, args.cruise_fraction,
                           tuple(args.design_delays),
                           payload_kg(robot, cond) if cond.payload_told else 0.0)
            except ValueError as exc:
                parser.error(f'design_gains: {exc}')
            try:
                outcomes = run_arm(robot, cond, potential, args.cases or 20, args.seed,
                                   args.rate, args.engine, workers=args.workers,
                                   ray_address=args.ray_address,
                                   friction_effort_share=args.friction_effort_share,
                                   overrides=overrides, approach_time_s=args.approach_time,
                                   cruise_fraction=args.cruise_fraction,
                                   design_delays=tuple(args.design_delays),
                                   armature_estimation=not args.no_armature_estimation,
                                   redesign=not args.no_redesign, warm_up_s=args.warm_up,
                                   q_star_by_starts=args.q_star_by_starts)
            except (cl.GainsError, sh.ShapingError) as exc:
                parser.error(f'--param: {exc}')
            shown = (dataclasses.replace(robot, duration_s=robot.duration_s + cond.identify_at_s)
                     if cond.identify_at_s > 0.0 else robot)  # judged as run_arm runs it
            label = ', '.join([potential, cond.describe(), args.engine]
                              + ([f'payload {payload_kg(robot, cond):.3g} kg']
                                 if cond.payload_share else [])
                              + (['rotor inertia not estimated']
                                 if args.no_armature_estimation else [])
                              + (['no design again'] if args.no_redesign else [])
                              + ([f'after a warm-up of {args.warm_up:g} s'] if args.warm_up
                                 else [])
                              + (['q* later for a longer search'] if args.q_star_by_starts
                                 else [])
                              + [f'{k} {v}' for k, v in overrides.items()])
            text.append(report(shown, label, outcomes, time.monotonic() - t0,
                               args.cruise_fraction or CRUISE_FRACTION))
            print(text[-1], flush=True)
            rows.append(table_row(shown, cond, outcomes))
            print(rows[-1], flush=True)
    print('\n' + '\n'.join(text) + '\n\n' + TABLE_HEADER + '\n' + '\n'.join(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())

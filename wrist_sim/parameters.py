"""
The simulator's ROS parameters, as one table.

One table (``STRUCTURE``, ``LIVE``) of
:class:`~quat_jt_runtime.params.Spec` rows, in the idiom of ``quat_jt_runtime.params``.

The declarations, the descriptors and docs/parameters.md are generated from the table. The
read-only rows are read once into a :class:`SimStructure`; the live rows are applied whole as
the immutable :class:`~wrist_sim.config.SimConfig` (validated by ``SimConfig.create``).
``joints`` and the per-joint rows default from the URDF, so ``robot_description`` is read first.
"""
from dataclasses import dataclass
from typing import Callable, Optional

from quat_jt_runtime.description import robot_description
from quat_jt_runtime.joints import movable_joints
from quat_jt_runtime.param_table import joint_zeros, JOINT_ZEROS_TEXT, Kind, names, Spec
from quat_jt_runtime.params import ChangeLog, declare, LiveParameters, REALTIME, Realtime
from quat_jt_runtime.params import realtime_from
from quat_jt_runtime.payload import Payload, PAYLOAD_MASS_MAX_KG, with_payload
from quat_jt_runtime.urdf_source import Description, DescriptionError, Source, SOURCES
from quat_jt_runtime.urdf_source import WithDescription
from rclpy.node import Node
from wrist_sim.config import SimConfig
from wrist_sim.simulator import ENGINES, per_joint, SimulatorError


ROBOT_DESCRIPTION = Spec('robot_description', Kind.STRING, '',
                         'URDF as an XML string, e.g. from a launch or params file; or '
                         'robot_description_file, or robot_description_topic; none of them = '
                         'the bundled spherical wrist', read_only=True)
ENGINE = Spec('engine', Kind.STRING, ENGINES[0],
              "the physics engine: 'pybullet' (the default) or 'mujoco' (the mujoco package, "
              'the same URDF compiled by MuJoCo; it simulates the armature, and has no '
              'window). docs/ros.md compares them', read_only=True,
              constraints=' or '.join(f"'{e}'" for e in ENGINES))
# Declared after ``joints``, whose length is its context's ``n``.
ARMATURE = Spec('armature', Kind.DOUBLE_ARRAY, joint_zeros,
                'rotor inertia per joint, kg m^2 (>= 0), added to the diagonal of M(q) by '
                "engine 'mujoco'; PyBullet has no joint armature, so with engine 'pybullet' a "
                'non-zero value is not simulated and the node warns once',
                read_only=True, constraints='{n} finite values >= 0',
                default_text=JOINT_ZEROS_TEXT)
JOINTS = Spec('joints', Kind.STRING_ARRAY, lambda context: list(context['movable']),
              'joints to drive, in command/state order; default the URDF movable joints',
              read_only=True, default_text="the URDF's movable joints")
# A payload the URDF does not list, simulated on a link (quat_jt_runtime.payload)
PAYLOAD = (
    Spec('payload_link', Kind.STRING, '',
         "the link that carries payload_mass (the controller's tip_link, say); '' = none",
         read_only=True),
    Spec('payload_mass', Kind.DOUBLE, 0.0,
         'mass on payload_link that the URDF does not list, kg: a plant carrying a tool or a '
         'part its controller may not be told of (the controller has the same parameter)',
         read_only=True, bounds=(0.0, PAYLOAD_MASS_MAX_KG)),
    Spec('payload_com', Kind.DOUBLE_ARRAY, [0.0, 0.0, 0.0],
         "where payload_mass is, x y z in m in payload_link's frame", read_only=True,
         constraints='3 finite values'),
)
DESCRIPTION = (ROBOT_DESCRIPTION, *SOURCES)
STRUCTURE = (
    *DESCRIPTION, JOINTS, ENGINE, ARMATURE, *PAYLOAD,
    Spec('rate_hz', Kind.INT, 1000, 'steps per second; the time step is 1 / rate_hz',
         read_only=True, bounds=(1, 20000)),
    Spec('use_gui', Kind.BOOL, False, "open the PyBullet window (engine 'pybullet' only)",
         read_only=True),
    Spec('publish_clock', Kind.BOOL, False,
         'publish /clock with the simulation time and step in lockstep with the commands '
         'instead of in real time', read_only=True),
    Spec('clock_divider', Kind.INT, 10,
         'with publish_clock: publish /clock every N-th step (10 at 1 kHz: 100 Hz of simulated '
         'time); each /clock costs a publish here and a callback in every node on simulated '
         'time', read_only=True, bounds=(1, 1000)),
    Spec('hold_until_first_command', Kind.BOOL, True,
         'hold the joints at rest (brakes) until the first valid command after start-up or '
         '~/reset, so the robot does not fall while a controller connects', read_only=True),
    Spec('enforce_velocity_limits', Kind.BOOL, True,
         'hold each joint at its URDF velocity limit, as a drive would; off, a joint past it '
         'is only reported', read_only=True),
    Spec('publish_robot_description', Kind.BOOL, True,
         'publish the URDF in use on robot_description (std_msgs/String, transient local, as '
         'robot_state_publisher does), for RViz and a controller with robot_description_topic; '
         'off where a robot_state_publisher publishes that topic (the launch files with '
         'rviz:=true). Not when the URDF came from robot_description_topic', read_only=True),
    Spec('stats_file', Kind.STRING, '',
         'if set, timing statistics are written there as JSON at shutdown', read_only=True),
    Spec('stats_window_steps', Kind.INT, 30000,
         'the timing percentiles and stale-step counts cover the last N steps (30000: 30 s at '
         '1 kHz)', read_only=True, bounds=(100, 10_000_000)),
)
# Context: n (the number of joints).
LIVE = (
    Spec('initial_positions', Kind.DOUBLE_ARRAY, joint_zeros,
         'joint positions (rad or m) at start and on ~/reset', constraints='{n} finite values',
         default_text=JOINT_ZEROS_TEXT),
    Spec('viscous_friction', Kind.DOUBLE_ARRAY, joint_zeros,
         'viscous friction per joint, N m s/rad (>= 0)', constraints='{n} finite values >= 0',
         default_text=JOINT_ZEROS_TEXT),
    Spec('coulomb_friction', Kind.DOUBLE_ARRAY, joint_zeros,
         'Coulomb friction / stiction level per joint, N m (>= 0)',
         constraints='{n} finite values >= 0', default_text=JOINT_ZEROS_TEXT),
    Spec('command_timeout', Kind.DOUBLE, 0.5,
         'seconds (simulation time) without a valid command before the torque goes to zero; '
         '0 disables the watchdog', bounds=(0.0, 60.0)),
    Spec('lockstep_timeout', Kind.DOUBLE, 0.05,
         'lockstep: wall seconds to wait for the command of the last state before stepping '
         'anyway', bounds=(1e-4, 10.0)),
    Spec('max_real_time_factor', Kind.DOUBLE, 0.0,
         'lockstep: at most this many times faster than real time; 0 = no limit',
         bounds=(0.0, 1000.0)),
)
LIVE_PARAMETERS = names(LIVE)
DOCS_CONTEXT = {'n': 'n', 'movable': ()}


def armature_note(structure: 'SimStructure', simulated: bool) -> str:
    """Say that the armature asked for is not simulated ('' if it is, or if it is zero)."""
    if simulated or not any(structure.armature):
        return ''
    return (f'armature {list(structure.armature)} kg m^2 is NOT simulated: engine '
            f"'{structure.engine}' has no joint armature, so the plant's inertia is the URDF's "
            "alone; use engine 'mujoco' to simulate the rotor inertia")


@dataclass(frozen=True)
class SimStructure(WithDescription):
    """The read-only parameters, read once at start-up."""

    description: Description  # the URDF in use and where it came from
    joints: tuple[str, ...]
    engine: str  # one of wrist_sim.simulator.ENGINES
    armature: tuple[float, ...]  # kg m^2 per joint, finite and >= 0
    payload_link: str  # '' = no payload
    payload: Payload  # what payload_link carries beyond the URDF
    rate_hz: int
    use_gui: bool
    publish_clock: bool
    clock_divider: int
    hold_until_first_command: bool
    enforce_velocity_limits: bool
    publish_robot_description: bool  # and the URDF did not come from a topic
    stats_file: str
    stats_window_steps: int
    realtime: Realtime  # cpu_affinity, thread_priority (off in lockstep and with the window)

    @property
    def plant_xml(self) -> str:
        """Return the URDF the engine simulates: the description's, the payload's link added."""
        if not self.payload_link or self.payload.mass_kg == 0.0:
            return self.urdf_xml
        return with_payload(self.urdf_xml, self.payload_link, self.payload.mass_kg,
                            self.payload.com_m)

    @property
    def dt_ns(self) -> int:
        """Return the time step in nanoseconds (1 / rate_hz)."""
        return int(round(1e9 / self.rate_hz))


def declare_structure(node: Node) -> SimStructure:
    """Declare the read-only parameters and return them; raise SimulatorError if unusable."""
    try:
        description = robot_description(node, declare(node, DESCRIPTION))
    except DescriptionError as exc:
        raise SimulatorError(str(exc)) from None
    urdf = description.xml
    try:
        movable = movable_joints(urdf)
    except ValueError as exc:
        raise SimulatorError(f'robot_description: {exc}') from None
    if not movable:
        raise SimulatorError('the URDF has no movable joints')
    rest = tuple(s for s in STRUCTURE[len(DESCRIPTION):] if s is not ARMATURE)
    values = declare(node, rest + REALTIME, {'movable': movable})
    values.update(declare(node, (ARMATURE,), {'n': len(values['joints'])}))
    if values['engine'] not in ENGINES:
        raise SimulatorError(f"engine must be one of {list(ENGINES)}, got {values['engine']!r}")
    armature = per_joint('armature', values['armature'], len(values['joints']),
                         nonnegative=True)
    try:
        payload = Payload.create(values['payload_mass'], values['payload_com'])
    except ValueError as exc:
        raise SimulatorError(str(exc)) from None
    if values['payload_link']:
        try:  # a link of the URDF?
            with_payload(urdf, values['payload_link'], 1.0, (0.0, 0.0, 0.0))
        except ValueError as exc:
            raise SimulatorError(f'payload_link: {exc}') from None
    if payload.mass_kg > 0.0 and not values['payload_link']:
        raise SimulatorError(f'payload_mass {payload.mass_kg:g} kg needs a payload_link to '
                             'carry it')
    # Applied by lifecycle.run_node; no deadlines in lockstep, and the window renders in a
    # thread of its own: normal scheduling there.
    off = 'lockstep' if values['publish_clock'] else 'the PyBullet window' if values[
        'use_gui'] else ''
    try:
        settings = realtime_from(values, off)
    except ValueError as exc:
        raise SimulatorError(str(exc)) from None
    return SimStructure(
        description=description, joints=tuple(values['joints']),
        engine=values['engine'], armature=armature, payload_link=values['payload_link'],
        payload=payload,
        rate_hz=int(values['rate_hz']), use_gui=bool(values['use_gui']),
        publish_clock=bool(values['publish_clock']),
        clock_divider=int(values['clock_divider']),
        hold_until_first_command=bool(values['hold_until_first_command']),
        enforce_velocity_limits=bool(values['enforce_velocity_limits']),
        publish_robot_description=bool(values['publish_robot_description'])
        and description.source is not Source.TOPIC,
        stats_file=values['stats_file'], stats_window_steps=int(values['stats_window_steps']),
        realtime=settings)


def declare_live(node: Node, n_joints: int,
                 on_apply: Optional[Callable[[SimConfig], None]] = None
                 ) -> LiveParameters[SimConfig]:
    """Declare the live parameters; return them as LiveParameters of a SimConfig."""
    declare(node, LIVE, {'n': n_joints})
    return LiveParameters(node, LIVE_PARAMETERS,
                          lambda values: SimConfig.create(values, n_joints), on_apply)


def change_log(node: Node, live: LiveParameters[SimConfig]) -> ChangeLog:
    """Log each parameter request once, with the live settings then in force."""
    return ChangeLog(node, ((LIVE_PARAMETERS, lambda: describe_config(live.current)),))


def describe_config(config: SimConfig) -> str:
    """Describe the live settings in force (logged once per parameter request)."""
    c = config
    return (f'initial_positions {list(c.initial_positions_rad)} rad, friction: viscous '
            f'{list(c.viscous_nm_s_per_rad)} N m s/rad, Coulomb {list(c.coulomb_nm)} N m, '
            f'command_timeout {c.command_timeout_s} s, lockstep_timeout '
            f'{c.lockstep_timeout_s} s, max_real_time_factor {c.max_real_time_factor}')

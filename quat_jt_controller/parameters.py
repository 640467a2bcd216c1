"""
The controller's ROS parameters: the table of ``parameter_table`` declared on the node.

Not part of the ROS-free core (it imports rclpy). The declarations and the descriptors are
generated from the table's rows (``parameter_table``: type, default, range, size rule,
description). The structural rows are read once at start-up into a :class:`StructuralConfig`;
the live rows are applied whole as the immutable
:class:`~quat_jt_controller.control_law.Gains` (validated by ``Gains.create``) and
:class:`~quat_jt_controller.shaping.Shaping` (``Shaping.create``, which checks every row, then
the robot's check).
"""
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional, Sequence

from quat_jt_controller import parameter_table as table
from quat_jt_controller.control_law import gain_ceiling, Gains, MAX_LAMBDA, Task
from quat_jt_controller.gain_cli import parse_design_options
from quat_jt_controller.regulator import Regulator
from quat_jt_controller.shaping import describe as describe_shaping
from quat_jt_controller.shaping import from_parameters as shaping_from_parameters
from quat_jt_controller.shaping import Shaping
from quat_jt_runtime.description import robot_description
from quat_jt_runtime.joints import check_state_rate
from quat_jt_runtime.param_table import names, row
from quat_jt_runtime.params import ChangeLog, declare, LiveParameters, rclpy_type
from quat_jt_runtime.payload import Payload
from quat_jt_runtime.urdf_source import Description, WithDescription
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter


@dataclass(frozen=True)
class StructuralConfig(WithDescription):
    """The read-only parameters, read once at start-up."""

    task: Task
    joints: tuple[str, ...]
    base_link: str
    tip_link: str
    description: Description  # the URDF in use and where it came from
    armature: tuple[float, ...]  # kg m^2 per joint, finite and >= 0
    position_resolution: tuple[float, ...]  # rad (m) a count per joint; 0: exact
    state_timeout_s: float
    max_state_age_s: float  # 0: stamps not checked
    state_rate_hz: float
    publish_rate_divider: int
    prewarm_lead_s: float  # 0: no throwaway tick before each state

    @classmethod
    def create(cls, values: Mapping[str, Any],
               description: Callable[[], Description]) -> 'StructuralConfig':
        """
        Build from the structural parameters; raise ValueError naming a bad value.

        ``description`` returns the URDF; it is called once the other values are checked (it
        may wait for a topic).
        """
        task = Task(row(table.STRUCTURE, 'task').check(values['task'], {}))
        joints = tuple(values['joints'])
        if not joints or any(not j for j in joints):
            raise ValueError(f'joints must be a non-empty list of names, got {list(joints)}')
        if not values['base_link'] or not values['tip_link']:
            raise ValueError('base_link and tip_link must not be empty')
        armature = table.ARMATURE.check(values['armature'], {'n': len(joints)})
        resolution = table.POSITION_RESOLUTION.check(values['position_resolution'],
                                                     {'n': len(joints)})
        state_rate_hz = check_state_rate(values['state_rate'])
        # read by a design again (design_inputs); checked here, so a bad one stops the start
        parse_design_options(tuple(values.get('design_options') or ()), len(joints))
        return cls(task=task, joints=joints, base_link=values['base_link'],
                   tip_link=values['tip_link'], armature=armature,
                   position_resolution=resolution,
                   description=description(),
                   state_timeout_s=float(values['state_timeout']),
                   max_state_age_s=float(values['max_state_age']),
                   state_rate_hz=state_rate_hz,
                   publish_rate_divider=int(values['publish_rate_divider']),
                   prewarm_lead_s=float(values['prewarm_lead']))


def declare_structural(node: Node) -> StructuralConfig:
    """
    Declare the read-only parameters and return their values, the URDF from its source.

    A ``robot_description_topic`` is waited for here, before the model is built. Raises
    ValueError naming the parameter if a value is unusable (DescriptionError for the URDF).
    """
    values = declare(node, tuple(s for s in table.STRUCTURE
                                 if s not in table.PER_JOINT_STRUCTURE))
    values.update(declare(node, table.PER_JOINT_STRUCTURE, {'n': len(values['joints'])}))
    return StructuralConfig.create(values, lambda: robot_description(node, values))


def gains_context(config: StructuralConfig, effort_limits_nm: Sequence[float]) -> dict:
    """Return the context of the GAINS rows for this robot (sizes, axes, the ceilings)."""
    ceiling = gain_ceiling(effort_limits_nm)
    return {'task': config.task, 'dim': config.task.dim, 'n': len(config.joints),
            'axes': ', '.join((['x', 'y', 'z'] if config.task.has_position else [])
                              + (['rx', 'ry', 'rz'] if config.task.has_orientation else [])),
            'top': f'{ceiling:g}', 'ceiling': ceiling, 'lambda_ceiling': MAX_LAMBDA}


def declare_gains(node: Node, config: StructuralConfig, effort_limits_nm: Sequence[float],
                  on_apply: Optional[Callable[[Gains], None]] = None) -> LiveParameters[Gains]:
    """
    Declare the live gain parameters; return them as LiveParameters of a Gains.

    ``on_apply`` is called with each new Gains after a successful parameter set.

    Raises GainsError (naming the bad value) if the start-up values are invalid.
    """
    declare(node, table.GAINS, gains_context(config, effort_limits_nm))
    return LiveParameters(
        node, names(table.GAINS), lambda values: build_gains(values, config, effort_limits_nm),
        on_apply)


def describe_start(config: StructuralConfig, regulator: Regulator,
                   state_topic: str = 'joint_states') -> list[str]:
    """Describe the controller at start-up: its extensions, then its task, robot and gains."""
    gains = regulator.gains
    return [f'extensions: {describe_shaping(regulator.shaping)}',
            f'{config.task.value} task, joints {list(config.joints)}, {config.base_link} -> '
            f'{config.tip_link}, potential {gains.potential.value}, kp {list(gains.kp)}, kv '
            f'{list(gains.kv)}, lambda {list(gains.lam)}, effort limits '
            f'{list(regulator.effort_limits_nm)} N m'
            + (f', {regulator.model.payload.describe(config.tip_link)}'
               if regulator.model.payload_kg > 0.0 else '')
            + f'; waiting for joint states on {state_topic}, '
            'then holding the first pose measured until a goal arrives on ~/target_pose'
            + ('' if config.task.has_orientation else
               " (the position task: a goal's orientation is not read; any quaternion, all "
               'zeros too, is accepted)')]


def change_log(node: Node, regulator: Regulator) -> ChangeLog:
    """Log each parameter request once, with the gains and the extensions then in force."""
    return ChangeLog(node, (
        (names(table.GAINS), lambda: describe_gains(regulator.gains)),
        (names(table.SHAPING), lambda: f'extensions: {describe_shaping(regulator.shaping)}'),
        (names(table.PAYLOAD),
         lambda: regulator.model.payload.describe(regulator.model.tip_link))))


def describe_gains(gains: Gains) -> str:
    """Describe the gains in force, as the log lines do."""
    return (f'potential {gains.potential.value}, kp {list(gains.kp)}, kv {list(gains.kv)}, '
            f'lambda {list(gains.lam)}, gravity_compensation {gains.gravity_compensation}')


def build_gains(values: Mapping[str, Any], config: StructuralConfig,
                effort_limits_nm: Optional[Sequence[float]] = None) -> Gains:
    """Gains from parameter values keyed by parameter name. Raises GainsError."""
    return Gains.create(values['potential'], values['kp'], values['kv'], values['lambda'],
                        config.task, len(config.joints), values['gravity_compensation'],
                        effort_limits_nm)


def declare_shaping(node: Node, config: StructuralConfig,
                    check: Optional[Callable[[Shaping], Shaping]] = None,
                    on_apply: Optional[Callable[[Shaping], None]] = None,
                    preferred_configuration: Optional[Sequence[float]] = None
                    ) -> LiveParameters[Shaping]:
    """
    Declare the live extension parameters (docs/lyapunov.md); return them as a Shaping.

    ``check`` validates a Shaping against the robot (``Regulator.check_shaping``: the margin
    must fit inside the joint ranges) as part of the on-set validation; ``on_apply`` is called
    with each new Shaping after a successful set; ``preferred_configuration`` is that
    parameter's default (the middle of the robot's ranges). Raises ShapingError (naming the bad
    value) if the start-up values are invalid.
    """
    n = len(config.joints)
    declare(node, table.SHAPING, {'n': n, 'preferred_configuration':
                                  preferred_configuration or [0.0] * n})

    def build(values: Mapping[str, Any]) -> Shaping:
        shaping = build_shaping(values, config)
        return shaping if check is None else check(shaping)

    return LiveParameters(node, names(table.SHAPING), build, on_apply)


def declare_payload(node: Node, check: Optional[Callable[[Payload], Payload]] = None,
                    on_apply: Optional[Callable[[Payload], None]] = None
                    ) -> LiveParameters[Payload]:
    """
    Declare the live payload parameters; return them as a Payload.

    ``check`` validates a Payload against the arm (``Regulator.check_payload``: held up where
    it is) as part of the on-set validation; ``on_apply`` is called with each new Payload after
    a successful set (the regulator's model carries it from the next tick). Raises ValueError
    naming a bad start-up value.
    """
    declare(node, table.PAYLOAD)

    def build(values: Mapping[str, Any]) -> Payload:
        payload = Payload.from_parameters(values)
        return payload if check is None else check(payload)

    return LiveParameters(node, names(table.PAYLOAD), build, on_apply)


def build_shaping(values: Mapping[str, Any], config: StructuralConfig) -> Shaping:
    """Shaping from parameter values keyed by parameter name. Raises ShapingError."""
    return shaping_from_parameters(dict(values), len(config.joints))


# The read-only parameters a design again reads (redesign.redesign), beside the live ones
DESIGN_STRUCTURE = ('task', 'joints', 'base_link', 'tip_link', 'state_rate', 'design_options')


def design_inputs(node: Node) -> dict[str, Any]:
    """Return what a design again reads: the robot's parameters and every live one."""
    wanted = DESIGN_STRUCTURE + tuple(names(table.GAINS) + names(table.SHAPING)
                                      + names(table.PAYLOAD))
    return {name: node.get_parameter(name).value for name in wanted}


def set_live(node: Node, values: Mapping[str, Any]) -> str:
    """
    Set live gain and extension parameters on ``node`` as one atomic change.

    Each value is converted to its row's type (a design's 5 is the parameter's 5.0); the
    node's on-set callbacks check them all, as for ``ros2 param set``. Return '' if they are
    in force, else why not.
    """
    rows = {spec.name: spec for spec in tuple(table.GAINS) + tuple(table.SHAPING)}
    try:
        result = node.set_parameters_atomically([
            Parameter(name, rclpy_type(rows[name].kind), _typed(rows[name].kind.label, value))
            for name, value in values.items()])
    except KeyError as exc:
        return f'{exc.args[0]} is not a live parameter'
    except (ParameterException, TypeError, ValueError) as exc:
        return str(exc)
    return '' if result.successful else result.reason


def _typed(label: str, value: Any) -> Any:
    """Return ``value`` as a parameter of type ``label`` holds it (a float for a double)."""
    convert = {'double': float, 'int': int, 'bool': bool, 'string': str}[label.rstrip('[]')]
    return [convert(v) for v in value] if label.endswith('[]') else convert(value)

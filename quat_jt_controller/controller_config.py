"""
The controller from its parameters, ROS-free: what a config file makes of the regulator.

``controller_node`` declares these parameters from its table (``parameter_table.py``) and
validates them with the same constructors: ``Gains.create`` with the URDF effort limits as
ceilings, ``shaping.from_parameters`` (every row's range and size) and
``Regulator.set_shaping``. :func:`controller_from_config` does
the same from a mapping (a config file's ``ros__parameters``), so the experiments, the
benchmark and the tests run the controller the node would run from that file.
"""
from typing import Any, Mapping, Optional

from quat_jt_controller import control_law as cl
from quat_jt_controller import shaping as sh
from quat_jt_controller.model import RobotModel
from quat_jt_controller.regulator import Regulator
from quat_jt_runtime.errors import QuatJtError
from quat_jt_runtime.resources import config_parameters
from quat_jt_runtime.urdf_source import choose, resolve_offline


class ConfigError(QuatJtError):
    """The controller parameters lack a value the controller needs."""


REQUIRED = ('task', 'potential', 'kp', 'kv', 'lambda', 'joints', 'base_link', 'tip_link')


def controller_from_config(params: Mapping[str, Any], urdf_xml: str = '',
                           potential: Optional[str] = None,
                           overrides: Optional[Mapping[str, Any]] = None) -> Regulator:
    """
    Build the Regulator of controller parameters keyed by their ROS names (no goal yet).

    ``urdf_xml`` is the robot (default: the parameters' ``robot_description`` or
    ``robot_description_file``, and if neither is set the bundled wrist, as for the node);
    ``potential`` and ``overrides`` replace the parameters' values. Raises the node's errors
    (ModelError, GainsError, ShapingError, DescriptionError), each naming the bad value, or
    ConfigError naming a missing one. A missing ``preferred_configuration`` is the middle of
    the ranges, and a missing ``armature`` zeros and ``payload_mass`` 0, as the node's defaults.
    """
    p = {**params, **(overrides or {})}
    missing = [name for name in REQUIRED if name not in p and not (
        name == 'potential' and potential)]
    if missing:
        raise ConfigError(f'the controller parameters lack {missing}')
    if not urdf_xml:  # the node's sources: the text, a file (a topic needs a running node)
        urdf_xml = resolve_offline(choose(p.get('robot_description', ''),
                                          p.get('robot_description_file', ''),
                                          p.get('robot_description_topic', ''))).xml
    model = RobotModel(urdf_xml, p['base_link'], p['tip_link'], p['joints'],
                       p.get('armature') or None, p.get('payload_mass', 0.0),
                       p.get('payload_com', (0.0, 0.0, 0.0)))
    task = cl.Task(p['task'])
    gains = cl.Gains.create(potential or p['potential'], p['kp'], p['kv'], p['lambda'], task,
                            model.n, p.get('gravity_compensation', True), model.effort_limits)
    regulator = Regulator(model, task, gains)
    if not p.get('preferred_configuration'):
        p['preferred_configuration'] = list(model.middle_of_ranges())
    regulator.set_shaping(sh.from_parameters(p, model.n))
    return regulator


def controller_from_package_config(name: str, urdf_xml: str = '',
                                   potential: Optional[str] = None,
                                   overrides: Optional[Mapping[str, Any]] = None) -> Regulator:
    """Build the Regulator of the package's ``config/<name>`` (see controller_from_config)."""
    return controller_from_config(config_parameters(name), urdf_xml, potential, overrides)

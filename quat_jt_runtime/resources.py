"""
Locate the package's data files (URDF, config) in a source tree, a pip or a colcon install.

ROS-free: looks for ``share/<package>`` the way ament_index does, without importing it. This is
the package's one resolver of ament share folders: the simulator's mesh lookup uses
:func:`ament_package_dirs` too.
"""
import os
from pathlib import Path
import sys

PACKAGE_NAME = 'quat_jt_controller'
DEFAULT_URDF = 'urdf/spherical_wrist.urdf'


def ament_package_dirs(package: str) -> list[Path]:
    """
    Return ``<prefix>/share/<package>`` of each sourced workspace that has it.

    The prefixes are ``AMENT_PREFIX_PATH``'s, as ``ament_index_python`` reads them (a package
    is in the index if ``<prefix>/share/ament_index/resource_index/packages/<package>``
    exists); ROS-free, so a pip install without ROS finds nothing and goes on.
    """
    out = []
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if not prefix:
            continue
        marker = Path(prefix) / 'share' / 'ament_index' / 'resource_index' / 'packages'
        share = Path(prefix) / 'share' / package
        if (marker / package).is_file() and share.is_dir():
            out.append(share)
    return out


def _candidate_roots() -> list[Path]:
    roots = []
    source_root = Path(__file__).resolve().parent.parent
    if (source_root / 'package.xml').is_file() and (source_root / 'urdf').is_dir():
        roots.append(source_root)  # a source checkout or an editable pip install
    roots += ament_package_dirs(PACKAGE_NAME)  # colcon / ROS install
    roots.append(Path(sys.prefix) / 'share' / PACKAGE_NAME)  # pip install (data_files)
    return roots


def share_path(relative: str) -> Path:
    """
    Return the path of a data file such as ``urdf/spherical_wrist.urdf``.

    Raises FileNotFoundError naming every place searched.
    """
    tried = []
    for root in _candidate_roots():
        path = root / relative
        if path.is_file():
            return path
        tried.append(str(path))
    raise FileNotFoundError(f'{relative!r} not found; searched: {", ".join(tried)}')


def default_urdf_xml() -> str:
    """Return the bundled spherical-wrist URDF as an XML string."""
    return share_path(DEFAULT_URDF).read_text()


def bundled_urdf_hint(robot_description: str) -> str:
    """
    Return advice to append to a joint or link error when no robot description was given.

    ``robot_description`` is the URDF as given ('' = none): then the bundled spherical wrist
    was loaded, and a user who runs a node for another robot (the xArm6, say) with ``ros2 run``
    must pass its URDF, as a file or from robot_state_publisher's topic.
    """
    if robot_description:
        return ''
    return ('. No robot description was given, so the bundled spherical wrist (joint1-joint3, '
            'base_link -> tool0) was loaded; for another robot pass its URDF file, e.g. '
            '--ros-args -p robot_description_file:=/path/robot.urdf (the xArm6 URDF is '
            '<pybullet_data>/xarm/xarm6_robot.urdf; python3 -c "import pybullet_data; '
            'print(pybullet_data.getDataPath())" prints that folder), or take it from '
            'robot_state_publisher with -p robot_description_topic:=/robot_description, or '
            'start the node with its launch file')


def config_parameters(name: str) -> dict:
    """
    Return the ``ros__parameters`` of the package's ``config/<name>``.

    The config files key their parameters by ``/**`` (any node name, any namespace), so the
    same file serves a renamed or namespaced node.
    """
    import yaml  # rclpy's own dependency; only needed here

    with open(share_path(f'config/{name}')) as f:
        return yaml.safe_load(f)['/**']['ros__parameters']

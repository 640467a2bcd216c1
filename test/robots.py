"""Robot models shared by the core tests: the paper's wrist, the xArm6 and the 7-DOF Panda."""
from pathlib import Path

import numpy as np
import pybullet_data

from quat_jt_controller import paper
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml

XARM6_URDF = Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf'
PANDA_URDF = Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf'
PANDA_JOINTS = tuple(f'panda_joint{i}' for i in range(1, 8))  # the fingers are not regulated

# The paper's experiment, from its one source in the package (docs/errata.md applied).
Q_DESIRED = paper.Q_DESIRED
Q_JOINT_DESIRED = paper.Q_JOINT_DESIRED_RAD
PAPER_KP = paper.KP
PAPER_KV = paper.KV
PAPER_LAMBDA = paper.LAMBDA


def wrist_model() -> RobotModel:
    return RobotModel(default_urdf_xml(), 'base_link', 'tool0')


def xarm6_model() -> RobotModel:
    return RobotModel(XARM6_URDF.read_text(), 'link_base', 'link6')


def panda_model() -> RobotModel:
    return RobotModel(PANDA_URDF.read_text(), 'panda_link0', 'panda_link8', PANDA_JOINTS)


def random_q(model: RobotModel, rng: np.random.Generator, margin: float = 0.1) -> np.ndarray:
    lo = np.maximum(np.array(model.position_lower), -np.pi) + margin
    hi = np.minimum(np.array(model.position_upper), np.pi) - margin
    return rng.uniform(lo, hi)


def assert_jacobian_matches_finite_differences(model: RobotModel, q, h: float = 1e-6) -> None:
    """J_p = dp/dq and S(J_o dq) R = dR by central differences in each joint (Eq. 12)."""
    _, R, J = model.kinematics(q)
    J = np.array(J)
    for j in range(model.n):
        dq = np.zeros(model.n)
        dq[j] = h
        p1, R1 = model.forward_kinematics(q + dq)
        p0, R0 = model.forward_kinematics(q - dq)
        np.testing.assert_allclose((np.subtract(p1, p0)) / (2 * h), J[:3, j], atol=1e-7)
        omega_skew = (np.array(R1) - np.array(R0)) / (2 * h) @ np.array(R).T
        omega = np.array([omega_skew[2, 1], omega_skew[0, 2], omega_skew[1, 0]])
        np.testing.assert_allclose(omega, J[3:, j], atol=1e-7)


def _inertial(mass: float, x: float) -> str:
    i = 0.01 * mass
    return (f'<inertial><origin xyz="{x} 0 0"/><mass value="{mass}"/><inertia ixx="{i}" '
            f'iyy="{1.5 * i}" izz="{2 * i}" ixy="0" ixz="0" iyz="0"/></inertial>')


def small_arm_urdf(joint_types=('continuous', 'revolute', 'revolute', 'continuous',
                                'revolute')) -> str:
    """
    Return a small serial arm written in the test, one joint per entry of ``joint_types``.

    The axes alternate z, y, y, x, y, ... The last joint and its child link are both named
    'tool' (a name that is a link and a joint). Revolute joints have stops at -2 and 2 rad.
    """
    axes = ('0 0 1', '0 1 0', '0 1 0', '1 0 0', '0 1 0', '1 0 0', '0 0 1')
    n = len(joint_types)
    links = ['base_link'] + [f'link{i}' for i in range(1, n)] + ['tool']
    parts = ['<robot name="small_arm">', '<link name="base_link"/>']
    for i, kind in enumerate(joint_types):
        child = links[i + 1]
        name = 'tool' if i == n - 1 else f'joint{i + 1}'
        limits = ('lower="-2" upper="2" ' if kind == 'revolute' else '')
        parts += [f'<link name="{child}">{_inertial(1.0 / (i + 1), 0.05)}</link>',
                  f'<joint name="{name}" type="{kind}"><parent link="{links[i]}"/>'
                  f'<child link="{child}"/><origin xyz="{0.2 if i else 0.0} 0 '
                  f'{0.1 if i == 0 else 0.0}" rpy="0 0 0"/><axis xyz="{axes[i % 7]}"/>'
                  f'<limit {limits}effort="{20.0 / (i + 1)}" velocity="3"/></joint>']
    parts.append('</robot>')
    return '\n'.join(parts)


def example_robot_data_urdf(relative: str) -> Path:
    """
    Return a URDF of example-robot-data (skip the test if it is absent).

    From the PyPI wheel (``pip install example-robot-data``: its cmeel prefix) or from a ROS
    install (ros-jazzy-example-robot-data, found through AMENT_PREFIX_PATH).
    """
    import os
    from importlib import metadata

    import pytest
    roots = [Path(p) / 'share' / 'example-robot-data' / 'robots'
             for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    try:
        dist = metadata.distribution('example-robot-data')
        roots.insert(0, Path(dist.locate_file('cmeel.prefix/share/example-robot-data/robots')))
    except metadata.PackageNotFoundError:
        pass
    for root in roots:
        if (root / relative).is_file():
            return root / relative
    pytest.skip(f'example-robot-data ({relative}) is not installed: pip install '
                'example-robot-data')

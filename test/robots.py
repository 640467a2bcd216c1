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

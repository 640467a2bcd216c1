"""Robot models shared by the core tests: the paper's wrist and a 6-DOF arm (xArm6)."""
from pathlib import Path

import numpy as np
import pybullet_data

from quat_jt_controller.model import RobotModel
from quat_jt_controller.resources import default_urdf_xml

XARM6_URDF = Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf'

# ERRATA.md note 2: corrected goal (scalar first) and where the wrist reaches it.
Q_DESIRED = (0.5566, 0.0, 0.4226, 0.7152)
Q_JOINT_DESIRED = (0.9095, 0.8727, 0.9095)
PAPER_KP = (4.5, 20.5, 17.5)
PAPER_KV = (1.0, 1.0, 1.0)
PAPER_LAMBDA = (30.0, 30.0, 30.0)


def wrist_model() -> RobotModel:
    return RobotModel(default_urdf_xml(), 'base_link', 'tool0')


def xarm6_model() -> RobotModel:
    return RobotModel(XARM6_URDF.read_text(), 'link_base', 'link6')


def random_q(model: RobotModel, rng: np.random.Generator, margin: float = 0.1) -> np.ndarray:
    lo = np.maximum(np.array(model.position_lower), -np.pi) + margin
    hi = np.minimum(np.array(model.position_upper), np.pi) - margin
    return rng.uniform(lo, hi)

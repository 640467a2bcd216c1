"""
A robot's transforms from its URDF, as ``robot_state_publisher`` publishes them, for 3D replay.

For each URDF joint, the transform from its parent link to its child link: on ``/tf_static``
for fixed joints (once), on ``/tf`` for the others (at the recorded joint positions). With the
URDF on ``/robot_description`` a viewer (Foxglove's 3D panel, RViz's RobotModel) draws the robot
from these alone. The placements come from Pinocchio's forward kinematics of the URDF (each
joint's transform is the relative placement of its child link's frame in its parent link's).

:func:`write_robot_replay` adds ``/robot_description``, ``/tf_static`` (the fixed joints and a
goal frame) and ``/tf`` (decimated to ``tf_rate_hz`` of the joint-state stamps) to a
:class:`~experiments.mcap_log.McapLog`. ROS-free.
"""
from typing import Optional, Sequence
from xml.etree import ElementTree

from experiments.mcap_log import cdr_string, cdr_tf_message, McapLog
import numpy as np
import pinocchio as pin
from quat_jt_controller import quaternion as quat

# (parent frame, child frame, translation xyz in m, rotation quaternion x, y, z, w)
Transform = tuple[str, str, tuple[float, float, float], tuple[float, float, float, float]]
GOAL_FRAME = 'goal'
TF_RATE_HZ = 100.0


def _as_transform(parent: str, child: str, placement: pin.SE3) -> Transform:
    xyzw = quat.to_xyzw(quat.from_rotation_matrix(placement.rotation))
    return (parent, child, tuple(float(v) for v in placement.translation),
            tuple(float(v) for v in xyzw))


class UrdfTfTree:
    """
    The parent-to-child transform of every joint of a URDF, at given joint positions.

    :param joint_names: the order of the positions passed to :meth:`moving_transforms`; joints
        of the URDF not named stay at zero (as the simulator and the model lock them).
    """

    def __init__(self, urdf_xml: str, joint_names: Sequence[str]) -> None:
        root = ElementTree.fromstring(urdf_xml)
        self.model = pin.buildModelFromXML(urdf_xml)
        self.data = self.model.createData()
        self.joint_names = tuple(joint_names)
        self._fixed: list[tuple[str, str]] = []
        self._moving: list[tuple[str, str]] = []
        for joint in root.findall('joint'):  # not those inside <transmission>
            link = (joint.find('parent').get('link'), joint.find('child').get('link'))
            (self._fixed if joint.get('type') == 'fixed' else self._moving).append(link)
        self._frame = {name: self.model.getFrameId(name, pin.BODY)
                       for pair in self._fixed + self._moving for name in pair}
        missing = [n for n, i in self._frame.items() if i >= self.model.nframes]
        if missing:
            raise ValueError(f'links {missing} are not in the Pinocchio model of the URDF')
        self._q_index = []
        for name in self.joint_names:
            if not self.model.existJointName(name):
                raise ValueError(f'joint {name!r} is not a movable joint of the URDF')
            joint = self.model.joints[self.model.getJointId(name)]
            if joint.nv != 1 or joint.nq not in (1, 2):
                raise ValueError(f'joint {name!r} has {joint.nq} coordinates; only revolute, '
                                 'continuous and prismatic joints are supported')
            self._q_index.append((joint.idx_q, joint.nq == 2))  # continuous: (cos q, sin q)
        self._q = pin.neutral(self.model)

    @property
    def parent_child_links(self) -> list[tuple[str, str]]:
        """Return (parent, child) of every joint: fixed joints first, then the others."""
        return self._fixed + self._moving

    def _placements(self, q_rad: Optional[Sequence[float]],
                    pairs: list[tuple[str, str]]) -> list[Transform]:
        self._q[:] = pin.neutral(self.model)
        if q_rad is not None:
            for (i, continuous), v in zip(self._q_index, q_rad):
                if continuous:
                    self._q[i:i + 2] = np.cos(v), np.sin(v)
                else:
                    self._q[i] = v
        pin.framesForwardKinematics(self.model, self.data, self._q)
        return [_as_transform(parent, child, self.data.oMf[self._frame[parent]].actInv(
            self.data.oMf[self._frame[child]])) for parent, child in pairs]

    def static_transforms(self) -> list[Transform]:
        """Return the transforms of the fixed joints."""
        return self._placements(None, self._fixed)

    def moving_transforms(self, q_rad: Sequence[float]) -> list[Transform]:
        """Return the transforms of the other joints at ``q_rad`` (``joint_names`` order)."""
        return self._placements(q_rad, self._moving)


def decimate(stamps_ns: Sequence[int], rate_hz: float) -> np.ndarray:
    """Return the indices of the first sample in each period of ``1 / rate_hz``."""
    period_ns = int(round(1e9 / rate_hz))
    bins = np.asarray(stamps_ns, dtype=np.int64) // period_ns
    return np.flatnonzero(np.r_[True, np.diff(bins) > 0])


def write_robot_replay(log: McapLog, urdf_xml: str, joint_names: Sequence[str],
                       log_ns: Sequence[int], stamps_ns: Sequence[int], q_rad: np.ndarray,
                       goal: Optional[tuple[str, Sequence[float], Sequence[float]]] = None,
                       tf_rate_hz: float = TF_RATE_HZ,
                       moving_goals: Sequence[tuple[int, str, Sequence[float],
                                                    Sequence[float]]] = ()) -> dict[str, int]:
    """
    Add the topics a 3D viewer needs to replay the robot to ``log``; return message counts.

    :param log_ns, stamps_ns, q_rad: the recorded joint states: time of recording (the MCAP log
        time), header stamp and positions (N, n) in ``joint_names`` order.
    :param goal: (base frame, p_base_m, quaternion x, y, z, w) of a frame named 'goal' child of
        the base frame, published on /tf_static.
    :param moving_goals: (stamp_ns, base frame, p_base_m, x, y, z, w) of a sequence of goals:
        the 'goal' frame on /tf from each stamp on (instead of ``goal``).
    """
    tree = UrdfTfTree(urdf_xml, joint_names)
    start_ns = int(log_ns[0])
    description = log.channel('/robot_description', 'std_msgs/msg/String', latched=True)
    log.write(description, cdr_string(urdf_xml), start_ns)
    static = [(int(stamps_ns[0]),) + t for t in tree.static_transforms()]
    if goal is not None:
        base, p_base_m, xyzw = goal
        static.append((int(stamps_ns[0]), base, GOAL_FRAME, tuple(p_base_m), tuple(xyzw)))
    log.write(log.channel('/tf_static', 'tf2_msgs/msg/TFMessage', latched=True),
              cdr_tf_message(static), start_ns)
    tf = log.channel('/tf', 'tf2_msgs/msg/TFMessage')
    keep = decimate(stamps_ns, tf_rate_hz)
    goals = sorted(moving_goals, key=lambda g: g[0])
    for k in keep:
        stamp = int(stamps_ns[k])
        transforms = [(stamp,) + t for t in tree.moving_transforms(q_rad[k])]
        current = [g for g in goals if g[0] <= stamp]
        if current:
            _, base, p_base_m, xyzw = current[-1]
            transforms.append((stamp, base, GOAL_FRAME, tuple(p_base_m), tuple(xyzw)))
        log.write(tf, cdr_tf_message(transforms), int(log_ns[k]))
    return {'/robot_description': 1, '/tf_static': 1, '/tf': int(keep.size)}

"""
Goals in the robot's own frames: a goal given in any link of the URDF, placed in the base.

A goal request names its frame (a PoseStamped's ``header.frame_id``). The base link (or an
empty frame id) is the frame of Eq. (2)-(3) and is taken as it is. Any other link F of the URDF
(the tip or a tool frame, for a move relative to where the robot is) is placed with the robot's
kinematics at the last measured joints q, once, when the goal arrives:

    R_d = R_F(q) R_d^F,    p_d = p_F(q) + R_F(q) p_d^F,    i.e.  Q_d = Q_F(q) * Q_d^F

(``*`` the quaternion product, (p_F, R_F) the link's pose in the base from the URDF), and the
goal is then held fixed in the base frame, as any other: the robot moving towards it does not
move it. A link goal before any joint state, or a frame the URDF does not have, is refused
with the reason and, for the latter, the frames accepted. The position task reads only the
position: the quaternion is not read, so any orientation (all zeros too) is accepted; a goal
in a link is the point ``p_F(q) + R_F(q) p_d^F``. ROS-free.
"""
from typing import Optional, Sequence

from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_controller.regulator import Goal


class GoalFrames:
    """The frames a goal may be given in: ``base_link`` (or '') and every link of the URDF."""

    def __init__(self, model: RobotModel, task: cl.Task) -> None:
        self._model = model
        self._task = cl.Task(task)
        self.base_link = model.base_link
        self.links = model.link_names()
        self._links = frozenset(self.links)

    def goal(self, frame_id: str, xyzw: Sequence[float], position: Sequence[float],
             q_measured: Optional[Sequence[float]]) -> Goal:
        """
        Validate a goal request and return it in the base frame; raise ValueError saying why not.

        The quaternion is checked as tf2 does and the position must be finite, in the frame
        they are given in (``Goal.from_xyzw``); the orientation task ignores the position, the
        position task the quaternion (``Goal.at_position``: any, unread). As in tf2 for ROS 2,
        a leading slash is not accepted.
        """
        with_position = self._task.has_position
        zero = (0.0, 0.0, 0.0)
        position_only = self._task is cl.Task.POSITION
        if frame_id in ('', self.base_link):
            if position_only:
                return Goal.at_position(position)
            return Goal.from_xyzw(*xyzw, position if with_position else zero)
        if frame_id not in self._links:
            raise ValueError(self._unknown(frame_id))
        given = Goal.at_position(position) if position_only else Goal.from_xyzw(*xyzw, position)
        if q_measured is None:
            raise ValueError(
                f"header.frame_id '{frame_id}' is a link of the robot, placed with the measured "
                f"joints, and no joint state has come yet: send the goal in '{self.base_link}' "
                'or after the first joint state')
        p_link, R_link = self._model.link_pose(frame_id, q_measured)
        q_base = quat.normalized(quat.multiply(quat.from_rotation_matrix(R_link),
                                               given.q_desired_base))
        if not with_position:
            return Goal(q_base, zero)
        p = given.p_desired_base
        p_base = tuple(p_link[i] + R_link[i][0] * p[0] + R_link[i][1] * p[1]
                       + R_link[i][2] * p[2] for i in range(3))
        return Goal.at_position(p_base) if position_only else Goal(q_base, p_base)

    def _unknown(self, frame_id: str) -> str:
        if frame_id.lstrip('/') in self._links or frame_id.lstrip('/') == self.base_link:
            return (f"header.frame_id is '{frame_id}', expected '{frame_id.lstrip('/')}' (tf2 "
                    'frame ids have no leading slash)')
        others = [link for link in self.links if link != self.base_link]
        return (f"header.frame_id is '{frame_id}', expected '{self.base_link}' (or empty) or a "
                f'link of the robot: {others} (placed with the measured joints; other tf '
                'frames: transform the goal with tf2 before sending it)')

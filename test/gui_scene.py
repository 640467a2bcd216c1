"""
Open the simulator's PyBullet window with the wrist and a goal frame (for test_simulator_gui).

Run as a script under an X display. Prints one line 'SCENE <json>': the window size and the pixel
coordinates of points of the robot and of the goal axes, projected through the GUI's own
camera. Then keeps the window open until its stdin closes.
"""
import json
import sys

import numpy as np
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from wrist_sim.simulator import RobotSimulator

AXIS_LENGTH_M = 0.1


def main() -> int:
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    with RobotSimulator(default_urdf_xml(), use_gui=True) as sim:
        q_goal = paper.Q_JOINT_DESIRED_RAD
        sim.reset(q_goal)
        p_goal, _ = model.forward_kinematics(q_goal)
        R_goal = np.array(quat.to_rotation_matrix(paper.Q_DESIRED))
        assert sim.show_frame('goal', p_goal, quat.to_xyzw(paper.Q_DESIRED), AXIS_LENGTH_M)
        width, height, view, proj = sim.gui_camera()
        clip_from_world = np.array(proj).reshape(4, 4).T @ np.array(view).reshape(4, 4).T

        def project(points):
            pts = np.asarray(points, float).reshape(-1, 3)
            clip = clip_from_world @ np.hstack((pts, np.ones((len(pts), 1)))).T
            ndc = clip[:2] / clip[3]
            return np.stack(((ndc[0] + 1.0) * 0.5 * width,
                             (1.0 - ndc[1]) * 0.5 * height), axis=1).tolist()

        print('SCENE ' + json.dumps({
            'width': width, 'height': height,
            # The base cylinder (0.06 m radius, 0.24 m tall), at mid height and low.
            'robot_uv': project([[0.0, 0.0, 0.12], [0.0, 0.0, 0.06]]),
            'goal_origin_uv': project([p_goal])[0],
            'goal_ends_uv': project(np.asarray(p_goal) + AXIS_LENGTH_M * R_goal.T),
        }), flush=True)
        sys.stdin.read()  # until the test closes our stdin
    return 0


if __name__ == '__main__':
    sys.exit(main())

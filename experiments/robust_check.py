"""
Reach on a plant the controller is not told about: rotor inertia and untold Coulomb friction.

ROS-free: the design of ``design_gains`` (``gain_design.design``) from the URDF plus the
rotor inertia a user would give (``--armature``: right, or 50% off), the node's regulator tick
(``reference_sim.run_sampled``: sampled, one tick of delay, clamped) on the MuJoCo engine of
the simulator with that rotor inertia and Coulomb friction of a share of each effort limit,
which the controller is not told (friction estimate 0). Random goals: the arm's pose at a
random configuration, from the middle of the ranges; q* given as the goal check would.

    .venv/bin/python -m experiments.robust_check --arms wrist ur5 panda --goals 20

Per arm and condition: the share of goals reached (within 1 mm and ||e|| < 0.01 from some
time on, within the duration), the time to reach them, the largest |qdot_j| / velocity limit
of the joint, and the goals still moving at the end (max |qdot| > 0.02 rad/s in the last 0.5 s:
a limit cycle if also off the goal).
"""
import argparse
from pathlib import Path
import sys
import time

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller.gain_design import design
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_runtime.resources import default_urdf_xml
from wrist_sim.simulator import RobotSimulator

ERD = 'cmeel.prefix/share/example-robot-data/robots'


def _erd(relative: str) -> str:
    from importlib import metadata
    return str(Path(metadata.distribution('example-robot-data').locate_file(ERD)) / relative)


ARMS = {  # name: (URDF path or None for the wrist, base, tip, joints, task)
    'wrist': (None, 'base_link', 'tool0', None, 'orientation'),
    'ur5': ('ur_description/urdf/ur5_robot.urdf', 'base_link', 'tool0', None, 'pose'),
    'ur3': ('ur_description/urdf/ur3_robot.urdf', 'base_link', 'tool0', None, 'pose'),
    'panda': ('panda_description/urdf/panda.urdf', 'panda_link0', 'panda_link8',
              [f'panda_joint{i}' for i in range(1, 8)], 'pose'),
    'xarm7': ('xarm_description/urdf/xarm7.urdf', 'link_base', 'link7', None, 'pose'),
}
CONDITIONS = {  # name: (armature told x the true one, true armature, friction share)
    'armature told': (1.0, 0.1, 0.01),
    'armature +50%': (1.5, 0.1, 0.01),
    'armature -50%': (0.5, 0.1, 0.01),
    'ideal': (1.0, 0.0, 0.0),  # the plant is the URDF: no rotor inertia, no friction
}


def run_arm(arm: str, condition: str, goals: int, duration_s: float, seed: int,
            effort_share: float = 0.0) -> dict:
    """Return the figures of ``goals`` random goals of ``arm`` under ``condition``."""
    path, base, tip, joints, task = ARMS[arm]
    urdf = default_urdf_xml() if path is None else Path(_erd(path)).read_text()
    told, true_armature, share = CONDITIONS[condition]
    plain = RobotModel(urdf, base, tip, joints)
    n = plain.n
    model = (RobotModel(urdf, base, tip, joints, [told * true_armature] * n) if true_armature
             else plain)
    t0 = time.time()
    d = design(model, cl.Task(task), friction_effort_share=effort_share)
    design_s = time.time() - t0
    gains, shaping = d.gains('tanh'), d.shaping
    lower = np.maximum(np.array(plain.position_lower), -np.pi)
    upper = np.minimum(np.array(plain.position_upper), np.pi)
    start = 0.5 * (lower + upper)
    velocity = np.array(plain.velocity_limits, float)
    coulomb = share * np.array(plain.effort_limits, float)
    rng = np.random.default_rng(seed)
    reached, times, peak, moving, final = 0, [], 0.0, 0, []
    for _ in range(goals):
        q_goal = rng.uniform(lower + 0.1 * (upper - lower), upper - 0.1 * (upper - lower))
        p, R = plain.forward_kinematics(q_goal.tolist())
        loop = ClosedLoop(plain, gains, cl.Task(task), quat.from_rotation_matrix(R), tuple(p),
                          shaping=shaping)
        with RobotSimulator(urdf, plain.joint_names, initial_positions_rad=start.tolist(),
                            coulomb_nm=coulomb.tolist(), engine='mujoco',
                            armature=[true_armature] * n,
                            enforce_velocity_limits=False) as sim:
            run = run_sampled(loop, sim, duration_s, 1, q_goal.tolist(), 0.05)
        settled = run.settled_at_s()
        if settled <= duration_s:
            reached += 1
            times.append(settled)
        qdot = np.diff(run.q_rad, axis=0) / (run.t_s[1] - run.t_s[0])
        peak = max(peak, float(np.max(np.abs(qdot) / velocity)))
        last = int(0.5 / (run.t_s[1] - run.t_s[0]))
        if np.abs(qdot[-last:]).max() > 0.02:
            moving += 1
        final.append(run.final())
    return {'arm': arm, 'condition': condition, 'goals': goals, 'reached': reached,
            'time_median_s': float(np.median(times)) if times else float('nan'),
            'time_max_s': float(np.max(times)) if times else float('nan'),
            'peak_speed_over_limit': peak, 'moving_at_end': moving,
            'worst_final_mm': 1e3 * max(f[0] for f in final),
            'worst_final_e': max(f[1] for f in final), 'design_s': design_s,
            'kp': d.kp, 'expected_time_s': d.figures['time_to_goal_s']}


def main(argv=None) -> int:
    """Run the arms x conditions and print one line each."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--arms', nargs='+', default=['wrist', 'ur5', 'panda'],
                        choices=sorted(ARMS))
    parser.add_argument('--conditions', nargs='+', default=list(CONDITIONS)[:3],
                        choices=list(CONDITIONS))
    parser.add_argument('--goals', type=int, default=20)
    parser.add_argument('--duration', type=float, default=5.0)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--friction-effort-share', type=float, default=0.0,
                        help="design_gains' --friction-effort-share (0.03 measured; default 0)")
    args = parser.parse_args(argv)
    for arm in args.arms:
        for condition in args.conditions:
            r = run_arm(arm, condition, args.goals, args.duration, args.seed,
                        args.friction_effort_share)
            print(f"{r['arm']:6s} {r['condition']:14s} reached {r['reached']}/{r['goals']} "
                  f"(median {r['time_median_s']:.2f} s, max {r['time_max_s']:.2f} s; "
                  f"expected {r['expected_time_s']:.2g} s), peak |qdot|/limit "
                  f"{r['peak_speed_over_limit']:.2f}, moving at the end {r['moving_at_end']}, "
                  f"worst last 0.5 s {r['worst_final_mm']:.2f} mm / ||e|| "
                  f"{r['worst_final_e']:.3g}; kp {list(r['kp'])}", flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())

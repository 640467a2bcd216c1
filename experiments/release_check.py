"""
The peak speed of each joint when a learned friction push is released with nothing to take it.

The worst case the friction learning must survive (docs/lyapunov.md, section 4): an arm held
still away from its goal (an obstacle, a hand, a brake) learns the most it may, then is let
go on a plant without friction. An arm from its URDF, with ``design_gains``' gains (as the
reach experiment's arms, ``experiments.arms``). For each case of the reach experiment's goals:
the goal configuration ``q*`` is the sampled goal's, every joint is held 0.05 rad short of
it for 3 s of ticks (zero velocity: each learns up to its limit), then released: the
model's own dynamics (Pinocchio), no friction, the tick acting on a state ``--delay`` ticks
old at 1 kHz, for 0.5 s. Prints the peak ``|qdot_j| / v_lim,j`` per joint, and the worst.

    python -m experiments.release_check --example-robot xarm7 [--delay 1] [--cases 5]
"""
import argparse
import sys
from typing import Optional

from experiments import arms
from experiments import reach_experiment as rx
import numpy as np
from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller.regulator import Goal, Regulator

DT_S = 1e-3
HOLD_S = 3.0
RELEASE_S = 0.5
SHORT_RAD = 0.05


def release(robot: rx.Robot, case: int, delay_ticks: int, seed: int = 10) -> tuple:
    """Return ``(learned / limit, peak |qdot| / v_lim)`` per joint for one case."""
    model, design = rx.arm_design(robot, 0.0, 1.0 / DT_S)
    gains, shaping = design.gains('tanh'), design.shaping
    q0, q_goal = rx.cases(model, robot, case + 1, seed)[case]
    p, R = model.forward_kinematics(q_goal.tolist())
    goal = Goal(quat.from_rotation_matrix(R), tuple(p))
    reg = Regulator(model, robot.task, gains, goal=goal, shaping=shaping)
    if not reg.set_goal_configuration(goal, tuple(q_goal)):
        raise RuntimeError('the goal was replaced')
    away = np.sign(np.array(q_goal) - np.array(q0))
    q = np.array(q_goal) - SHORT_RAD * np.where(away == 0.0, 1.0, away)
    for _ in range(int(HOLD_S / DT_S)):
        reg.update(q.tolist(), [0.0] * model.n, DT_S)
    limit = np.array(shaping.friction_learning_limit_nm)
    learned = np.array(reg.learned_friction_nm) / np.where(limit > 0.0, limit, 1.0)
    v = np.zeros(model.n)
    states = [(q.copy(), v.copy())] * (delay_ticks + 1)
    v_lim = np.array(model.velocity_limits)
    peak = np.zeros(model.n)
    for _ in range(int(RELEASE_S / DT_S)):
        q_seen, v_seen = states[0]
        tau = reg.update(q_seen.tolist(), v_seen.tolist(), DT_S).tau_nm
        v = v + DT_S * np.asarray(model.forward_dynamics(q.tolist(), v.tolist(), tau))
        q = q + DT_S * v
        states = states[1:] + [(q.copy(), v.copy())]
        peak = np.maximum(peak, np.abs(v) / v_lim)
    return learned, peak


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--example-robot', default='xarm7', help='an example-robot-data arm')
    parser.add_argument('--tip-link', help='the regulated link (default: experiments.arms)')
    parser.add_argument('--delay', type=int, default=1, help='ticks of delay (default 1)')
    parser.add_argument('--cases', type=int, default=5)
    args = parser.parse_args(argv)
    robot = rx.arm_robot(args.example_robot, str(arms.example_robot_urdf(args.example_robot)),
                         None, args.tip_link, cl.Task.POSE)
    worst = np.zeros(len(robot.joints))
    with np.printoptions(precision=2, floatmode='fixed'):
        print(f'{args.example_robot}, joints {list(robot.joints)}, {args.delay} tick(s) of '
              'delay')
        for case in range(args.cases):
            learned, peak = release(robot, case, args.delay)
            worst = np.maximum(worst, peak)
            print(f'case {case}: learned / limit {learned}, peak |qdot| / v_lim {peak}')
        print(f'worst peak |qdot| / v_lim {worst}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

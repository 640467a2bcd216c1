"""
The extensions end to end on the simulator core: a handful of the reach experiment's cases.

experiments/reach_experiment.py runs hundreds (README); here a few of each robot and potential,
with the package's configs, PyBullet, friction and a tick of delay: every one reached, no stop
touched. And the stall classification names the cause of a case made to fail.
"""
import dataclasses

from experiments import reach_experiment as rx
import numpy as np
import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.inverse_kinematics import goal_configuration
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from wrist_sim.simulator import RobotSimulator

pytestmark = pytest.mark.e2e


@pytest.mark.parametrize('robot, potential, count', [
    ('wrist', 'tanh', 4), ('wrist', 'quadratic', 3), ('xarm6', 'tanh', 2)])
def test_random_cases_are_reached_without_touching_a_stop(robot, potential, count):
    outcomes = rx.run_robot(rx.ROBOTS[robot], potential, count, seed=10, progress=None)
    for o in outcomes:
        assert o.reached and not o.touched, (o.index, o.orientation_error, o.cause)
    text = rx.report(rx.ROBOTS[robot], potential, outcomes, 1.0)
    assert f'{count}/{count} reached (100.0%)' in text


def test_without_the_goal_configuration_a_long_way_round_stalls_at_the_band():
    """Joint 1 must go the long way round its stop: without q* it stalls in the band."""
    robot = rx.ROBOTS['wrist']
    model, gains, shaping = rx.load_controller(robot, 'tanh')
    sim = rx.config_parameters(robot.sim_config)
    q0, qg = [2.6, 0.5, 0.0], [-2.6, 0.5, 0.0]  # the short way crosses joint 1's stop
    off = dataclasses.replace(shaping, configuration_gain=())
    stuck = rx.run_case(robot, model, gains, off, sim, 0, np.array(q0), np.array(qg))
    assert not stuck.reached and not stuck.touched
    assert 'limit' in stuck.cause
    done = rx.run_case(robot, model, gains, shaping, sim, 0, np.array(q0), np.array(qg))
    assert done.reached and not done.touched


def test_xarm6_reaches_the_documented_goal_after_an_unreachable_one():
    """
    The issue's xArm6 case: after an unreachable goal, the reachable goal of the launch file.

    Without the extensions the arm stayed 26.6 mm / ||e|| 0.466 off, joint 3 in its limit. Here the
    unreachable goal (no q*: the goal-configuration term stays off) is held for 3 s, then the
    reachable one, whose q* arrives 0.1 s later, as from the worker.
    """
    robot = rx.ROBOTS['xarm6']
    model, gains, shaping = rx.load_controller(robot, 'tanh')
    sim_params = rx.config_parameters(robot.sim_config)
    start = sim_params['initial_positions']
    _, R0 = model.forward_kinematics(start)
    far = ClosedLoop(model, gains, robot.task, quat.from_rotation_matrix(R0), (1.2, 0.0, 0.5),
                     shaping=shaping)
    q_goal = [0.2, -0.4, -1.1, 0.2, 1.4, 0.3]  # launch/xarm6_demo.launch.py's goal
    p_d, R_d = model.forward_kinematics(q_goal)
    q_d = quat.from_rotation_matrix(R_d)
    near = ClosedLoop(model, gains, robot.task, q_d, p_d, shaping=shaping)
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    with rx.quiet():
        sim = RobotSimulator(rx.robot_urdf(robot), model.joint_names,
                             initial_positions_rad=start,
                             viscous_nm_s_per_rad=sim_params['viscous_friction'],
                             coulomb_nm=sim_params['coulomb_friction'])
    try:
        stretched = run_sampled(far, sim, 3.0)
        assert stretched.all_finite and stretched.position_error_m[-1] > 0.3
        q_star = goal_configuration(model, sim.q_rad.tolist(), q_d, p_d, robot.task,
                                    shaping.joint_limit_margin_rad)
        run = run_sampled(near, sim, 5.0, 1, q_star, 0.1)
    finally:
        sim.close()
    for r in (stretched, run):  # no stop touched, in either phase
        assert np.minimum(r.q_rad - lower, upper - r.q_rad).min() > rx.TOUCH_RAD
    position_m, orientation = run.final(0.1)
    assert position_m < 1e-3 and orientation < 0.01, (position_m, orientation)

"""
Issue 10 end to end on the simulator core: a handful of the reach experiment's cases.

tools/reach_experiment.py runs hundreds (README); here a few of each robot and potential, with
the package's configs, PyBullet, friction and a tick of delay: every one reached, no stop
touched. And the stall classification names the cause of a case made to fail.
"""
import dataclasses

import numpy as np
import pytest
from quat_jt_controller.tools import reach_experiment as rx

pytestmark = pytest.mark.unit


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

"""
The gains designed again for the rotor inertia the motion shows (redesign.py), ROS-free.

When a design is due, with what, how often at most; the design's options read back from the
file; the worker process; the controller that starts it and says so; and the law with gains
designed for half the rotor inertia the plant has: V does not increase in the ideal loop.
"""
from dataclasses import replace
import time

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import diagnostics
from quat_jt_controller import gain_design as gd
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller import Controller, GoalRequest, Severity
from quat_jt_controller.controller_config import controller_from_config
from quat_jt_controller.gain_cli import parse_design_options
from quat_jt_controller.model import RobotModel
from quat_jt_controller.redesign import (DESIGN_SHARE, DesignWorker, GROWTH_FACTOR,
                                         InertiaWatch, KEPT, LOOK_S, redesign,
                                         SETTLED_S)
from quat_jt_controller.reference_sim import ClosedLoop
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_runtime.resources import default_urdf_xml
from robots import wrist_model

pytestmark = pytest.mark.unit

WAIT_S = 120.0  # the most a worker may take to start Python and Pinocchio and design


def test_settled_joints_are_seen_at_each_look_against_the_look_settled_s_before():
    watch = InertiaWatch((0.0, 0.0), start_s=0.0)
    assert watch.settled(0.5 * LOOK_S, (0.1, 0.0)) is None  # not yet time to look
    assert watch.settled(LOOK_S, (0.1, 0.0)) == []  # nothing to compare with yet
    assert watch.settled(1.5 * LOOK_S, (0.1, 0.0)) is None
    assert watch.settled(2.0 * LOOK_S, (0.5, 0.0)) == []  # no look SETTLED_S old yet
    # the look SETTLED_S before saw 0.1: within 5%
    assert watch.settled(LOOK_S + SETTLED_S, (0.102, 0.0)) == [0]
    # against the look at 2 LOOK_S (0.5), not the one at LOOK_S (0.1): moved
    assert watch.settled(2.0 * LOOK_S + SETTLED_S, (0.1, 0.0)) == []
    t_s = 2.0 * LOOK_S + SETTLED_S
    for _ in range(round(SETTLED_S / LOOK_S)):  # the same estimate for SETTLED_S
        t_s += LOOK_S
        seen = watch.settled(t_s, (0.1, 0.0))
    assert seen == [0]
    assert watch.settled(t_s + LOOK_S + 0.02, (0.2, 0.0)) == []  # a timer late; moved by 50%
    # the look a little less than SETTLED_S before (a timer that was late) is the one
    assert watch.settled(t_s + LOOK_S + 0.02 + SETTLED_S - 0.05, (0.2, 0.0)) == [0]


def test_a_design_is_due_for_a_joint_twice_as_heavy_and_every_joint_takes_half():
    told = (0.01, 0.0, 0.0)
    watch = InertiaWatch(told)
    found = (0.1, 0.009, 0.0)
    model_inertia = np.array([0.05, 0.01, 0.02])  # the links and the armature told
    assert watch.due((0.0, 0.009, 0.0), tuple(model_inertia + (0.0, 0.009, 0.0))) is None
    # ... joint 1 shows 0.019 < 2 x 0.01; joint 0 shows 0.15 > 2 x 0.05, settled or not: due
    armature = watch.due(found, tuple(model_inertia + found))
    # ... and every joint takes half of its estimate
    assert armature == pytest.approx((0.01 + DESIGN_SHARE * 0.1, DESIGN_SHARE * 0.009, 0.0))
    watch.designed_with(armature)
    # designed for the model + half of what was found: the same estimate asks for nothing more
    assert watch.due(found, tuple(model_inertia + found)) is None
    # joint 2's estimate still rising (0.03 of a real 0.5): due again once it asks 1.5 x
    # what it was designed for; the others' estimates fell: they keep the armature designed with
    for rising, design in ((0.01, False), (0.03, True), (0.5, True)):
        grown = (0.05, 0.0, rising)
        armature = watch.due(grown, tuple(model_inertia + grown))
        assert (armature is not None) == design, rising
        if design:
            assert armature == pytest.approx((0.01 + DESIGN_SHARE * 0.1,
                                              DESIGN_SHARE * 0.009, DESIGN_SHARE * rising))
            watch.designed_with(armature)


def test_designs_stop_as_the_estimate_stops_growing_whatever_it_grows_to():
    """Each design multiplies a joint's designed inertia by more than GROWTH_FACTOR: a few."""
    watch = InertiaWatch((0.0,))
    model_inertia, most = 1e-4, 5.0
    designs = 0
    for found in np.geomspace(1e-6, most, 2000):  # the estimate growing to its limit
        armature = watch.due((found,), (model_inertia + found,))
        if armature is not None:
            watch.designed_with(armature)
            designs += 1
            assert armature[0] == DESIGN_SHARE * found
    bound = np.log((model_inertia + DESIGN_SHARE * most) / model_inertia) / np.log(GROWTH_FACTOR)
    assert 1 <= designs <= bound + 1


def test_the_design_options_read_back_as_the_design_took_them():
    model = wrist_model()
    d = gd.design(model, cl.Task.ORIENTATION, delays=(1, 2), cruise_fraction=0.7,
                  friction_effort_share=0.02, approach_time_s=1.5,
                  effort_limits_nm=[40.0, 25.0, 15.0])
    assert d.structure()['design_options'] == list(d.options)
    options = parse_design_options(d.options, model.n)
    assert options == {'effort_limits_nm': [40.0, 25.0, 15.0], 'delays': (1, 2),
                       'friction_learning': gd.FRICTION_LEARNING,
                       'friction_effort_share': 0.02, 'cruise_fraction': 0.7,
                       'approach_time_s': 1.5}
    assert gd.design(model, cl.Task.ORIENTATION).options == ()  # the defaults: nothing


@pytest.mark.parametrize('tokens, words', [
    (['--delays', 'one'], "'one' is not an integer"),
    (['--armature', '0.1'], 'unrecognized arguments: --armature 0.1'),
    (['--effort-limits', '1', '2'], '--effort-limits: 2 values for 3 joints'),
    (['--cruise-fraction', '2'], '2 is not a finite number in (0, 1]')])
def test_bad_design_options_are_refused_by_name(tokens, words):
    with pytest.raises(ValueError, match='design_options') as raised:
        parse_design_options(tokens, 3)
    assert words in str(raised.value)


def wrist_values(armature: tuple = (0.0, 0.0, 0.0), **options) -> tuple:
    """Return ``(design, parameters)`` of the wrist's design, as a node holds them."""
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0', ['joint1', 'joint2', 'joint3'],
                       list(armature))
    d = gd.design(model, cl.Task.ORIENTATION, delays=(1, 2), **options)
    return d, {**d.structure(), **d.parameters('tanh')}


def test_a_design_again_is_design_gains_with_the_armature_and_the_same_options():
    _, values = wrist_values(friction_nm=[1.8, 0.72, 0.45])
    armature = (0.05, 0.0, 0.2)
    new = redesign(default_urdf_xml(), values, armature)
    told, _ = wrist_values(armature, friction_nm=[1.8, 0.72, 0.45])
    expected = told.parameters('tanh')
    assert new and not set(new) & KEPT
    for name, value in new.items():
        assert value == expected[name], name
    assert new['kv'][2] > values['kv'][2]  # the heavier joint is damped harder
    unchanged = {name for name, value in expected.items()
                 if name not in KEPT and value == values[name]}
    assert not unchanged & set(new)  # only what changes


def test_the_worker_designs_in_a_process_of_its_own_and_says_why_it_cannot():
    _, values = wrist_values()
    worker = DesignWorker(default_urdf_xml())
    try:
        # it imports what a design needs as it starts, not at the first design
        wait_for(lambda: worker.ready or None)
        worker.submit(values, (0.0, 0.0, 0.1))
        assert worker.busy
        answer = wait_for(worker.poll)
        assert answer == {'parameters': redesign(default_urdf_xml(), values, (0.0, 0.0, 0.1))}
        assert not worker.busy
        worker.submit({**values, 'design_options': ['--delays', 'x']}, (0.0, 0.0, 0.1))
        answer = wait_for(worker.poll)
        assert 'design_options' in answer['error'], answer
    finally:
        worker.close()


def test_a_design_at_a_time_and_none_once_the_worker_is_closed():
    _, values = wrist_values()
    worker = DesignWorker(default_urdf_xml())
    worker.submit(values, (0.0, 0.0, 0.1))
    with pytest.raises(RuntimeError, match='a design is running'):
        worker.submit(values, (0.0, 0.0, 0.1))  # one at a time
    worker.close()  # the design running is stopped, and says so
    assert 'the design worker was closed' in wait_for(worker.poll)['error']
    worker.submit(values, (0.0, 0.0, 0.1))  # refused at once, with the reason
    assert 'the design worker was closed' in wait_for(worker.poll)['error']
    assert not worker.busy


def test_a_design_worker_that_dies_says_so_once_and_is_started_again(monkeypatch):
    """
    Killed: said once, a design in the back-off refused with the reason, then a new worker.

    The new worker is the launcher's (the node's process starts none), and designs; killed
    during a design, that design's answer is the reason.
    """
    import os
    import signal
    import subprocess
    from quat_jt_runtime.worker import RESTART_BACKOFF_S
    now = [0.0]
    _, values = wrist_values()
    worker = DesignWorker(default_urdf_xml(), clock=lambda: now[0])
    try:
        wait_for(lambda: worker.ready or None)
        first_pid = worker.pid
        os.kill(first_pid, signal.SIGKILL)
        failure = wait_for(lambda: worker.poll() or worker.take_failure())  # no design: no answer
        assert failure == ('the design worker exited (exit code -9): the gains cannot be '
                           'designed again until it is back; restarting it in 1 s'), failure
        assert worker.take_failure() is None  # said once
        assert not worker.ready and worker.restarts == 0
        worker.submit(values, (0.0, 0.0, 0.1))
        refused = wait_for(worker.poll)['error']
        assert 'the design worker exited (exit code -9); restarting in 1.0 s' == refused
        now[0] += RESTART_BACKOFF_S[0]
        with monkeypatch.context() as patched:  # the node itself starts no process
            patched.setattr(subprocess, 'Popen', forbidden_popen)
            worker.poll()
        assert worker.restarts == 1
        wait_for(lambda: worker.ready or None)
        assert worker.pid not in (None, first_pid)
        with pytest.raises(ChildProcessError):  # the launcher's child, not this process's
            os.waitpid(worker.pid, os.WNOHANG)
        worker.submit(values, (0.0, 0.0, 0.1))
        assert 'parameters' in wait_for(worker.poll)
        # killed during a design: its answer is why
        worker.submit(values, (0.0, 0.0, 0.2))
        os.kill(worker.pid, signal.SIGKILL)
        reply = wait_for(worker.poll)
        assert reply == {'error': 'the design worker exited (exit code -9)'}, reply
        failure = worker.take_failure()
        assert failure.startswith('the design worker exited (exit code -9): the gains cannot '
                                  'be designed again until it is back; restarting it in ')
    finally:
        worker.close()


def forbidden_popen(*args, **kwargs):
    raise AssertionError('a process started from the node while its loop runs')


class DeadDesigner:
    """A design worker that has just died: its failure is told once."""

    busy = False
    ready = False
    unavailable_reason = 'the design worker exited (exit code -9); restarting in 0.6 s'

    def __init__(self) -> None:
        self.failure = 'the design worker exited (exit code -9): ...; restarting it in 1 s'

    def poll(self):
        return None

    def take_failure(self):
        failure, self.failure = self.failure, None
        return failure


def test_the_controller_says_once_that_the_design_worker_died():
    d, values = wrist_values()
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0', list(d.joints))
    reg = Regulator(model, cl.Task.ORIENTATION, d.gains('tanh'), shaping=d.shaping)
    ctl = Controller(reg, 0.5, 1, started_ns=0, designer=DeadDesigner(),
                     parameter_values=lambda: values)
    designed, logs = ctl.take_design()
    assert designed is None
    assert [tuple(line) for line in logs] == [(Severity.ERROR, (
        'the design worker exited (exit code -9): ...; restarting it in 1 s; regulation goes '
        'on'))]
    assert ctl.take_design() == (None, ())
    # ... and /diagnostics says so while it is down (a WARN of the goal status)
    figures = {'control_rate_hz': 0.0, 'ticks_in_window': 0, 'saturated_ticks': 0}
    _, goal, _ = ctl.statuses(figures)
    assert goal[1] == diagnostics.WARN and ('design_worker', 'unavailable') in goal[3]
    assert ('designs again unavailable (gain_redesign): the design worker exited (exit code '
            '-9); restarting in 0.6 s') in goal[2]
    ctl.regulator.set_shaping(replace(ctl.regulator.shaping, gain_redesign=False))
    _, goal, _ = ctl.statuses(figures)  # designs off: nothing said of the worker
    assert not any(key == 'design_worker' for key, _ in goal[3])


def wait_for(poll, timeout_s: float = WAIT_S):
    """Return ``poll()``'s first answer (not None) within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        answer = poll()
        if answer is not None:
            return answer
        time.sleep(0.01)
    raise AssertionError(f'no answer within {timeout_s} s')


def test_the_controller_designs_again_for_an_untold_rotor_inertia_and_says_so():
    """
    The design's wrist on a MuJoCo wrist with 0.2 kg m^2 per joint nobody told.

    As the estimate grows, a design is started with half of it, and its parameters, set as the
    node sets them, damp the joints for their real inertia; the goal is still reached.
    """
    pytest.importorskip('mujoco')
    from wrist_sim.simulator import RobotSimulator
    d, values = wrist_values()
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0', list(d.joints))
    reg = Regulator(model, cl.Task.ORIENTATION, d.gains('tanh'), shaping=d.shaping)
    worker = DesignWorker(default_urdf_xml())
    ctl = Controller(reg, 0.5, 1, started_ns=0, designer=worker,
                     parameter_values=lambda: values)
    assert ctl.on_goal(GoalRequest('base_link', Goal(paper.Q_DESIRED).xyzw(), (0.0, 0.0, 0.0),
                                   0.0), 0).accepted
    logs, designed = [], None
    try:
        with RobotSimulator(default_urdf_xml(), model.joint_names, engine='mujoco',
                            armature=(0.2,) * 3, initial_positions_rad=paper.Q_INITIAL_RAD
                            ) as sim:
            k = 0
            deadline = time.monotonic() + WAIT_S
            while time.monotonic() < deadline and (designed is None or k < 12000):
                k += 1
                cmd = ctl.on_state(model.joint_names, sim.q_rad.tolist(),
                                   sim.qdot_rad_s.tolist(), 0, 0, k * 1_000_000)
                sim.step(cmd.tau_nm)
                if k % 50 == 0:  # the node's timer: designs again while the estimate grows
                    logs += ctl.take_model_notes()
                    parameters, said = ctl.take_design()
                    logs += said
                    if parameters is not None:  # as the node: every value checked, then set
                        values.update(parameters)
                        made = controller_from_config(values, default_urdf_xml())
                        reg.set_gains(made.gains)
                        reg.set_shaping(made.shaping)
                        logs += ctl.design_set(parameters)
                        designed = parameters
            error = ctl.last.orientation_error_norm
    finally:
        worker.close()
    assert designed is not None, logs
    text = [line for level, line in logs]
    assert any(level == Severity.INFO and line.startswith('designing the gains again')
               for level, line in logs), text
    assert any(level == Severity.WARN and 'are being designed again' in line
               for level, line in logs), text
    assert any(line.startswith('gains designed again for armature') and 'kv' in line
               for line in text), text
    assert all(a > b for a, b in zip(designed['kv'], d.kv))  # damped for the heavier joints
    assert error < 0.01  # and the goal reached with the new gains


@pytest.mark.parametrize('potential', ['tanh', 'quadratic'])
def test_gains_designed_for_half_the_plants_rotor_inertia_leave_v_non_increasing(potential):
    """
    The ideal loop with every extension of a design again, on a plant that is not the model.

    The plant has 0.2 kg m^2 per joint; the model none, and the estimate 0.2 in M(q); the gains
    are designed for 0.1 (half of it, as a design again takes).
    """
    model = wrist_model()
    plant = RobotModel(default_urdf_xml(), 'base_link', 'tool0', list(model.joint_names),
                       [0.2] * 3)
    _, values = wrist_values()
    values.update(redesign(default_urdf_xml(), values, (0.1, 0.1, 0.1)))
    made = controller_from_config(values, default_urdf_xml(), potential)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    loop = ClosedLoop(model, made.gains, cl.Task.ORIENTATION, quat.from_rotation_matrix(R),
                      shaping=made.shaping, q_star=q_goal, plant=plant)
    model.set_armature_estimate((0.2, 0.2, 0.2))
    traj = loop.run((0.2, 0.8, 0.3), 1.0, dt_s=1e-3)
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert traj.lyapunov[-1] < 0.5 * traj.lyapunov[0]

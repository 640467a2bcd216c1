"""
The rotor inertia the motion shows beyond the armature told (quat_jt_controller.armature_estimate).

One joint driven by a known torque: the fit finds its rotor inertia and its friction, nothing
on a joint the model has right, nothing at rest, and the estimate keeps within its limit and
its steps. Then the regulator on the wrist simulated by MuJoCo with a rotor inertia it is not
told: it finds it and puts it in M(q); what it puts there is damping only, so V does not
increase; a new regulator and a shaping without it start from the model told; the controller
says once what it found and /diagnostics shows it.
"""
import math

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import gain_design as gd
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.armature_estimate import ArmatureEstimator, SOLVE_S, TRUST_SHARE
from quat_jt_controller.controller import Controller, GoalRequest, Severity
from quat_jt_controller.diagnostics import configuration_state
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_runtime.resources import default_urdf_xml
from robots import wrist_model
from wrist_sim.simulator import RobotSimulator

pytestmark = pytest.mark.unit

DT_S = 1e-3
INERTIA = 0.01  # kg m^2, the joint as its model has it


def drive_one_joint(rotor: float, coulomb_nm: float, duration_s: float, limit: float = 1.0,
                    torque=None, told_noise=None):
    """
    Drive one joint of ``INERTIA + rotor`` against ``coulomb_nm`` with a known torque.

    The estimator is fed as the regulator feeds it: the last tick's torque, the velocity's
    filtered derivative and ``M qddot`` with the estimate in force. Returns the estimator and
    the estimates after each solve. ``told_noise(t)``, if given, is added to the torque the
    estimator reads and not to the plant's.
    """
    est = ArmatureEstimator(1)
    torque = torque or (lambda t: 0.6 * math.sin(4.1 * t) + 0.3 * math.sin(11.3 * t))
    v = slow = 0.0
    seeded = False
    last = None
    history = []
    for k in range(int(duration_s / DT_S)):
        t = k * DT_S
        # the filtered derivative of qdot (Regulator._track_acceleration)
        if not seeded:
            slow, qddot, seeded = v, 0.0, True
        else:
            qddot = (v - slow) / sh.ACCELERATION_TIME_S
            slow += DT_S / sh.ACCELERATION_TIME_S * (v - slow)
        if last is not None and est.track([last], [v], 0.05, DT_S):
            est.sample([qddot], [(INERTIA + est.estimate[0]) * qddot], est.estimate, [slow],
                       0.05)
            if est.solve_due:
                est.solve([INERTIA + est.estimate[0]], [limit])
                history.append(est.estimate[0])
        u = torque(t)
        last = u + (told_noise(t) if told_noise else 0.0)
        # the plant: a Coulomb friction (smooth at 1 mrad/s), semi-implicit Euler
        v += DT_S * (u - coulomb_nm * math.tanh(v / 1e-3)) / (INERTIA + rotor)
    return est, history


def test_a_fit_finds_the_rotor_inertia_and_the_estimate_follows():
    est, history = drive_one_joint(0.1, 0.05, 3.0)
    a, error = est.fit(0)
    assert a == pytest.approx(0.1, rel=0.05) and error < 0.01
    assert est.estimate[0] == pytest.approx(0.1, rel=0.05)
    # it got there within the first second, in steps that at most double the inertia
    assert history[int(1.0 / SOLVE_S)] == pytest.approx(0.1, rel=0.1)
    before = 0.0
    for after in history:
        assert after <= before + (INERTIA + before) + 1e-12
        before = after


def test_a_joint_the_model_has_right_shows_no_rotor_inertia():
    est, history = drive_one_joint(0.0, 0.05, 3.0)
    assert max(history) <= 0.05 * INERTIA


def test_at_rest_nothing_is_fitted():
    est, history = drive_one_joint(0.1, 0.0, 1.0, torque=lambda t: 0.0)
    assert est.fit(0)[1] == math.inf and history and max(history) == 0.0


def test_the_estimate_keeps_within_its_limit_and_a_zero_limit_is_none():
    est, _ = drive_one_joint(0.1, 0.05, 2.0, limit=0.03)
    assert est.estimate[0] == 0.03
    est, _ = drive_one_joint(0.1, 0.05, 2.0, limit=0.0)
    assert est.estimate[0] == 0.0
    est.reset()
    assert est.fit(0)[1] == math.inf and est.estimate == [0.0]


def test_a_fit_is_adopted_only_where_it_is_known():
    """
    Torque the motion does not explain (noise in what the estimator reads, not in the plant).

    Its fit is no better known than a fifth, counting the low-passed samples a filter's memory
    spans as one: it is not adopted. The same motion read without the noise is.
    """
    rng = np.random.default_rng(3)
    slow = (lambda t: 0.02 * math.sin(1.3 * t))  # little excitation
    est, history = drive_one_joint(0.1, 0.0, 2.0, torque=slow,
                                   told_noise=lambda t: 0.05 * rng.standard_normal())
    a, error = est.fit(0)
    assert error > TRUST_SHARE * (INERTIA + max(a, 0.0))
    assert max(history) == 0.0
    est, history = drive_one_joint(0.1, 0.0, 2.0, torque=slow)
    assert est.estimate[0] == pytest.approx(0.1, rel=0.05)


def test_the_model_carries_the_estimate_beside_the_armature_told():
    model = wrist_model()
    q = [0.3, 1.0, -0.5]
    M = model.mass_matrix(q)
    qddot = [1.0, -2.0, 0.5]
    model.set_armature_estimate([0.1, 0.0, 0.2])
    np.testing.assert_allclose(model.mass_matrix(q) - M, np.diag([0.1, 0.0, 0.2]), atol=1e-12)
    np.testing.assert_allclose(model.inertial_torque(q, qddot),
                               (M + np.diag([0.1, 0.0, 0.2])) @ qddot, atol=1e-12)
    assert model.armature == (0.0, 0.0, 0.0)
    assert model.armature_estimate == (0.1, 0.0, 0.2)


def wrist_run(plant_armature, duration_s: float = 2.0):
    """Run the design's wrist (no armature told) to the paper's goal on MuJoCo with this one."""
    model = wrist_model()
    d = gd.design(model, cl.Task.ORIENTATION)
    assert d.shaping.armature_estimation_on and not any(model.armature)
    loop = ClosedLoop(model, d.gains('tanh'), cl.Task.ORIENTATION, paper.Q_DESIRED,
                      shaping=d.shaping)
    with RobotSimulator(default_urdf_xml(), model.joint_names, engine='mujoco',
                        armature=plant_armature, coulomb_nm=[0.0] * 3,
                        viscous_nm_s_per_rad=[0.0] * 3) as sim:
        run = run_sampled(loop, sim, duration_s, 1, list(paper.Q_JOINT_DESIRED_RAD), 0.05)
    return model, loop, run


def test_the_regulator_finds_a_rotor_inertia_it_is_not_told_and_puts_it_in_m():
    pytest.importorskip('mujoco')
    model, loop, run = wrist_run((0.05, 0.05, 0.05))
    found = loop.clamped.armature_estimate
    np.testing.assert_allclose(found, 0.05, rtol=0.2)
    assert model.armature_estimate == found
    assert run.final()[1] < 0.01
    # on a plant the model has right, a small share of each joint's inertia at most
    model, loop, run = wrist_run((0.0, 0.0, 0.0))
    own = model.own_inertias(list(paper.Q_JOINT_DESIRED_RAD))
    assert np.all(np.array(loop.clamped.armature_estimate) < 0.25 * np.array(own))


def test_a_new_regulator_and_a_shaping_without_it_start_from_the_model_told():
    pytest.importorskip('mujoco')
    model, loop, _ = wrist_run((0.05, 0.05, 0.05), 1.0)
    assert all(e > 0.0 for e in model.armature_estimate)
    reg = loop.clamped
    limits = reg.shaping.armature_estimation_limit_kg_m2
    reg.set_shaping(sh.Shaping.create(3, armature_estimation_limit=[0.01, 0.0, 0.0]))
    assert reg.armature_estimate == (0.01, 0.0, 0.0) == model.armature_estimate
    reg.set_shaping(sh.Shaping.create(3))
    assert reg.armature_estimate == (0.0, 0.0, 0.0) == model.armature_estimate
    model.set_armature_estimate([0.02, 0.02, 0.02])
    ClosedLoop(model, loop.gains, cl.Task.ORIENTATION, paper.Q_DESIRED,
               shaping=sh.Shaping.create(3, armature_estimation_limit=limits))
    assert model.armature_estimate == (0.0, 0.0, 0.0)


@pytest.mark.parametrize('potential', ['quadratic', 'tanh'])
@pytest.mark.parametrize('estimate', [(0.3, 0.1, 0.05), (2.0, 2.0, 2.0)])
def test_lyapunov_never_increases_with_a_rotor_inertia_estimate_in_m(potential, estimate):
    """
    docs/lyapunov.md, section 13: the estimate only changes damping, right or wrong.

    The ideal loop's plant is the URDF's (no rotor inertia); the law's M(q) has an estimate
    in it, a modest one and one 20 to 100 times the joints' inertia: V, with the plant's
    M(q), never increases.
    """
    model, plant = wrist_model(), wrist_model()
    d = gd.design(model, cl.Task.ORIENTATION)
    q_goal = (0.5, 1.2, -0.4)
    _, R = model.forward_kinematics(list(q_goal))
    loop = ClosedLoop(model, d.gains(potential), cl.Task.ORIENTATION,
                      quat.from_rotation_matrix(R), shaping=d.shaping, q_star=q_goal,
                      plant=plant)
    model.set_armature_estimate(estimate)
    assert plant.armature_estimate == (0.0, 0.0, 0.0)
    traj = loop.run((0.2, 0.8, 0.3), 1.0, dt_s=1e-3)
    dV = np.diff(traj.lyapunov)
    assert dV.max() <= 1e-9 * traj.lyapunov[0], f'V increased by {dV.max()}'
    assert traj.lyapunov[-1] < 0.5 * traj.lyapunov[0]
    assert model.armature_estimate == estimate  # the ideal loop does not estimate


def designed_wrist_controller() -> tuple:
    """Return ``(model, regulator, controller)`` of the design's wrist, the paper's goal set."""
    model = wrist_model()
    d = gd.design(model, cl.Task.ORIENTATION)
    reg = Regulator(model, cl.Task.ORIENTATION, d.gains('tanh'), shaping=d.shaping)
    ctl = Controller(reg, 0.5, 1, started_ns=0)
    assert ctl.on_goal(GoalRequest('base_link', Goal(paper.Q_DESIRED).xyzw(), (0.0, 0.0, 0.0),
                                   0.0), 0).accepted
    return model, reg, ctl


def drive_refused_wrist(refused: bool) -> tuple:
    """
    Feed the design's wrist controller the states of a MuJoCo wrist that another PD moves.

    No rotor inertia anywhere; our commands refused (``refuse_commands``) if ``refused``, else
    computed as usual but not applied either. Returns the estimate after 3 s.
    """
    model, reg, ctl = designed_wrist_controller()
    if refused:
        ctl.refuse_commands('another receiver')
    joints = model.joint_names
    with RobotSimulator(default_urdf_xml(), joints, engine='mujoco',
                        initial_positions_rad=paper.Q_INITIAL_RAD) as sim:
        for k in range(3000):
            q, qdot = sim.q_rad, sim.qdot_rad_s
            cmd = ctl.on_state(joints, q.tolist(), qdot.tolist(), 0, 0, (k + 1) * 1_000_000)
            assert (cmd.tau_nm is None) == refused
            target = np.array(paper.Q_JOINT_DESIRED_RAD) * math.sin(2.0 * k * DT_S)
            sim.step((20.0 * (target - q) - 2.0 * qdot
                      + np.array(model.gravity(q.tolist()))).tolist())
    return reg.armature_estimate, model.own_inertias(list(paper.Q_JOINT_DESIRED_RAD))


def test_a_torque_that_does_not_reach_the_plant_is_not_fitted():
    """
    Commands refused: the estimator reads no torque of ours as the plant's, and finds nothing.

    The same states read with our torque taken for the plant's would give a rotor inertia
    that is not there.
    """
    pytest.importorskip('mujoco')
    found, own = drive_refused_wrist(refused=True)
    assert found == (0.0, 0.0, 0.0)
    wrong, own = drive_refused_wrist(refused=False)
    assert max(w / m for w, m in zip(wrong, own)) > 0.1


def test_a_regulator_that_does_not_estimate_leaves_the_model_alone():
    """A closed loop's two regulators share one model: the one not estimating keeps out."""
    pytest.importorskip('mujoco')
    model, loop, _ = wrist_run((0.05, 0.05, 0.05), 1.0)
    found = loop.clamped.armature_estimate
    assert all(e > 0.0 for e in found) and model.armature_estimate == found
    loop.regulator.set_shaping(sh.Shaping.create(3))  # it estimates nothing
    assert model.armature_estimate == found


def test_the_controller_says_once_what_it_found_and_diagnostics_show_it():
    pytest.importorskip('mujoco')
    model, reg, ctl = designed_wrist_controller()
    joints = model.joint_names
    said = []
    with RobotSimulator(default_urdf_xml(), joints, engine='mujoco', armature=(0.2,) * 3,
                        initial_positions_rad=paper.Q_INITIAL_RAD) as sim:
        for k in range(4000):
            cmd = ctl.on_state(joints, sim.q_rad.tolist(), sim.qdot_rad_s.tolist(), 0, 0,
                               (k + 1) * 1_000_000)
            sim.step(cmd.tau_nm)
            if k % 50 == 0:
                said += [text for level, text in ctl.take_model_notes()
                         if level == Severity.WARN]
    assert said and all(text.startswith('rotor inertia the model lacks, found from the motion: ')
                        and 'design again with --armature 0.' in text for text in said)
    for name in joints:  # each joint heavier than twice its model, said once
        assert sum(f'{name} 0.' in text for text in said) == 1, said
    values = dict(configuration_state(reg).values())
    found = [float(x) for x in values['armature_estimate'].strip('[]').split(',')]
    assert found == pytest.approx(reg.armature_estimate, rel=1e-2)
    np.testing.assert_allclose(found, 0.2, rtol=0.2)
    assert not ctl.take_model_notes()  # said once


def test_a_joint_that_friction_holds_is_not_fitted():
    """
    The SO-100 with rotor inertia and a Coulomb friction nobody told: stick and slip.

    While a friction holds a joint (at rest or creeping), the torque it takes can be anything
    up to its level, which no regressor carries: before only moving joints were fitted, such
    samples made the SO-100's first joints 35 times as heavy as they are (the limit). Now
    what is found is the plant's, or nothing where a joint never moved enough to tell.
    """
    pytest.importorskip('mujoco')
    from experiments import arms
    from experiments import reach_experiment as rx
    robot = rx.arm_robot('so100', str(arms.example_robot_urdf('so100')), None, 'gripper',
                         cl.Task.POSE)
    outcomes = rx.run_arm(robot, rx.condition('armature-untold-friction', armature=0.1), 'tanh',
                          2, seed=10, progress=None, workers=1)
    for outcome in outcomes:
        found = np.array(outcome.armature_estimate)
        assert np.all(found <= 0.12) and found.max() > 0.08, found

"""
Stall detection (quat_jt_controller.stall), ROS-free: fed from the tick, at 10 Hz.

At rest off the goal for more than 0.5 s it warns and names the cause: a joint at a limit,
the potential's torque below the friction estimate (a joint held), a slow approach (a joint still
moving along its weak push), a near-singular configuration, a near-180-degree error. Moving, or
at the goal, it stays OK. The SVD runs at most at 10 Hz.
"""
import math

import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller import stall
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_runtime.payload import Payload
from robots import wrist_model

pytestmark = pytest.mark.unit

REST = [0.0, 0.0, 0.0]
WEAK_KP = tuple(0.02 * k for k in paper.KP)  # a weak potential: the wrist crawls near the goal


def regulator(friction=(0.0, 0.0, 0.0), potential='tanh', kp=paper.KP,
              learning=(0.0, 0.0, 0.0)) -> Regulator:
    gains = cl.Gains.create(potential, kp, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    return Regulator(wrist_model(), cl.Task.ORIENTATION, gains, goal=Goal(paper.Q_DESIRED),
                     shaping=sh.Shaping.create(3, friction_compensation=friction,
                                               friction_learning_limit=learning))


def feed_for(detector, reg, q, qdot, seconds, t0=0.0, dt=1e-3):
    t = t0
    while t < t0 + seconds:
        detector.feed(t, q, qdot, reg.update(q, qdot))
        t += dt
    return t


def test_a_stall_against_a_joint_limit_is_warned_with_its_cause():
    reg = regulator()
    det = stall.StallDetector(reg)
    q = [math.pi - 0.01, 0.8, 0.3]  # joint 1 at its upper stop
    feed_for(det, reg, q, REST, 0.45)
    assert not det.stalled and det.status()[0] == stall.OK  # not yet 0.5 s
    feed_for(det, reg, q, REST, 0.2, t0=0.45)
    level, message, values = det.status()
    assert det.stalled and level == stall.WARN
    assert 'joint1' in message and 'upper limit' in message
    assert dict(values)['stalled'] == 'True'


def test_moving_or_at_the_goal_is_not_a_stall():
    reg = regulator()
    det = stall.StallDetector(reg)
    feed_for(det, reg, [0.2, 0.8, 0.3], [0.5, 0.0, 0.0], 1.0)  # moving
    assert not det.stalled and det.status()[0] == stall.OK
    feed_for(det, reg, list(paper.Q_JOINT_DESIRED_RAD), REST, 1.0, t0=1.0)  # at the goal
    assert not det.stalled and det.status()[1] == 'not stalled'


def test_torque_below_the_friction_estimate_is_named():
    """The quadratic law with the paper's gains stalls ~0.2 away, as in the paper."""
    reg = regulator(friction=(2.0, 0.8, 0.5), potential='quadratic')
    det = stall.StallDetector(reg)
    q = [0.75, 0.75, 0.75]
    assert reg.update(q, REST).orientation_error_norm > 0.05
    feed_for(det, reg, q, REST, 0.7)
    assert det.stalled
    assert 'below the friction estimate' in det.status()[1]


def test_near_singular_and_near_180_degrees_are_named():
    reg = regulator()
    det = stall.StallDetector(reg)
    feed_for(det, reg, [0.0, 0.0, 0.0], REST, 0.7)  # q2 = 0: J_o has rank 2
    assert det.stalled and 'near-singular' in det.status()[1]
    assert det.sigma_min < 1e-9
    here = quat.from_rotation_matrix(reg.model.forward_kinematics([0.0, 1.0, 0.0])[1])
    reg.set_goal(Goal(quat.multiply((0.0, 1.0, 0.0, 0.0), here)))  # a half turn about x away
    det = stall.StallDetector(reg)
    feed_for(det, reg, [0.0, 1.0, 0.0], REST, 0.7)
    assert det.stalled and '180 degrees' in det.status()[1]


def test_the_detector_is_cheap_svd_at_most_at_10_hz(monkeypatch):
    reg = regulator()
    det = stall.StallDetector(reg)
    calls = []
    real = np.linalg.svd

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)
    monkeypatch.setattr(stall.np.linalg, 'svd', counting)
    feed_for(det, reg, [math.pi - 0.01, 0.8, 0.3], REST, 2.0)  # 2000 ticks, stalled
    assert det.stalled
    assert 10 <= len(calls) <= 21  # once per evaluation while stalled, never per tick


def test_with_no_friction_estimate_a_weak_push_names_friction():
    """Off the goal by a little, at rest, no estimate: friction, not a local minimum."""
    reg = regulator(potential='quadratic')
    det = stall.StallDetector(reg)
    near = [v + 0.02 for v in paper.Q_JOINT_DESIRED_RAD]
    out = reg.update(near, REST)
    assert out.orientation_error_norm > stall.ORIENTATION_TOLERANCE
    feed_for(det, reg, near, REST, 0.7)
    message = det.status()[1]
    assert det.stalled and 'likely friction' in message
    assert 'local minimum' not in message


def test_a_joint_held_against_its_weak_push_names_friction_and_what_it_learned():
    """Held at rest, pushed, while it learns all it may: the friction exceeds a_max."""
    a_max = (0.002, 0.002, 0.002)
    reg = regulator(potential='quadratic', learning=a_max)
    det = stall.StallDetector(reg)
    near = [v + 0.02 for v in paper.Q_JOINT_DESIRED_RAD]
    tau_p = reg.update(near, REST).tau_potential_nm
    assert min(abs(t) for t in tau_p) > max(a_max)  # the push is above what it may learn
    t, dt = 0.0, 1e-3
    while t < 5.0 * reg.shaping.friction_learning_time_s:  # held: it learns all it may
        det.feed(t, near, REST, reg.update(near, REST, dt))
        t += dt
    assert reg.learned_friction_nm == pytest.approx(a_max, rel=1e-3)
    message = det.status()[1]
    assert det.stalled and 'likely friction' in message, message
    assert 'exceeds what it may learn' in message and 'slow approach' not in message


@pytest.mark.parametrize('direction', [0.0, -1.0])
def test_a_joint_at_rest_or_moving_against_its_push_is_held(direction):
    """Not moving along its push (at rest, or pushed back): held, so friction is named."""
    reg = regulator(potential='quadratic', kp=WEAK_KP)
    det = stall.StallDetector(reg)
    near = [v + 0.1 for v in paper.Q_JOINT_DESIRED_RAD]
    tau_p = reg.update(near, REST).tau_potential_nm
    qdot = [direction * t / kv for t, kv in zip(tau_p, reg.gains.kv)]  # K_v qdot = -tau_p
    assert max(abs(v) for v in qdot) < stall.REST_SPEED_RAD_S
    feed_for(det, reg, near, qdot, 0.7)
    message = det.status()[1]
    assert det.stalled and 'likely friction' in message and 'slow approach' not in message


def test_a_joint_the_learning_saw_accelerate_is_not_held_by_a_friction():
    """
    At rest by the detector's measure, but its push goes into its acceleration: no friction.

    The velocities ramp as M(q) qddot = tau_p, below the rest speed for the whole stall (a
    frictionless wrist starting to move under a very weak potential, its damping small). With
    the learning on, the regulator saw the push taken by the acceleration (its ``h`` stays
    below 1/2), so the detector does not name a friction; the same joints fed at rest are held.
    """
    model = wrist_model()
    gains = cl.Gains.create('tanh', tuple(5e-5 * k for k in paper.KP),
                            tuple(1e-3 * k for k in paper.KV), paper.LAMBDA,
                            cl.Task.ORIENTATION, 3)
    shaping = sh.Shaping.create(3, friction_learning_limit=(0.5, 0.5, 0.5))
    near = [v + 0.05 for v in paper.Q_JOINT_DESIRED_RAD]
    messages = {}
    for case in ('accelerating', 'at rest'):
        reg = Regulator(model, cl.Task.ORIENTATION, gains, goal=Goal(paper.Q_DESIRED),
                        shaping=shaping)
        det = stall.StallDetector(reg)
        tau_p = np.array(reg.update(near, REST).tau_potential_nm)
        qddot = np.linalg.solve(model.mass_matrix(near), tau_p)
        dt, steps = 1e-3, 800
        assert np.abs(qddot).max() * dt * steps < stall.REST_SPEED_RAD_S
        for k in range(steps):
            qdot = (qddot * k * dt).tolist() if case == 'accelerating' else REST
            det.feed(k * dt, near, qdot, reg.update(near, qdot, dt))
        assert det.stalled, case
        messages[case] = det.status()[1]
    assert 'likely friction' not in messages['accelerating'], messages['accelerating']
    assert 'no friction holds' in messages['accelerating']
    assert 'likely friction' in messages['at rest'], messages['at rest']


def test_on_a_frictionless_plant_a_slow_crawl_is_a_slow_approach_not_friction():
    """
    A weak potential on the ideal plant: the arm crawls below the rest speed, not held.

    Simulated (M(q) qddot = tau - C qdot - g, no friction) from 0.1 rad off the goal with
    2% of the paper's k_p: the damping takes the push, K_v qdot = tau_p, and the wrist moves
    towards the goal at about 0.01 rad/s, so the detector sees a stall. Its potential torque
    is below a plausible friction, but every joint still moves along it.
    """
    reg = regulator(potential='quadratic', kp=WEAK_KP)
    det = stall.StallDetector(reg)
    model = reg.model
    q = [v + 0.1 for v in paper.Q_JOINT_DESIRED_RAD]
    qdot = list(REST)
    dt = 1e-3
    for k in range(1500):
        out = reg.update(q, qdot, dt)
        det.feed(k * dt, q, qdot, out)
        qddot = model.forward_dynamics(q, qdot, out.tau_nm)
        qdot = [v + dt * a for v, a in zip(qdot, qddot)]
        q = [x + dt * v for x, v in zip(q, qdot)]
    assert det.stalled and out.orientation_error_norm > stall.ORIENTATION_TOLERANCE
    assert all(t * v > 0.0 for t, v in zip(out.tau_potential_nm, qdot))  # along the push
    message = det.status()[1]
    assert 'slow approach' in message and 'still moving towards the goal' in message, message
    assert 'likely friction' not in message and 'local minimum' not in message


def test_near_singular_is_judged_per_unit_of_the_arms_length():
    """A 10x large arm near full stretch: sigma_min(J_p) is 10x larger, still near-singular."""
    from quat_jt_controller.model import SINGULAR_SIGMA_MIN
    from test_goal_check import scaled_small_arm
    model = scaled_small_arm(10.0)
    q = [0.3, -0.4, 0.1, 0.2, 0.1]  # nearly stretched: the elbow bent by 0.1 rad
    p_goal, _ = model.forward_kinematics([0.3, -0.4, 1.0, 0.2, 0.1])
    gains = cl.Gains.create('tanh', (1.0, 1.0, 1.0), (1.0,) * 5, (1.0, 1.0, 1.0),
                            cl.Task.POSITION, 5)
    reg = Regulator(model, cl.Task.POSITION, gains, goal=Goal.at_position(p_goal))
    det = stall.StallDetector(reg)
    feed_for(det, reg, q, [0.0] * 5, 0.7)
    _, _, J = model.kinematics(q)
    assert np.linalg.svd(np.array(J)[:3], compute_uv=False)[-1] > SINGULAR_SIGMA_MIN
    assert det.stalled and 'near-singular' in det.status()[1]
    assert det.sigma_min < SINGULAR_SIGMA_MIN


def test_the_settling_damping_counts_as_the_damping_of_a_slow_approach():
    """
    Near the goal a joint's damping includes its share of the settling damping, psi alpha M_jj.

    Each joint crawls along its weak push at 0.3 tau_p / k_v: k_v alone takes less than half
    the push, so without the settling damping the joints look held (a friction, with none
    estimated); with alpha = 40 their own share takes the rest, and it is a slow approach.
    """
    q = [v + 0.05 for v in paper.Q_JOINT_DESIRED_RAD]
    found = {}
    for alpha in (0.0, 40.0):
        gains = cl.Gains.create('quadratic', WEAK_KP, paper.KV, paper.LAMBDA,
                                cl.Task.ORIENTATION, 3)
        reg = Regulator(wrist_model(), cl.Task.ORIENTATION, gains, goal=Goal(paper.Q_DESIRED),
                        shaping=sh.Shaping.create(3, settling_damping_rate=alpha))
        tau_p = reg.update(q, REST).tau_potential_nm
        qdot = [0.3 * t / kv for t, kv in zip(tau_p, paper.KV)]
        out = reg.update(q, qdot)
        assert sh.settling_fade(out.y_tilde, gains.lam) > 0.5
        found[alpha] = ' '.join(stall.StallDetector(reg).diagnose(q, out, qdot))
    assert 'likely friction' in found[0.0] and 'slow approach' not in found[0.0]
    assert 'slow approach' in found[40.0] and 'likely friction' not in found[40.0]


def test_a_held_torque_that_an_untold_payload_explains_names_it_and_its_mass():
    """At rest, tau - g(q) = Y(q) [m; m c]: the weight of a payload the model lacks, by mass."""
    from robots import panda_model, random_q
    model = panda_model()
    gains = cl.Gains.create('tanh', (50.0,) * 3 + (5.0,) * 3, (5.0,) * 7, (40.0,) * 3
                            + (4.0,) * 3, cl.Task.POSE, 7)
    reg = Regulator(model, cl.Task.POSE, gains)
    rng = np.random.default_rng(4)
    q = random_q(model, rng).tolist()
    reg.set_goal(reg.pose([x + 0.05 for x in q]))  # held 0.05 rad a joint off its goal
    out = reg.update(q, [0.0] * 7)
    g = np.array(model.gravity(q))
    weight = model.payload_regressor(q) @ np.array([1.2, 0.0, 0.012, 0.06])  # 1.2 kg
    det = stall.StallDetector(reg)
    [cause] = [c for c in det.diagnose(q, out._replace(tau_nm=(g + weight).tolist()))
               if 'payload' in c]
    assert 'what 1.2 kg more at the tip (panda_link8) would need' in cause
    assert 'set payload_mass, 1.2 kg' in cause
    lighter = g - 0.5 * weight  # the URDF's tip heavier than the arm's
    assert any('0.6 kg less' in c and 'the model carries more than the arm' in c
               for c in det.diagnose(q, out._replace(tau_nm=lighter.tolist())))
    too_light = g - (model.link_mass_kg + 1.0) / 1.2 * weight  # lighter than its links: no
    assert not any('payload' in c or 'kg less' in c
                   for c in det.diagnose(q, out._replace(tau_nm=too_light.tolist())))
    # a friction holds each joint with a torque of its own: no payload fits that pattern
    held = g + 0.02 * np.array(model.effort_limits) * np.array([1, -1, 1, 1, -1, -1, 1])
    assert not any('payload' in c for c in det.diagnose(q, out._replace(tau_nm=held.tolist())))
    reg.set_payload(Payload.create(1.2, (0.0, 0.01, 0.05)))  # told: its g(q) has it
    assert 'set payload_mass, 2.4 kg' in det.diagnose(
        q, out._replace(tau_nm=(np.array(model.gravity(q)) + weight).tolist()))[0]

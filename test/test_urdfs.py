"""URDFs as they come: continuous joints, a link and a joint of one name, arms of 4 or 5 joints."""
import numpy as np
import pinocchio as pin
import pytest

from quat_jt_controller import control_law as cl
from quat_jt_controller import gain_analysis as ga
from quat_jt_controller import gain_design as gd
from quat_jt_controller import gain_output as go
from quat_jt_controller.inverse_kinematics import goal_configuration
from quat_jt_controller.model import ModelError, RobotModel
from robots import assert_jacobian_matches_finite_differences, example_robot_data_urdf
from robots import small_arm_urdf
from wrist_sim.simulator import RobotSimulator

pytestmark = pytest.mark.unit

SO100_ARM = ('shoulder_pan', 'shoulder_lift', 'elbow_flex', 'wrist_flex', 'wrist_roll')


def test_continuous_joints_have_one_angle_and_no_stops():
    model = RobotModel(small_arm_urdf(), 'base_link', 'tool')
    assert model.n == 5
    assert model.continuous == (True, False, False, True, False)
    assert model.position_lower[0] == -np.inf and model.position_upper[3] == np.inf
    assert model.position_lower[1] == -2.0 and model.position_upper[2] == 2.0
    assert model.effort_limits == pytest.approx((20.0, 10.0, 20.0 / 3, 5.0, 4.0))
    q = np.array([0.4, -0.3, 0.9, 1.2, -0.5])
    turned = q + np.array([2 * np.pi, 0.0, 0.0, -4 * np.pi, 0.0])  # whole turns: same pose
    for a, b in zip(model.kinematics(q), model.kinematics(turned)):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_continuous_joint_model_against_finite_differences():
    """J_G = d(pose)/dq and g = dV/dq by central differences in the one angle per joint."""
    model = RobotModel(small_arm_urdf(), 'base_link', 'tool')
    rng = np.random.default_rng(7)
    h = 1e-6

    def energy(q):
        return pin.computePotentialEnergy(model.model, model.data, model.configuration(q))

    for _ in range(10):
        q = rng.uniform(-1.8, 1.8, model.n) + np.array([3.0, 0.0, 0.0, -5.0, 0.0])
        assert_jacobian_matches_finite_differences(model, q, h)
        fd = [(energy(q + h * e) - energy(q - h * e)) / (2 * h) for e in np.eye(model.n)]
        np.testing.assert_allclose(model.gravity(q), fd, atol=1e-6)


def test_continuous_joints_have_the_dynamics_of_revolute_ones():
    """The same arm with every joint revolute (wide stops): same M(q), g(q) and qddot."""
    cont = RobotModel(small_arm_urdf(), 'base_link', 'tool', ['tool', 'joint4', 'joint1',
                                                              'joint2', 'joint3'])
    rev = RobotModel(small_arm_urdf(('revolute',) * 5).replace('lower="-2" upper="2"',
                                                               'lower="-9" upper="9"'),
                     'base_link', 'tool', ['tool', 'joint4', 'joint1', 'joint2', 'joint3'])
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qdot, tau = rng.uniform(-2, 2, (3, 5))
        np.testing.assert_allclose(cont.mass_matrix(q), rev.mass_matrix(q), atol=1e-12)
        np.testing.assert_allclose(cont.gravity(q), rev.gravity(q), atol=1e-12)
        np.testing.assert_allclose(cont.forward_dynamics(q, qdot, tau),
                                   rev.forward_dynamics(q, qdot, tau), atol=1e-9)


def test_armature_sits_at_each_continuous_joints_velocity_index():
    """Continuous joints take two coordinates but one velocity: the rotor inertia follows v."""
    joints = ['tool', 'joint4', 'joint1', 'joint3']  # joint2 locked; not Pinocchio's order
    armature = (0.05, 0.4, 0.2, 0.1)
    plain = RobotModel(small_arm_urdf(), 'base_link', 'tool', joints)
    rotor = RobotModel(small_arm_urdf(), 'base_link', 'tool', joints, armature)
    assert rotor.model.nq > rotor.model.nv == 4
    rng = np.random.default_rng(5)
    for _ in range(5):
        q, qdot, tau = rng.uniform(-2, 2, (3, 4))
        M = plain.mass_matrix(q) + np.diag(armature)
        np.testing.assert_allclose(rotor.mass_matrix(q), M, atol=1e-12)
        h = plain.mass_matrix(q) @ plain.forward_dynamics(q, qdot, np.zeros(4)) * -1.0
        np.testing.assert_allclose(rotor.forward_dynamics(q, qdot, tau),
                                   np.linalg.solve(M, tau - h), atol=1e-9)


def test_links_are_looked_up_as_links_when_a_joint_has_the_name():
    model = RobotModel(small_arm_urdf(), 'base_link', 'tool')  # 'tool': a link and a joint
    p, _ = model.forward_kinematics([0.0] * model.n)
    np.testing.assert_allclose(p, [0.8, 0.0, 0.1], atol=1e-12)  # the link 'tool', not joint
    with pytest.raises(ModelError, match="'joint3' is not in the URDF .it names a joint"):
        RobotModel(small_arm_urdf(), 'base_link', 'joint3')


def test_a_name_clash_on_a_locked_joint_is_no_problem():
    """SO-100: its gripper is a link and a joint; the arm's five joints, the jaw locked."""
    path = example_robot_data_urdf('so_arm_description/urdf/so100.urdf')
    model = RobotModel(path.read_text(), 'base', 'gripper', SO100_ARM)
    assert model.n == 5
    full = RobotModel(path.read_text(), 'base', 'gripper')
    assert full.n == 6  # the jaw's joint 'gripper' too
    q = [0.1, 1.0, -1.0, 0.3, 0.2]
    np.testing.assert_allclose(model.forward_kinematics(q)[0],
                               full.forward_kinematics(q + [0.0])[0], atol=1e-12)


def test_the_simulator_takes_continuous_joints():
    urdf = small_arm_urdf()
    model = RobotModel(urdf, 'base_link', 'tool')
    with RobotSimulator(urdf, dt_s=1e-3, enforce_velocity_limits=False) as sim:
        assert sim.position_lower[0] == -np.inf and sim.position_upper[3] == np.inf
        np.testing.assert_allclose(sim.position_lower[1:3], [-2.0, -2.0])
        q, qdot = np.array([7.0, 0.3, -0.6, -4.0, 0.2]), np.array([0.5, -0.2, 0.1, 1.0, 0.0])
        tau = np.array([1.0, -2.0, 0.5, 0.3, 0.1])
        sim.reset(q, qdot)
        sim.step(tau)
        qddot = (sim.state().qdot_rad_s - qdot) / 1e-3
        np.testing.assert_allclose(qddot, model.forward_dynamics(q, qdot, tau), rtol=1e-4,
                                   atol=1e-3)


def test_goal_configuration_of_a_continuous_joint_is_the_turn_nearest_the_arm():
    model = RobotModel(small_arm_urdf(), 'base_link', 'tool')
    q_goal = np.array([0.5, 0.4, -0.7, 0.3, 0.6])
    p, R, _ = model.kinematics(q_goal)
    from quat_jt_controller import quaternion as quat
    q_d = quat.from_rotation_matrix(R)
    q_now = q_goal + np.array([2 * np.pi + 0.05, 0.05, -0.05, -2 * np.pi, 0.05])
    q_star = goal_configuration(model, q_now, q_d, p, cl.Task.POSE)
    assert q_star is not None
    np.testing.assert_allclose(model.forward_kinematics(q_star)[0], p, atol=1e-9)
    assert np.all(np.abs(q_star - q_now) < 1.0), q_star  # no whole turn back


@pytest.mark.parametrize('task', [cl.Task.POSE, cl.Task.ORIENTATION])
def test_design_on_a_five_joint_arm_finishes(task):
    """SO-100's best sigma_min(J_G) is below 0.1: the survey takes its best configurations."""
    path = example_robot_data_urdf('so_arm_description/urdf/so100.urdf')
    model = RobotModel(path.read_text(), 'base', 'gripper', SO100_ARM)
    data = gd.survey(model, task)
    assert len(data['configurations']) == gd.SAMPLES
    sigmas = [ga.sigma_min(rows) for _, rows, _ in data['configurations']]
    assert min(sigmas) >= data['regular_sigma_min'] > 0.0
    if task is cl.Task.POSE:
        assert data['regular_sigma_min'] < gd.REGULAR_SIGMA_MIN
    d = _pose_design(model) if task is cl.Task.POSE else gd.design(model, task)
    assert all(k > 0 for k in d.kp + d.kv)
    assert max(d.figures['spectral_radius'].values()) < 1.0
    text = ' '.join(go.to_yaml(d).replace('#', ' ').split())
    assert (f'none of {gd.REGULAR_TRIES} random ones reached' in text) == (task is cl.Task.POSE)


def test_design_on_arms_with_continuous_joints():
    model = RobotModel(small_arm_urdf(('continuous', 'revolute', 'revolute', 'continuous')),
                       'base_link', 'tool')
    d = gd.design(model, cl.Task.POSE)
    assert d.shaping.joint_limit_gain[0] == 0.0 and d.shaping.joint_limit_gain[3] == 0.0
    assert d.shaping.joint_limit_gain[1] > 0.0
    assert max(d.figures['spectral_radius'].values()) < 1.0


def test_a_task_the_joints_cannot_do_fails_at_once():
    """Two parallel axes cannot turn the tip about x: the orientation task is out of reach."""
    model = RobotModel(small_arm_urdf(('revolute', 'revolute')).replace(
        '<axis xyz="0 0 1"/>', '<axis xyz="0 1 0"/>'), 'base_link', 'tool')
    with pytest.raises(ValueError, match='orientation task Jacobian is singular at each of'):
        gd.survey(model, cl.Task.ORIENTATION)


_DESIGNS = {}


def _pose_design(model):
    """Return design_gains' pose design of a model (learning a friction nobody measured)."""
    key = (model.tip_link, model.joint_names, model.continuous)
    if key not in _DESIGNS:
        _DESIGNS[key] = gd.design(model, cl.Task.POSE,
                                  friction_effort_share=gd.FRICTION_EFFORT_SHARE)
    return _DESIGNS[key]


def _arm(name):
    if name == 'so100':
        path = example_robot_data_urdf('so_arm_description/urdf/so100.urdf')
        return path.read_text(), RobotModel(path.read_text(), 'base', 'gripper', SO100_ARM)
    kinds = {'four': ('continuous', 'revolute', 'revolute', 'continuous'),
             'five': ('continuous', 'revolute', 'revolute', 'continuous', 'revolute')}[name]
    urdf = small_arm_urdf(kinds)
    return urdf, RobotModel(urdf, 'base_link', 'tool')


@pytest.mark.parametrize('name', ['four', 'five', 'so100'])
def test_an_arm_of_four_or_five_joints_reaches_a_pose_it_can_reach(name):
    """
    design_gains from the URDF alone, then the sampled loop in PyBullet (1 tick of delay).

    The design learns a friction nobody measured (a share of the effort limits), and the plant
    has none: on the SO-100, whose potential is weak near the goal, the learning must not take
    the slow end of the approach for stiction and push the arm off its goal.
    """
    from quat_jt_controller import quaternion as quat
    from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
    urdf, model = _arm(name)
    d = _pose_design(model)
    assert d.shaping.learning_on
    mid = np.array(model.middle_of_ranges())
    q0, q_goal = mid - 0.2, mid + 0.3
    p_d, R, _ = model.kinematics(q_goal)
    q_d = quat.from_rotation_matrix(R)
    q_star = goal_configuration(model, q0, q_d, p_d, cl.Task.POSE,
                                d.shaping.joint_limit_margin_rad)
    assert q_star is not None
    with RobotSimulator(urdf, model.joint_names, initial_positions_rad=q0) as sim:
        loop = ClosedLoop(model, d.gains('tanh'), cl.Task.POSE, q_d, p_d, shaping=d.shaping)
        # 5 s: the reach target's budget (the SO-100, held within its URDF's 1 rad/s with
        # links of 1e-4 kg m^2, settles in about 3.5 s)
        run = run_sampled(loop, sim, 5.0, 1, q_star, 0.1)
    assert run.all_finite
    position_m, orientation = run.final(window_s=0.5)
    assert position_m < 1e-3 and orientation < 0.01, (position_m, orientation)
    learned = np.array(loop.clamped.learned_friction_nm)
    assert np.all(learned <= 0.1 * np.array(d.shaping.friction_learning_limit_nm)), learned

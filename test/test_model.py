"""Core tests of model.py: the URDF model against the paper's closed forms and differences."""
import numpy as np
import pinocchio as pin
import pytest

from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from robots import (assert_jacobian_matches_finite_differences, Q_DESIRED, Q_JOINT_DESIRED,
                    random_q, wrist_model, xarm6_model, XARM6_URDF)

pytestmark = pytest.mark.unit


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def jacobian_eq39(q):
    """Return the paper's orientation Jacobian of the wrist, Eq. (39): the test oracle."""
    q1, q2 = q[0], q[1]
    return np.array([[0.0, -np.sin(q1), np.cos(q1) * np.sin(q2)],
                     [0.0, np.cos(q1), np.sin(q1) * np.sin(q2)],
                     [1.0, 0.0, np.cos(q2)]])


def test_wrist_angular_jacobian_equals_eq39_at_random_q():
    model = wrist_model()
    rng = np.random.default_rng(39)
    for _ in range(200):
        q = rng.uniform(-np.pi, np.pi, 3)
        _, R, J = model.kinematics(q)
        np.testing.assert_allclose(np.array(J)[3:], jacobian_eq39(q), atol=1e-12)
        # docs/errata.md note 4: R(q) = Rz(q1) Ry(q2) Rz(q3).
        np.testing.assert_allclose(R, rz(q[0]) @ ry(q[1]) @ rz(q[2]), atol=1e-12)


def test_wrist_reaches_the_errata_goal_at_q_desired():
    _, R = wrist_model().forward_kinematics(Q_JOINT_DESIRED)
    q = quat.from_rotation_matrix(R)
    eta_e, e = quat.orientation_error(q, quat.normalized(Q_DESIRED))
    assert np.linalg.norm(e) < 1e-4
    assert abs(eta_e) == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize('make_model', [wrist_model, xarm6_model])
def test_geometric_jacobian_matches_finite_differences(make_model):
    """J_p = dp/dq and S(J_o dq) R = dR, with base-frame axes (Eq. 12)."""
    model = make_model()
    rng = np.random.default_rng(12)
    h = 1e-6
    for _ in range(20):
        assert_jacobian_matches_finite_differences(model, random_q(model, rng), h)


@pytest.mark.parametrize('make_model', [wrist_model, xarm6_model])
def test_gravity_is_gradient_of_potential_energy(make_model):
    model = make_model()
    rng = np.random.default_rng(1)
    h = 1e-6

    def energy(q):
        return pin.computePotentialEnergy(model.model, model.data, np.asarray(q, dtype=float))

    for _ in range(10):
        q = random_q(model, rng)
        fd = [(energy(q + h * e) - energy(q - h * e)) / (2 * h) for e in np.eye(model.n)]
        np.testing.assert_allclose(model.gravity(q), fd, atol=1e-6)


def test_wrist_gravity_is_not_trivial():
    """The URDF puts centres of mass off the joint-2 axis, so g(q) is exercised."""
    g = wrist_model().gravity([0.0, 0.8, 0.3])
    assert abs(g[0]) < 1e-12  # joint 1 is vertical
    assert abs(g[1]) > 0.1


def test_limits_come_from_the_urdf():
    model = wrist_model()
    assert model.joint_names == ('joint1', 'joint2', 'joint3')
    assert model.effort_limits == (50.0, 30.0, 20.0)
    assert model.position_lower[1] == pytest.approx(-2.6)


def test_joint_order_is_the_callers():
    xml = default_urdf_xml()
    ref = RobotModel(xml, 'base_link', 'tool0')
    perm = RobotModel(xml, 'base_link', 'tool0', joint_names=['joint3', 'joint1', 'joint2'])
    q = np.array([0.3, -0.4, 1.1])
    q_perm = q[[2, 0, 1]]
    p0, R0, J0 = ref.kinematics(q)
    p1, R1, J1 = perm.kinematics(q_perm)
    np.testing.assert_allclose(p0, p1, atol=1e-14)
    np.testing.assert_allclose(R0, R1, atol=1e-14)
    np.testing.assert_allclose(np.array(J0)[:, [2, 0, 1]], J1, atol=1e-14)
    np.testing.assert_allclose(np.array(ref.gravity(q))[[2, 0, 1]], perm.gravity(q_perm))
    assert perm.effort_limits == (20.0, 50.0, 30.0)


def test_uncontrolled_joints_are_locked():
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0', joint_names=['joint1', 'joint2'])
    _, R, J = model.kinematics([0.2, 0.5])
    np.testing.assert_allclose(R, rz(0.2) @ ry(0.5), atol=1e-12)
    assert np.array(J).shape == (6, 2)


def test_base_link_other_than_root():
    """Kinematics relative to a fixed non-root base link (xArm6: 'world' -> 'link_base')."""
    a = RobotModel(XARM6_URDF.read_text(), 'world', 'link6')
    b = RobotModel(XARM6_URDF.read_text(), 'link_base', 'link6')
    q = [0.1, -0.2, -0.5, 0.3, 0.4, -0.6]
    for x, y in zip(a.kinematics(q), b.kinematics(q)):
        np.testing.assert_allclose(x, y, atol=1e-12)  # world_joint is the identity here


@pytest.mark.parametrize('kwargs, match', [
    ({'base_link': 'nope', 'tip_link': 'tool0'}, "'nope' is not in the URDF"),
    ({'base_link': 'base_link', 'tip_link': 'tool0', 'joint_names': ['joint9']},
     r"\['joint9'\] are not movable"),
    ({'base_link': 'link2', 'tip_link': 'tool0'}, 'moves with joint'),
    ({'base_link': 'base_link', 'tip_link': 'tool0', 'joint_names': ['joint1', 'joint1']},
     'repeat'),
])
def test_model_errors_are_clear(kwargs, match):
    with pytest.raises(ModelError, match=match):
        RobotModel(default_urdf_xml(), **kwargs)


def test_bad_urdf_is_a_model_error():
    with pytest.raises(ModelError, match='cannot parse'):
        RobotModel('<robot name="x"><link name="a"/', 'a', 'a')


@pytest.mark.parametrize('old, new, match', [
    ('effort="30.0" velocity="6.2832"', 'effort="30.0"',
     r"joints \['joint2'\] have no velocity in their <limit> \(the URDF format asks"),
    ('<limit lower="-2.6" upper="2.6" effort="30.0" velocity="6.2832"/>', '',
     r"joints \['joint2'\] have no <limit>"),
    ('effort="30.0"', 'effort="thirty"', r'not numbers: joint2 effort="thirty"'),
    ('velocity="6.2832"/>', 'velocity="${max_speed}"/>', 'a xacro file, not expanded'),
    ('</robot>', '<xacro:include xmlns:xacro="http://wiki.ros.org/xacro" filename="a.xacro"/>'
     '</robot>', 'a xacro file, not expanded'),
])
def test_a_urdf_the_parser_refuses_is_refused_naming_the_joint_and_the_value(old, new, match):
    """The URDF parser says only that the file is no URDF; the model names what in it is not."""
    urdf = default_urdf_xml()
    assert old in urdf
    with pytest.raises(ModelError, match=match):
        RobotModel(urdf.replace(old, new, 1), 'base_link', 'tool0')


LINK2_MASS, BASE_MASS = '<mass value="2.0"/>', '<mass value="8.0"/>'
LINK2_IXY, BASE_IXY = 'ixx="0.025" ixy="0"', 'ixx="0.1" ixy="0"'
LINK2_IXX, BASE_IXX = 'ixx="0.025"', 'ixx="0.1"'


@pytest.mark.parametrize('link2, base, fault, match', [
    (LINK2_MASS, BASE_MASS, '<mass value="nan"/>', r"'link2': mass nan kg"),
    (LINK2_MASS, BASE_MASS, '<mass value="-2.0"/>', r"'link2': mass -2 kg"),
    (LINK2_MASS, BASE_MASS, '<mass value="two"/>',
     r"'link2': a value of its <inertial> is not a number \('two'\)"),
    (LINK2_IXY, BASE_IXY, 'ixx="0.025" ixy="0.2"',
     r"'link2': its inertia has a negative principal moment"),
    (LINK2_IXX, BASE_IXX, 'ixx="inf"', "'link2': an inertia moment is not finite"),
])
def test_inertias_no_body_has_are_refused_on_the_links_the_joints_move(
        link2, base, fault, match):
    """
    Pinocchio takes a negative mass as it comes, and one that is no number as none at all.

    The same fault on a link the controlled joints do not move (here the base) does not reach
    the arm's model: accepted, as a whole robot's URDF with a faulty link elsewhere is.
    """
    urdf = default_urdf_xml()
    assert link2 in urdf and base in urdf
    with pytest.raises(ModelError, match=match):
        RobotModel(urdf.replace(link2, fault, 1), 'base_link', 'tool0')
    RobotModel(urdf.replace(base, fault, 1), 'base_link', 'tool0')
    # a CAD export's rounding: a principal moment a hair below zero passes
    rounded = urdf.replace('ixx="1e-7" ixy="0"', 'ixx="1e-7" ixy="1.0000001e-7"', 1)
    assert np.linalg.eigvalsh([[1e-7, 1.0000001e-7, 0], [1.0000001e-7, 1e-7, 0],
                               [0, 0, 1e-7]])[0] < 0.0
    RobotModel(rounded, 'base_link', 'tool0')


def test_inverse_inertia_is_the_inverse_of_m_in_the_callers_order():
    """M(q)^-1 as rows, symmetric, the armature in, for the chain's order and a permuted one."""
    xml = default_urdf_xml()
    armature = (0.1, 0.25, 0.05)
    model = RobotModel(xml, 'base_link', 'tool0', armature=armature)
    order = [2, 0, 1]
    perm = RobotModel(xml, 'base_link', 'tool0', joint_names=['joint3', 'joint1', 'joint2'],
                      armature=[armature[i] for i in order])
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = random_q(model, rng)
        inverse = np.linalg.inv(model.mass_matrix(q))
        np.testing.assert_allclose(model.inverse_inertia(q), inverse, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(perm.inverse_inertia(np.asarray(q)[order]),
                                   inverse[np.ix_(order, order)], rtol=1e-9, atol=1e-12)


def test_armature_adds_to_the_diagonal_of_the_inertia_in_the_callers_order():
    """M(q) = M_links(q) + diag(a), and the forward dynamics are Pinocchio's ABA with it."""
    xml = default_urdf_xml()
    plain = RobotModel(xml, 'base_link', 'tool0')
    armature = (0.1, 0.25, 0.05)  # joints 1, 2, 3
    rotor = RobotModel(xml, 'base_link', 'tool0', armature=armature)
    perm = RobotModel(xml, 'base_link', 'tool0', joint_names=['joint3', 'joint1', 'joint2'],
                      armature=[armature[i] for i in (2, 0, 1)])
    assert rotor.armature == armature
    assert plain.armature == (0.0, 0.0, 0.0)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = random_q(plain, rng)
        M0 = plain.mass_matrix(q)
        np.testing.assert_allclose(rotor.mass_matrix(q), M0 + np.diag(armature), atol=1e-12)
        order = [2, 0, 1]
        np.testing.assert_allclose(perm.mass_matrix(np.asarray(q)[order]),
                                   (M0 + np.diag(armature))[np.ix_(order, order)], atol=1e-12)
        qddot = rng.uniform(-3.0, 3.0, 3)  # M(q) qddot, the armature in, no gravity
        np.testing.assert_allclose(rotor.inertial_torque(q, qddot.tolist()),
                                   (M0 + np.diag(armature)) @ qddot, atol=1e-12)
        np.testing.assert_allclose(perm.inertial_torque(np.asarray(q)[order], qddot[order]),
                                   ((M0 + np.diag(armature)) @ qddot)[order], atol=1e-12)
        qdot = rng.uniform(-1.0, 1.0, 3)
        tau = rng.uniform(-5.0, 5.0, 3)
        # qddot = (M0 + A)^-1 (tau - h), h = C qdot + g from the plain model's dynamics
        h = -M0 @ plain.forward_dynamics(q, qdot, np.zeros(3))
        np.testing.assert_allclose(rotor.forward_dynamics(q, qdot, tau),
                                   np.linalg.solve(M0 + np.diag(armature), tau - h),
                                   atol=1e-10)
    full = pin.buildModelFromXML(xml)  # the same through Pinocchio directly
    full.armature[:] = armature
    data = full.createData()
    q = np.array([0.3, -0.7, 1.2])
    np.testing.assert_allclose(rotor.forward_dynamics(q, [0.2, 0.0, -0.4], [1.0, 2.0, 3.0]),
                               pin.aba(full, data, q, np.array([0.2, 0.0, -0.4]),
                                       np.array([1.0, 2.0, 3.0])), atol=1e-10)


def test_a_payload_adds_its_weight_through_its_jacobian_and_its_mass_to_the_inertia():
    """g(q) gains J_c(q)^T m g0 of a point mass at c in the tip frame; M(q) gains m J_c^T J_c."""
    from quat_jt_runtime.payload import PAYLOAD_RADIUS_M
    xml = default_urdf_xml()
    plain = RobotModel(xml, 'base_link', 'tool0')
    com_tip_m = (0.02, -0.01, 0.05)
    loaded = RobotModel(xml, 'base_link', 'tool0', payload_kg=0.8, payload_com_tip_m=com_tip_m)
    assert (loaded.payload_kg, loaded.payload_com_tip_m) == (0.8, com_tip_m)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = random_q(plain, rng)
        p, R, J = plain.kinematics(q)
        R, J = np.array(R), np.array(J)
        c = R @ np.array(com_tip_m)  # tip origin -> payload, base axes
        J_c = J[:3] - np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]],
                                [-c[1], c[0], 0.0]]) @ J[3:]
        g0 = 9.81 * np.array([0.0, 0.0, 1.0])  # the weight -m g0, held up by the torques
        np.testing.assert_allclose(np.subtract(loaded.gravity(q), plain.gravity(q)),
                                   J_c.T @ (0.8 * g0), atol=1e-9)
        sphere = 0.4 * 0.8 * PAYLOAD_RADIUS_M ** 2  # its inertia about c, any axis
        np.testing.assert_allclose(loaded.mass_matrix(q) - plain.mass_matrix(q),
                                   0.8 * J_c.T @ J_c + sphere * J[3:].T @ J[3:], atol=1e-12)


@pytest.mark.parametrize('mass, com, match', [
    (-0.1, (0.0, 0.0, 0.0), 'payload_mass must be finite and >= 0 kg, got -0.1'),
    (float('nan'), (0.0, 0.0, 0.0), 'payload_mass must be finite and >= 0 kg, got nan'),
    (0.5, (0.0, 0.1), 'payload_com must be 3 finite numbers'),
    (0.5, (0.0, float('inf'), 0.0), 'payload_com must be 3 finite numbers'),
    (0.5, 'abc', 'payload_com must be 3'),
])
def test_a_bad_payload_is_refused_by_name(mass, com, match):
    with pytest.raises(ModelError, match=match):
        RobotModel(default_urdf_xml(), 'base_link', 'tool0', payload_kg=mass,
                   payload_com_tip_m=com)


def test_the_payload_set_live_is_the_one_a_simulator_gets_as_a_link_of_its_urdf():
    """set_payload (Pinocchio, in place) == with_payload (a URDF link, what a plant loads)."""
    from quat_jt_runtime.payload import with_payload
    xml = default_urdf_xml()
    model = RobotModel(xml, 'base_link', 'tool0')
    plain = RobotModel(xml, 'base_link', 'tool0')
    rng = np.random.default_rng(8)
    for mass, com in ((0.8, (0.02, -0.01, 0.05)), (2.5, (0.0, 0.1, 0.0))):
        model.set_payload(mass, com)
        linked = RobotModel(with_payload(xml, 'tool0', mass, com), 'base_link', 'tool0')
        for _ in range(3):
            q = random_q(plain, rng)
            np.testing.assert_allclose(model.gravity(q), linked.gravity(q), atol=1e-12)
            np.testing.assert_allclose(model.mass_matrix(q), linked.mass_matrix(q), atol=1e-12)
            qddot = rng.uniform(-2.0, 2.0, 3).tolist()
            np.testing.assert_allclose(model.inertial_torque(q, qddot),
                                       linked.inertial_torque(q, qddot), atol=1e-12)
    with pytest.raises(ModelError, match='payload_mass must be finite and >= 0 kg'):
        model.set_payload(-1.0, (0.0, 0.0, 0.0))
    assert model.payload_kg == 2.5  # a refused set changes nothing
    model.set_payload(0.0, (0.0, 0.0, 0.0))  # taken away: the URDF's own again
    q = random_q(plain, rng)
    np.testing.assert_allclose(model.gravity(q), plain.gravity(q), atol=1e-12)
    np.testing.assert_allclose(model.mass_matrix(q), plain.mass_matrix(q), atol=1e-12)


def test_the_payload_regressor_gives_the_gravity_of_any_payload_linearly():
    """Y(q) [m; m c] = g(q) with the payload - g(q) without, the base turned from the root."""
    from robots import panda_model
    xml = default_urdf_xml()
    tilted = xml.replace('<link name="base_link">', '<link name="world"/><joint name="mount" '
                         'type="fixed"><parent link="world"/><child link="base_link"/><origin '
                         'rpy="0.4 -0.3 0.2" xyz="0 0 0.5"/></joint><link name="base_link">', 1)
    for plain in (panda_model(), RobotModel(tilted, 'base_link', 'tool0')):
        rng = np.random.default_rng(11)
        for mass, com in ((0.7, (0.01, 0.02, 0.1)), (3.0, (-0.05, 0.0, 0.02))):
            for _ in range(3):
                q = random_q(plain, rng).tolist()
                Y = plain.payload_regressor(q)
                before = np.array(plain.gravity(q))
                plain.set_payload(mass, com)
                np.testing.assert_allclose(Y @ np.array([mass, *(mass * c for c in com)]),
                                           np.array(plain.gravity(q)) - before, atol=1e-9)
                plain.set_payload(0.0, (0.0, 0.0, 0.0))


def test_a_payload_link_takes_a_free_name_and_needs_its_link():
    from quat_jt_runtime.payload import with_payload
    xml = with_payload(default_urdf_xml(), 'tool0', 1.0, (0.0, 0.0, 0.1))
    again = with_payload(xml, 'tool0', 0.5, (0.0, 0.0, 0.0))  # tool0_payload is taken
    assert 'tool0_payload_' in again and again.count('<link name="tool0_payload') == 2
    assert with_payload(xml, 'tool0', 0.0, (0.0, 0.0, 0.0)) == xml  # no mass: as it was
    with pytest.raises(ValueError, match="link 'nowhere' is not in the URDF"):
        with_payload(default_urdf_xml(), 'nowhere', 1.0, (0.0, 0.0, 0.0))


@pytest.mark.parametrize('armature, match', [
    ([0.1, -0.2, 0.0], r'armature\[1\] must be finite and >= 0, got -0.2'),
    ([0.1, float('nan'), 0.0], r'armature\[1\] must be finite and >= 0, got nan'),
    ([0.1, 0.2], r'armature must have 3 values \(one per joint\), got 2'),
    (['a', 0.2, 0.1], 'armature must be a list of numbers'),
])
def test_a_bad_armature_is_refused_naming_the_value(armature, match):
    with pytest.raises(ModelError, match=match):
        RobotModel(default_urdf_xml(), 'base_link', 'tool0', armature=armature)

"""The ROS-free simulator core: dynamics against Pinocchio, friction, limits, reset, loading."""
from pathlib import Path

import numpy as np
import pybullet_data
import pytest
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from wrist_sim.simulator import resolve_meshes, SimulatorError, take_zero_inertia_warnings
from wrist_sim.simulator import RobotSimulator, zero_inertia_note

pytestmark = pytest.mark.unit

DT_S = 1e-3
XARM = Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf'


@pytest.fixture(scope='module')
def urdf() -> str:
    return default_urdf_xml()


@pytest.fixture(scope='module')
def model(urdf) -> RobotModel:
    return RobotModel(urdf, 'base_link', 'tool0')


@pytest.fixture
def sim(urdf):
    with RobotSimulator(urdf) as s:
        yield s


def test_defaults_come_from_the_urdf(sim):
    assert sim.joint_names == ('joint1', 'joint2', 'joint3')
    np.testing.assert_allclose(sim.effort_limits_nm, [50.0, 30.0, 20.0])
    np.testing.assert_allclose(sim.position_lower, [-3.14159, -2.6, -3.14159])
    assert sim.dt_s == DT_S and sim.time_s == 0.0
    st = sim.state()
    np.testing.assert_array_equal(st.q_rad, 0.0)
    np.testing.assert_array_equal(st.qdot_rad_s, 0.0)


def test_one_step_acceleration_matches_pinocchio(sim, model):
    """Check PyBullet's qddot for a known torque = M^-1 (tau - C qdot - g) from Pinocchio."""
    rng = np.random.default_rng(1)
    for _ in range(30):
        q = rng.uniform(-1.2, 1.2, 3)
        qdot = rng.uniform(-3.0, 3.0, 3)
        tau = rng.uniform(-10.0, 10.0, 3)
        sim.reset(q, qdot)
        sim.step(tau)
        st = sim.state()
        qddot = (st.qdot_rad_s - qdot) / DT_S
        expected = model.forward_dynamics(q, qdot, tau)
        np.testing.assert_allclose(qddot, expected, rtol=1e-6, atol=1e-6)
        # Semi-implicit Euler: the new velocity moves the position.
        np.testing.assert_allclose(st.q_rad, q + DT_S * st.qdot_rad_s, atol=1e-9)


def test_pendulum_swing_matches_pinocchio_integration(sim, model):
    """
    Let joint 2 fall from 0.4 rad under gravity alone for 0.4 s.

    The same trajectory as Pinocchio's forward dynamics integrated the same way (semi-implicit
    Euler), while the speeds stay under the URDF velocity limits (6.28 rad/s; it would pass
    them at about 0.45 s, where the simulator holds the speed: see the next test).
    """
    q = np.array([0.3, 0.4, -0.2])
    qdot = np.zeros(3)
    sim.reset(q)
    for _ in range(400):
        qdot = qdot + DT_S * model.forward_dynamics(q, qdot, np.zeros(3))
        q = q + DT_S * qdot
        sim.step(np.zeros(3))
    st = sim.state()
    assert st.q_rad[1] > 0.6, 'the pendulum must fall (away from the upright q2 = 0)'
    np.testing.assert_allclose(st.q_rad, q, atol=1e-6)
    np.testing.assert_allclose(st.qdot_rad_s, qdot, atol=1e-5)
    assert np.abs(qdot).max() < 0.9 * sim.velocity_limits_rad_s.min()


def test_urdf_velocity_limits_are_enforced(sim):
    """A huge torque cannot spin a joint past its URDF velocity limit (6.28 rad/s here)."""
    np.testing.assert_allclose(sim.velocity_limits_rad_s, 6.2832)
    sim.reset([0.0, 0.0, 0.0])
    fastest = 0.0
    for _ in range(1000):
        sim.step(sim.effort_limits_nm)  # full torque on every joint, for 1 s
        fastest = max(fastest, float(np.abs(sim.qdot_rad_s).max()))
    assert 6.0 < fastest <= 6.2832 + 1e-9, fastest


def test_joint_subset_and_order(urdf):
    """Any order and subset of joints: the others are locked at zero, as in RobotModel."""
    names = ['joint3', 'joint2']
    model = RobotModel(urdf, 'base_link', 'tool0', names)
    with RobotSimulator(urdf, names) as s:
        np.testing.assert_allclose(s.effort_limits_nm, [20.0, 30.0])
        q, qdot, tau = np.array([0.2, 0.5]), np.array([1.0, -0.5]), np.array([1.0, 2.0])
        s.reset(q, qdot)
        s.step(tau)
        qddot = (s.state().qdot_rad_s - qdot) / DT_S
        np.testing.assert_allclose(qddot, model.forward_dynamics(q, qdot, tau), rtol=1e-4,
                                   atol=1e-3)


def test_effort_limits_clamp_the_applied_torque(sim, model):
    q = np.array([0.0, 0.5, 0.0])
    sim.reset(q)
    applied = sim.step([100.0, -100.0, 5.0])
    np.testing.assert_allclose(applied, [50.0, -30.0, 5.0])
    st = sim.state()
    np.testing.assert_allclose(st.tau_applied_nm, [50.0, -30.0, 5.0])
    expected = model.forward_dynamics(q, np.zeros(3), applied)
    np.testing.assert_allclose(st.qdot_rad_s / DT_S, expected, rtol=1e-6)


@pytest.mark.parametrize('bad', [[1.0, 2.0], [1.0, np.nan, 0.0], [np.inf, 0.0, 0.0]])
def test_bad_torques_raise_and_do_not_step(sim, bad):
    with pytest.raises(SimulatorError):
        sim.step(bad)
    assert sim.step_count == 0


def _run(sim: RobotSimulator, tau, steps: int) -> np.ndarray:
    vel = np.empty((steps, sim.n))
    for k in range(steps):
        sim.step(tau)
        vel[k] = sim.qdot_rad_s
    return vel


def test_coulomb_below_the_level_holds_the_joint_still(urdf):
    """
    Apply 0.9 x the Coulomb level on each joint (and gravity) for 1 s.

    Stiction: no motion, no chattering at 1 kHz (the velocity is zero at every step, not
    oscillating around it).
    """
    coulomb = np.array([2.0, 3.0, 2.0])
    q0 = np.array([0.2, 0.5, -0.3])  # gravity torque on joint 2 here ~0.6 N m < 3 N m
    with RobotSimulator(urdf, coulomb_nm=coulomb, initial_positions_rad=q0) as s:
        vel = _run(s, [1.8, 0.0, -1.8], 1000)
        np.testing.assert_allclose(s.q_rad, q0, atol=1e-9)
        assert np.abs(vel).max() < 1e-9


def test_coulomb_above_the_level_moves_the_joint(urdf, model):
    """Above the Coulomb level the joint accelerates with (tau - f_c) / I, the right way."""
    coulomb = np.array([2.0, 3.0, 2.0])
    q0 = np.array([0.0, 0.5, 0.0])
    with RobotSimulator(urdf, coulomb_nm=coulomb, initial_positions_rad=q0) as s:
        vel = _run(s, [3.0, 0.0, 0.0], 200)
        t = 0.2
        inertia = model.mass_matrix(q0)[0, 0]
        expected = 0.5 * (3.0 - 2.0) / inertia * t ** 2
        assert s.q_rad[0] == pytest.approx(expected, rel=0.1)
        assert np.all(np.diff(vel[:, 0]) > 0.0), 'steady acceleration, no stick-slip'
        np.testing.assert_allclose(s.q_rad[1:], q0[1:], atol=1e-6)  # others still stick
        s.reset()
        _run(s, [-3.0, 0.0, 0.0], 200)
        assert s.q_rad[0] == pytest.approx(-expected, rel=0.1)


def test_viscous_friction_is_minus_b_qdot(urdf, model):
    """
    Check viscous friction is an explicit -b qdot torque.

    The same trajectory as Pinocchio's dynamics integrated with that torque; the spinning joint
    slows down.
    """
    b = np.array([0.2, 0.1, 0.05])
    q, qdot = np.zeros(3), np.array([2.0, 0.0, 0.0])
    with RobotSimulator(urdf, viscous_nm_s_per_rad=b) as s:
        s.reset(q, qdot)
        _run(s, [0.0, 0.0, 0.0], 500)
        for _ in range(500):
            qdot = qdot + DT_S * model.forward_dynamics(q, qdot, -b * qdot)
            q = q + DT_S * qdot
        np.testing.assert_allclose(s.qdot_rad_s, qdot, atol=1e-6)
        np.testing.assert_allclose(s.q_rad, q, atol=1e-6)
        assert 0.0 < s.qdot_rad_s[0] < 1.0
        np.testing.assert_allclose(s.tau_applied_nm, 0.0)  # friction is not "applied" torque


def test_set_friction_validates_before_changing_anything(sim):
    sim.set_friction([0.1, 0.2, 0.3], [1.0, 2.0, 3.0])
    for viscous, coulomb in [([0.1, 0.2], None), ([0.1, -0.2, 0.3], None),
                             (None, [1.0, np.nan, 1.0]), (None, [1.0, 1.0, -1.0])]:
        with pytest.raises(SimulatorError):
            sim.set_friction(viscous, coulomb)
    viscous, coulomb = sim.friction
    np.testing.assert_allclose(viscous, [0.1, 0.2, 0.3])
    np.testing.assert_allclose(coulomb, [1.0, 2.0, 3.0])


def test_reset_returns_to_rest_and_time_goes_on(urdf):
    q0 = [0.1, -0.2, 0.3]
    with RobotSimulator(urdf, initial_positions_rad=q0) as s:
        _run(s, [5.0, 5.0, 5.0], 100)
        assert not np.allclose(s.q_rad, q0)
        s.reset()
        st = s.state()
        np.testing.assert_allclose(st.q_rad, q0, atol=1e-12)
        np.testing.assert_array_equal(st.qdot_rad_s, 0.0)
        np.testing.assert_array_equal(st.tau_applied_nm, 0.0)
        assert st.time_s == pytest.approx(0.1)
        with pytest.raises(SimulatorError):
            s.reset([0.0, 0.0])


def test_instances_are_independent(urdf):
    with RobotSimulator(urdf) as a, RobotSimulator(urdf) as b:
        _run(a, [5.0, 0.0, 0.0], 50)
        assert a.q_rad[0] > 0.0
        np.testing.assert_array_equal(b.q_rad, 0.0)


def test_unknown_or_repeated_joints_are_refused(urdf):
    with pytest.raises(SimulatorError, match='not movable'):
        RobotSimulator(urdf, ['joint1', 'tool_joint'])
    with pytest.raises(SimulatorError, match='repeat'):
        RobotSimulator(urdf, ['joint1', 'joint1'])
    with pytest.raises(SimulatorError):
        RobotSimulator(urdf, coulomb_nm=[1.0])


def _link_with_meshes(*filenames: str) -> str:
    shapes = ''.join(f'<visual><geometry><mesh filename="{f}"/></geometry></visual>'
                     for f in filenames)
    return (f'<robot name="r"><link name="base">{shapes}<inertial><mass value="1"/>'
            '<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
            '</robot>')


def test_meshes_resolve_from_search_dirs_and_the_missing_ones_are_dropped(tmp_path):
    mesh = tmp_path / 'pkgs' / 'my_description' / 'meshes' / 'a.stl'
    mesh.parent.mkdir(parents=True)
    mesh.write_text('solid a\nendsolid a\n')
    xml = _link_with_meshes('package://my_description/meshes/a.stl', 'package://missing/b.stl',
                            'my_description/meshes/a.stl', 'meshes/c.stl')
    out, missing = resolve_meshes(xml, [tmp_path])  # found one level down, in pkgs/
    assert out.count(f'filename="{mesh.resolve()}"') == 2  # package:// and relative
    assert missing == ['package://missing/b.stl', 'meshes/c.stl']
    assert 'b.stl' not in out and 'c.stl' not in out and '<inertial>' in out
    assert resolve_meshes(_link_with_meshes(str(mesh)), []) == (
        _link_with_meshes(str(mesh)), [])  # found as written: the XML is untouched


def test_package_uris_resolve_through_the_ament_index(tmp_path, monkeypatch):
    """A robot_description from a sourced workspace: package:// is share/<package>/."""
    prefix = tmp_path / 'install'
    mesh = prefix / 'share' / 'my_robot_description' / 'meshes' / 'a.stl'
    mesh.parent.mkdir(parents=True)
    mesh.write_text('solid a\nendsolid a\n')
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'my_robot_description').write_text('')
    monkeypatch.setenv('AMENT_PREFIX_PATH', f'/nonexistent:{prefix}')
    out, missing = resolve_meshes(
        _link_with_meshes('package://my_robot_description/meshes/a.stl'), [])
    assert f'filename="{mesh.resolve()}"' in out and missing == []


def test_a_robot_whose_meshes_are_missing_loads_without_them():
    """The dynamics need only the inertias: the arm loads, moves and names what is missing."""
    xml = XARM.read_text().replace('package://xarm_description/', 'package://nowhere/')
    with RobotSimulator(xml) as s:
        assert s.n == 6
        assert s.missing_meshes and all('package://nowhere/' in m for m in s.missing_meshes)
        s.step(np.zeros(6))
        assert np.all(np.isfinite(s.q_rad))


@pytest.mark.skipif(not XARM.is_file(), reason='pybullet_data has no xArm6')
def test_loads_the_xarm6_with_package_meshes():
    xml = XARM.read_text()
    assert 'package://xarm_description/' in xml
    with RobotSimulator(xml) as s:
        assert s.n == 6
        s.step(np.zeros(6))
        assert np.all(np.isfinite(s.q_rad))


@pytest.mark.skipif(not XARM.is_file(), reason='pybullet_data has no xArm6')
def test_links_pybullet_gives_no_inertia_are_named_once_and_its_warnings_kept_out(capfd):
    """The xArm6's link2 and link3 tensors break the triangle inequality: PyBullet zeroes them."""
    with RobotSimulator(XARM.read_text()) as s:
        assert s.zero_inertia_links == ('link2', 'link3')
        c, body = s._engine._client, s._engine._body
        names = {c.getJointInfo(body, j)[12].decode(): j for j in range(c.getNumJoints(body))}
        for link in ('link2', 'link3'):  # what the note says is what PyBullet simulates
            assert c.getDynamicsInfo(body, names[link])[2] == (0.0, 0.0, 0.0), link
        assert c.getDynamicsInfo(body, names['link4'])[2] != (0.0, 0.0, 0.0)
    out, err = capfd.readouterr()
    assert 'inertia' not in out + err, out + err
    note = zero_inertia_note(('link2', 'link3'))
    assert note.startswith('PyBullet simulates link2, link3 without rotational inertia')
    with RobotSimulator(default_urdf_xml()) as wrist:  # valid tensors: nothing to say
        assert wrist.zero_inertia_links == ()


def test_only_the_zero_inertia_warnings_are_taken_out_of_the_loaders_output():
    header = 'b3Warning[examples/Importers/ImportURDFDemo/BulletUrdfImporter.cpp,467]:\n'
    text = (header + 'Bad inertia tensor properties, setting inertia to zero for link: a\n'
            'something else\n' + header
            + 'Bad inertia tensor properties, setting inertia to zero for link: b\n'
            + header + 'Bad inertia tensor properties, setting inertia to zero for link: a\n')
    assert take_zero_inertia_warnings(text) == (('a', 'b'), 'something else\n')


def test_hold_passes_time_with_the_joints_at_rest(urdf):
    q0 = [0.2, 0.6, -0.3]
    with RobotSimulator(urdf, initial_positions_rad=q0) as s:
        for _ in range(100):
            s.hold()
        assert s.step_count == 100 and s.time_s == pytest.approx(0.1)
        np.testing.assert_array_equal(s.q_rad, q0)
        np.testing.assert_array_equal(s.qdot_rad_s, 0.0)
        s.step_zero()  # released: gravity moves joint 2
        s.step_zero()
        assert s.qdot_rad_s[1] != 0.0


def test_gui_without_a_display_is_a_clear_error(urdf, monkeypatch):
    """Refuse use_gui without a display, saying why (PyBullet would end the process)."""
    monkeypatch.delenv('DISPLAY', raising=False)
    with pytest.raises(SimulatorError, match='DISPLAY is not set.*xvfb-run'):
        RobotSimulator(urdf, use_gui=True)

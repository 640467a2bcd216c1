"""
The simulator's MuJoCo engine against Pinocchio, and what both engines share.

The same :class:`RobotSimulator` interface with ``engine='mujoco'``: the one-step
acceleration is Pinocchio's ABA with ``model.armature`` set (the rotor inertia simulated),
Coulomb friction holds and breaks away, viscous friction is MuJoCo's implicit damping, the
speeds are held at the URDF velocity limits, the joints not driven are locked, and the bundled
wrist, the xArm6 and the Panda compile. PyBullet cannot simulate the armature, and says so.
"""
import numpy as np
import pytest
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from robots import PANDA_JOINTS, PANDA_URDF, random_q, XARM6_URDF
from wrist_sim.mujoco_engine import MASSLESS_LINK_KG, mujoco_urdf
from wrist_sim.simulator import ENGINES, repaired_inertia_note, RobotSimulator, SimulatorError

pytestmark = pytest.mark.unit
mujoco = pytest.importorskip('mujoco')

DT_S = 1e-3
ARMATURE = (0.3, 0.2, 0.1)


@pytest.fixture(scope='module')
def urdf() -> str:
    return default_urdf_xml()


def one_step_acceleration(sim: RobotSimulator, q, qdot, tau) -> np.ndarray:
    """Return (qdot_k+1 - qdot_k) / dt of one step from (q, qdot) under ``tau``."""
    sim.reset(q, qdot)
    sim.step(tau)
    return (sim.qdot_rad_s - np.asarray(qdot)) / sim.dt_s


@pytest.mark.parametrize('robot', ['wrist', 'panda'])
def test_the_acceleration_is_pinocchios_with_the_armature(urdf, robot):
    """The one-step qddot = (M(q) + diag(a))^-1 (tau - C qdot - g), ABA with model.armature."""
    if robot == 'wrist':
        xml, base, tip, joints = urdf, 'base_link', 'tool0', None
    else:  # seven of nine joints: the fingers locked at zero in both
        xml, base, tip, joints = PANDA_URDF.read_text(), 'panda_link0', 'panda_link8', \
            PANDA_JOINTS
    plain = RobotModel(xml, base, tip, joints)
    armature = np.linspace(0.05, 0.4, plain.n)
    model = RobotModel(xml, base, tip, joints, armature)
    rng = np.random.default_rng(7)
    with RobotSimulator(xml, model.joint_names, engine='mujoco', armature=armature,
                        enforce_velocity_limits=False) as sim:
        assert sim.engine == 'mujoco' and sim.supports_armature
        np.testing.assert_array_equal(sim.armature, armature)
        for _ in range(10):
            q = random_q(model, rng, margin=0.2)  # off the stops: no limit force
            qdot = rng.uniform(-1.0, 1.0, model.n)
            tau = rng.uniform(-5.0, 5.0, model.n)
            qddot = one_step_acceleration(sim, q, qdot, tau)
            np.testing.assert_allclose(qddot, model.forward_dynamics(q, qdot, tau),
                                       rtol=1e-7, atol=1e-7)
            # the rotor inertia matters here: without it the acceleration is another
            assert np.abs(qddot - plain.forward_dynamics(q, qdot, tau)).max() > 1e-2
            # semi-implicit Euler: the new velocity moves the position
            np.testing.assert_allclose(sim.q_rad, q + DT_S * sim.qdot_rad_s, atol=1e-12)


def test_pybullet_keeps_the_armature_but_cannot_simulate_it(urdf):
    """Its dynamics stay the URDF's alone, and ``supports_armature`` says so."""
    plain = RobotModel(urdf, 'base_link', 'tool0')
    with RobotSimulator(urdf, armature=ARMATURE) as sim:
        assert sim.engine == 'pybullet' and not sim.supports_armature
        np.testing.assert_array_equal(sim.armature, ARMATURE)
        q, qdot, tau = [0.3, 0.5, -0.2], [0.5, 0.0, -0.5], [2.0, 1.0, -1.0]
        np.testing.assert_allclose(one_step_acceleration(sim, q, qdot, tau),
                                   plain.forward_dynamics(q, qdot, tau), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize('engine', ENGINES)
def test_the_pendulum_falls_the_same_in_both_engines(urdf, engine):
    """Gravity alone from rest, 0.3 s, against Pinocchio integrated the same way."""
    model = RobotModel(urdf, 'base_link', 'tool0')
    q, qdot = np.array([0.3, 0.4, -0.2]), np.zeros(3)
    with RobotSimulator(urdf, engine=engine, initial_positions_rad=q) as sim:
        for _ in range(300):
            qdot = qdot + DT_S * model.forward_dynamics(q, qdot, np.zeros(3))
            q = q + DT_S * qdot
            sim.step_zero()
        assert sim.q_rad[1] > 0.5
        np.testing.assert_allclose(sim.q_rad, q, atol=1e-6)


def test_coulomb_friction_holds_below_its_level_and_breaks_away_above(urdf):
    """
    Stiction: 0.9 x the level (net of gravity) for 2 s barely moves a joint; 1.1 x moves it.

    MuJoCo's friction loss is a stiff soft constraint: a held joint creeps at a few 1e-6 rad/s
    at most, where PyBullet's velocity motor holds it exactly.
    """
    model = RobotModel(urdf, 'base_link', 'tool0')
    coulomb = np.array([2.0, 3.0, 2.0])
    q0 = np.array([0.2, 0.5, -0.3])
    g = np.array(model.gravity(q0))
    with RobotSimulator(urdf, engine='mujoco', coulomb_nm=coulomb,
                        initial_positions_rad=q0) as sim:
        held = g + 0.9 * coulomb * np.array([1.0, -1.0, 1.0])
        for _ in range(2000):
            sim.step(held)
        np.testing.assert_allclose(sim.q_rad, q0, atol=1e-4)
        assert np.abs(sim.qdot_rad_s).max() < 1e-4
        sim.reset()
        moved = g + 1.1 * coulomb * np.array([1.0, -1.0, 1.0])
        for _ in range(200):
            sim.step(moved)
        assert sim.q_rad[0] - q0[0] > 1e-3 and q0[1] - sim.q_rad[1] > 1e-3
        assert sim.q_rad[2] - q0[2] > 1e-3
        np.testing.assert_array_equal(sim.friction[1], coulomb)


def test_viscous_friction_is_implicit_damping(urdf):
    """One step: (M + dt B) qddot = tau - C qdot - g - B qdot (MuJoCo's implicit Euler)."""
    model = RobotModel(urdf, 'base_link', 'tool0', armature=ARMATURE)
    b = np.array([0.5, 0.3, 0.2])
    q, qdot, tau = np.array([0.3, 0.5, -0.2]), np.array([2.0, -1.0, 0.5]), np.zeros(3)
    with RobotSimulator(urdf, engine='mujoco', viscous_nm_s_per_rad=b,
                        armature=ARMATURE) as sim:
        qddot = one_step_acceleration(sim, q, qdot, tau)
        M = model.mass_matrix(q)
        h = -M @ model.forward_dynamics(q, qdot, np.zeros(3))  # C qdot + g
        np.testing.assert_allclose(qddot, np.linalg.solve(M + DT_S * np.diag(b),
                                                          tau - h - b * qdot), rtol=1e-6)
        np.testing.assert_array_equal(sim.tau_applied_nm, 0.0)  # friction is not "applied"


def test_speeds_are_held_at_the_velocity_limits_and_efforts_clamped(urdf):
    """Full torque for 1 s: no joint passes 6.28 rad/s, and q integrates the held speed."""
    with RobotSimulator(urdf, engine='mujoco') as sim:
        np.testing.assert_allclose(sim.velocity_limits_rad_s, 6.2832)
        applied = sim.step([100.0, -100.0, 5.0])
        np.testing.assert_allclose(applied, [50.0, -30.0, 5.0])
        fastest = 0.0
        for _ in range(1000):
            q_before = sim.q_rad.copy()
            sim.step(sim.effort_limits_nm)
            fastest = max(fastest, float(np.abs(sim.qdot_rad_s).max()))
            np.testing.assert_allclose(sim.q_rad, q_before + DT_S * sim.qdot_rad_s, atol=1e-12)
        assert 6.0 < fastest <= 6.2832 + 1e-12, fastest
    with RobotSimulator(urdf, engine='mujoco', enforce_velocity_limits=False) as sim:
        fastest = 0.0
        for _ in range(1000):  # until the stops
            sim.step(sim.effort_limits_nm)
            fastest = max(fastest, float(np.abs(sim.qdot_rad_s).max()))
        assert fastest > 6.2832  # off: only reported by the node


def test_the_robots_of_the_configs_compile(urdf):
    """The wrist, the xArm6 (its two impossible inertias balanced) and the Panda load."""
    for xml, joints in ((urdf, None), (XARM6_URDF.read_text(), None),
                        (PANDA_URDF.read_text(), PANDA_JOINTS)):
        with RobotSimulator(xml, joints, engine='mujoco') as sim:
            with RobotSimulator(xml, joints) as bullet:
                assert sim.joint_names == bullet.joint_names
                np.testing.assert_array_equal(sim.effort_limits_nm, bullet.effort_limits_nm)
                np.testing.assert_array_equal(sim.velocity_limits_rad_s,
                                              bullet.velocity_limits_rad_s)
                np.testing.assert_allclose(sim.position_lower, bullet.position_lower)
                np.testing.assert_allclose(sim.position_upper, bullet.position_upper)
            assert sim.missing_meshes == []  # no shapes: no mesh is looked for
            for _ in range(10):
                sim.step(np.zeros(sim.n))
            assert np.all(np.isfinite(sim.q_rad))


def test_the_joints_not_driven_are_locked(urdf):
    """Two of the wrist's joints driven: the third held at zero, as RobotModel locks it."""
    names = ['joint3', 'joint2']
    model = RobotModel(urdf, 'base_link', 'tool0', names)
    with RobotSimulator(urdf, names, engine='mujoco') as sim:
        np.testing.assert_allclose(sim.effort_limits_nm, [20.0, 30.0])
        q, qdot, tau = np.array([0.2, 0.5]), np.array([1.0, -0.5]), np.array([1.0, 2.0])
        np.testing.assert_allclose(one_step_acceleration(sim, q, qdot, tau),
                                   model.forward_dynamics(q, qdot, tau), rtol=1e-7, atol=1e-7)


def test_bad_engines_and_values_are_refused_by_name(urdf, monkeypatch):
    with pytest.raises(SimulatorError, match=r"engine must be one of \['pybullet', 'mujoco'\], "
                                             "got 'ode'"):
        RobotSimulator(urdf, engine='ode')
    with pytest.raises(SimulatorError, match=r'armature: values must be >= 0, got \[0.1, -1.0'):
        RobotSimulator(urdf, engine='mujoco', armature=[0.1, -1.0, 0.0])
    with pytest.raises(SimulatorError, match='armature: expected 3 values'):
        RobotSimulator(urdf, armature=[0.1])
    with pytest.raises(SimulatorError, match="use_gui: the window is PyBullet's"):
        RobotSimulator(urdf, engine='mujoco', use_gui=True)
    monkeypatch.setitem(__import__('sys').modules, 'mujoco', None)  # not installed
    with pytest.raises(SimulatorError, match='pip install mujoco'):
        RobotSimulator(urdf, engine='mujoco')


def test_a_moving_link_without_mass_gets_a_milligram_if_it_carries_mass(urdf):
    """
    A frame between two joints' axes (the human model's shoulder): MuJoCo refuses it as it is.

    link1 of the wrist made massless, with link2 and link3 below it: the simulator gives it
    ``MASSLESS_LINK_KG`` (and m (1 mm)^2) and names it; the fall under gravity is the
    URDF's to within that milligram. A massless link that carries nothing is left to MuJoCo's
    refusal, which says to leave its joint undriven.
    """
    link1 = ('<mass value="3.0"/>\n      <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.03" iyz="0" '
             'izz="0.05"/>')
    assert link1 in urdf
    virtual = urdf.replace(link1, '<mass value="0"/>\n      <inertia ixx="0" ixy="0" ixz="0" '
                                  'iyy="0" iyz="0" izz="0"/>')
    with pytest.raises(ValueError, match='mass and inertia of moving bodies'):
        mujoco.MjModel.from_xml_string(virtual)  # MuJoCo alone
    text, repaired = mujoco_urdf(virtual, ('joint1', 'joint2', 'joint3'))
    assert repaired == ('link1',)
    assert f'<mass value="{MASSLESS_LINK_KG!r}"' in text
    q0 = [0.3, 0.8, -0.4]
    model = RobotModel(virtual, 'base_link', 'tool0')
    with RobotSimulator(virtual, engine='mujoco', initial_positions_rad=q0) as sim:
        assert sim.repaired_inertia_links == ('link1',)
        accel = one_step_acceleration(sim, q0, [0.0] * 3, [0.0] * 3)
    want = model.forward_dynamics(q0, [0.0] * 3, [0.0] * 3)
    np.testing.assert_allclose(accel, want, rtol=1e-3, atol=1e-3)
    tip = ('<mass value="0.8"/>\n      <inertia ixx="0.012" ixy="0" ixz="0" iyy="0.012" iyz="0" '
           'izz="0.02"/>')
    assert tip in urdf
    leaf = urdf.replace(tip, '<mass value="0"/>\n      <inertia ixx="0" ixy="0" ixz="0" '
                             'iyy="0" iyz="0" izz="0"/>').replace(
        '<mass value="0.001"/>', '<mass value="0"/>')  # tool0, below it, massless too
    with pytest.raises(SimulatorError, match='drive only the joints that move mass'):
        RobotSimulator(leaf, engine='mujoco')


def with_antenna(urdf: str, inertia: str) -> str:
    """Return the wrist with a light link welded to its base, of inertia ``inertia``."""
    antenna = ('<link name="antenna"><inertial><origin xyz="0 0 0" rpy="0 0 0"/>'
               f'<mass value="1e-6"/><inertia {inertia}/></inertial></link>'
               '<joint name="antenna_joint" type="fixed"><parent link="base_link"/>'
               '<child link="antenna"/><origin xyz="0.1 0 0" rpy="0 0 0"/></joint>')
    return urdf.replace('</robot>', antenna + '</robot>')


def test_a_tensor_with_a_negative_moment_is_repaired_and_named(urdf):
    """An antenna of TIAGo: ixy larger than ixx and iyy, which MuJoCo refuses as it is."""
    bad = ('ixx="2.371e-8" ixy="6.119e-8" ixz="1.179e-8" iyy="2.833e-8" iyz="7.74e-9" '
           'izz="3.849e-8"')
    xml = with_antenna(urdf, bad)
    with pytest.raises(ValueError, match='inertia must have positive eigenvalues'):
        mujoco.MjModel.from_xml_string(xml)  # MuJoCo alone
    with RobotSimulator(xml, engine='mujoco') as sim:
        assert sim.repaired_inertia_links == ('antenna',)
        sim.step(np.array([1.0, -1.0, 0.5]))
        assert np.all(np.isfinite(sim.q_rad)) and np.any(sim.q_rad != 0.0)
    with RobotSimulator(urdf, engine='mujoco') as wrist:  # valid tensors: nothing to say
        assert wrist.repaired_inertia_links == ()
    # a rod (izz 0: the finger of finger_edu) and a point mass (iCub's l_ankle_2), both
    # refused by MuJoCo as they come; a massless link with no tensor is left alone
    for tensor in ('ixx="1.2e-4" ixy="0" ixz="0" iyy="1.2e-4" iyz="0" izz="0"',
                   'ixx="0" ixy="0" ixz="1.3e-20" iyy="0" iyz="0" izz="0"',
                   'ixx="2.7e-20" ixy="0" ixz="0" iyy="5.4e-20" iyz="0" izz="1.4e-20"'):
        xml = with_antenna(urdf, tensor).replace('value="1e-6"', 'value="0.27"')
        with pytest.raises(ValueError, match='inertia must have positive eigenvalues'):
            mujoco.MjModel.from_xml_string(xml)
        with RobotSimulator(xml, engine='mujoco') as sim:
            assert sim.repaired_inertia_links == ('antenna',)
    # no tensor on a link a driven joint moves (iCub's): MuJoCo refuses it; given m (1 mm)^2
    point = urdf.replace('<inertia ixx="0.012" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.02"/>',
                         '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>')
    assert point != urdf
    with RobotSimulator(point, engine='mujoco') as sim:
        assert sim.repaired_inertia_links == ('link3',)
    with RobotSimulator(point, ['joint1', 'joint2'], engine='mujoco') as sim:
        assert sim.repaired_inertia_links == ()  # joint3 locked: link3 does not move
    for mass in ('0', '1e-9', '0.27'):  # no tensor: a frame (the SO-101's gripper_frame_link),
        # or a point mass (the TALOS arm's wrist_left_ft_link), both of which MuJoCo takes
        massless = with_antenna(urdf, 'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"')
        with RobotSimulator(massless.replace('value="1e-6"', f'value="{mass}"'),
                            engine='mujoco') as sim:
            assert sim.repaired_inertia_links == ()
    assert repaired_inertia_note(('antenna',)).startswith(
        'MuJoCo simulates antenna with a principal moment of inertia raised')
    with pytest.raises(SimulatorError, match=r"link 'antenna': the inertia tensor is not "
                                             'finite'):
        RobotSimulator(with_antenna(urdf, bad.replace('2.371e-8', 'nan')), engine='mujoco')
    with pytest.raises(SimulatorError, match="link 'antenna': an inertia value is not a "
                                             'number'):
        RobotSimulator(with_antenna(urdf, bad.replace('2.371e-8', 'heavy')), engine='mujoco')

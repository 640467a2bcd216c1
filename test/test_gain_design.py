"""
Gain design from the robot (quat_jt_controller.gain_design, docs/gain_design.md), ROS-free.

The rules hold for the wrist and the xArm6: the tanh law's torque stays under its a-priori
bound, which stays within the budget; the goal-configuration term out-pulls the task term;
the sampled loop is stable; the package's configs are exactly what the tool writes; the
command runs from pip (``python -m``) and writes a parameter file the tests can load.
"""
import math
from pathlib import Path
import subprocess
import sys

import numpy as np
import pybullet_data
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import gain_analysis as ga
from quat_jt_controller import gain_design as gd
from quat_jt_controller import gain_output as go
from quat_jt_controller import quaternion as quat
from quat_jt_controller import shaping as sh
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from robots import PANDA_JOINTS, panda_model, PANDA_URDF, random_q, small_arm_urdf
from robots import wrist_model, xarm6_model
import yaml

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parent.parent
# The command lines that wrote config/wrist_controller.yaml and config/xarm6_controller.yaml.
WRIST_ARGS = ['--task', 'orientation', '--friction', '1.8', '0.72', '0.45', '--delays', '1',
              '2']
XARM6_ARGS = ['--urdf', str(Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf'),
              '--base-link', 'link_base', '--tip-link', 'link6', '--task', 'pose',
              '--friction', '0.009', '0.009', '0.0045', '0.0018', '0.0018', '0.00045',
              '--delays', '1', '2']
# ... and config/panda_controller.yaml with config/panda_sim.yaml
PANDA_ARGS = ['--urdf', str(PANDA_URDF), '--base-link', 'panda_link0', '--tip-link',
              'panda_link8', '--joints', *PANDA_JOINTS, '--task', 'pose',
              '--friction', '0.09', '0.09', '0.09', '0.09', '0.045', '0.045', '0.045',
              '--delays', '1', '2', '--cruise-fraction', '0.8',
              '--preferred-configuration', '0', '-0.785', '0', '-2.356', '0', '1.571', '0.785']
PANDA_SIM_ARGS = ['--initial-positions', '0', '-0.785', '0', '-2.356', '0', '1.571', '0.785',
                  '--sim-coulomb', '0.1', '0.1', '0.1', '0.1', '0.05', '0.05', '0.05',
                  '--sim-viscous', '0.1', '0.1', '0.1', '0.1', '0.05', '0.05', '0.05']


@pytest.fixture(scope='module')
def designs():
    return {
        'wrist': (wrist_model(), gd.design(wrist_model(), cl.Task.ORIENTATION,
                                           friction_nm=(1.8, 0.72, 0.45), delays=(1, 2))),
        'xarm6': (xarm6_model(), gd.design(xarm6_model(), cl.Task.POSE,
                                           friction_nm=(0.009, 0.009, 0.0045, 0.0018, 0.0018,
                                                        0.00045), delays=(1, 2))),
        'panda': (panda_model(), gd.design(panda_model(), cl.Task.POSE,
                                           friction_nm=(0.09,) * 4 + (0.045,) * 3,
                                           delays=(1, 2), cruise_fraction=0.8)),
    }


def params_of(text: str) -> dict:
    data = yaml.safe_load(text)
    assert list(data) == ['/**']
    return data['/**']['ros__parameters']


@pytest.mark.parametrize('robot', ['wrist', 'xarm6', 'panda'])
def test_the_budget_holds_the_bound_and_the_bound_holds_the_torque(designs, robot):
    model, d = designs[robot]
    f = d.figures
    assert np.all(f['budget_nm'] > 0.0)
    # task term + goal-configuration term within the budget, which leaves room for damping
    assert np.all(f['task_bound_nm'] + f['guide_nm'] <= f['budget_nm'] + 1e-9)
    assert np.all(f['budget_nm'] + f['gravity_max_nm'] + f['friction_nm']
                  < f['effort_limits_nm'])
    # the goal-configuration term out-pulls the task term where the design allows it
    assert np.all(f['guide_nm'] >= gd.GUIDE_OVER_TASK * f['task_bound_nm'] * 0.5)
    rng = np.random.default_rng(5)
    for potential in ('tanh', 'quadratic'):
        gains = d.gains(potential)
        for _ in range(200):  # the tanh law's torque obeys the a-priori bound anywhere
            q, q_goal = random_q(model, rng, 0.0), random_q(model, rng, 0.0)
            p_d, R_d = model.forward_kinematics(q_goal.tolist())
            p, R, J = model.kinematics(q.tolist())
            y, eta_e = cl.output_error(p, R, p_d, quat.from_rotation_matrix(R_d), d.task)
            if potential == 'quadratic' and np.linalg.norm(y[:-3]) > math.sqrt(3.0):
                continue  # the bound covers the quadratic law up to sqrt(3) m
            rows = np.array(J)[3:] if d.task is cl.Task.ORIENTATION else np.array(J)
            tau = np.abs(cl.potential_torque(rows.tolist(), y, eta_e, gains))
            assert np.all(tau <= f['task_bound_nm'] * (1 + 1e-9) + 1e-12), (potential, tau)


@pytest.mark.parametrize('robot', ['wrist', 'xarm6', 'panda'])
def test_the_sampled_loop_is_stable_with_the_delays_designed_for(designs, robot):
    model, d = designs[robot]
    data = gd.survey(model, d.task)
    for potential in ('tanh', 'quadratic'):
        gains = d.gains(potential)
        for q, _, _ in data['configurations'][:6]:
            for delay in (1, 3):
                rho = ga.linearized_spectral_radius(model, q, gains, delay, task=d.task,
                                                    shaping=d.shaping)
                assert rho < 1.0
                assert ga.time_constant_s(rho) < 1.0
    assert max(d.figures['spectral_radius'].values()) < 1.0
    # near-critical damping for the tanh law, as designed (less where the sampled loop caps
    # the damping: the xArm6's joint 1, folded, has 0.026 kg m^2; more where the speed rule
    # raised K_v to hold the push below the velocity limit: those joints cruise at the ceiling;
    # or where the arm would carry the joint too fast: those cruise below it)
    zeta = d.figures['damping_ratio']['tanh']
    assert np.all(zeta > 0.5), zeta
    over = zeta >= 1.1 * gd.DAMPING_RATIO
    speed = d.figures['terminal_speed_rad_s']
    ceiling = d.figures['speed_ceiling_rad_s']
    assert np.all(speed[over] <= 1.01 * ceiling[over])
    held = over & (d.figures['carry_damping_nms'] == 0.0)
    np.testing.assert_allclose(speed[held], ceiling[held], rtol=1e-2)


def test_spectral_radius_of_a_sampled_mass_spring_damper():
    """1 kg, 1 ms: stable with one tick of delay for modest gains, unstable when too stiff."""
    m, k, c = np.array([[1.0]]), np.array([[100.0]]), np.array([[2.0 * 10.0]])
    rho = ga.spectral_radius(m, k, c, 1)
    assert rho < 1.0 and ga.time_constant_s(rho) == pytest.approx(0.1, rel=0.2)
    assert ga.spectral_radius(m, np.array([[4e6]]), np.array([[0.0]]), 1) > 1.0
    assert ga.largest_stable_damping(1.0, (1,), 1e-3) == pytest.approx(1000.0, rel=1e-3)


def test_the_limit_band_stops_what_the_damping_brakes_at_the_speed_ceiling(designs):
    """
    At the stop the band holds 1.5 x the task bound, or K_v x 0.8 x the velocity limit if more.

    Within the budget and the effort left after gravity, and lower only where the joint's
    sampled mass-spring-damper would be unstable: a joint the others carry into its band is
    stopped there (docs/gain_design.md, section 5).
    """
    for name in ('xarm6', 'panda'):
        model, d = designs[name]
        f = d.figures
        at_stop, bound, kv = f['limit_at_stop_nm'], f['task_bound_nm'], np.array(d.kv)
        wanted = np.maximum(gd.LIMIT_OVER_TASK * bound,
                            np.minimum(f['budget_nm'],
                                       gd.SPEED_MARGIN * f['velocity_limits_rad_s'] * kv))
        wanted = np.minimum(wanted, f['effort_limits_nm'] - f['gravity_reserve_nm'])
        limited = at_stop > 0.0
        assert limited.sum() >= 3, name
        assert np.all(at_stop[limited] <= wanted[limited] * (1.0 + 1e-3)), name
        # the damping's share is the larger on these arms' joints: the band is stiffer than
        # the task bound alone asked
        assert np.all(at_stop[limited] > 1.5 * gd.LIMIT_OVER_TASK * bound[limited]), name


@pytest.mark.parametrize('name, args', [('wrist_controller.yaml', WRIST_ARGS),
                                        ('xarm6_controller.yaml', XARM6_ARGS),
                                        ('panda_controller.yaml', PANDA_ARGS)])
def test_the_configs_are_what_the_tool_writes(tmp_path, name, args):
    out = tmp_path / name
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design', *args,
                             '--out', str(out)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    written = params_of(out.read_text())
    shipped = params_of((REPO / 'config' / name).read_text())
    assert written == shipped
    text = (REPO / 'config' / name).read_text()
    assert 'python -m quat_jt_controller.gain_design' in text  # how to reproduce it
    # the extensions are on in the product configs
    s = sh.from_parameters(shipped, len(shipped['joints']))
    assert s.limits_on and s.friction_on and s.configuration_on and s.speed_damping_on


def test_the_paper_config_is_the_paper_experiment():
    p = params_of((REPO / 'config' / 'paper_wrist_controller.yaml').read_text())
    assert tuple(p['kp']) == (4.5, 20.5, 17.5) and tuple(p['lambda']) == (30.0, 30.0, 30.0)
    assert tuple(p['kv']) == (1.0, 1.0, 1.0)
    assert sh.from_parameters(p, 3) == sh.Shaping.create(3)  # no extension on


def test_the_command_prints_a_loadable_file_and_the_design_parameters_match():
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design',
                             '--potential', 'quadratic'], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    p = params_of(result.stdout)
    assert p['potential'] == 'quadratic' and p['task'] == 'orientation'
    gains = cl.Gains.create(p['potential'], p['kp'], p['kv'], p['lambda'], cl.Task(p['task']),
                            3)
    assert len(gains.kv) == 3
    for key, value in p.items():  # strictly typed: floats are written as floats
        values = value if isinstance(value, list) else [value]
        if key in ('joints', 'publish_rate_divider', 'gravity_compensation', 'task',
                   'potential', 'base_link', 'tip_link', 'robot_description',
                   'gain_redesign', 'design_options'):
            continue
        assert all(isinstance(v, float) for v in values), (key, value)


def test_a_payload_given_to_the_design_is_in_its_file_and_in_the_controller_it_makes(
        tmp_path):
    """--payload-mass/--payload-com: the design's g(q), the header, the controller, the sim."""
    from quat_jt_controller.controller_config import controller_from_config
    sim = tmp_path / 'sim.yaml'
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design',
                             '--payload-mass', '0.3', '--payload-com', '0', '0', '0.05',
                             '--sim-out', str(sim)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    simulated = params_of(sim.read_text())
    assert (simulated['payload_link'], simulated['payload_mass'],
            simulated['payload_com']) == ('tool0', 0.3, [0.0, 0.0, 0.05])
    p = params_of(result.stdout)
    assert p['payload_mass'] == 0.3 and p['payload_com'] == [0.0, 0.0, 0.05]
    header = ' '.join(line.lstrip('# ') for line in result.stdout.splitlines()
                      if line.startswith('#'))
    assert 'payload 0.3 kg at [0.0, 0.0, 0.05] m in tool0' in header
    loaded = controller_from_config(p, default_urdf_xml()).model
    plain = wrist_model()
    q = [0.3, 0.8, -0.5]
    assert loaded.payload_kg == 0.3
    assert np.linalg.norm(np.subtract(loaded.gravity(q), plain.gravity(q))) > 0.01
    refused = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design',
                              '--payload-mass', '-1'], capture_output=True, text=True,
                             timeout=120)
    assert refused.returncode == 2
    assert '--payload-mass must be finite and >= 0 kg, got -1.0' in refused.stderr
    refused = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design',
                              '--payload-com', '0', 'nan', '0'], capture_output=True,
                             text=True, timeout=120)  # checked with no mass too
    assert refused.returncode == 2 and '--payload-com must be 3 finite numbers' in refused.stderr


def test_the_design_warns_of_estimates_the_urdf_does_not_support():
    model = xarm6_model()  # <dynamics friction="1.0"/> on every joint
    assert model.friction_nm == (1.0,) * 6
    ok = gd.friction_warnings(model, np.full(6, 0.5), np.full(6, 0.5))
    assert ok == []
    high = gd.friction_warnings(model, np.array([1.5, 0.5, 0.5, 0.5, 0.5, 0.5]),
                                np.full(6, 0.5))
    assert len(high) == 1 and high[0].startswith('joint1: the friction estimate 1.5 N m is '
                                                 "above the URDF's 1 N m")
    unknown = gd.friction_warnings(wrist_model(), np.array([1.8, 0.72, 0.45]), np.zeros(3))
    assert len(unknown) == 1 and 'cannot be checked' in unknown[0]
    assert gd.friction_warnings(wrist_model(), np.zeros(3), np.zeros(3)) == []


def test_the_design_warns_of_velocity_limits_no_drive_has():
    """A velocity limit of 100 rad/s (iCub's) is named a placeholder; 6.28 rad/s is not."""
    stock = gd.design(wrist_model(), cl.Task.ORIENTATION)
    assert not [w for w in stock.figures['warnings'] if w.startswith('velocity limits')]
    urdf = default_urdf_xml()
    placeholder = urdf.replace('effort="30.0" velocity="6.2832"', 'effort="30.0" velocity="100"')
    assert placeholder != urdf
    fast = gd.design(RobotModel(placeholder, 'base_link', 'tool0'), cl.Task.ORIENTATION)
    warned = [w for w in fast.figures['warnings'] if w.startswith('velocity limits')]
    assert len(warned) == 1 and 'joint2 (100 rad/s)' in warned[0]
    assert 'joint1' not in warned[0] and 'joint3' not in warned[0]


def test_the_design_and_the_node_warn_of_joints_without_a_velocity_limit():
    """Velocity 0 in a URDF (a CAD export writes it) says none: designed for 2 pi, unguarded."""
    from quat_jt_controller.diagnostics import start_warnings
    from quat_jt_controller.regulator import Regulator
    stock = gd.design(wrist_model(), cl.Task.ORIENTATION)
    assert not [w for w in stock.figures['warnings'] if w.startswith('no velocity limit')]
    assert start_warnings(Regulator(wrist_model(), cl.Task.ORIENTATION, stock.gains())) == []
    urdf = default_urdf_xml()
    unlimited = urdf.replace('effort="30.0" velocity="6.2832"', 'effort="30.0" velocity="0"')
    assert unlimited != urdf
    model = RobotModel(unlimited, 'base_link', 'tool0')
    design = gd.design(model, cl.Task.ORIENTATION)
    warned = [w for w in design.figures['warnings'] if w.startswith('no velocity limit')]
    assert len(warned) == 1 and ': joint2.' in warned[0] and '6.28 rad/s' in warned[0]
    assert design.figures['velocity_limits_rad_s'][1] == pytest.approx(gd.DEFAULT_VELOCITY)
    at_start = start_warnings(Regulator(model, cl.Task.ORIENTATION, design.gains()))
    assert len(at_start) == 1 and "['joint2']" in at_start[0]


def test_the_learnable_friction_comes_out_of_the_budget():
    model = wrist_model()
    friction = [1.8, 0.72, 0.45]
    plain = gd.design(model, cl.Task.ORIENTATION, friction_nm=friction, friction_learning=0.0,
                      friction_effort_share=0.0)
    learning = gd.design(model, cl.Task.ORIENTATION, friction_nm=friction,
                         friction_effort_share=0.0)
    assert learning.shaping.friction_learning_limit_nm == pytest.approx(
        [gd.FRICTION_LEARNING * f for f in friction])
    assert plain.shaping.friction_learning_limit_nm == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(plain.figures['budget_nm'] - learning.figures['budget_nm'],
                               gd.TORQUE_SHARE * gd.FRICTION_LEARNING * np.array(friction))
    with pytest.raises(ValueError, match='friction_learning'):
        gd.design(model, cl.Task.ORIENTATION, friction_nm=friction, friction_learning=-1.0)


def test_an_arm_that_cannot_hold_itself_everywhere_is_designed_with_a_warning():
    """Gravity past the effort limit in some configurations: warned, not refused."""
    model = xarm6_model()  # joint2 needs up to 25.3 N m against gravity within its limits
    stock = gd.design(model, cl.Task.POSE)
    assert not [w for w in stock.figures['warnings'] if w.startswith('gravity')]
    weak = gd.design(model, cl.Task.POSE, effort_limits_nm=[50.0, 20.0, 32.0, 32.0, 32.0, 20.0])
    warned = [w for w in weak.figures['warnings'] if w.startswith('gravity takes more')]
    assert len(warned) == 1 and 'joint2 (up to 25.3 N m of its 20;' in warned[0], warned
    assert 'joint1' not in warned[0] and 'joint3' not in warned[0]
    # only the reserve, 0.75 x 20 N m, is spoken for: the budget is what is left of the rest
    assert 0.0 < weak.figures['budget_nm'][1] <= gd.TORQUE_SHARE * (
        20.0 * (1.0 - gd.GRAVITY_RESERVE_SHARE))
    np.testing.assert_allclose(weak.figures['budget_nm'][2:], stock.figures['budget_nm'][2:])
    with pytest.raises(ValueError, match=r'cannot hold itself up in most of its configurations: '
                       r"joints \['joint2'\] need more") as refused:
        gd.design(model, cl.Task.POSE, effort_limits_nm=[50.0, 5.0, 32.0, 32.0, 32.0, 20.0])
    assert 'An arm that a spring or a counterweight holds up' in str(refused.value)


def test_a_goal_configuration_gain_held_below_the_factor_is_named():
    model = wrist_model()
    bound = np.array([1.0, 1.0, 1.0])
    assert gd.guide_warnings(model, gd.GUIDE_OVER_TASK * bound, bound) == []
    warned = gd.guide_warnings(model, np.array([2.0, 1.5, 3.0]), bound)
    assert len(warned) == 1 and 'on joint2 (1.50 x) to keep the sampled loop' in warned[0]


def test_the_simulator_config_is_what_the_tool_writes(tmp_path):
    """config/panda_sim.yaml comes from the same command as the controller's, for its joints."""
    out, sim_out = tmp_path / 'c.yaml', tmp_path / 's.yaml'
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design',
                             *PANDA_ARGS, *PANDA_SIM_ARGS, '--out', str(out), '--sim-out',
                             str(sim_out)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    shipped = params_of((REPO / 'config' / 'panda_sim.yaml').read_text())
    assert params_of(sim_out.read_text()) == shipped
    assert tuple(shipped['joints']) == PANDA_JOINTS  # the fingers are held, not driven
    assert shipped['enforce_velocity_limits'] is True
    with pytest.raises(ValueError, match='outside the limits'):  # joint 4 lies in [-3.14, 0]
        go.sim_yaml(panda_model(), 1000.0, [0.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0], None, None)
    with pytest.raises(ValueError, match='--sim-coulomb: expected 7'):
        go.sim_yaml(panda_model(), 1000.0, None, [0.1] * 6, None)


def test_a_strong_joint_is_not_held_to_the_pace_of_the_weakest(designs):
    """
    The Panda's task bound is set by its 12 N m wrist; the 87 N m joints get a larger T_j.

    Raised only as far as their budget allows, so both terms still fit in it, and still at
    least GUIDE_OVER_TASK x the task bound, so the argument of docs/lyapunov.md, section 5
    holds.
    """
    model, d = designs['panda']
    f = d.figures
    guide, bound = f['guide_nm'], f['task_bound_nm']
    assert np.all(guide >= gd.GUIDE_OVER_TASK * bound - 1e-9)
    strong = [0, 2, 3]  # joints 1, 3 and 4 (joint 2 lifts the arm: gravity takes its budget)
    assert np.all(guide[strong] > 1.5 * gd.GUIDE_OVER_TASK * bound[strong])
    assert np.all(bound + guide <= f['budget_nm'] + 1e-9)
    assert np.all(f['terminal_speed_rad_s'] <= f['velocity_limits_rad_s'])
    # the default aims at 0.6 of the limits: the strong joints are raised less
    slower = gd.design(model, cl.Task.POSE, friction_nm=(0.09,) * 4 + (0.045,) * 3,
                       delays=(1, 2))
    assert np.all(slower.figures['guide_nm'][strong] <= guide[strong])
    assert np.any(slower.figures['guide_nm'][strong] < guide[strong])
    with pytest.raises(ValueError, match='cruise_fraction'):
        gd.design(model, cl.Task.POSE, cruise_fraction=1.5)
    with pytest.raises(ValueError, match='within the joint limits'):  # the node would refuse it
        gd.design(model, cl.Task.POSE,
                  preferred_configuration_rad=[0.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0])


def test_a_bad_simulator_argument_writes_neither_file(tmp_path):
    out, sim_out = tmp_path / 'c.yaml', tmp_path / 's.yaml'
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design',
                             *PANDA_ARGS, '--out', str(out), '--sim-out', str(sim_out),
                             '--sim-coulomb', '0.1'], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2 and result.stderr == (
        f'design_gains: error: --sim-coulomb: 1 value for the 7 joints {list(PANDA_JOINTS)} '
        '(see design_gains --help)\n')
    assert not out.exists() and not sim_out.exists()


def run_main(argv, capsys) -> tuple[int, list[str]]:
    """Run the command's main() in this process; return its status and stderr lines."""
    try:
        status = gd.main(argv)
    except SystemExit as exc:
        status = exc.code
    return status, capsys.readouterr().err.splitlines()


def test_a_urdf_without_links_given_gets_its_longest_chain_and_says_so(tmp_path, capsys):
    """A whole robot's URDF: the root, the end of the longest chain, the joints between."""
    urdf = small_arm_urdf(('revolute',) * 4).replace('</robot>', (
        '<link name="side"/><joint name="side_joint" type="revolute"><parent link="link1"/>'
        '<child link="side"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="5" '
        'velocity="3"/></joint></robot>'))
    path = tmp_path / 'robot.urdf'
    path.write_text(urdf)
    out = tmp_path / 'robot.yaml'
    code, lines = run_main(['--urdf', str(path), '--task', 'orientation', '--out', str(out)],
                           capsys)
    assert code == 0, lines
    assert lines[0] == ("design_gains: --base-link base_link (the URDF's root link); --tip-link "
                        'tool (the end of its longest chain of revolute joints); --joints joint1 '
                        'joint2 joint3 tool (the movable joints between them)'), lines
    params = params_of(out.read_text())
    assert params['joints'] == ['joint1', 'joint2', 'joint3', 'tool']  # not side_joint
    assert (params['base_link'], params['tip_link']) == ('base_link', 'tool')
    code, lines = run_main(['--urdf', str(path), '--tip-link', 'side', '--out', str(out)],
                           capsys)
    assert code == 1 and lines[-1].startswith('design_gains: error: no design: M(q) is '
                                              'singular at q = '), lines  # a massless link
    assert "joints ['side_joint'] move no inertia there" in lines[-1], lines
    code, lines = run_main(['--urdf', str(path), '--base-link', 'link2', '--out', str(out)],
                           capsys)  # the longest chain below the base given
    assert code == 0 and lines[0] == ('design_gains: --tip-link tool (the end of its longest '
                                      'chain of revolute joints); --joints joint3 tool (the '
                                      'movable joints between them)'), lines
    code, lines = run_main(['--urdf', str(path), '--base-link', 'side', '--out', str(out)],
                           capsys)
    assert code == 2 and "no revolute or continuous joint below link 'side'" in lines[0], lines
    code, lines = run_main(['--urdf', str(path), '--base-link', 'side', '--tip-link', 'tool',
                            '--out', str(out)], capsys)
    assert code == 2 and "link 'tool' is not below link 'side'" in lines[0], lines
    lift = tmp_path / 'lift.urdf'  # a torso lift under the arm: said, and how to leave it out
    lift.write_text(small_arm_urdf(('prismatic', 'revolute', 'revolute', 'revolute')))
    _, lines = run_main(['--urdf', str(lift), '--out', str(out)], capsys)
    assert lines[0].endswith('--joints joint1 joint2 joint3 tool (the movable joints between '
                             'them); of them joint1 slide: the goal-configuration ramp '
                             '(configuration_ramp) is metres for them, and a slow lift makes a '
                             'slow arm. To regulate the arm alone (as an arm controller does), '
                             'give --base-link link1'), lines


def test_a_position_task_takes_the_point_fixed_below_the_last_link(tmp_path, capsys):
    """A fingertip or a foot fixed below the last link: the point a position task means."""
    tip = ('<link name="tip"/><joint name="tip_joint" type="fixed"><parent link="tool"/>'
           '<child link="tip"/><origin xyz="0.1 0 0"/></joint>')
    path = tmp_path / 'finger.urdf'
    path.write_text(small_arm_urdf(('revolute',) * 3).replace('</robot>', tip + '</robot>'))
    out = tmp_path / 'finger.yaml'
    code, lines = run_main(['--urdf', str(path), '--task', 'position', '--out', str(out)],
                           capsys)
    assert code == 0, lines
    assert ('--tip-link tip (the end of its longest chain of revolute joints, and the fixed '
            'links below tool: a position task regulates a point, such as a fingertip or a '
            'foot)') in lines[0], lines
    assert params_of(out.read_text())['tip_link'] == 'tip'
    code, lines = run_main(['--urdf', str(path), '--task', 'pose', '--out', str(out)], capsys)
    assert '--tip-link tool (the end of its longest chain of revolute joints)' in lines[0]
    # a fork below (two fixed links) leaves the tip where it was
    fork = tip.replace('"tip"', '"tip2"').replace('tip_joint', 'tip2_joint')
    path.write_text(small_arm_urdf(('revolute',) * 3).replace('</robot>', tip + fork
                                                              + '</robot>'))
    code, lines = run_main(['--urdf', str(path), '--task', 'position', '--out', str(out)],
                           capsys)
    assert '--tip-link tool (the end of its longest chain of revolute joints)' in lines[0]


def test_a_urdf_without_effort_limits_or_ranges_is_refused_by_name(tmp_path, capsys):
    """Effort 0 (none given) and a revolute joint's unset range [0, 0], as URDFs come."""
    urdf = small_arm_urdf(('revolute',) * 4)
    path = tmp_path / 'arm.urdf'
    path.write_text(urdf.replace('effort="10.0"', 'effort="0"'))  # joint2's
    code, lines = run_main(['--urdf', str(path), '--task', 'position'], capsys)
    assert code == 1 and ("joints ['joint2'] have no effort limit ([0.0] N m; 0 or absent in "
                          'a URDF means none given)') in lines[-1], lines
    assert '--effort-limits' in lines[-1]
    code, lines = run_main(['--urdf', str(path), '--task', 'position', '--effort-limits',
                            '20', '10', '6', '5'], capsys)
    assert code == 0, lines  # given on the command line instead
    path.write_text(urdf.replace('lower="-2" upper="2"', 'lower="0" upper="0"', 1))
    code, lines = run_main(['--urdf', str(path), '--task', 'position'], capsys)
    assert code == 1 and "joints ['joint1'] have an empty range ([(0.0, 0.0)]" in lines[-1], lines


@pytest.mark.parametrize('argv, status, words', [
    (['--urdf', 'no/such.urdf'], 2, '--urdf no/such.urdf: No such file or directory'),
    (['--urdf', '.'], 2, '--urdf .: Is a directory'),
    (['--urdf', 'setup.py'], 2, '--urdf setup.py: not XML'),
    (['--urdf', 'package.xml'], 2, 'not a URDF (its root element is <package>'),
    (['--joints', 'joint1', 'jointX', 'joint3'], 2, "joints ['jointX'] are not movable"),
    (['--tip-link', 'nowhere'], 2, "link 'nowhere' is not in the URDF"),
    (['--effort-limits', '50', '30'], 2, "--effort-limits: 2 values for the 3 joints ['joint1'"),
    (['--friction', '1'], 2, '--friction: 1 value for the 3 joints'),
    (['--preferred-configuration', '0', '9', '0'], 2, "puts ['joint2'] outside the joint"),
    (['--rate', 'fast'], 2, "argument --rate: 'fast' is not a number"),
    (['--rate', '0'], 2, '--rate 0.0 Hz is outside [100, 1000] Hz'),
    (['--effort-limits', 'nan', '1', '1'], 2, 'argument --effort-limits: nan is not a finite'),
    (['--delays', '-1'], 2, 'argument --delays: -1 is not an integer in [0, inf)'),
    (['--cruise-fraction', '1.5'], 2, 'argument --cruise-fraction: 1.5 is not a finite number '
     'in (0, 1]'),
    (['--approach-time', '0'], 2, 'argument --approach-time: 0 is not a finite number in '
     '(0, inf)'),
    (['--task', 'velocity'], 2, "argument --task: invalid choice: 'velocity'"),
    (['--task', 'position'], 1, 'the position task Jacobian is singular'),
    (['--effort-limits', '0.1', '0.1', '0.1'], 1, 'no design: the arm cannot hold itself up '
     "in most of its configurations: joints ['joint2'] need more than their effort limits"),
    (['--effort-limits', '0.1', '0.1', '0.1'], 1, 'check the effort limits of the URDF, and '
     'that gravity is along -z of the base link'),
    (['--friction', '40', '1', '1'], 1, "no torque left for the potential on joints ['joint1']"),
    (['--out', 'no/such/folder/x.yaml'], 1, 'cannot write no/such/folder/x.yaml: No such file'),
])
def test_a_bad_input_is_one_line_naming_it(argv, status, words, capsys, monkeypatch):
    """Usage errors: status 2, as argparse's own; a robot the rules cannot serve: 1."""
    monkeypatch.chdir(REPO)
    code, lines = run_main(argv, capsys)
    assert code == status and len(lines) == 1, (code, lines)
    assert lines[0].startswith('design_gains: error: ') and words in lines[0], lines


def test_the_command_line_gives_one_line_and_status_2_for_a_missing_urdf(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design', '--urdf',
                             str(tmp_path / 'robot.urdf')], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2 and result.stdout == ''
    assert result.stderr == (f'design_gains: error: --urdf {tmp_path / "robot.urdf"}: No such '
                             'file or directory (see design_gains --help)\n')


def test_a_design_at_100_hz_is_stable_where_the_1_khz_one_is_not():
    """The sampled loop at the rate given: the 1 kHz gains with 10 ms ticks diverge."""
    model = wrist_model()
    task = cl.Task.ORIENTATION
    configs = gd.survey(model, task)['configurations']

    def worst(d):
        return max(ga.linearized_spectral_radius(model, q, d.gains('tanh'), 1, 0.01, M, task,
                                                 d.shaping) for q, _, M in configs)
    slow = gd.design(model, task, rate_hz=100.0)
    assert slow.rate_hz == 100.0 and 'state_rate: 100.0' in go.to_yaml(slow)
    assert worst(slow) < 1.0 < worst(gd.design(model, task, rate_hz=1000.0))


@pytest.mark.parametrize('rate', [50.0, 2000.0, float('nan')])
def test_a_rate_outside_100_to_1000_hz_is_refused_by_value(rate):
    with pytest.raises(ValueError, match=f'rate_hz {rate!r} Hz is outside'):
        gd.design(wrist_model(), cl.Task.ORIENTATION, rate_hz=rate)
    result = subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design', '--rate',
                             str(rate)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and f'--rate {rate!r} Hz is outside' in result.stderr
    assert 'Traceback' not in result.stderr


def test_rotor_inertia_enters_the_design_through_the_inertia():
    """With armature, each joint sees more inertia, so K_v grows (the same damping ratio)."""
    plain = gd.design(wrist_model(), cl.Task.ORIENTATION, friction_nm=(1.8, 0.72, 0.45))
    armature = (0.2, 0.2, 0.2)
    rotor_model = RobotModel(default_urdf_xml(), 'base_link', 'tool0', armature=armature)
    rotor = gd.design(rotor_model, cl.Task.ORIENTATION, friction_nm=(1.8, 0.72, 0.45))
    # the inertia each joint sees is the links' plus at least its rotor
    assert np.all(rotor.figures['inertia_min']
                  >= plain.figures['inertia_min'] + 0.99 * np.array(armature))
    assert all(b > a for a, b in zip(plain.kv, rotor.kv))  # more inertia, more damping
    assert rotor.armature == armature and plain.armature == (0.0, 0.0, 0.0)
    assert max(rotor.figures['spectral_radius'].values()) < 1.0
    assert params_of(go.to_yaml(rotor))['armature'] == list(armature)
    assert params_of(go.to_yaml(plain))['armature'] == [0.0, 0.0, 0.0]


def test_the_command_takes_one_armature_for_all_joints_or_one_per_joint(tmp_path):
    def run(*args):
        return subprocess.run([sys.executable, '-m', 'quat_jt_controller.gain_design', *args],
                              capture_output=True, text=True, timeout=120)

    one, each = run('--armature', '0.1'), run('--armature', '0.1', '0.1', '0.1')
    assert one.returncode == 0 and each.returncode == 0, one.stderr + each.stderr
    assert params_of(one.stdout)['armature'] == [0.1, 0.1, 0.1]
    assert params_of(one.stdout)['kv'] == params_of(each.stdout)['kv']
    wrong = run('--armature', '0.1', '0.2')
    assert wrong.returncode == 2
    assert '--armature: give one value for every joint or 3 (one per joint), got 2' in (
        wrong.stderr)
    negative = run('--armature', '-0.1')
    assert negative.returncode == 2 and 'armature[0] must be finite and >= 0, got -0.1' in (
        negative.stderr)
    sim_out = tmp_path / 's.yaml'
    both = run('--armature', '0.1', '--sim-out', str(sim_out), '--sim-engine', 'mujoco',
               '--out', str(tmp_path / 'c.yaml'))
    assert both.returncode == 0, both.stderr
    sim = params_of(sim_out.read_text())  # the simulated rotor defaults to the designed one
    assert sim['armature'] == [0.1, 0.1, 0.1] and sim['engine'] == 'mujoco'


def test_the_simulator_engines_are_the_ones_the_tool_writes():
    from wrist_sim.simulator import ENGINES
    assert go.ENGINES == ENGINES


def test_with_no_friction_estimate_a_share_of_the_effort_may_be_learned():
    model = wrist_model()
    unmeasured = gd.design(model, cl.Task.ORIENTATION)  # the default: a share is learnable
    effort = np.array(model.effort_limits)
    # the wrist is heavy enough that one tick of the share moves it far less than its limit
    np.testing.assert_allclose(unmeasured.shaping.friction_learning_limit_nm,
                               gd.FRICTION_EFFORT_SHARE * effort)
    assert unmeasured.shaping.friction_compensation_nm == (0.0, 0.0, 0.0)
    none = gd.design(model, cl.Task.ORIENTATION, friction_effort_share=0.0)
    assert none.shaping.friction_learning_limit_nm == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(none.figures['budget_nm'] - unmeasured.figures['budget_nm'],
                               gd.TORQUE_SHARE * gd.FRICTION_EFFORT_SHARE * effort)
    with pytest.raises(ValueError, match='friction_effort_share'):
        gd.design(model, cl.Task.ORIENTATION, friction_effort_share=0.6)


def test_on_a_light_joint_the_learnable_push_moves_it_less_than_its_limit_in_a_tick():
    """One tick of the whole learnable push changes a joint's speed by at most the share."""
    model = _xarm7()  # no rotor inertia: a wrist of ~1e-4 kg m^2 on a 20 N m drive
    rate_hz = 1000.0
    d = gd.design(model, cl.Task.POSE, rate_hz)
    limit = np.array(d.shaping.friction_learning_limit_nm)
    effort = np.array(model.effort_limits)
    velocity = np.array(model.velocity_limits)
    inertia = d.figures['inertia_min']
    speed_change = limit / inertia / rate_hz
    assert np.all(speed_change <= gd.TICK_SPEED_SHARE * velocity * (1.0 + 1e-9))
    assert np.all(limit <= gd.FRICTION_EFFORT_SHARE * effort * (1.0 + 1e-9))
    assert np.any(limit < gd.FRICTION_EFFORT_SHARE * effort)  # the bound binds somewhere
    assert np.all(limit > 0.0)


def _xarm7(armature=None):
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('xarm_description/urdf/xarm7.urdf').read_text()
    model = RobotModel(urdf, 'link_base', 'link7')
    return model if armature is None else RobotModel(urdf, 'link_base', 'link7', None,
                                                     [armature] * model.n)


def test_a_light_wrist_does_not_collapse_the_task_gains():
    """The xArm7's last link sees ~1.3e-4 kg m^2: its joint gets what it takes, not the rows."""
    light = gd.design(_xarm7(), cl.Task.POSE)
    geared = gd.design(_xarm7(0.1), cl.Task.POSE)
    assert min(light.figures['inertia_min']) < 1e-3
    # the position rows keep a useful share of what they get with the drives' inertia
    assert light.kp[0] > 0.1 * geared.kp[0]
    bound = light.figures['task_bound_nm']
    assert max(bound) > 0.01 * max(light.figures['budget_nm'])
    for d in (light, geared):  # the expected speeds stay within the URDF velocity limits
        assert np.all(d.figures['terminal_speed_rad_s'] < d.figures['velocity_limits_rad_s'])
        assert 0.0 < d.figures['time_to_goal_s'] < 10.0
    assert any('--armature' in w for w in light.figures['warnings'])
    assert not any('--armature' in w for w in geared.figures['warnings'])
    # its friction learning is held below the 3% of the effort asked, and it says so
    held = [w for w in light.figures['warnings'] if 'may learn' in w]
    assert len(held) == 1 and 'joint7' in held[0] and 'joint1 ' not in held[0]
    assert not any('may learn' in w for w in geared.figures['warnings'])
    assert 'Expected time to a goal' in go.to_yaml(light)


def test_the_design_checks_the_damping_the_tick_applies_its_fast_modes_capped(monkeypatch):
    """
    docs/gain_design.md, section 4: the design's linearised checks see the tick's damping.

    The G1's left arm (example-robot-data, from its torso): each joint's inertial damping is
    within what the loop takes on the inertia that joint sees, but M(q) couples them into
    modes faster than beta. The tick brings each such mode down to beta (docs/lyapunov.md,
    section 10), and so does the design's model of it (gain_analysis.joint_damping_matrix):
    the damping alone is then stable with the margins, and K_p keeps a useful share of the
    budget. Checked on the uncapped diagonal, the design runs K_p down more than 100 times.
    """
    from quat_jt_runtime.joints import chain_joints
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('g1_description/urdf/g1_29dof_rev_1_0.urdf').read_text()
    model = RobotModel(urdf, 'torso_link', 'left_wrist_yaw_link',
                       chain_joints(urdf, 'torso_link', 'left_wrist_yaw_link'))
    d = gd.design(model, cl.Task.POSE)
    delays, dt_s = d.figures['delays'], 1.0 / d.rate_hz
    assert max(d.figures['spectral_radius'].values()) < 1.0
    beta = d.shaping.inertial_damping_rate_per_s
    assert beta == pytest.approx(gd.inertial_damping_rate(delays, dt_s), rel=1e-3)
    assert max(d.figures['task_bound_nm']) > 0.01 * max(d.figures['budget_nm'])
    configs = gd.survey(model, cl.Task.POSE)['configurations']
    c = np.array(d.shaping.inertial_damping)
    fastest = 0.0
    for _, _, M in configs:
        capped = ga.joint_damping_matrix(d.kv, c, beta, M)
        rates = np.linalg.eigvals(np.linalg.solve(M, capped)).real
        assert rates.max() <= beta * (1.0 + 1e-9)
        diagonal = np.diag(ga.damping_at(d.kv, c, beta, M))
        fastest = max(fastest, np.linalg.eigvals(np.linalg.solve(M, diagonal)).real.max())
        for scale, k in ga.margin_cases(delays):
            assert ga.coupled_damper_spectral_radius(M, scale * capped, [k], dt_s) < 1.0
    assert fastest > 1.5 * beta, 'M(q) must couple the damping into faster modes'
    monkeypatch.setattr(ga, 'joint_damping_matrix',
                        lambda kv, c, rate, M: np.diag(ga.damping_at(kv, c, rate, M)))
    uncapped = gd.design(model, cl.Task.POSE)
    assert d.kp[0] > 100.0 * uncapped.kp[0] and d.kp[3] > 100.0 * uncapped.kp[3]


def test_the_damping_alone_of_two_coupled_joints_is_checked_on_m():
    """A damping each joint takes on the inertia it sees may not be taken coupled by M."""
    M = np.array([[1.0, 0.9], [0.9, 1.0]])
    seen = ga.seen_inertia(M)
    dt_s = 1e-3
    per_joint = [ga.largest_stable_damping(i, [1], dt_s) for i in seen]
    for j in range(2):  # each alone, on the inertia it sees: stable just below its bound
        assert ga.damper_spectral_radius(seen[j], 0.99 * per_joint[j], [1], dt_s) < 1.0
    # both at once through M: the speeds' modes are M^-1 D's eigenvalues, not its diagonal
    both = ga.coupled_damper_spectral_radius(M, np.diag(0.99 * np.array(per_joint)), [1], dt_s)
    assert both > 1.0
    assert ga.coupled_damper_spectral_radius(M, np.diag(0.4 * np.array(per_joint)), [1],
                                             dt_s) < 1.0


def test_the_carried_speed_is_the_lag_of_a_joint_behind_the_others_push():
    """No coupling, no carried speed; a heavy and a light joint: a lag, by hand."""
    kv, push = np.array([2.0, 0.5]), np.array([3.0, 1.0])
    diagonal = [(None, None, np.diag([1.0, 0.01]))]
    np.testing.assert_array_equal(ga.carried_speed(diagonal, kv, push), [0.0, 0.0])

    def by_hand(M: np.ndarray) -> np.ndarray:
        inverse = np.linalg.inv(M)
        tau = 1.0 / (np.diag(inverse) * kv)  # I_j / k_v,j
        lag = tau[0] * tau[1] / (tau[0] + tau[1])
        return np.array([abs(inverse[0, 1]) * push[1] * lag,
                         abs(inverse[1, 0]) * push[0] * lag])

    weak = np.array([[1.0, -0.03], [-0.03, 0.01]])  # a negative coupling counts as much
    strong = np.array([[1.0, 0.09], [0.09, 0.01]])  # the light joint nearly carried whole
    assert np.all(by_hand(strong) > by_hand(weak)) and np.all(by_hand(weak) > 0.0)
    np.testing.assert_allclose(ga.carried_speed([(None, None, weak)], kv, push),
                               by_hand(weak))
    np.testing.assert_allclose(  # the largest over the configurations
        ga.carried_speed([(None, None, weak), (None, None, strong), diagonal[0]], kv, push),
        by_hand(strong))
    # the light joint is the one carried: (M^-1)_10 push_0 lag = 47.4 x 3 x 3.65e-3 rad/s
    carried = ga.carried_speed([(None, None, strong)], kv, push)
    assert carried[1] == pytest.approx(0.519, rel=1e-3) and carried[1] > 2.0 * carried[0]


def test_a_joint_the_arm_would_carry_past_its_limit_gets_more_damping(monkeypatch):
    """The xArm7 without rotor inertia: its light joint5/joint6 are thrown by the arm."""
    model = _xarm7()
    held = gd.design(model, cl.Task.POSE)
    limits = held.figures['velocity_limits_rad_s']
    monkeypatch.setattr(gd, 'CARRIED_SPEED_SHARE', np.inf)  # the rule off
    free = gd.design(model, cl.Task.POSE)
    raised = np.flatnonzero(np.array(held.kv) > 1.05 * np.array(free.kv))
    assert set(raised) >= {4, 5}, (held.kv, free.kv)
    assert np.all(free.figures['carried_speed_rad_s'][raised] > limits[raised])
    # held to the limit (within the step of the rule and the rounding of what is written), or
    # the damping as high as the rule raises it (the sampled loop's b_max, a share of it)
    over = held.figures['carried_speed_rad_s'] > 1.05 * limits
    top = gd.SPEED_DAMPING_SHARE * held.figures['damping_max_nms']
    assert np.all(np.array(held.kv)[over] >= 0.99 * top[over]), (over, held.kv, top)
    # the joints keep their linear pace, push / K_v (within the 10% steps the goal-configuration
    # gain grows by), and so the cruise: that gain grows with the damping
    pace = {name: (d.figures['task_bound_nm'] + d.figures['guide_nm'])[raised]
            / np.array(d.kv)[raised] for name, d in (('held', held), ('free', free))}
    assert np.all(pace['held'] >= 0.9 * pace['free']), pace
    assert np.all(held.figures['guide_nm'][raised] > free.figures['guide_nm'][raised])
    cruise = gd.CRUISE_FRACTION * limits[raised]
    assert np.all(held.figures['terminal_speed_rad_s'][raised] >= 0.99 * np.minimum(
        cruise, free.figures['terminal_speed_rad_s'][raised]))
    geared = gd.design(_xarm7(0.1), cl.Task.POSE)  # with the drives' inertia: nothing to hold
    assert np.all(geared.figures['carried_speed_rad_s'] <= limits)


def test_a_sliding_joint_is_left_out_of_the_carried_speed_rule():
    """The torso lift of TIAGo under its arm: over its limit by the estimate, its K_v as is."""
    from robots import example_robot_data_urdf
    urdf = example_robot_data_urdf('tiago_description/robots/tiago_no_hand.urdf').read_text()
    joints = ['torso_lift_joint'] + [f'arm_{i}_joint' for i in range(1, 8)]
    model = RobotModel(urdf, 'base_footprint', 'arm_7_link', joints)
    assert model.prismatic == (True,) + (False,) * 7
    d = gd.design(model, cl.Task.POSE)
    assert d.figures['carried_speed_rad_s'][0] > d.figures['velocity_limits_rad_s'][0]
    assert d.figures['carry_damping_nms'][0] == 0.0
    header = ' '.join(line.strip('# ') for line in go.to_yaml(d).splitlines())
    assert 'on torso_lift_joint, left as they are (sliding joints' in header
    model.prismatic = (False,) * 8  # taken for a rotation, the lift would be damped hard
    assert gd.design(model, cl.Task.POSE).kv[0] > 5.0 * d.kv[0]


def test_the_inertial_damping_damps_the_heavy_arm_within_what_the_light_one_tolerates(designs):
    """
    docs/gain_design.md, "Damping that follows the inertia": capped at beta I, b_max's rate.

    The sampled loop tolerates a damping proportional to the seen inertia I: beta is
    DAMPER_SAFETY x that ratio, so beta I_min is b_max on every joint. On the xArm7, whose
    joint 1 sees 0.01 to 1.1 kg m^2, the damping of its heavy configurations exceeds K_v, and
    the design no longer expects more than 5 s to a goal (6.8 s with K_v alone).
    """
    model7 = _xarm7()
    xarm7 = gd.design(model7, cl.Task.POSE)
    for model, d in [designs[name] for name in ('wrist', 'xarm6', 'panda')] + [(model7, xarm7)]:
        c = np.array(d.shaping.inertial_damping)
        assert c.size == model.n and np.all(c > 0.0)
        beta = d.shaping.inertial_damping_rate_per_s
        inertia_min = d.figures['inertia_min']
        delays = ga.checked_delays(d.figures['delays'])
        b_max = np.array([gd.DAMPER_SAFETY * ga.largest_stable_damping(i, delays,
                                                                       1.0 / d.rate_hz)
                          for i in inertia_min])
        np.testing.assert_allclose(beta * inertia_min, b_max, rtol=1e-3)
        # the floor of the damping ratio holds after the rounding of the written values
        assert np.all(d.figures['damping_ratio']['tanh'] >= gd.DAMPING_RATIO_MIN)
    rng = np.random.default_rng(0)
    lower, upper = np.array(model7.position_lower), np.array(model7.position_upper)
    heavy = max((model7.mass_matrix(rng.uniform(np.maximum(lower, -3.0),
                                                np.minimum(upper, 3.0)).tolist())
                 for _ in range(200)), key=lambda M: ga.seen_inertia(M)[0])
    assert ga.seen_inertia(heavy)[0] > 50.0 * xarm7.figures['inertia_min'][0]
    c, beta = xarm7.shaping.inertial_damping, xarm7.shaping.inertial_damping_rate_per_s
    assert ga.damping_at(xarm7.kv, c, beta, heavy)[0] > 1.5 * xarm7.kv[0]
    assert xarm7.figures['time_to_goal_s'] < 5.0
    # the median cruise, with the damping at each configuration, is no faster than K_v's
    assert np.all(xarm7.figures['typical_speed_rad_s']
                  <= xarm7.figures['terminal_speed_rad_s'] * (1.0 + 1e-6))


def test_the_ramp_is_the_approach_time_at_the_slowest_revolute_cruise():
    """docs/gain_design.md, section 5, "The ramp": 0.25 rad, or that time at the cruise."""
    cruise = np.array([0.6, 1.2, 0.05])
    slide = [False, False, True]  # its 0.05 m/s does not count: its ramp would be metres
    assert gd.approach_ramp(cruise, slide) == gd.GUIDE_RAMP_RAD
    assert gd.approach_ramp(cruise, slide, 0.2) == pytest.approx(0.12)
    assert gd.approach_ramp(cruise, slide, 1.0) == gd.GUIDE_RAMP_RAD  # never more
    assert gd.approach_ramp(cruise, [True] * 3, 0.2) == gd.GUIDE_RAMP_RAD
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match=f'approach_time_s must be finite and > 0, got {bad}'):
            gd.approach_ramp(cruise, slide, bad)


def test_the_approach_time_shortens_the_ramp_and_speeds_the_linear_approach(designs):
    """
    0.05 s at the wrist's cruise, 0.6 x 2 pi rad/s, is a ramp of 0.188 rad: the design's.

    The design sizes the goal-configuration stiffness T / w and the damping for that ramp;
    the sampled loop stays stable and the linear loop's slowest mode decays faster.
    """
    model, d = designs['wrist']
    assert d.shaping.configuration_ramp_rad == gd.GUIDE_RAMP_RAD
    short = gd.design(model, cl.Task.ORIENTATION, friction_nm=(1.8, 0.72, 0.45),
                      delays=(1, 2), approach_time_s=0.05)
    w = short.shaping.configuration_ramp_rad
    assert w == pytest.approx(0.05 * gd.CRUISE_FRACTION * min(model.velocity_limits), rel=3e-3)
    assert w < gd.GUIDE_RAMP_RAD
    assert max(short.figures['spectral_radius'].values()) < 1.0
    assert short.figures['settling_decay_per_s'][0] > d.figures['settling_decay_per_s'][0]
    assert 'configuration_ramp: 0.188' in go.to_yaml(short)


def test_the_design_damps_the_slowest_coupled_mode(designs):
    """
    docs/lyapunov.md, section 11: alpha M near the goal, the smallest alpha nearly the best.

    Two joints whose diagonal damping leaves their coupled slow mode underdamped get an alpha
    > 0 that makes it decay faster; one joint already overdamped gets none (more damping would
    slow it). The Panda's design takes an alpha, and its sampled loop is checked with it.
    """
    rates = gd.SETTLING_RATES_PER_S
    coupled = np.array([[2.0, 1.2], [1.2, 1.0]])  # heavy, coupled inertia
    rows = np.eye(2)  # a 2-row task, one row per joint (no Q on the position task)
    configs = [(None, rows, coupled)]
    alpha, before, after = ga.settling_rate(configs, np.array([40.0, 40.0]),
                                            np.array([2.0, 2.0]), np.zeros(2), rates,
                                            gd.SETTLING_NEAR_BEST, cl.Task.POSITION)
    assert alpha > 0.0 and after > 1.5 * before
    K = np.diag([40.0, 40.0])
    D = np.diag([2.0, 2.0])
    assert ga.slowest_decay_per_s(coupled, K, D + alpha * coupled) == pytest.approx(after)
    assert max(ga.slowest_decay_per_s(coupled, K, D + a * coupled)
               for a in rates) <= after / gd.SETTLING_NEAR_BEST + 1e-9
    overdamped = [(None, np.eye(1), np.array([[1.0]]))]
    alpha, before, after = ga.settling_rate(overdamped, np.array([1.0]), np.array([10.0]),
                                            np.zeros(1), rates, gd.SETTLING_NEAR_BEST,
                                            cl.Task.POSITION)
    assert alpha == 0.0 and after == before
    model, d = designs['panda']
    alpha = d.shaping.settling_damping_rate_per_s
    before, after = d.figures['settling_decay_per_s']
    assert alpha > 0.0 and after > before
    assert max(d.figures['spectral_radius'].values()) < 1.0
    q = model.middle_of_ranges()  # the tick's check with it, at a goal, one tick of delay
    assert ga.linearized_spectral_radius(model, q, d.gains('tanh'), 1, 1.0 / d.rate_hz,
                                         task=d.task, shaping=d.shaping) < 1.0
    assert 'settling damping' in go.to_yaml(d)
    # the sampled-loop check reads alpha: 500/s of alpha M tips the delayed loop over
    args = (configs, np.array([40.0, 40.0]), np.array([2.0, 2.0]), np.ones(2), np.zeros(2),
            (1, 2), 1e-3, cl.Task.POSITION)
    assert max(ga.worst_rho(*args).values()) < 1.0
    assert max(ga.worst_rho(*args, settling_per_s=500.0).values()) > 1.0


def test_the_design_drops_a_settling_damping_the_sampled_loop_does_not_take(monkeypatch):
    """If the final check fails with alpha M, the design writes alpha = 0, checked without."""
    model = wrist_model()
    d = gd.design(model, cl.Task.ORIENTATION)
    assert d.shaping.settling_damping_rate_per_s > 0.0
    worst = ga.worst_rho

    def fails_with_alpha(*args, settling_per_s=0.0, **kwargs):
        if len(args) > 10:
            settling_per_s = args[10]
            args = args[:10]
        rho = worst(*args, settling_per_s=settling_per_s, **kwargs)
        return dict.fromkeys(rho, 1.0) if settling_per_s > 0.0 else rho
    monkeypatch.setattr(gd, 'worst_rho', fails_with_alpha)
    dropped = gd.design(model, cl.Task.ORIENTATION)
    assert dropped.shaping.settling_damping_rate_per_s == 0.0
    before, after = dropped.figures['settling_decay_per_s']
    assert after == before and max(dropped.figures['spectral_radius'].values()) < 1.0
    assert dropped.kp == d.kp and dropped.kv == d.kv  # nothing else moves


def test_the_default_inertial_damping_rate_is_the_designs_at_1_khz():
    """parameter_table's default beta is what design_gains writes at 1 kHz, delays 1 and 2."""
    from quat_jt_controller import parameter_table as table
    assert table.DEFAULT_INERTIAL_DAMPING_RATE == pytest.approx(
        gd.inertial_damping_rate((1, 2), 1e-3), rel=1e-3)

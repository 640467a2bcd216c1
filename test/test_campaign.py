"""
The reach campaign's infrastructure: its runners, and any arm from its URDF.

The cases of an experiment give the same outcomes whichever runner ran them (one after the
other here, or on local processes); Ray is imported only when asked and its absence is a clear
error; the chain of an arm is found from its URDF alone.
"""
import dataclasses
from pathlib import Path
import re
import shlex
import sys

from experiments import arms
from experiments import reach_experiment as rx
from experiments import runners
from experiments import urdf_sweep
import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_runtime import joints

from robots import small_arm_urdf


def _square(x: int) -> int:
    return x * x


@pytest.mark.unit
@pytest.mark.parametrize('workers', [1, 2])
def test_run_all_keeps_the_order_of_the_jobs(workers):
    seen = []
    assert runners.run_all(_square, range(7), workers,
                           progress=lambda d, t: seen.append((d, t))) == [
        x * x for x in range(7)]
    assert seen[-1] == (7, 7)


@pytest.mark.unit
def test_bad_worker_count_and_missing_ray_are_clear_errors(monkeypatch):
    with pytest.raises(runners.RunnerError, match='workers must be >= 1, got 0'):
        runners.run_all(_square, [1, 2], workers=0)
    monkeypatch.setitem(sys.modules, 'ray', None)  # as if not installed
    with pytest.raises(runners.RunnerError, match="--ray-address 'auto' needs Ray"):
        runners.run_all(_square, [1], ray_address='auto')


@pytest.mark.unit
def test_the_chain_of_an_arm_is_found_from_its_urdf():
    urdf = small_arm_urdf(('continuous', 'revolute', 'revolute', 'revolute'))
    assert arms.default_links(urdf) == ('base_link', 'tool')
    assert arms.arm_links(urdf) == ('base_link', 'tool', ['joint1', 'joint2', 'joint3', 'tool'])
    assert arms.arm_links(urdf, tip_link='link2')[2] == ['joint1', 'joint2']
    with pytest.raises(ValueError, match="'base_link' is not below link 'link2'"):
        arms.chain_joints(urdf, 'link2', 'base_link')
    with pytest.raises(ValueError, match='the URDF has no <link>'):  # UR's ur3.urdf
        arms.default_links('<robot xmlns:xacro="http://wiki.ros.org/xacro"></robot>')
    with pytest.raises(ValueError, match="unknown example robot 'nao'"):
        arms.example_robot_urdf('nao')


def campaign_arms() -> dict:
    """Return each arm of experiments/reach_campaign.sh (its main and more arms): its arguments."""
    script = (Path(__file__).resolve().parent.parent / 'experiments' / 'reach_campaign.sh')
    text = script.read_text().split('arms=(', 1)[1].split('for entry in', 1)[0]
    entries = re.findall(r"^\s*['\"]([a-z0-9_]+)\|([^'\"]*)['\"]", text, flags=re.M)
    return {name: shlex.split(args.replace('\n', ' ')) for name, args in entries}


@pytest.mark.unit
def test_every_example_robot_arm_of_the_campaign_resolves_to_its_chain():
    """Each arm the campaign names by ``--example-robot``: its URDF installed, its links found."""
    found = campaign_arms()
    assert {'ur3', 'wrist', 'talos_right_arm', 'tiago_dual_right_arm'} <= set(found)
    named = {name: args for name, args in found.items() if '--example-robot' in args}
    assert len(named) >= 20
    for name, args in named.items():
        option = dict(zip(args[::2], args[1::2]))
        urdf = arms.example_robot_urdf(option['--example-robot']).read_text()
        base, tip, joints = arms.arm_links(urdf, option.get('--base-link'),
                                           option.get('--tip-link'))
        # the arms run have 5 to 7 joints; a finger and a leg, for a position task, 3
        least = 3 if option.get('--task') == 'position' else 5
        assert len(joints) >= least, (name, base, tip, joints)


def finger(name: str, parent: str, mimic: str = '') -> str:
    """Return a revolute finger link and joint below ``parent``, mimicking ``mimic`` if given."""
    return (f'<link name="{name}"/><joint name="{name}_joint" type="revolute"><parent '
            f'link="{parent}"/><child link="{name}"/><axis xyz="0 1 0"/><limit lower="0" '
            'upper="1" effort="1" velocity="1"/>'
            + (f'<mimic joint="{mimic}" multiplier="-1"/>' if mimic else '') + '</joint>')


@pytest.mark.unit
def test_the_chain_stops_at_a_gripper_whose_fingers_mimic_each_other():
    """PR2's and TIAGo Pro's grippers: two-joint fingers, coupled by <mimic>, below the arm."""
    fingers = (finger('left', 'tool') + finger('left_tip', 'left', 'left_joint')
               + finger('right', 'tool', 'left_joint')
               + finger('right_tip', 'right', 'left_joint'))
    urdf = small_arm_urdf(('revolute',) * 3).replace('</robot>', fingers + '</robot>')
    assert arms.default_links(urdf) == ('base_link', 'tool')  # not left_tip
    uncoupled = urdf.replace('<mimic joint="left_joint" multiplier="-1"/>', '')
    assert arms.default_links(uncoupled) == ('base_link', 'tool')  # two free fingers: a hand
    one_jaw = small_arm_urdf(('revolute',) * 3).replace(
        '</robot>', finger('jaw', 'tool') + finger('jaw_tip', 'jaw') + '</robot>')
    assert arms.default_links(one_jaw) == ('base_link', 'jaw_tip')  # a jaw: as before
    # a linkage in the arm (joint2 mimicked by a side link) does not cut the chain short
    linkage = small_arm_urdf(('revolute',) * 3).replace(
        '</robot>', finger('rod', 'link1', 'joint2') + '</robot>')
    assert arms.default_links(linkage) == ('base_link', 'tool')
    only_coupled = small_arm_urdf(('revolute',)).replace(
        '</robot>', finger('rod', 'base_link', 'tool') + '</robot>')
    with pytest.raises(ValueError, match='but those coupled by <mimic>; give the tip link'):
        arms.default_links(only_coupled)


def heavy_finger(name: str, parent: str, kg: float) -> str:
    """Return ``finger(name, parent)`` with a link of ``kg``."""
    return finger(name, parent).replace(
        f'<link name="{name}"/>', f'<link name="{name}"><inertial><mass value="{kg}"/><inertia '
        'ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>')


@pytest.mark.unit
def test_the_chain_stops_at_the_wrist_above_a_hand():
    """
    TIAGo++'s, the G1's and Alex's hands: fingers of free joints end the default chain.

    A link with two or more branches of rotating joints, lighter than a quarter of what the
    chain moves above it and with no more joints below than above, is a hand; a torso's arms,
    as heavy as what carries them or longer, are not.
    """
    arm = small_arm_urdf(('revolute',) * 4)  # links of 1, 1/2, 1/3 and 1/4 kg
    hand = ''.join(heavy_finger(f'f{i}', 'tool', 0.02) + heavy_finger(f'f{i}_tip', f'f{i}', 0.01)
                   for i in range(3))
    assert joints.default_chain_end(arm.replace('</robot>', hand + '</robot>')) == (
        'base_link', 'tool', 'tool')
    assert joints.default_chain_end(arm) == ('base_link', 'tool', None)
    # fingers as heavy as the arm: limbs, not a hand; the chain runs on to a fingertip
    limbs = ''.join(heavy_finger(f'f{i}', 'tool', 1.0) + heavy_finger(f'f{i}_tip', f'f{i}', 1.0)
                    for i in range(3))
    assert joints.default_chain_end(arm.replace('</robot>', limbs + '</robot>'))[1:] == (
        'f0_tip', None)
    # light arms on a torso, longer than the chain that carries them: not a hand either
    arms_of_torso = ''.join(
        heavy_finger(f'a{i}', 'tool', 0.01) + heavy_finger(f'a{i}_2', f'a{i}', 0.01)
        + heavy_finger(f'a{i}_3', f'a{i}_2', 0.01) + heavy_finger(f'a{i}_4', f'a{i}_3', 0.01)
        for i in range(2))
    torso = small_arm_urdf(('revolute',) * 2).replace('</robot>', arms_of_torso + '</robot>')
    assert joints.default_chain_end(torso)[1:] == ('a0_4', None)


@pytest.mark.unit
def test_an_arm_with_continuous_joints_gets_its_cases_within_one_turn(tmp_path):
    """A joint without stops is drawn from one turn (its limits are infinite)."""
    path = tmp_path / 'arm.urdf'
    path.write_text(small_arm_urdf())  # joints 1 and 4 continuous
    robot = rx.arm_robot('small', str(path), None, None, cl.Task.ORIENTATION)
    model = rx.RobotModel(path.read_text(), robot.base_link, robot.tip_link, list(robot.joints))
    assert model.continuous == (True, False, False, True, False)
    pairs = np.array(rx.cases(model, robot, 20, seed=1))
    assert pairs.shape == (20, 2, 5) and np.isfinite(pairs).all()
    assert np.abs(pairs).max() <= robot.fraction * np.pi
    assert np.abs(pairs[:, :, [0, 3]]).max() > 1.0  # spread over the turn, not stuck at 0


@pytest.mark.unit
def test_an_arm_with_too_few_goals_is_a_clear_error(tmp_path):
    path = tmp_path / 'arm.urdf'
    path.write_text(small_arm_urdf())
    robot = dataclasses.replace(rx.arm_robot('small', str(path), None, None,
                                             cl.Task.ORIENTATION), goal_sigma_min=1e9)
    model = rx.RobotModel(path.read_text(), robot.base_link, robot.tip_link, list(robot.joints))
    with pytest.raises(ValueError, match=r'small: only 0 of 1000 random goals are regular'):
        rx.cases(model, robot, 1, seed=1)


def _short(robot: rx.Robot) -> rx.Robot:
    return dataclasses.replace(robot, duration_s=0.3)


@pytest.mark.e2e
def test_local_processes_give_the_outcomes_of_a_serial_run():
    robot = _short(rx.ROBOTS['wrist'])
    serial = rx.run_robot(robot, 'tanh', 2, seed=3, progress=None, workers=1)
    parallel = rx.run_robot(robot, 'tanh', 2, seed=3, progress=None, workers=2)
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_array_equal(a.q_final, b.q_final)
        assert (a.reached, a.orientation_error, a.speed_ratio) == (
            b.reached, b.orientation_error, b.speed_ratio)


@pytest.mark.e2e
def test_a_local_ray_cluster_gives_the_outcomes_of_a_serial_run():
    ray = pytest.importorskip('ray')
    robot = _short(rx.ROBOTS['wrist'])
    serial = rx.run_robot(robot, 'tanh', 2, seed=3, progress=None, workers=1)
    try:
        on_ray = rx.run_robot(robot, 'tanh', 2, seed=3, progress=None, ray_address='local')
    finally:
        ray.shutdown()
    for a, b in zip(serial, on_ray, strict=True):
        np.testing.assert_array_equal(a.q_final, b.q_final)


def _small_arm(tmp_path) -> tuple:
    """Return a 4-joint arm's URDF file in ``tmp_path`` and its short Robot (MuJoCo plant)."""
    pytest.importorskip('mujoco')
    path = tmp_path / 'arm.urdf'
    path.write_text(small_arm_urdf(('revolute',) * 4))
    return path, _short(rx.arm_robot('small', str(path), None, None, cl.Task.ORIENTATION))


@pytest.mark.e2e
@pytest.mark.parametrize('name', ['armature-wrong', 'no-velocities', 'encoder',
                                  'armature-untold-friction'])
def test_an_arm_from_its_urdf_runs_the_same_serial_or_parallel(tmp_path, name):
    """The design from the URDF, a MuJoCo plant with the condition's rotor inertia or states."""
    path, robot = _small_arm(tmp_path)
    cond = rx.condition(name, armature=0.01)
    runs = [rx.run_arm(robot, cond, 'tanh', 2, seed=1, progress=None, workers=w)
            for w in (1, 2)]
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a.q_final, b.q_final)
        assert np.isfinite(a.q_final).all() and a.speed_ratio >= 0.0
    row = rx.table_row(robot, cond, runs[0])
    assert row.startswith(f'| small | {cond.describe()} | ') and '/2 |' in row
    # the goal check's starts, and the report's count of the searches that went past the least
    assert all(rx.MAX_STARTS <= o.ik_starts <= 48 for o in runs[0])
    longer = [dataclasses.replace(o, ik_starts=48) for o in runs[0]]
    assert ("the goal check's search for q* took more than 12 IK starts (no regular q* out of "
            'the bands in 12) in 2 cases, 48 at most') in rx.report(robot, 'tanh', longer, 1.0)
    least = [dataclasses.replace(o, ik_starts=rx.MAX_STARTS) for o in runs[0]]
    assert 'IK starts' not in rx.report(robot, 'tanh', least, 1.0)
    # q* given 0.1 s in every case, or (--q-star-by-starts) 0.1 s per 12 starts its search took
    assert all(o.q_star_after_s == rx.Q_STAR_AFTER_S for o in runs[0])
    by_starts = rx.run_arm(robot, cond, 'tanh', 2, seed=1, progress=None, workers=1,
                           q_star_by_starts=True)
    for a, b in zip(runs[0], by_starts, strict=True):
        assert b.ik_starts == a.ik_starts
        assert b.q_star_after_s == pytest.approx(
            rx.Q_STAR_AFTER_S * max(1.0, b.ik_starts / rx.MAX_STARTS))
        if b.ik_starts == rx.MAX_STARTS:  # the same q* at the same time: the same run
            np.testing.assert_array_equal(a.q_final, b.q_final)
    later = [dataclasses.replace(o, ik_starts=48, q_star_after_s=0.4) for o in runs[0]]
    assert ('in 2 cases, 48 at most: q* is given 0.1 s after the goal per 12 starts there '
            '(--q-star-by-starts), 0.40 s at most') in rx.report(robot, 'tanh', later, 1.0)


@pytest.mark.unit
def test_the_untold_rotor_inertia_conditions_tell_the_design_none():
    """The plant's rotor inertia (and friction) as a real geared arm has them; the design 0."""
    untold = rx.condition('armature-untold', armature=0.2)
    both = rx.condition('armature-untold-friction', armature=0.2, friction_fraction=0.02)
    assert (untold.plant_armature, untold.told_armature, untold.coulomb_effort_fraction) == (
        0.2, 0.0, 0.0)
    assert (both.plant_armature, both.told_armature, both.coulomb_effort_fraction) == (
        0.2, 0.0, 0.02)
    assert untold.describe() == 'rotor inertia 0.2 kg m^2, untold'
    assert both.describe() == ('rotor inertia 0.2 kg m^2 and Coulomb friction 0.02 x effort, '
                               'both untold')


@pytest.mark.e2e
def test_a_payload_is_carried_by_the_plant_and_told_to_the_design_only_if_asked(tmp_path):
    """'payload': the plant's tip carries it, the design does not know; 'payload-told': both."""
    path, robot = _small_arm(tmp_path)
    untold, told = (rx.condition(name, payload_share=0.5) for name in ('payload', 'payload-told'))
    capacity = rx.payload_capacity_kg(robot)  # its weight within the gravity reserve
    assert rx.payload_kg(robot, told) == pytest.approx(min(0.5 * rx.link_mass_kg(robot),
                                                           0.5 * capacity))
    assert capacity > 0.0 and rx.payload_kg(robot, told) > 0.0
    assert not untold.payload_told and told.payload_told
    heavier = rx.RobotModel(rx.robot_urdf(robot), robot.base_link, robot.tip_link,
                            list(robot.joints), None, capacity, rx.PAYLOAD_COM_TIP_M)
    rng = np.random.default_rng(0)  # the capacity's first configuration: within the reserve
    lower, upper = rx.sampling_box(heavier)
    q = rng.uniform(lower, upper).tolist()
    assert np.all(np.abs(heavier.gravity(q)) <= 0.75 * np.array(heavier.effort_limits) + 1e-9)
    [ideal], [carried], [known] = (rx.run_arm(robot, cond, 'tanh', 1, seed=1, progress=None,
                                              workers=1)
                                   for cond in (rx.condition('ideal'), untold, told))
    assert not np.array_equal(ideal.q_final, carried.q_final)  # the plant carries it
    assert not np.array_equal(carried.q_final, known.q_final)  # ... and the controller knows
    model, design = rx.arm_design(robot, 0.0, 1000.0, told_payload_kg=rx.payload_kg(robot, told))
    assert model.payload_kg == rx.payload_kg(robot, told) == design.payload_kg
    assert rx.table_row(robot, told, [known]).startswith(
        '| small | payload 0.5 x link mass, given | ')
    with pytest.raises(ValueError, match='--payload-share must be finite and >= 0'):
        rx.condition('payload', payload_share=-0.1)
    stalled = [dataclasses.replace(carried, reached=False, cause=(
        f'stalled: the torque held at rest is what {kg} kg {way} at the tip (x) would need'))
        for kg, way in (('1.5', 'more'), ('0.5', 'less'), ('2.5', 'more'))]
    assert ('the stall diagnosis names a payload the model does not carry in 3 cases: median '
            '1.5 kg (from -0.5 to 2.5)') in rx.report(robot, 'tanh', stalled, 1.0)
    identify = rx.condition('armature-payload-identify')
    assert identify.identify_at_s == rx.IDENTIFY_AT_S and not identify.payload_told
    set_at_rest = [dataclasses.replace(carried, identified_kg=kg) for kg in (0.3, 0.5)]
    assert ('a payload identified at rest in 2 cases: median 0.4 kg (from 0.3 to 0.5)'
            in rx.report(robot, 'tanh', set_at_rest, 1.0))


@pytest.mark.e2e
def test_an_arm_runs_with_the_ticks_of_delay_asked_for(tmp_path, capsys):
    """``--delay`` reaches an arm's cases (it was 1 whatever was asked), and its table row."""
    path, robot = _small_arm(tmp_path)
    finals = {}
    for ticks in (1, 3):
        cond = rx.condition('ideal', delay_ticks=ticks)
        [outcome] = rx.run_arm(robot, cond, 'tanh', 1, seed=1, progress=None, workers=1)
        finals[ticks] = outcome.q_final
    assert not np.array_equal(finals[1], finals[3])
    assert rx.table_row(robot, rx.condition('ideal', delay_ticks=3), [outcome]).startswith(
        '| small | ideal plant, 3 ticks of delay | ')
    with pytest.raises(SystemExit):
        rx.main(['--urdf', str(path), '--task', 'orientation', '--cases', '1', '--workers',
                 '1', '--delay', '11'])
    assert '--delay must be in [0, 10] ticks, got 11' in capsys.readouterr().err


@pytest.mark.e2e
def test_an_arm_from_its_urdf_takes_parameter_overrides(tmp_path, capsys):
    """``--param`` replaces a parameter of the design (it was silently ignored for an arm)."""
    path, robot = _small_arm(tmp_path)
    cond = rx.condition('ideal')
    runs = [rx.run_arm(robot, cond, 'tanh', 1, seed=1, progress=None, workers=1,
                       overrides=overrides)
            for overrides in (None, {'kv': [50.0] * 4})]
    assert not np.array_equal(runs[0][0].q_final, runs[1][0].q_final)
    with pytest.raises(SystemExit):
        rx.main(['--urdf', str(path), '--task', 'orientation', '--cases', '1', '--workers',
                 '1', '--param', 'settling_damping_rate:=-1'])
    assert 'settling_damping_rate must be in [0, 40], got -1.0' in capsys.readouterr().err
    with pytest.raises(SystemExit):  # a misspelt name, before any design is run
        rx.main(['--urdf', str(path), '--task', 'orientation', '--cases', '1', '--workers',
                 '1', '--param', 'settling_dampng_rate:=1'])
    assert "['settling_dampng_rate'] are no controller parameters it can set here" in (
        capsys.readouterr().err)


@pytest.mark.unit
def test_an_arm_the_design_refuses_is_one_line_not_a_traceback(tmp_path, capsys):
    """PR2's arm (no counterbalance in its URDF) ended the experiment in a traceback."""
    path = tmp_path / 'weak.urdf'
    path.write_text(re.sub(r'effort="[0-9.]+"', 'effort="0.001"',
                           small_arm_urdf(('revolute',) * 4)))
    with pytest.raises(SystemExit) as exit_info:
        rx.main(['--urdf', str(path), '--cases', '1', '--workers', '1'])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert 'error: design_gains: the arm cannot hold itself up' in err
    assert 'Traceback' not in err


@pytest.mark.unit
def test_the_design_options_reach_the_design_and_a_bad_one_is_one_line(tmp_path, capsys):
    """``--approach-time``, ``--cruise-fraction``, ``--design-delays``: design_gains'."""
    path = tmp_path / 'arm.urdf'
    path.write_text(small_arm_urdf(('revolute',) * 4))  # 3 rad/s: a cruise of 1.8 rad/s
    robot = rx.arm_robot('small', str(path), None, None, cl.Task.ORIENTATION)
    one = rx.arm_design(robot, 0.0, 1000.0)[1]
    assert one.shaping.configuration_ramp_rad == 0.25 and one.figures['delays'] == (1,)
    assert rx.arm_design(robot, 0.0, 1000.0, None, 0.1)[1].shaping.configuration_ramp_rad == (
        pytest.approx(0.18))
    three = rx.arm_design(robot, 0.0, 1000.0, None, None, None, (3,))[1]
    assert three.figures['delays'] == (3,)  # checked at 3 and 4 ticks: less damping allowed
    assert three.shaping.inertial_damping_rate_per_s < one.shaping.inertial_damping_rate_per_s
    for option, value, words in (
            ('--approach-time', '-1', 'design_gains: approach_time_s must be finite and > 0, '
                                      'got -1.0'),
            ('--cruise-fraction', '1.5', 'design_gains: cruise_fraction must be in (0, 1], '
                                         'got 1.5'),
            ('--design-delays', '-1', '--design-delays must be in [0, 10] ticks, got [-1]')):
        with pytest.raises(SystemExit) as exit_info:
            rx.main(['--urdf', str(path), '--task', 'orientation', '--cases', '1',
                     '--workers', '1', option, value])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        assert f'error: {words}' in err and 'Traceback' not in err, err


class _Slide:
    """A unit mass on a line, stepped at 1 kHz: the plant an encoder reads."""

    n, dt_s = 1, 1e-3

    def __init__(self, q_rad: float, qdot_rad_s: float) -> None:
        self.q_rad, self.qdot_rad_s = np.array([q_rad]), np.array([qdot_rad_s])

    def step(self, tau):
        self.qdot_rad_s = self.qdot_rad_s + np.asarray(tau) * self.dt_s
        self.q_rad = self.q_rad + self.qdot_rad_s * self.dt_s
        return np.asarray(tau)


@pytest.mark.unit
def test_an_encoder_reads_whole_counts_and_the_velocities_come_from_them():
    """The controller's positions are whole counts; the plant's stay exact, for the verdict."""
    count = rx.encoder_resolution_rad(12)
    assert count == pytest.approx(2.0 * np.pi / 4096) and rx.encoder_resolution_rad(0) == 0.0
    speed = 0.25 * count / 1e-3  # a count every 4 ticks
    worst = {}
    for told in (True, False):
        plant = rx.PositionsOnly(_Slide(0.3 * count, speed), count, told)
        sensed, true, estimates = [], [], []
        for _ in range(40):
            plant.step([0.0])
            sensed.append(float(plant.sensed_q_rad[0]))
            true.append(float(plant.q_rad[0]))
            estimates.append(float(plant.qdot_rad_s[0]))
        counts = np.array(sensed) / count
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
        assert np.abs(np.array(sensed) - np.array(true)).max() <= 0.5 * count + 1e-12
        assert len(set(sensed)) > 5 and true[-1] == pytest.approx(10.3 * count)
        worst[told] = np.abs(np.array(estimates[20:]) - speed).max() / (count / 1e-3)
    # told the count, the window spans the steps and finds the speed; not told, the low-pass
    # of one period jumps by most of a count a tick at each step
    assert worst[True] < 1e-9 and worst[False] > 0.3
    exact = rx.PositionsOnly(_Slide(0.3 * count, speed))
    exact.step([0.0])
    assert exact.sensed_q_rad[0] == exact.q_rad[0]
    for bits in (7, 33, -1):
        with pytest.raises(ValueError, match=f'--encoder-bits must be 0 .exact. or in '
                                             fr'\[8, 32\], got {bits}'):
            rx.condition('encoder', encoder_bits=bits)
    assert rx.condition('encoder', encoder_bits=16).describe() == (
        'positions from 16-bit encoders, no velocities (estimated, the count told)')


@pytest.mark.unit
def test_the_last_second_tells_a_torque_that_flips_from_one_that_shakes():
    """Sign changes above the floor count as a cycle; the ripple is the std, x effort."""

    class Model:
        n, effort_limits = 2, (10.0, 100.0)

        def gravity(self, q):
            return [1.0, 0.0]

    t_s = np.arange(1, 2001) * 1e-3
    wave = np.where(np.arange(2000) % 2 == 0, 1.0, -1.0)
    # joint 0 holds its gravity torque exactly; joint 1 flips by +-1 N m every tick
    run = dataclasses.make_dataclass('Run', ['t_s', 'q_rad', 'tau_nm'])(
        t_s, np.zeros((2000, 2)), np.column_stack([np.ones(2000), wave]))
    model = Model()
    rest = rx.last_second_torques(model, run)  # 1001 samples from t = 1 s
    assert rx.torque_flips_per_s(model, rest) == 1000.0
    assert rx.torque_ripple(model, rest) == pytest.approx(1.0 / 100.0)
    run.tau_nm[:, 1] = 0.05 * wave  # below the floor, 1e-3 x 100 N m: no sign, but a ripple
    rest = rx.last_second_torques(model, run)
    assert rx.torque_flips_per_s(model, rest) == 0.0
    assert rx.torque_ripple(model, rest) == pytest.approx(0.05 / 100.0)


@pytest.mark.unit
def test_the_sampled_loop_regulates_what_the_encoder_reads_and_records_the_plant():
    """An encoder off by 0.05 rad on one joint: the regulator ends there, the record shows it."""
    from quat_jt_controller import paper
    from quat_jt_controller import shaping as sh
    from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
    from quat_jt_runtime.resources import default_urdf_xml
    from wrist_sim.simulator import RobotSimulator

    from robots import wrist_model

    class Offset:
        """The plant, read by an encoder mounted 0.05 rad off on the first joint."""

        def __init__(self, sim) -> None:
            self.sim, self.n, self.dt_s = sim, sim.n, sim.dt_s

        q_rad = property(lambda self: self.sim.q_rad)
        qdot_rad_s = property(lambda self: self.sim.qdot_rad_s)
        sensed_q_rad = property(lambda self: self.sim.q_rad + np.array([0.05, 0.0, 0.0]))

        def step(self, tau):
            return self.sim.step(tau)

    model = wrist_model()
    ori = cl.Task.ORIENTATION
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, ori, 3)
    finals = []
    for wrap in (lambda sim: sim, Offset):
        loop = ClosedLoop(model, gains, ori, paper.Q_DESIRED, shaping=sh.Shaping.create(3))
        with RobotSimulator(default_urdf_xml(), model.joint_names, coulomb_nm=[0.0] * 3,
                            viscous_nm_s_per_rad=[0.0] * 3) as sim:
            run = run_sampled(loop, wrap(sim), 4.0, delay_ticks=1)
        finals.append((run.q_rad[-1], run.orientation_error[-1]))
    (q_exact, e_exact), (q_offset, e_offset) = finals
    assert e_exact < 1e-3 < e_offset  # judged by the plant, not by what the encoder read
    assert q_offset[0] - q_exact[0] == pytest.approx(-0.05, abs=5e-3)


@pytest.mark.unit
def test_the_urdf_sweep_tells_taken_refused_and_crashed_apart(tmp_path):
    """design_gains and the simulator on a URDF as it comes: each outcome, and what was said."""
    good = tmp_path / 'arm.urdf'
    good.write_text(small_arm_urdf(('revolute',) * 4))
    assert urdf_sweep.design_outcome(good, 120.0) == ('taken', '')
    assert urdf_sweep.simulator_outcome(good, 'mujoco') == ('taken', '')
    no_effort = tmp_path / 'no_effort.urdf'
    no_effort.write_text(small_arm_urdf(('revolute',) * 4).replace('effort="10.0"', 'effort="0"'))
    kind, said = urdf_sweep.design_outcome(no_effort, 120.0)
    assert kind == 'refused' and "joints ['joint2'] have no effort limit" in said
    empty = tmp_path / 'empty.urdf'
    empty.write_text('<robot name="nothing"></robot>')
    assert urdf_sweep.simulator_outcome(empty, 'mujoco')[0] == 'refused'
    assert urdf_sweep.cell(('refused', 'x' * 200)).endswith('...')
    assert urdf_sweep.cell(('crashed', 'a | b')) == 'crashed: a / b'


@pytest.mark.unit
def test_each_fault_of_the_mutation_table_changes_the_urdf_and_the_model_names_it():
    """The faults of ``urdf_sweep --mutate`` on the wrist: each refused by name, or warned of."""
    from quat_jt_controller.model import ModelError, RobotModel
    from quat_jt_runtime.resources import default_urdf_xml
    urdf = default_urdf_xml()
    faults = urdf_sweep.mutations(urdf)
    assert len(faults) == 9 and 'mass nan on link3' in faults  # the revolute chain's end
    for name, mutate in faults.items():
        faulty = mutate(urdf)
        assert faulty != urdf, name
        if name == 'velocity="0" everywhere':
            model = RobotModel(faulty, 'base_link', 'tool0')
            assert model.velocity_limits == (0.0, 0.0, 0.0)
            continue
        with pytest.raises((ModelError, ValueError), match=r"'link3'|joint|xacro"):
            RobotModel(faulty, 'base_link', 'tool0')


@pytest.mark.unit
def test_nodes_that_do_not_stop_are_all_killed_before_any_is_waited_for():
    """
    local_ros.stop_nodes: Ctrl-C in turn, then SIGKILL to every group left, then reap.

    Two nodes pinned to one CPU in SCHED_FIFO once starved each other: the one Ctrl-C'd
    first could not run to die while the other spun, and the harness waited for it for ever.
    Here both ignore Ctrl-C: both are killed, and neither is left running.
    """
    import signal
    import subprocess
    from experiments import local_ros
    stubborn = ('import signal, sys, time; signal.signal(signal.SIGINT, signal.SIG_IGN); '
                "print('ready', flush=True); time.sleep(600)")
    procs = [subprocess.Popen([sys.executable, '-c', stubborn], stdout=subprocess.PIPE,
                              text=True, start_new_session=True) for _ in range(2)]
    try:
        for proc in procs:  # each has set its handler
            assert proc.stdout.readline().strip() == 'ready'
        assert local_ros.stop_nodes(procs, timeout=0.2) == [-signal.SIGKILL] * 2
        assert all(proc.poll() is not None for proc in procs)
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
            proc.stdout.close()


@pytest.mark.unit
def test_a_failed_case_names_where_gravity_asked_more_than_an_effort_limit():
    """The classification says when the arm passed where it could not hold itself."""
    from quat_jt_controller import paper
    from quat_jt_controller.reference_sim import ClosedLoop, SampledRun
    from quat_jt_controller.shaping import Shaping
    from quat_jt_runtime.payload import Payload
    from robots import wrist_model
    model = wrist_model()
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    loop = ClosedLoop(model, gains, cl.Task.ORIENTATION, paper.Q_DESIRED)
    t = np.arange(200) * 1e-3
    q = np.outer(0.1 * t, np.ones(3)) + np.array([0.0, 0.5, 0.0])  # still moving, 0.1 rad/s
    zeros = np.zeros_like(t)
    run = SampledRun(t, zeros, zeros + 0.5, zeros, 0, True, q, np.zeros_like(q))
    assert 'cannot hold itself' not in rx.classify(model, loop, Shaping(), None, run)
    loop.clamped.set_payload(Payload(200.0, (0.3, 0.0, 0.0)))  # far more than it carries
    cause = rx.classify(model, loop, Shaping(), None, run)
    assert cause.startswith('still moving at the end (up to 0.100 rad/s): too slow; '), cause
    ratio = np.array([np.abs(model.gravity(x.tolist())) / np.array(model.effort_limits)
                      for x in q[::rx.GRAVITY_CHECK_EVERY]]).max(axis=0)
    j = int(np.argmax(ratio))
    assert ratio[j] > 1.0
    assert (f'on its way the arm passed where it cannot hold itself: joint{j + 1} needed up to '
            f'{ratio[j]:.3g} x its effort limit against gravity (its command clamped there, it '
            'sagged) for 0.20 s') in cause, cause

"""The experiment and benchmark tools run end to end (short runs; no timing asserted)."""
import csv
import json
import math
from pathlib import Path
import subprocess
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image
import pytest
from quat_jt_controller import realtime

pytestmark = pytest.mark.e2e


def run_tool(module, *args, timeout=240):
    out = subprocess.run([sys.executable, '-m', module, *args], capture_output=True, text=True,
                         timeout=timeout)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out.stdout


@pytest.mark.parametrize('mode', ['two processes', 'composed'])
def test_paper_experiment_reproduces_the_qualitative_result(tmp_path, mode):
    """
    Both controllers over DDS with the simulated friction: tanh ends far below quadratic.

    Lockstep (simulated clock), so the outcome does not depend on how busy the machine is; the
    nodes as two processes, or composed in one.
    """
    stdout = run_tool('experiments.paper_experiment', '--out', str(tmp_path),
                      '--duration', '2.5', '--lockstep',
                      *(['--composed'] if mode == 'composed' else []))
    assert f'({mode if mode == "two processes" else "composed (one process)"}):' in stdout
    rows = list(csv.DictReader(open(tmp_path / 'paper_experiment.csv')))
    final = {}
    for potential in ('quadratic', 'tanh', 'tanh_extended'):
        run = [r for r in rows if r['potential'] == potential]
        assert len(run) > 1000, f'{potential}: only {len(run)} states recorded'
        assert float(run[0]['error_norm']) > 0.8  # from q(0) = 0 to the errata goal
        final[potential] = float(run[-1]['error_norm'])
        with open(tmp_path / potential / f'{potential}.mcap', 'rb') as f:
            topics = {ch.topic for _, ch, _, _ in
                      make_reader(f, decoder_factories=[DecoderFactory()])
                      .iter_decoded_messages()}
        assert {'/joint_states', '/effort_controller/commands',
                '/quat_jt_controller/orientation_error', '/robot_description', '/tf_static',
                '/tf'} <= topics
        # The animation, rendered after the run: 25 fps of the recorded time, and a still.
        with Image.open(tmp_path / potential / f'{potential}.gif') as gif:
            assert gif.n_frames >= 25 and gif.size == (320, 240)
        assert (tmp_path / potential / f'{potential}_frame.png').stat().st_size > 1000
    # Section 5 (docs/errata.md note 5): Coulomb friction holds the quadratic law back near 0.2,
    # the tanh law gets within a few 1e-3.
    assert 0.1 < final['quadratic'] < 0.4, final
    assert final['tanh'] < 0.02, final
    # Issue 10: the product config (designed gains, extensions) reaches the goal too.
    assert final['tanh_extended'] < 0.005, final
    assert (tmp_path / 'fig2_error_norm.png').stat().st_size > 10_000
    assert '| quadratic (Eq. 37) |' in stdout and '| tanh (Eq. 38) |' in stdout
    assert stdout.count('Animation ') == 3 and 'rendered in' in stdout  # two + the extended
    assert '| tanh_extended (Eq. 38 + issue 10' in stdout


def test_benchmark_reports_every_figure(tmp_path):
    stdout = run_tool('experiments.benchmark', '--out', str(tmp_path),
                      '--duration', '3', '--composed-duration', '3', '--lockstep-duration', '3',
                      '--warmup', '1')
    two_cpus = len(realtime.allowed_cpus()) >= 2  # else there is no pinned run
    assert ('| figure | ' + ('two processes, pinned | minimal pair, pinned | ' if two_cpus
                             else '') + 'two processes, not pinned | minimal pair, not pinned | '
            'composed (3 s) | Panda 7-DOF pose, two processes' + (', pinned' if two_cpus else '')
            + ' | target |') in stdout
    for row in ('state rate (Hz)', 'command rate (Hz)', 'missed ticks: steps without a fresh',
                'late publications', 'latency p50 / p99 / max (ms)',
                'controller compute p50 (lowest-highest 1 s window) / p99 (us)',
                'CPU % (sim / controller, or the one process)',
                'paper experiment in lockstep (x real time)', 'host CPU steal during the run (%)',
                'core tick Regulator.update, xArm6 6-DOF pose',
                'core tick Regulator.update, Panda 7-DOF pose',
                'controller throwaway ticks before a state (prewarm_lead; % of states)'):
        assert f'| {row}' in stdout, row
    result = json.loads((tmp_path / 'bench.json').read_text())
    pinned = ('two processes, pinned',) if two_cpus else ()
    for mode in (*pinned, 'two processes, not pinned', 'composed',
                 'Panda 7-DOF pose, two processes'):
        # the loop ran; figures are not asserted
        assert result['loops'][mode]['sim']['window_steps'] > 1000, mode
        assert result['loops'][mode]['command_rate_hz'] > 100.0, mode
    for mode in ('two processes', 'composed'):
        assert result['lockstep'][mode]['real_time_factor'] > 0.0, mode
    # The throwaway tick runs in the two-process runs (pinned or not), not composed.
    for mode in (*pinned, 'two processes, not pinned'):
        assert result['loops'][mode]['prewarm_per_state'] > 0.0, mode
    assert result['loops']['composed']['prewarm_per_state'] == 0.0
    for mode in (*pinned, 'two processes, not pinned'):
        assert result['baselines'][mode]['window_steps'] > 1000  # the minimal pair ran too
    for log in ('wrist_sim_node.log', 'controller_node.log') if two_cpus else ():
        # pinned means pinned: each node said so in its log
        assert 'process pinned to CPUs' in (
            tmp_path / 'two_processes_pinned' / log).read_text(), log
    for name, core in result['core'].items():
        assert math.isfinite(core['us_per_tick']) and core['us_per_tick'] > 0.0, name


def test_benchmark_compares_prewarm_off_and_on(tmp_path):
    stdout = run_tool('experiments.benchmark', '--out', str(tmp_path),
                      '--prewarm-pairs', '1', '--duration', '4', '--warmup', '1')
    modes = ('not pinned', 'pinned') if len(realtime.allowed_cpus()) >= 2 else ('not pinned',)
    table = stdout[stdout.index('| mode | pair |'):].strip().splitlines()
    assert len(table) == 2 + 4 * len(modes), table  # header; per mode, a run and a mean each way
    runs = json.loads((tmp_path / 'prewarm.json').read_text())
    assert {(run['mode'], run['prewarm']) for run in runs} == {
        (mode, label) for mode in modes for label in ('off (prewarm_lead 0)', 'on (its default)')}
    for run in runs:  # no throwaway tick when off; some when on (1 kHz states)
        assert (run['prewarm_pct'] > 0.0) == run['prewarm'].startswith('on'), run


def test_tick_profile_times_every_piece_of_both_ticks():
    stdout = run_tool('experiments.tick_profile', '--calls', '500')
    pieces_table, sleep_table = stdout[stdout.index('| controller'):].split('\n\n')[:2]
    rows = [line.split('|') for line in pieces_table.splitlines()[2:]]
    pieces = {cells[1].strip(): cells[2].strip() for cells in rows}
    pieces.update({cells[3].strip(): cells[4].strip() for cells in rows if cells[3].strip()})
    assert len(sleep_table.strip().splitlines()) == 4, sleep_table  # default and 1 ns slack
    assert '(1 ns)' in sleep_table, sleep_table
    for piece in ('rclpy deserialising the JointState (before the callback)',
                  'Regulator.update (paper config)', 'publish the command (no subscriber)',
                  'PyBullet step and read', 'publish JointState (no subscriber)'):
        assert float(pieces[piece]) > 0.0, (piece, stdout)


def test_friction_trace_shows_a_steady_torque_at_rest(tmp_path):
    stdout = run_tool('experiments.friction_trace', '--duration', '2.5',
                      '--plot', str(tmp_path / 'trace.png'))
    assert 'paper gains, quadratic, exact estimate:' in stdout
    assert stdout.count('sign changes [0, 0, 0]') == 7
    assert (tmp_path / 'trace.png').stat().st_size > 10_000


def test_design_gains_entry_point_is_installed():
    """``ros2 run quat_jt_controller design_gains`` runs the console script of setup.py."""
    script = Path(sys.executable).parent / 'design_gains'  # pip puts it next to python
    out = subprocess.run([script, '--task', 'orientation'], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith('# quat_jt_controller: orientation task')


def test_goal_stream_reports_the_loop_and_the_tracking_error(tmp_path):
    """Short streams: every figure is there and finite, from the simulator's own statistics."""
    out = subprocess.run([sys.executable, '-m', 'experiments.goal_stream',
                          '--rates', '100', '--duration', '2', '--out', str(tmp_path)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    figures = json.loads((tmp_path / 'stream.json').read_text())
    stream = figures['streams']['100.0']
    assert stream['goals_sent'] > 100 and stream['states'] > 500, stream
    for key in ('fresh_rate_hz_min', 'fresh_gap_ms_max', 'median_error', 'max_error'):
        assert math.isfinite(stream[key]) and math.isfinite(
            figures['control'].get(key, 0.0)), (key, figures)
    assert 0.0 <= stream['median_error'] <= stream['max_error'] < 0.5
    assert '| 100 |' in out.stdout and 'tracking at 100 goals/s' in out.stdout

"""
Benchmark of the 1 kHz loop: the two nodes over DDS in separate processes, and the pure core.

Loop: ``wrist_sim_node`` (real-time pacing at 1 kHz) and ``controller_node`` (tanh law, paper
gains, regulating to the paper's goal) on a private loopback ROS graph, warmed up, then measured
for ``--duration`` seconds, three ways: two processes pinned to a CPU each (``cpu_affinity``:
the simulator on the first CPU, the controller on the second), two processes not pinned, and
both nodes composed in one process (not pinned; ``--composed-duration``, 60 s). Figures and
where they come from:

* state rate, period jitter, missed deadlines, stale ticks (a step that applied no command
  computed from the previous state), state-to-command latency (state publish -> arrival of the
  command computed from it): the simulator's own loop statistics over the measured interval
  (``stats_file``);
* command rate and compute time per tick (JointState callback to command ready): the
  controller's ``/diagnostics``, one window per second; p50 is the median of the windows' p50
  (the lowest and highest beside it: a second disturbed by the host stands out), p99 the
  largest window p99;
* CPU % per process: ``/proc/<pid>/stat`` user + system time over the measured interval;
* host CPU steal % over the same interval (``/proc/stat``): time the hypervisor gave this
  virtual machine's CPUs to others. On a shared host it dominates the tails; read every
  figure with it.

Baseline: the same loop figures for a minimal rclpy pair with nothing to compute
(``experiments/minimal_pair.py``), run just before each two-process run, pinned the same way,
for the same duration: the floor this machine sets at that moment. What the real nodes show
beyond it is theirs.

Core: ticks per second of the node's own tick, ``Regulator.update`` (kinematics, Jacobian, g(q),
error, law, finite check, clamp), for the wrist (3-DOF, orientation task), the xArm6 (6-DOF,
pose task) and the Panda (7-DOF, pose task, ``config/panda_controller.yaml``; also 0.01 rad
from its goal, with and without the settling damping, which acts only there), in one process;
and, for the wrist, the whole tick the node calls, ``Controller.on_state`` (the state check and
the decisions around ``Regulator.update``).

Panda: the same two-process figures, pinned, for the 7-DOF Panda with its product configs
(``config/panda_*.yaml``, every extension on), regulating to the goal of
``launch/panda_demo.launch.py`` and holding it, in the same run (``--no-panda`` skips it).

    python -m experiments.benchmark [--duration 30] [--composed-duration 60]
        [--prewarm-lead S] [--thread-priority P] [--out results/bench]

``--prewarm-pairs N`` runs only the comparison behind the controller's ``prewarm_lead``: N pairs
of two-process runs, the throwaway tick off then on, each ``--duration`` s, not pinned and then
pinned.
"""
import argparse
import json
import os
from pathlib import Path
import random
import statistics
import sys
import time
from typing import Optional

from experiments import local_ros
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller import Controller, GoalRequest
from quat_jt_controller.model import RobotModel
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_runtime import realtime
from quat_jt_runtime.resources import default_urdf_xml

CONTROLLER = 'quat_jt_controller'
TARGETS = {'command rate (Hz)': '>= 995', 'missed ticks (%)': 'two: floor + 0.1 pt; composed: 0',
           'latency p99 (ms)': '<= 1.0', 'compute p50 (us)': '<= 25 (two processes)',
           'CPU per node (%)': '<= 30 per node', 'lockstep (x real time)': '>= 3 / >= 6'}


def xarm6_urdf_xml() -> str:
    import pybullet_data
    return (Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf').read_text()


def core_ticks(regulator: Regulator, q, qdot, n: int = 20000) -> dict:
    """Time the node's tick (``Regulator.update``) in one process: best of 5 batches."""
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n // 5):
            regulator.update(q, qdot)
        times.append((time.perf_counter() - t0) / (n // 5))
    best = min(times)
    return {'us_per_tick': best * 1e6, 'ticks_per_s': 1.0 / best}


def controller_ticks(controller: Controller, q, qdot, n: int = 20000) -> dict:
    """
    Time the node's whole tick without ROS (``Controller.on_state``): best of 5 batches.

    States 1 ms apart in stamps and on the steady clock, as the node gets them at 1 kHz: the
    state check, the goal's hold and stream, ``Regulator.update``, the stall's 10 Hz look,
    feedback decimation.
    """
    names = controller.regulator.model.joint_names
    times = []
    k = 0
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n // 5):
            k += 1
            controller.on_state(names, q, qdot, k * 1_000_000, k * 1_000_000, k * 1_000_000)
        times.append((time.perf_counter() - t0) / (n // 5))
    best = min(times)
    return {'us_per_tick': best * 1e6, 'ticks_per_s': 1.0 / best,
            'tick': "Controller.on_state (the node's tick without ROS)"}


def core_benchmark() -> dict:
    import pybullet_data
    from quat_jt_controller.controller_config import controller_from_package_config

    panda_urdf = (Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf').read_text()
    home7 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]

    def panda_at_home(overrides=None) -> Regulator:
        """Return the Panda's config regulating to its home pose, q* = home (+ ``overrides``)."""
        reg = controller_from_package_config('panda_controller.yaml', panda_urdf, 'tanh',
                                             overrides)
        goal = reg.pose(home7)
        reg.set_goal(goal)
        reg.set_goal_configuration(goal, home7)
        return reg

    q7 = [0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.9]
    # also near its goal: the settling damping (psi = 1) and the friction compensation
    # (outside its band) both act, the tick's most expensive place; and without the settling
    # damping there: what the term costs
    panda_tick, panda_near = panda_at_home(), panda_at_home()
    unsettled = panda_at_home({'settling_damping_rate': 0.0})
    wrist = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    g3 = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    xarm = RobotModel(xarm6_urdf_xml(), 'link_base', 'link6')
    g6 = cl.Gains.create('tanh', (300.0,) * 3 + paper.KP, (2.0,) * 6, (20.0,) * 3 + paper.LAMBDA,
                         cl.Task.POSE, 6)
    goal6 = Regulator(xarm, cl.Task.POSE, g6).pose([0.3, -0.2, -0.6, 0.1, 0.7, 0.2])
    wrist_controller = Controller(Regulator(wrist, cl.Task.ORIENTATION, g3), 0.5, 10)
    wrist_controller.on_goal(GoalRequest('', quat.to_xyzw(paper.Q_DESIRED), (0.0, 0.0, 0.0)), 0)
    return {
        'wrist 3-DOF orientation': core_ticks(
            Regulator(wrist, cl.Task.ORIENTATION, g3, goal=Goal(paper.Q_DESIRED)),
            [0.3, 0.5, -0.2], [0.1, 0.1, 0.1]),
        'xArm6 6-DOF pose': core_ticks(Regulator(xarm, cl.Task.POSE, g6, goal=goal6),
                                       [0.1, -0.3, -0.8, 0.2, 0.9, -0.1], [0.1] * 6),
        'Panda 7-DOF pose, its config (every extension on)': core_ticks(
            panda_tick, q7, [0.1] * 7),
        'Panda 7-DOF pose, its config, 0.01 rad from its goal': core_ticks(
            panda_near, [v + 0.01 for v in home7], [0.1] * 7),
        'Panda 7-DOF pose, the same without the settling damping': core_ticks(
            unsettled, [v + 0.01 for v in home7], [0.1] * 7),
        'wrist 3-DOF orientation, the whole tick': controller_ticks(
            wrist_controller, [0.3, 0.5, -0.2], [0.1, 0.1, 0.1]),
    }


def _cpu_seconds(pid: int) -> float:
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _cpu_times() -> list[int]:
    """Aggregate CPU jiffies of the machine: user nice system idle iowait irq softirq steal."""
    return [int(v) for v in Path('/proc/stat').read_text().split('\n', 1)[0].split()[1:9]]


def baseline_benchmark(duration_s: float, warmup_s: float, out: Path,
                       cpus: tuple[tuple[int, ...], tuple[int, ...]] = ((), ()),
                       thread_priority: Optional[int] = None) -> dict:
    """
    Run the minimal pair; return its loop statistics (LoopStats.summary of its sim).

    ``cpus``: the CPUs of its sim and its controller, as for :func:`loop_benchmark`;
    ``thread_priority``: its ``--priority`` (None: the nodes' default, as the nodes).
    """
    out = out / ('baseline_pinned' if any(cpus) else 'baseline')
    out.mkdir(parents=True, exist_ok=True)
    env = local_ros.isolated_env(out, random.randint(1, 100))
    stats_file = out / 'minimal_pair_stats.json'
    stats_file.unlink(missing_ok=True)
    priority = () if thread_priority is None else (f'--priority={thread_priority}',)
    sim_cpus, ctrl_cpus = (tuple(a for c in each for a in ('--cpu', str(c))) + priority
                           for each in cpus)
    ctrl = local_ros.spawn_node('minimal_pair', env, out, name='minimal_controller',
                                args=('--role', 'controller', *ctrl_cpus))
    sim = local_ros.spawn_node('minimal_pair', env, out, name='minimal_sim',
                               args=('--role', 'sim', '--duration', str(duration_s),
                                     '--warmup', str(warmup_s), '--stats', str(stats_file),
                                     *sim_cpus))
    host0 = _cpu_times()
    try:
        sim.wait(timeout=duration_s + warmup_s + 60.0)
    finally:
        local_ros.stop_nodes((sim, ctrl))
    host = [b - a for a, b in zip(host0, _cpu_times())]
    if not stats_file.exists():
        raise RuntimeError(f'the minimal pair wrote no statistics; logs in {out}')
    return {**json.loads(stats_file.read_text()),
            'host_steal_percent': 100.0 * host[7] / max(sum(host), 1)}


# The 7-DOF run: the package's Panda configs and the goal of launch/panda_demo.launch.py (the
# flange's pose at q = (0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.9), 0.25 m from the start).
PANDA_GOAL = ('panda_link0', (0.3514, 0.2278, 0.6777), (-0.9678, 0.2055, -0.1104, 0.0942))


def loop_benchmark(duration_s: float, warmup_s: float, out: Path, composed: bool = False,
                   cpus: tuple[tuple[int, ...], tuple[int, ...]] = ((), ()),
                   controller_params: Optional[dict] = None, robot: str = 'wrist',
                   thread_priority: Optional[int] = None) -> dict:
    """
    Measure the real-time loop of the two nodes: two processes, or composed in one.

    ``cpus``: the simulator's and the controller's ``cpu_affinity`` (composed: the process is
    pinned to both); empty = not pinned. ``controller_params`` override the paper's config.
    ``robot='panda'``: the Panda with ``config/panda_*.yaml`` (two processes), to PANDA_GOAL.
    ``thread_priority``: both nodes' (None: their default).
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from experiments.probe import ProbeNode
    from geometry_msgs.msg import PoseStamped

    out = out / ((f'{robot}_' if robot != 'wrist' else '') + (
        'composed' if composed else 'two_processes_pinned' if any(cpus) else 'two_processes'))
    out.mkdir(parents=True, exist_ok=True)
    domain_id = random.randint(1, 100)
    env = local_ros.isolated_env(out, domain_id)
    stats_file = out / 'sim_stats.json'
    stats_file.unlink(missing_ok=True)
    # The simulator's statistics cover the measured interval: it is stopped right after it.
    sim_params = {'stats_file': str(stats_file),
                  'stats_window_steps': max(int(duration_s * 1000), 100)}
    controller_params = {'potential': 'tanh', **(controller_params or {})}
    configs = {}
    if robot == 'panda':
        import pybullet_data
        urdf = {'robot_description': (Path(pybullet_data.getDataPath()) / 'franka_panda'
                                      / 'panda.urdf').read_text()}
        sim_params.update(urdf)
        controller_params.update(urdf)
        configs = {'sim_config': 'config/panda_sim.yaml',
                   'controller_config': 'config/panda_controller.yaml'}
        frame, position, xyzw = PANDA_GOAL
    else:
        sim_params['coulomb_friction'] = [0.0] * 3
        frame, position, xyzw = 'base_link', (0.0, 0.0, 0.0), quat.to_xyzw(paper.Q_DESIRED)
    for params, cpu_affinity in zip((sim_params, controller_params), cpus):
        if cpu_affinity:
            params['cpu_affinity'] = list(cpu_affinity)
        if thread_priority is not None:
            params['thread_priority'] = thread_priority
    sim, ctrl = local_ros.spawn_wrist_pair(env, out, sim_params=sim_params,
                                           controller_params=controller_params,
                                           composed=composed, **configs)
    procs = {sim.pid: sim, ctrl.pid: ctrl}  # one entry when composed
    probe = ProbeNode('benchmark_probe', domain_id)
    node, executor = probe.node, probe.executor
    windows: list[dict] = []
    measuring = [False]

    def on_diag(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith('control loop') and measuring[0]:
                windows.append({kv.key: kv.value for kv in status.values})

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 10)
    goal_pub = node.create_publisher(PoseStamped, f'/{CONTROLLER}/target_pose', 10)

    def spin_for(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for proc in (sim, ctrl):
                if proc.poll() is not None:
                    raise RuntimeError(f'a node exited early ({proc.returncode}); logs in {out}')
            executor.spin_once(timeout_sec=min(0.1, max(end - time.monotonic(), 0.0)))

    try:
        mode = ('composed' if composed else
                'two processes, pinned' if any(cpus) else 'two processes')
        print(f'loop ({robot}, {mode}): starting the nodes '
              f'(domain {domain_id}), warm-up {warmup_s} s')
        goal = PoseStamped()
        goal.header.frame_id = frame
        o, p = goal.pose.orientation, goal.pose.position
        o.x, o.y, o.z, o.w = xyzw
        p.x, p.y, p.z = position
        spin_for(2.0)
        goal_pub.publish(goal)
        spin_for(warmup_s)
        cpu0 = {pid: _cpu_seconds(pid) for pid in procs}
        host0 = _cpu_times()
        t0 = time.monotonic()
        measuring[0] = True
        print(f'loop: measuring {duration_s} s')
        spin_for(duration_s)
        measuring[0] = False
        wall = time.monotonic() - t0
        cpu = {pid: 100.0 * (_cpu_seconds(pid) - cpu0[pid]) / wall for pid in procs}
        host = [b - a for a, b in zip(host0, _cpu_times())]
    finally:
        # the sim first: its statistics end with the controller alive
        local_ros.stop_nodes((sim, ctrl))
        probe.close()
    sim_stats = json.loads(stats_file.read_text())
    if not windows:
        raise RuntimeError(f'no controller diagnostics received; logs in {out}')
    full = [w for w in windows if int(w['ticks_in_window']) > 0]
    passes = [int(w.get('prewarm_passes_total', 0)) for w in full]
    logs = ''.join(path.read_text(errors='replace') for path in out.glob('*.log'))
    return {
        'duration_s': wall,
        'sched_fifo': 'every thread at SCHED_FIFO' in logs,  # thread_priority applied
        'sim': sim_stats,
        'controller_windows': full,
        'cpu_percent': ({'composed': cpu[sim.pid]} if composed else
                        {'wrist_sim_node': cpu[sim.pid], 'controller_node': cpu[ctrl.pid]}),
        'host_steal_percent': 100.0 * host[7] / max(sum(host), 1),
        'command_rate_hz': statistics.mean(float(w['control_rate_hz']) for w in full),
        'compute_us_p50': statistics.median(float(w['compute_us_p50']) for w in full),
        'compute_us_p99': max(float(w['compute_us_p99']) for w in full),
        # throwaway ticks (prewarm_lead) per state, over the windows after the first
        'prewarm_per_state': (passes[-1] - passes[0]) / max(
            sum(int(w['ticks_in_window']) for w in full[1:]), 1),
    }


def _loop_rows(s: dict) -> list[str]:
    """Missed ticks, jitter and latency from a LoopStats summary, as table cells."""
    return [f'{100.0 * s["window_stale_steps"] / s["window_steps"]:.3f} '
            f'({s["window_stale_steps"]} of {s["window_steps"]})',
            f'{s["jitter_us_p50"]:.1f} / {s["jitter_us_p99"]:.1f} / {s["jitter_us_max"]:.1f}',
            f'{s["cmd_latency_us_p50"] / 1e3:.3f} / {s["cmd_latency_us_p99"] / 1e3:.3f} / '
            f'{s["cmd_latency_us_max"] / 1e3:.3f}']


def lockstep_benchmark(out: Path, duration_s: float = 20.0) -> dict:
    """Run the paper experiment (tanh) in lockstep in both modes: how many times real time."""
    from experiments.paper_experiment import run_once

    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    factors = {}
    for mode, composed in (('two processes', False), ('composed', True)):
        run = run_once('tanh', duration_s, out / 'lockstep' / mode.replace(' ', '_'), model,
                       lockstep=True, composed=composed, progress=lambda *_: None)
        factors[mode] = {'real_time_factor': duration_s / run.recording_wall_s,
                         'missing_states': run.missing_states}
        print(f'lockstep ({mode}): {factors[mode]["real_time_factor"]:.2f}x real time')
    return factors


def _window_range(loop: dict) -> str:
    """Return the lowest and highest p50 compute time of the controller's 1 s windows (us)."""
    p50s = [float(w['compute_us_p50']) for w in loop['controller_windows']]
    return f'{min(p50s):.0f}-{max(p50s):.0f}'


PINNED = 'two processes, pinned'
UNPINNED = 'two processes, not pinned'
COMPOSED = 'composed'
PANDA = 'Panda 7-DOF pose, two processes'


def pinned_layout() -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Return the CPUs of the simulator (the first this process may use) and the controller."""
    cpus = sorted(realtime.allowed_cpus())
    return ((cpus[0],), (cpus[1],)) if len(cpus) >= 2 else ((), ())


def report(loops: dict, baselines: dict, core: dict, lockstep: dict,
           layout: tuple[tuple[int, ...], tuple[int, ...]],
           prewarm_text: str = 'its default', priority_text: str = 'its default') -> str:
    """
    Return the figures as a markdown table: each mode beside the minimal pair run the same way.

    ``loops`` and ``baselines`` are keyed by mode (PINNED, UNPINNED; loops also COMPOSED).
    """
    modes = [m for m in (PINNED, UNPINNED) if m in loops]
    columns = [(loops[m], baselines[m]) for m in modes] + [(loops[COMPOSED], None)]
    header = []
    for m in modes:
        header += [m, f'minimal pair, {"pinned" if m == PINNED else "not pinned"}']
    header.append(f'composed ({loops[COMPOSED]["duration_s"]:.0f} s)')
    if PANDA in loops:
        columns.append((loops[PANDA], None))
        header.append(PANDA + (', pinned' if any(layout) else ''))

    def cells(ours, floor=None, node=None) -> list[str]:
        """One row: ``ours(loop)`` per mode, ``floor(baseline)`` beside it ('' if None)."""
        out = []
        for loop, base in columns:
            out.append(ours(loop))
            if base is not None:
                out.append(floor(base) if floor else '')
        return out

    def cpu(loop: dict) -> str:
        c = loop['cpu_percent']
        return (f'{c["composed"]:.0f}' if 'composed' in c else
                f'{c["wrist_sim_node"]:.0f} / {c["controller_node"]:.0f}')

    def lock(mode: str) -> str:
        f = lockstep[mode]
        return f'{f["real_time_factor"]:.2f}' + (
            f' ({f["missing_states"]} states lost)' if f['missing_states'] else '')

    rows = [
        ('state rate (Hz)', *cells(lambda r: f'{r["sim"]["window_rate_hz"]:.1f}',
                                   lambda b: f'{b["window_rate_hz"]:.1f}'), ''),
        ('command rate (Hz)', *cells(lambda r: f'{r["command_rate_hz"]:.1f}'),
         TARGETS['command rate (Hz)']),
        ('missed ticks: steps without a fresh command (%)',
         *cells(lambda r: _loop_rows(r['sim'])[0], lambda b: _loop_rows(b)[0]),
         TARGETS['missed ticks (%)']),
        ('late publications (> half a period; in the window)',
         *cells(lambda r: str(r['sim']['window_late_steps']),
                lambda b: str(b['window_late_steps'])), ''),
        ('period jitter p50 / p99 / max (us)',
         *cells(lambda r: _loop_rows(r['sim'])[1], lambda b: _loop_rows(b)[1]), ''),
        ('latency p50 / p99 / max (ms)',
         *cells(lambda r: _loop_rows(r['sim'])[2], lambda b: _loop_rows(b)[2]),
         TARGETS['latency p99 (ms)']),
        ('controller compute p50 (lowest-highest 1 s window) / p99 (us)',
         *cells(lambda r: f'{r["compute_us_p50"]:.1f} ({_window_range(r)}) / '
                          f'{r["compute_us_p99"]:.1f}'),
         TARGETS['compute p50 (us)']),
        ('controller throwaway ticks before a state (prewarm_lead; % of states)',
         *cells(lambda r: f'{100.0 * r.get("prewarm_per_state", 0.0):.0f}'), ''),
        ('sim step + publish p50 / p99 (us)',
         *cells(lambda r: f'{r["sim"]["step_compute_us_p50"]:.1f} / '
                          f'{r["sim"]["step_compute_us_p99"]:.1f}'), ''),
        ('CPU % (sim / controller, or the one process)', *cells(cpu),
         TARGETS['CPU per node (%)']),
        ('host CPU steal during the run (%)',
         *cells(lambda r: f'{r["host_steal_percent"]:.1f}',
                lambda b: f'{b["host_steal_percent"]:.1f}'), ''),
    ]
    lines = ['| figure | ' + ' | '.join(header) + ' | target |',
             '|---' * (len(header) + 2) + '|']
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    lines += ['', f'Pinned: simulator on CPU {list(layout[0])}, controller on CPU '
              f'{list(layout[1])} (``cpu_affinity``); the minimal pair likewise. The '
              f"controller's prewarm_lead: {prewarm_text}. The nodes' thread_priority: "
              f'{priority_text}; SCHED_FIFO in '
              f'{sum(1 for r in loops.values() if r.get("sched_fifo"))} of {len(loops)} runs '
              '(the lockstep runs: never).', '',
              '| figure | two processes | composed | target |', '|---|---|---|---|',
              f'| paper experiment in lockstep (x real time) | {lock("two processes")} | '
              f'{lock("composed")} | {TARGETS["lockstep (x real time)"]} |']
    for name, c in core.items():
        lines.append(f'| core tick {c.get("tick", "Regulator.update")}, {name} (us; ticks/s) | '
                     f'{c["us_per_tick"]:.1f}; {c["ticks_per_s"]:,.0f} | | |')
    return '\n'.join(lines)


def prewarm_comparison(duration_s: float, warmup_s: float, out: Path,
                       pairs: int) -> tuple[str, list[dict]]:
    """
    Run two processes with the controller's ``prewarm_lead`` 0, then its default.

    ``pairs`` times, alternating, so that both see the same host; not pinned, then pinned as
    in the benchmark (with at least 2 CPUs). Return a markdown table of each run and the
    means, and the figures of each run.
    """
    columns = (('compute p50 (us)', 'compute_us_p50', 1),
               ('missed ticks (%)', 'missed_pct', 3),
               ('latency p50 (ms)', 'latency_ms_p50', 3),
               ('latency p99 (ms)', 'latency_ms_p99', 3),
               ('CPU sim (%)', 'cpu_sim_pct', 1), ('CPU controller (%)', 'cpu_controller_pct', 1),
               ('throwaway ticks (% of states)', 'prewarm_pct', 0))
    layout = pinned_layout()
    modes = [('not pinned', ((), ()))] + ([('pinned', layout)] if any(layout) else [])
    runs, rows = [], []
    for mode, cpus in modes:
        for k in range(pairs):
            for label, params in (('off (prewarm_lead 0)', {'prewarm_lead': 0.0}),
                                  ('on (its default)', {})):
                loop = loop_benchmark(
                    duration_s, warmup_s,
                    out / f'prewarm_{mode.replace(" ", "_")}_{k}_{label[:3].strip()}',
                    cpus=cpus, controller_params=params)
                s, cpu = loop['sim'], loop['cpu_percent']
                run = {'mode': mode, 'pair': k + 1, 'prewarm': label,
                       'compute_us_p50': loop['compute_us_p50'],
                       'missed_pct': 100.0 * s['window_stale_steps'] / s['window_steps'],
                       'latency_ms_p50': s['cmd_latency_us_p50'] / 1e3,
                       'latency_ms_p99': s['cmd_latency_us_p99'] / 1e3,
                       'cpu_sim_pct': cpu['wrist_sim_node'],
                       'cpu_controller_pct': cpu['controller_node'],
                       'prewarm_pct': 100.0 * loop['prewarm_per_state'],
                       'steal_pct': loop['host_steal_percent']}
                runs.append(run)
                rows.append(f'| {mode} | {k + 1} | {label} | ' + ' | '.join(
                    f'{run[key]:.{d}f}' for _, key, d in columns) +
                    f' | {run["steal_pct"]:.1f} |')
        for label in dict.fromkeys(run['prewarm'] for run in runs):
            mine = [run for run in runs if run['prewarm'] == label and run['mode'] == mode]
            rows.append(f'| {mode} | mean | {label} | ' + ' | '.join(
                f'{statistics.mean(run[key] for run in mine):.{d}f}' for _, key, d in columns) +
                ' | |')
    header = ' | '.join(title for title, _, _ in columns)
    return '\n'.join([f'| mode | pair | prewarm | {header} | steal (%) |',
                      '|---' * (len(columns) + 4) + '|', *rows]), runs


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--duration', type=float, default=30.0,
                        help='measured seconds of each two-process run and minimal pair')
    parser.add_argument('--composed-duration', type=float, default=60.0,
                        help='measured seconds of the composed run')
    parser.add_argument('--lockstep-duration', type=float, default=20.0,
                        help='simulated seconds of each lockstep paper experiment')
    parser.add_argument('--prewarm-lead', type=float, default=None,
                        help="the controller's prewarm_lead (s) in the two-process runs; "
                             'default: its own default (0 = off)')
    parser.add_argument('--thread-priority', type=int, default=None,
                        help="both nodes' and the minimal pair's thread_priority in the "
                        "real-time runs (default: the nodes' default; 0: normal scheduling)")
    parser.add_argument('--warmup', type=float, default=3.0)
    parser.add_argument('--out', type=Path, default=Path('results/bench'))
    parser.add_argument('--page', type=Path,
                        help='also write the figures to this generated page (make bench: '
                        'docs/benchmark_latest.md)')
    parser.add_argument('--no-panda', action='store_true',
                        help='skip the Panda run (7-DOF, pose task, its product configs)')
    parser.add_argument('--prewarm-pairs', type=int, default=0,
                        help='instead of the benchmark: this many pairs of two-process runs, '
                             'prewarm off then on (--duration s each), not pinned then pinned')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.prewarm_lead is not None and args.prewarm_lead < 0.0:
        parser.error(f'--prewarm-lead must be >= 0 s, got {args.prewarm_lead}')
    if args.prewarm_pairs > 0:
        if args.prewarm_lead is not None:
            parser.error('--prewarm-pairs compares prewarm_lead 0 with its default: '
                         'no --prewarm-lead with it')
        text, runs = prewarm_comparison(args.duration, args.warmup, args.out,
                                        args.prewarm_pairs)
        (args.out / 'prewarm.md').write_text(text + '\n')
        (args.out / 'prewarm.json').write_text(json.dumps(runs, indent=1))
        print()
        print(text)
        return 0
    print('core: timing the control tick in one process')
    core = core_benchmark()
    layout = pinned_layout()
    loops, baselines = {}, {}
    prewarm = {} if args.prewarm_lead is None else {'prewarm_lead': args.prewarm_lead}
    for mode, cpus in ((PINNED, layout), (UNPINNED, ((), ()))):
        if mode == PINNED and not any(cpus):
            print('fewer than 2 CPUs: no pinned run')
            continue
        print(f'baseline ({mode}): a minimal rclpy pair for {args.duration} s')
        baselines[mode] = baseline_benchmark(args.duration, args.warmup, args.out, cpus,
                                             args.thread_priority)
        loops[mode] = loop_benchmark(args.duration, args.warmup, args.out, cpus=cpus,
                                     controller_params=prewarm,
                                     thread_priority=args.thread_priority)
    loops[COMPOSED] = loop_benchmark(args.composed_duration, args.warmup, args.out,
                                     composed=True, thread_priority=args.thread_priority)
    if not args.no_panda:
        loops[PANDA] = loop_benchmark(args.duration, args.warmup, args.out, cpus=layout,
                                      controller_params=dict(prewarm), robot='panda',
                                      thread_priority=args.thread_priority)
    lockstep = lockstep_benchmark(args.out, args.lockstep_duration)
    text = report(loops, baselines, core, lockstep, layout,
                  'its default' if args.prewarm_lead is None else f'{args.prewarm_lead:g} s',
                  f'its default ({realtime.DEFAULT_THREAD_PRIORITY})'
                  if args.thread_priority is None else str(args.thread_priority))
    (args.out / 'bench.json').write_text(json.dumps(
        {'loops': loops, 'core': core, 'baselines': baselines, 'lockstep': lockstep,
         'pinned_layout': layout}, indent=1))
    (args.out / 'bench.md').write_text(text + '\n')
    print()
    print(text)
    print(f'\n(machine: {os.cpu_count()} cores; raw figures in {args.out / "bench.json"})')
    if args.page:
        command = ['python -m experiments.benchmark'] + list(
            sys.argv[1:] if argv is None else argv)
        args.page.write_text(page(text, ' '.join(command)))
        print(f'wrote {args.page}')
    return 0


def page(report_text: str, command: str, ended: Optional[str] = None) -> str:
    """
    Return the generated page of the latest figures (docs/benchmark_latest.md).

    One run, as the benchmark printed it, with when and where it ran; no history: the next run
    overwrites it.
    """
    ended = ended or time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())
    return '\n'.join([
        '# The 1 kHz loop: the latest benchmark',
        '',
        f'Generated by `{command}` (`make bench`), which overwrites this page; run ended '
        f'{ended}, on a machine with {os.cpu_count()} cores. How each figure is measured, the '
        'targets and what they mean: [benchmark.md](benchmark.md).',
        '',
        report_text,
        ''])


if __name__ == '__main__':
    sys.exit(main())

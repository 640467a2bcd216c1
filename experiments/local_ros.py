"""
Run this package's nodes as separate processes on a private, loopback-only ROS graph.

Used by the multi-process tests, the paper experiment and the benchmark, standing in for
``ros2 launch`` (launch/launch_ros are not on PyPI). ROS-free: it only builds environments and
starts processes; the nodes themselves talk over real DDS.
"""
from dataclasses import dataclass
import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
from typing import Any, Mapping, Optional, Sequence

from quat_jt_runtime.resources import share_path

REPOSITORY = Path(__file__).resolve().parent.parent  # the folder that holds experiments/

# How each executable starts: the package's nodes through their console-script entry points
# (the stop flag before the slow imports, as ``ros2 run`` does), the baseline as a module.
NODE_COMMANDS = {
    'controller_node': ('-m', 'quat_jt_bringup.entry_points', 'controller_node'),
    'wrist_sim_node': ('-m', 'quat_jt_bringup.entry_points', 'wrist_sim_node'),
    'composed': ('-m', 'quat_jt_bringup.entry_points', 'composed'),  # both in one process
    'minimal_pair': ('-m', 'experiments.minimal_pair'),  # the benchmark's baseline
}


def isolated_env(work_dir: Path, domain_id: Optional[int] = None,
                 base: Optional[Mapping[str, str]] = None) -> dict[str, str]:
    """
    Build the environment of a private ROS graph.

    Localhost-only discovery, its own domain id, ROS_HOME and ROS_LOG_DIR under ``work_dir``,
    and the repository on PYTHONPATH (``experiments`` is not installed; the minimal pair and
    the tools' subprocesses import it from any working directory).
    """
    env = dict(os.environ if base is None else base)
    env['PYTHONPATH'] = os.pathsep.join(
        p for p in (str(REPOSITORY), env.get('PYTHONPATH', '')) if p)
    work_dir = Path(work_dir)
    (work_dir / 'log').mkdir(parents=True, exist_ok=True)
    env.update({
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_DOMAIN_ID': str(domain_id if domain_id is not None else random.randint(1, 100)),
        'ROS_HOME': str(work_dir),
        'ROS_LOG_DIR': str(work_dir / 'log'),
        'RCUTILS_COLORIZED_OUTPUT': '0',
        'PYTHONUNBUFFERED': '1',
    })
    env.pop('ROS_STATIC_PEERS', None)
    return env


def keep_this_process_local() -> None:
    """
    Make this process's own ROS traffic loopback-only, before its ``rclpy.init``.

    The tools' own node (the recorder, the probe) would otherwise discover over the subnet
    (Jazzy's default range). Its logs go under a temporary folder unless ROS_LOG_DIR is set.
    """
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.pop('ROS_STATIC_PEERS', None)
    if 'ROS_LOG_DIR' not in os.environ:
        os.environ['ROS_LOG_DIR'] = tempfile.mkdtemp(prefix='qjt_tool_log_')


def write_params_file(path: Path, params: Mapping[str, Any], node: str = '/**') -> Path:
    """Write a ROS 2 parameter file (JSON is valid YAML) for ``--params-file``."""
    path = Path(path)
    path.write_text(json.dumps({node: {'ros__parameters': dict(params)}}, indent=1))
    return path


def spawn_node(executable: str, env: Mapping[str, str], work_dir: Path,
               params: Optional[Mapping[str, Any]] = None,
               params_files: tuple[Path, ...] = (), ros_args: tuple[str, ...] = (),
               name: Optional[str] = None, args: tuple[str, ...] = ()) -> subprocess.Popen:
    """
    Start ``executable`` (a key of NODE_COMMANDS) as ``python -m ... --ros-args ...``.

    ``args`` go before ``--ros-args``. Its stdout and stderr go to ``work_dir/<name>.log``. It
    leads a process group of its own, as a command started from a terminal does: Ctrl-C
    (:func:`stop_node`) goes to the whole group.
    """
    name = name or executable
    work_dir = Path(work_dir)
    argv = [sys.executable, *NODE_COMMANDS[executable], *args, '--ros-args']
    for f in params_files:
        argv += ['--params-file', str(f)]
    if params:
        argv += ['--params-file', str(write_params_file(work_dir / f'{name}.params.yaml',
                                                        params))]
    argv += list(ros_args)
    log = open(work_dir / f'{name}.log', 'wb')
    try:
        return subprocess.Popen(argv, env=dict(env), stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
    finally:
        log.close()


PAPER_CONTROLLER_CONFIG = 'config/paper_wrist_controller.yaml'  # the paper's experiment
PRODUCT_CONTROLLER_CONFIG = 'config/wrist_controller.yaml'  # designed gains, the extensions


def spawn_wrist_pair(env: Mapping[str, str], work_dir: Path,
                     sim_params: Optional[Mapping[str, Any]] = None,
                     controller_params: Optional[Mapping[str, Any]] = None,
                     controller_config: str = PAPER_CONTROLLER_CONFIG,
                     composed: bool = False,
                     sim_config: str = 'config/wrist_sim.yaml'
                     ) -> tuple[subprocess.Popen, subprocess.Popen]:
    """
    Start ``wrist_sim_node`` and ``controller_node`` as the demos do.

    Each reads the package's ``sim_config`` (by default ``config/wrist_sim.yaml``) /
    ``controller_config`` (by default ``config/paper_wrist_controller.yaml``, the paper's
    experiment), then the given overrides (``robot_description`` for another robot).
    Returns ``(sim, controller)``; with ``composed`` both run in one ``composed`` process,
    returned twice.
    """
    if composed:
        both = spawn_node('composed', env, work_dir,
                          params={**(sim_params or {}), **(controller_params or {})},
                          params_files=(share_path(sim_config),
                                        share_path(controller_config)))
        return both, both
    sim = spawn_node('wrist_sim_node', env, work_dir, params=sim_params,
                     params_files=(share_path(sim_config),))
    controller = spawn_node('controller_node', env, work_dir, params=controller_params,
                            params_files=(share_path(controller_config),))
    return sim, controller


def interrupt_group(proc: subprocess.Popen) -> None:
    """Send SIGINT to ``proc``'s process group, as a terminal's Ctrl-C does."""
    try:
        os.killpg(proc.pid, signal.SIGINT)  # spawn_node made it a group leader
    except ProcessLookupError:
        pass


@dataclass
class RecordedPair:
    """A wrist pair on a private domain whose simulator writes its statistics at shutdown."""

    domain_id: int
    env: dict[str, str]
    sim: subprocess.Popen
    controller: subprocess.Popen
    stats_file: Path

    def stop(self) -> dict:
        """Ctrl-C both (the simulator first); return its statistics ({} if none came)."""
        stop_nodes((self.sim, self.controller))
        try:
            return json.loads(self.stats_file.read_text())
        except (OSError, ValueError):
            return {}


def spawn_recorded_pair(work_dir: Path, sim_params: Optional[Mapping[str, Any]] = None,
                        **pair_options: Any) -> RecordedPair:
    """
    :func:`spawn_wrist_pair` in ``work_dir`` on a new private domain, with ``stats_file`` set.

    ``pair_options`` go to :func:`spawn_wrist_pair` (controller params and config, composed).
    """
    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    domain_id = random.randint(1, 100)
    env = isolated_env(work_dir, domain_id)
    stats_file = work_dir / 'sim_stats.json'
    stats_file.unlink(missing_ok=True)
    sim, controller = spawn_wrist_pair(
        env, work_dir, sim_params={'stats_file': str(stats_file), **(sim_params or {})},
        **pair_options)
    return RecordedPair(domain_id, env, sim, controller, stats_file)


def stop_nodes(procs: Sequence[subprocess.Popen], timeout: float = 10.0) -> list[int]:
    """
    Ctrl-C each process group in turn, then SIGKILL every group left; return the exit codes.

    Each gets ``timeout`` to exit after its Ctrl-C. One that does not is killed with all the
    others still running before any is waited for: two nodes pinned to one CPU in SCHED_FIFO
    can starve each other, and a process must run to die, so waiting for one to die while the
    other spins would wait for ever.
    """
    for proc in procs:
        if proc.poll() is None:
            interrupt_group(proc)
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                break
    for proc in procs:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    return [proc.wait() for proc in procs]


def stop_node(proc: subprocess.Popen, timeout: float = 10.0) -> int:
    """Ctrl-C the process group, then SIGKILL it if it does not exit in ``timeout``: its code."""
    return stop_nodes([proc], timeout)[0]

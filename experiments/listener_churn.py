"""
Listeners joining the nodes' topics: whether a ``ros2 topic echo`` delays the 1 kHz loop.

For each topic the nodes publish, a fresh wrist pair (``config/wrist_sim.yaml`` and the product
``config/wrist_controller.yaml``, real time, as a user runs them) is started on a private
loopback graph, and ``--listeners`` short-lived processes join that topic one after another, as
``ros2 topic echo --once`` does: each starts rclpy, subscribes with the QoS the publishers
offer, takes one message and exits. The figures are the nodes' own statistics:

- the controller's largest period between two ticks, from its ``/diagnostics``
  (``period_max_us``, one window a second);
- the simulator's largest step period and largest gap between two fresh commands, from its
  ``stats_file`` written at shutdown.

Target: every one of them under 10 ms, whoever joins.

    python -m experiments.listener_churn [--listeners 50] [--topics all] [--out DIR]
"""
import argparse
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from experiments import local_ros
from experiments.probe import ProbeNode
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from quat_jt_runtime import dds_transport
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

# The topics the two nodes publish, with their types (rosidl module, class).
TOPICS = {
    '/quat_jt_controller/orientation_error': ('geometry_msgs.msg', 'Vector3Stamped'),
    '/quat_jt_controller/current_pose': ('geometry_msgs.msg', 'PoseStamped'),
    '/effort_controller/commands': ('std_msgs.msg', 'Float64MultiArray'),
    '/diagnostics': ('diagnostic_msgs.msg', 'DiagnosticArray'),
    '/joint_states': ('sensor_msgs.msg', 'JointState'),
}
TARGET_MS = 10.0
_ = (PoseStamped, Vector3Stamped, JointState, Float64MultiArray)  # the types are importable

# One listener, as ``ros2 topic echo --once TOPIC``: the publishers' reliability and
# durability, one message, exit.
LISTENER = r"""
import importlib, sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, DurabilityPolicy
topic, module, name = sys.argv[1:4]
msg_type = getattr(importlib.import_module(module), name)
rclpy.init()
node = rclpy.create_node('listener_churn_echo')
deadline = time.monotonic() + 20.0
while not node.get_publishers_info_by_topic(topic) and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.05)
infos = node.get_publishers_info_by_topic(topic)
qos = QoSProfile(depth=10)
if infos and all(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos):
    qos.reliability = ReliabilityPolicy.BEST_EFFORT
if infos and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos):
    qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
got = []
node.create_subscription(msg_type, topic, got.append, qos)
while not got and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.05)
node.destroy_node()
rclpy.try_shutdown()
sys.exit(0 if got else 3)
"""


def run_topic(topic: str, listeners: int, out: Path, params: Optional[dict] = None) -> dict:
    """
    Start a pair, let ``listeners`` processes join ``topic`` one after another; figures.

    ``params`` go to both nodes (``thread_priority``, say).
    """
    pair = local_ros.spawn_recorded_pair(
        out, sim_params=params, controller_config=local_ros.PRODUCT_CONTROLLER_CONFIG,
        controller_params=params)
    probe = ProbeNode('listener_churn_probe', pair.domain_id)
    period_max_us: list[float] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith('quat_jt_controller: control loop'):
                for kv in status.values:
                    if kv.key == 'period_max_us' and kv.value != 'nan':
                        period_max_us.append(float(kv.value))

    probe.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    received = 0
    try:
        deadline = time.monotonic() + 60.0
        while len(period_max_us) < 3:  # the loop runs, and its first windows are behind us
            if time.monotonic() > deadline or pair.sim.poll() is not None \
                    or pair.controller.poll() is not None:
                raise RuntimeError(f'the nodes did not start; logs in {out}')
            probe.executor.spin_once(timeout_sec=0.05)
        period_max_us.clear()
        module, name = TOPICS[topic]
        for _ in range(listeners):
            listener = subprocess.Popen([sys.executable, '-c', LISTENER, topic, module, name],
                                        env=pair.env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL)
            while listener.poll() is None:
                probe.executor.spin_once(timeout_sec=0.05)
            received += listener.returncode == 0
        end = time.monotonic() + 2.5  # the last window's diagnostics
        while time.monotonic() < end:
            probe.executor.spin_once(timeout_sec=0.05)
    finally:
        probe.close()
        sim_stats = pair.stop()
    return {'topic': topic, 'listeners': listeners, 'received': received,
            'controller_period_max_ms': max(period_max_us, default=math.nan) / 1e3,
            'controller_windows_over_10ms': sum(p > TARGET_MS * 1e3 for p in period_max_us),
            'sim_period_max_ms': sim_stats.get('period_us_max', math.nan) / 1e3,
            'sim_fresh_gap_max_ms': sim_stats.get('fresh_gap_ms_max', math.nan),
            'sim_missed_deadlines': sim_stats.get('missed_deadlines')}


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--listeners', type=int, default=50, help='listeners per topic')
    parser.add_argument('--topics', nargs='*', default=list(TOPICS),
                        help='topics to join (default: every topic the nodes publish)')
    parser.add_argument('--thread-priority', type=int, default=None,
                        help="both nodes' thread_priority (default: theirs)")
    parser.add_argument('--cpu-affinity', type=int, nargs='*', default=None,
                        help="both nodes' cpu_affinity (default: theirs)")
    parser.add_argument('--shared-memory', action='store_true',
                        help="the nodes on Fast DDS's default transports, shared memory on "
                        '(QUAT_JT_SHARED_MEMORY=1), as before the nodes chose UDP')
    parser.add_argument('--out', type=Path, default=Path('results/listener_churn'))
    args = parser.parse_args(argv)
    if args.shared_memory:  # the nodes inherit this process's environment
        os.environ[dds_transport.OPT_OUT_VARIABLE] = '1'
    params = {}
    if args.thread_priority is not None:
        params['thread_priority'] = args.thread_priority
    if args.cpu_affinity is not None:
        params['cpu_affinity'] = args.cpu_affinity
    rows = []
    print('nodes on ' + ('shared memory (Fast DDS defaults)' if args.shared_memory
                         else 'UDP (their own choice, quat_jt_runtime/dds_transport.py)'))
    print(f'{"topic":40} {"echoes":>6} {"ctrl period max ms":>18} {"windows > 10 ms":>15} '
          f'{"sim period max ms":>17} {"fresh gap max ms":>16}', flush=True)
    for k, topic in enumerate(args.topics):
        r = run_topic(topic, args.listeners, args.out / f'topic{k}', params)
        rows.append(r)
        print(f'{topic:40} {r["received"]:>3}/{r["listeners"]:<2} '
              f'{r["controller_period_max_ms"]:18.1f} {r["controller_windows_over_10ms"]:15d} '
              f'{r["sim_period_max_ms"]:17.1f} {r["sim_fresh_gap_max_ms"]:16.1f}', flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'listener_churn.json').write_text(json.dumps(rows, indent=1))
    worst = max(max(r['controller_period_max_ms'], r['sim_period_max_ms'],
                    r['sim_fresh_gap_max_ms']) for r in rows)
    print(f'worst of all: {worst:.1f} ms (target < {TARGET_MS:.0f} ms)')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
The floor of the host: a minimal rclpy state/command pair, for the benchmark's baseline.

Two processes, like ``wrist_sim_node`` and ``controller_node`` but with nothing to compute:
``--role sim`` publishes a 3-joint ``JointState`` on each 1 kHz tick, with the simulator's own
deadline loop pieces (``realtime``: the answer deadline, the timer slack, the wait for the tick),
and counts how many ticks get an answer in time; ``--role controller`` answers each state at once
with a ``Float64MultiArray``. ``--cpu N`` pins the process, as ``cpu_affinity`` pins a node, and
``--priority P`` (the nodes' default ``thread_priority`` unless given) runs its threads in
SCHED_FIFO as a node's.
The sim's figures use the simulator's own ``LoopStats``, so they compare one to one with
``wrist_sim_node``'s: whatever the real nodes add beyond this pair is theirs, the rest is the
machine.

    python -m experiments.minimal_pair --role controller &
    python -m experiments.minimal_pair --role sim --duration 30 --stats out.json
"""
import argparse
import json
from pathlib import Path
import time

from quat_jt_runtime import realtime
from quat_jt_runtime.loop_stats import LoopStats
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray


def run_controller(node, executor) -> None:
    pub = node.create_publisher(Float64MultiArray, 'effort_controller/commands', 10)
    out = Float64MultiArray(data=[0.0, 0.0, 0.0])

    def answer(msg: JointState) -> None:
        out.data = [msg.position[0], 0.0, 0.0]
        pub.publish(out)
    node.create_subscription(JointState, 'joint_states', answer, 10)
    while rclpy.ok(context=node.context):
        executor.spin_once(timeout_sec=0.5)


def run_sim(node, executor, duration_s: float, warmup_s: float, stats_path: Path) -> None:
    pub = node.create_publisher(JointState, 'joint_states', 10)
    state = {'published': 0, 'answered': 0, 't_pub': 0.0, 'measuring': False}
    stats = LoopStats(capacity=int(duration_s * 1000) + 10)

    def on_command(_msg: Float64MultiArray) -> None:
        if state['answered'] != state['published']:
            if state['measuring']:
                stats.record_latency(time.perf_counter() - state['t_pub'])
            state['answered'] = state['published']
    node.create_subscription(Float64MultiArray, 'effort_controller/commands', on_command, 10)
    js = JointState(name=['joint1', 'joint2', 'joint3'], position=[0.0] * 3,
                    velocity=[0.0] * 3, effort=[0.0] * 3)

    def publish() -> None:
        js.header.stamp = node.get_clock().now().to_msg()
        state['published'] += 1
        state['t_pub'] = clock()
        pub.publish(js)

    realtime.set_timer_slack(1)
    clock = time.perf_counter
    period = 1e-3
    next_t = clock() + period
    measure_from = clock() + warmup_s
    end = measure_from + duration_s
    publish()

    def answered() -> bool:
        return state['answered'] == state['published']
    ok = realtime.RunCheck(lambda: True, node.context.ok)  # as the simulator asks
    while clock() < end and ok():
        realtime.await_answer(executor, answered,
                              realtime.answer_deadline(next_t, state['t_pub'], period), ok)
        fresh = answered()  # (nothing to step)
        now = realtime.wait_for_tick(executor, next_t)
        if state['measuring']:
            if now - next_t > 0.5 * period:
                stats.missed_deadlines += 1
            stats.record_step(now, 0.0, now - next_t, fresh)
        state['measuring'] = now >= measure_from
        publish()
        next_t += period
        skipped = realtime.ticks_to_skip(next_t, period, clock())  # as the simulator does
        if state['measuring']:
            stats.missed_deadlines += skipped
        next_t += skipped * period
    stats_path.write_text(json.dumps(stats.summary(), indent=1))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--role', choices=('sim', 'controller'), required=True)
    parser.add_argument('--duration', type=float, default=30.0)
    parser.add_argument('--warmup', type=float, default=3.0)
    parser.add_argument('--stats', type=Path, default=Path('minimal_pair_stats.json'))
    parser.add_argument('--cpu', type=int, action='append', default=[],
                        help='pin the process to this CPU (repeat for several)')
    parser.add_argument('--priority', type=int, default=realtime.DEFAULT_THREAD_PRIORITY,
                        help="SCHED_FIFO priority of its threads, as a node's thread_priority "
                        '(0: normal scheduling)')
    args, ros_args = parser.parse_known_args(argv)
    rclpy.init(args=ros_args)
    node = rclpy.create_node(f'minimal_{args.role}')
    executor = EventsExecutor()
    executor.add_node(node)
    realtime.pin_process(args.cpu)
    refused = realtime.set_thread_priority(args.priority)
    if refused:
        node.get_logger().warning(f'--priority {args.priority}: {refused}')
    try:
        if args.role == 'sim':
            run_sim(node, executor, args.duration, args.warmup, args.stats)
        else:
            run_controller(node, executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()

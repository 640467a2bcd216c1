"""
Where a tick's time goes: each piece of the controller's and the simulator's tick, timed hot.

Every piece is the code the nodes run (the node's own objects, built as the nodes build them),
called in a loop in this one process: best of 5 batches, in microseconds per call. Publishers
have no subscriber here, so a publish is its local cost only (a cross-process subscriber adds
the transport). The benchmark gives the same tick in the loop, where caches are cold
(``make bench``); the difference between the two is the price of running 1000 times a second
beside another process.

    python -m experiments.tick_profile [--calls 20000]
"""
import argparse
import random
import sys
import time
from typing import Callable, Optional

from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller import Controller, GoalRequest
from quat_jt_controller.model import RobotModel
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_controller.shaping import Shaping
from quat_jt_runtime.joints import stamp_problem, StateLayout, velocity_estimator
from quat_jt_runtime.loop_stats import LoopStats, TickStats
from quat_jt_runtime.resources import default_urdf_xml


def best_us(fn: Callable[[], object], calls: int) -> float:
    """Return the time of one call of ``fn`` in us: the best of 5 batches."""
    batch = max(calls // 5, 1)
    best = float('inf')
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(batch):
            fn()
        best = min(best, (time.perf_counter() - t0) / batch)
    return best * 1e6


def slowest_us(fn: Callable[[], object], calls: int, share: float) -> float:
    """
    Return the time of ``fn``'s slower calls in us: the ``1 - share`` quantile of single calls.

    For work done once in so many calls (``share`` of them), which the batch mean spreads out.
    """
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[min(len(times) - 1, int((1.0 - share) * len(times)))] * 1e6


def sleep_overshoot(executor, sleeps: int, sleep_s: float = 7e-4) -> dict[str, tuple]:
    """
    Measure how late ``executor.spin_once(timeout)`` wakes up: default timer slack, and 1 ns.

    Run in a thread of its own, whose slack is set for it alone. Returns ``{setting: (p50, p99)}``
    in us. The simulator sleeps this way before each tick, then busy-waits the rest.
    """
    import threading

    from quat_jt_runtime import realtime
    result = {}

    def measure(label: str, slack_ns: Optional[int]) -> None:
        if slack_ns is not None:
            realtime.set_timer_slack(slack_ns)
        late = []
        for _ in range(sleeps):
            t0 = time.perf_counter()
            executor.spin_once(timeout_sec=sleep_s)
            late.append((time.perf_counter() - t0 - sleep_s) * 1e6)
        late.sort()
        result[f'{label} ({realtime.timer_slack_ns()} ns)'] = (
            late[len(late) // 2], late[min(len(late) - 1, int(0.99 * len(late)))])

    for label, slack in (('default timer slack', None), ('timer slack set', 1)):
        thread = threading.Thread(target=measure, args=(label, slack))
        thread.start()
        thread.join()
    return result


def profile(calls: int) -> dict[str, dict[str, float]]:
    """Time each piece of both ticks; return ``{'controller': {...}, 'simulator': {...}}``."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from wrist_sim.simulator import RobotSimulator

    from experiments.probe import ProbeNode

    urdf = default_urdf_xml()
    model = RobotModel(urdf, 'base_link', 'tool0')
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    regulator = Regulator(model, cl.Task.ORIENTATION, gains, goal=Goal(paper.Q_DESIRED))
    sim = RobotSimulator(urdf, model.joint_names)
    probe = ProbeNode('tick_profile', random.randint(1, 100))  # a private domain
    try:
        node = probe.node
        js_pub = node.create_publisher(JointState, 'tick_profile/joint_states', 10)
        cmd_pub = node.create_publisher(Float64MultiArray, 'tick_profile/commands', 10)
        js = JointState()
        js.name = list(model.joint_names)
        js.header.stamp.sec, js.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        js.position, js.velocity, js.effort = [0.3, 0.5, -0.2], [0.1, 0.1, 0.1], [0.0] * 3
        raw = serialize_message(js)
        layout = StateLayout(model.joint_names)
        q, qdot = layout.extract(js.name, js.position, js.velocity)
        stamp_ns = js.header.stamp.sec * 1_000_000_000 + js.header.stamp.nanosec
        out = regulator.update(q, qdot)
        # the inertial damping on, so the speed guard: at rest, and every joint past its guard
        # (the guard's damping and the push taken away, docs/lyapunov.md, section 6)
        guarded = Regulator(model, cl.Task.ORIENTATION, gains, goal=Goal(paper.Q_DESIRED),
                            shaping=Shaping.create(3, inertial_damping=(1.0, 1.0, 1.0),
                                                   inertial_damping_rate=222.5))
        fast = [0.95 * v * sign for v, sign in zip(model.velocity_limits, (1.0, -1.0, 1.0))]
        # the rotor inertia estimate on (docs/lyapunov.md, section 13), an arm that moves: its
        # filters every tick, an RNEA and the sums every 4th, the fits every 50th
        estimating = Regulator(model, cl.Task.ORIENTATION, gains, goal=Goal(paper.Q_DESIRED),
                               shaping=Shaping.create(3, armature_estimation_limit=(1.0,) * 3))
        moved = [0]

        def estimating_tick() -> None:
            moved[0] += 1
            s = 1e-4 * (moved[0] % 1000)
            estimating.update([q[0] + s, q[1], q[2]], [qdot[0] + s, qdot[1], qdot[2]], 1e-3)
        cmd = Float64MultiArray(data=[0.0] * 3)
        tick_stats, loop_stats = TickStats(), LoopStats()
        tau = [0.1, -0.1, 0.05]

        ctl = Controller(Regulator(model, cl.Task.ORIENTATION, gains), 0.5, 10, 0.5)
        ctl.on_goal(GoalRequest('', quat.to_xyzw(paper.Q_DESIRED), (0.0, 0.0, 0.0)), 0)
        ticks = [0]

        def whole_tick() -> None:  # a state 1 ms after the last (its stamp's age: 0)
            ticks[0] += 1
            ctl.on_state(js.name, js.position, js.velocity, stamp_ns, stamp_ns,
                         ticks[0] * 1_000_000)

        def set_data() -> None:
            cmd.data = out.tau_nm

        def fill_state() -> None:
            js.position = sim.q_rad.tolist()
            js.velocity = sim.qdot_rad_s.tolist()
            js.effort = sim.tau_applied_nm.tolist()

        def full_window() -> None:
            for k in range(1000):  # one second of ticks, then its 1 Hz summary
                tick_stats.record(k, k + 20_000, k + 30_000, 250.0, False)
            tick_stats.window(1.0)
        window_us = best_us(full_window, 50) - 1000 * best_us(
            lambda: tick_stats.record(1, 2, 3, 4.0, False), calls)
        # states without velocities: the estimate on each state, at rest on a count boundary
        estimators = {resolution: velocity_estimator(3, 1000.0, [resolution] * 3)
                      for resolution in (0.0, 1e-4)}
        states = [0]

        def estimate(resolution: float) -> None:
            states[0] += 1
            k = states[0]
            estimators[resolution].update([1e-4 * (k % 2)] * 3, k * 1_000_000)

        controller = {
            'rclpy deserialising the JointState (before the callback)':
                best_us(lambda: deserialize_message(raw, JointState), calls),
            'picking the joints out of it (StateLayout)':
                best_us(lambda: layout.extract(js.name, js.position, js.velocity), calls),
            'stamp check': best_us(lambda: stamp_problem(stamp_ns, time.time_ns(), 500_000_000),
                                   calls),
            'velocities estimated, states without them (one-period low-pass)':
                best_us(lambda: estimate(0.0), calls),
            "... an encoder's, position_resolution given (window of up to 16 states)":
                best_us(lambda: estimate(1e-4), calls),
            'Regulator.update (paper config)': best_us(lambda: regulator.update(q, qdot), calls),
            '... with the inertial damping, no guard acting':
                best_us(lambda: guarded.update(q, qdot), calls),
            '... every joint past its speed guard':
                best_us(lambda: guarded.update(q, fast), calls),
            '... with the rotor inertia estimate, a moving arm (paper config otherwise)':
                best_us(estimating_tick, calls),
            '... its slower ticks, the fits solved (1 in 50: the 99th percentile)':
                slowest_us(estimating_tick, calls, 0.01),
            'the whole tick without ROS (Controller.on_state: joints, stamp, law and the '
            'decisions around it)': best_us(whole_tick, calls),
            'command into the message': best_us(set_data, calls),
            'publish the command (no subscriber)': best_us(lambda: cmd_pub.publish(cmd), calls),
            'statistics': best_us(lambda: tick_stats.record(1, 2, 3, 4.0, False), calls),
            '/diagnostics statistics of a 1 s window (once a second)': window_us,
        }
        simulator = {
            'PyBullet step and read': best_us(lambda: sim.step(tau), calls),
            'filling the JointState': best_us(fill_state, calls),
            'publish JointState (no subscriber)': best_us(lambda: js_pub.publish(js), calls),
            'statistics': best_us(lambda: loop_stats.record_step(1.0, 1e-5, 0.0, True), calls),
        }
        return {'controller': controller, 'simulator': simulator,
                'sleep': sleep_overshoot(probe.executor, max(calls // 10, 10))}
    finally:
        probe.close()
        sim.close()


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--calls', type=int, default=20000, help='calls per piece')
    args = parser.parse_args(argv)
    result = profile(args.calls)  # its ProbeNode keeps this process's ROS traffic local
    ctrl, sim = list(result['controller'].items()), list(result['simulator'].items())
    print('| controller, per state | us | simulator, per step | us |')
    print('|---|---|---|---|')
    for k in range(max(len(ctrl), len(sim))):
        left = f'{ctrl[k][0]} | {ctrl[k][1]:.1f}' if k < len(ctrl) else ' | '
        right = f'{sim[k][0]} | {sim[k][1]:.1f}' if k < len(sim) else ' | '
        print(f'| {left} | {right} |')
    print()
    print(f'| sleep of {0.7:.1f} ms with spin_once: wakes late by (us) | p50 | p99 |')
    print('|---|---|---|')
    for setting, (p50, p99) in result['sleep'].items():
        print(f'| {setting} | {p50:.0f} | {p99:.0f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())

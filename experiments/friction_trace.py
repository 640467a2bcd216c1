"""
Traces of ||e|| and torque with and without Coulomb friction compensation.

The paper's experiment (q(0) = 0, the corrected goal, the paper's gains) on the PyBullet core
with the wrist's Coulomb friction of config/wrist_sim.yaml, sampled at 1 kHz with a tick of
delay (``reference_sim.run_sampled``), for each law: no compensation, the exact estimate, 90%
of it. Then the product config (config/wrist_controller.yaml), tanh. Prints ||e|| and the
torque over time, and at rest (the last second) the range of each joint's torque and its sign
changes: steady torque, no sign flips, no motion means no chattering and no limit cycle.

    python -m experiments.friction_trace [--duration 6] [--plot trace.png]
"""
import argparse
from pathlib import Path
import sys
from typing import Optional

from experiments.reach_experiment import (config_parameters, load_controller,
                                          Q_STAR_AFTER_S, quiet, ROBOTS)
import numpy as np
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import shaping as sh
from quat_jt_controller.inverse_kinematics import goal_configuration
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled, SampledRun
from quat_jt_runtime.resources import default_urdf_xml

TIMES_S = (0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


def trace(label: str, gains: cl.Gains, shaping: sh.Shaping, duration_s: float,
          friction) -> tuple[str, SampledRun]:
    """Run the paper's experiment once; return a label and the run."""
    from wrist_sim.simulator import RobotSimulator

    model, _, _ = load_controller(ROBOTS['wrist'])
    loop = ClosedLoop(model, gains, cl.Task.ORIENTATION, paper.Q_DESIRED, shaping=shaping)
    q_star = (goal_configuration(model, paper.Q_INITIAL_RAD, paper.Q_DESIRED, (0, 0, 0),
                                 cl.Task.ORIENTATION, shaping.joint_limit_margin_rad)
              if shaping.configuration_on else None)
    with quiet():
        sim = RobotSimulator(default_urdf_xml(), model.joint_names, coulomb_nm=friction)
    try:
        return label, run_sampled(loop, sim, duration_s, 1, q_star, Q_STAR_AFTER_S)
    finally:
        sim.close()


def at_rest(run: SampledRun, window_s: float = 1.0) -> dict:
    """Figures of the last ``window_s``: torque range and sign changes per joint, motion."""
    k = int(round(window_s / (run.t_s[1] - run.t_s[0])))
    tau, q = run.tau_nm[-k:], run.q_rad[-k:]
    signs = np.sign(np.where(np.abs(tau) < 1e-12, 0.0, tau))
    flips = (np.diff(signs, axis=0) != 0).sum(axis=0)
    return {'tau_range_nm': tau.max(axis=0) - tau.min(axis=0), 'sign_changes': flips,
            'motion_rad': np.abs(q - q[-1]).max(), 'tau_nm': tau[-1]}


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--duration', type=float, default=6.0)
    parser.add_argument('--plot', type=Path, help='write a figure of ||e|| and torque')
    args = parser.parse_args(argv)
    friction = config_parameters('wrist_sim.yaml')['coulomb_friction']
    runs = []
    for potential in ('quadratic', 'tanh'):
        gains = cl.Gains.create(potential, paper.KP, paper.KV, paper.LAMBDA,
                                cl.Task.ORIENTATION, 3)
        for share, name in ((0.0, 'no compensation'), (1.0, 'exact estimate'),
                            (0.9, '90% estimate')):
            shaping = sh.Shaping.create(3, friction_compensation=[share * f for f in friction])
            runs.append(trace(f'paper gains, {potential}, {name}', gains, shaping,
                              args.duration, friction))
    _, gains, shaping = load_controller(ROBOTS['wrist'], 'tanh')
    runs.append(trace('config/wrist_controller.yaml, tanh', gains, shaping, args.duration,
                      friction))
    for label, run in runs:
        print(f'{label}:')
        print('   t [s]   ||e||      tau [N m]')
        for t in TIMES_S:
            if t <= args.duration:
                k = int(round(t / (run.t_s[1] - run.t_s[0]))) - 1
                print(f'   {t:4.2f}   {run.orientation_error[k]:.3e}  '
                      + ' '.join(f'{v:7.3f}' for v in run.tau_nm[k]))
        rest = at_rest(run)
        print(f'   at rest (last 1 s): torque range {np.round(rest["tau_range_nm"], 9).tolist()}'
              f' N m, sign changes {rest["sign_changes"].tolist()}, motion '
              f'{rest["motion_rad"]:.1e} rad; final ||e|| {run.orientation_error[-1]:.4g}')
    if args.plot:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(len(runs), 2, figsize=(11, 2.2 * len(runs)), sharex=True)
        for (label, run), (ax_e, ax_t) in zip(runs, axes):
            ax_e.semilogy(run.t_s, run.orientation_error)
            ax_e.set_ylabel('||e||')
            ax_e.set_title(label, fontsize=8)
            ax_t.plot(run.t_s, run.tau_nm)
            ax_t.set_ylabel('tau [N m]')
        for ax in axes[-1]:
            ax.set_xlabel('t [s]')
        fig.tight_layout()
        fig.savefig(args.plot, dpi=100)
        print(f'figure: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

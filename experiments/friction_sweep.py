"""
Choose the simulated wrist's Coulomb friction so the paper's Section 5 result reproduces.

ROS-free: the PyBullet simulator core and the control law in a sampled loop at 1 kHz, timed as
the two nodes are when every command arrives in time: the torque computed from the state of
step k is held over the step from k to k + 1 (``reference_sim.run_sampled``, no extra delay).
For each friction vector of a grid, both controllers run the paper's experiment (q(0) = 0,
corrected goal, gains Eq. 43-45) and the final ||e|| is compared with the paper's 0.2043
(quadratic, Eq. 37) and 5.3184e-3 (tanh, Eq. 38) by
``|ln(e_quad / 0.2043)| + |ln(e_tanh / 5.3184e-3)|``. The README's friction values come from

    python -m experiments.friction_sweep
"""
import argparse
import itertools
import math
import time
from typing import Sequence

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_runtime.resources import default_urdf_xml
from wrist_sim.simulator import RobotSimulator


def sampled_run(model: RobotModel, potential: str, coulomb_nm: Sequence[float],
                duration_s: float = 6.0) -> np.ndarray:
    """||e|| after every 1 ms step of the paper's experiment on the simulated wrist."""
    gains = cl.Gains.create(potential, paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION,
                            model.n)
    loop = ClosedLoop(model, gains, cl.Task.ORIENTATION, paper.Q_DESIRED)
    with RobotSimulator(default_urdf_xml(), model.joint_names, coulomb_nm=coulomb_nm) as sim:
        return run_sampled(loop, sim, duration_s, delay_ticks=0).orientation_error


def score(final_quadratic: float, final_tanh: float) -> float:
    return (abs(math.log(final_quadratic / paper.FINAL_ERROR['quadratic']))
            + abs(math.log(max(final_tanh, 1e-12) / paper.FINAL_ERROR['tanh'])))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--joint1', type=float, nargs='+', default=[1.0, 1.5, 2.0])
    parser.add_argument('--joint2', type=float, nargs='+', default=[0.6, 0.8, 1.0])
    parser.add_argument('--joint3', type=float, nargs='+', default=[0.4, 0.5, 0.6])
    parser.add_argument('--duration', type=float, default=6.0, help='seconds per run')
    args = parser.parse_args(argv)
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    rows = []
    print(f'{"coulomb N m":>20} {"quadratic ||e||":>16} {"tanh ||e||":>12} {"score":>7}')
    for coulomb in itertools.product(args.joint1, args.joint2, args.joint3):
        t0 = time.perf_counter()
        final = {p: sampled_run(model, p, coulomb, args.duration)[-1] for p in paper.FINAL_ERROR}
        rows.append((score(final['quadratic'], final['tanh']), coulomb, final))
        print(f'{str(coulomb):>20} {final["quadratic"]:16.4f} {final["tanh"]:12.5f} '
              f'{rows[-1][0]:7.3f}   ({time.perf_counter() - t0:.1f} s)', flush=True)
    best = min(rows)
    print(f'best: coulomb_friction {list(best[1])}: quadratic {best[2]["quadratic"]:.4f} '
          f'(paper 0.2043), tanh {best[2]["tanh"]:.5f} (paper 0.0053)')


if __name__ == '__main__':
    main()

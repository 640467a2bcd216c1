"""
The pose regulator as the real system runs it, without ROS: sampled, delayed, saturated.

The ideal loop of ``reference_sim`` evaluates Eq. (24) / (32) continuously. Over ROS the
controller sees the joint state of one tick and its torque is applied, held constant (zero-order
hold), during a later tick of the 1 kHz simulator, clamped to the URDF effort limits, with
PyBullet's integrator and the simulator's friction. This module reproduces that loop in one
process on the simulator core (``wrist_sim.simulator.RobotSimulator``). The linearised
sampled-and-delayed loop around the goal (``linearized_spectral_radius``, re-exported here)
lives in ``quat_jt_controller.gain_analysis``, by which ``gain_design`` checked the gains of
``config/xarm6_controller.yaml``.

    .venv/bin/python test/sampled_loop.py     # the figures quoted in docs/xarm6.md
"""
import dataclasses
from pathlib import Path
import sys
from typing import Optional, Sequence

import numpy as np
from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller_config import controller_from_package_config
from quat_jt_controller.gain_analysis import linearized_spectral_radius, time_constant_s
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_controller.shaping import Shaping
from quat_jt_runtime.resources import config_parameters


def _xarm6_controller(potential: Optional[str] = None):
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from robots import XARM6_URDF
    return controller_from_package_config('xarm6_controller.yaml', XARM6_URDF.read_text(),
                                          potential)


def xarm6_gains(potential: Optional[str] = None) -> cl.Gains:
    """Return the gains of ``config/xarm6_controller.yaml`` (its potential unless given)."""
    return _xarm6_controller(potential).gains


def xarm6_shaping() -> Shaping:
    """Return the extensions of ``config/xarm6_controller.yaml``."""
    return _xarm6_controller().shaping


def goal_of(model: RobotModel, q_goal_rad: Sequence[float]):
    """Return the reachable goal (p_d, quaternion_d): the arm's pose at ``q_goal_rad`` (A1)."""
    p, R = model.forward_kinematics(q_goal_rad)
    return tuple(p), quat.from_rotation_matrix(R)


def _report() -> None:  # pragma: no cover - the figures behind config/xarm6_controller.yaml
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from robots import xarm6_model, XARM6_URDF
    from wrist_sim.simulator import RobotSimulator

    model = xarm6_model()
    sim_params = config_parameters('xarm6_sim.yaml')
    q0 = sim_params['initial_positions']
    goals = {
        'near (0.10 m, 0.25 rad)': [0.2, -0.4, -1.1, 0.2, 1.4, 0.3],
        'far (0.26 m, 0.48 rad)': [0.5, -0.1, -1.3, 0.4, 1.2, 0.6],
        'left-low (0.32 m, 0.51 rad)': [-0.6, 0.0, -1.1, -0.5, 1.3, -0.4],
    }
    shaping = xarm6_shaping()
    for potential in ('quadratic', 'tanh'):
        gains = xarm6_gains(potential)
        for label, q_goal in goals.items():
            p_d, q_d = goal_of(model, q_goal)
            rho = [linearized_spectral_radius(model, q_goal, gains, d, shaping=shaping)
                   for d in (1, 3, 6, 7)]
            print(f'{potential:9s} {label}: linearised rho (delay 1/3/6/7) '
                  + ' '.join(f'{r:.5f}' for r in rho)
                  + f', slowest time constant {time_constant_s(rho[0]):.3f} s (delay 1)')
            # no friction in the ideal loop, so no compensation (docs/lyapunov.md, section 4)
            frictionless = dataclasses.replace(shaping, friction_compensation_nm=())
            ideal = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d, shaping=frictionless,
                               q_star=q_goal).run(q0, 5.0)
            y, _, _ = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d).error(ideal.q_rad[-1])
            print(f'    ideal 5 s: |p_d - p| {np.linalg.norm(y[:3]) * 1e3:.4f} mm, '
                  f'||e|| {np.linalg.norm(y[3:]):.2e}, V non-increasing: '
                  f'{bool(np.diff(ideal.lyapunov).max() <= 1e-9 * ideal.lyapunov[0])}')
            for delay in (1, 3, 6):
                for friction in (False, True):
                    with RobotSimulator(
                            XARM6_URDF.read_text(), model.joint_names, initial_positions_rad=q0,
                            viscous_nm_s_per_rad=(sim_params['viscous_friction']
                                                  if friction else None),
                            coulomb_nm=sim_params['coulomb_friction'] if friction else None,
                            enforce_velocity_limits=sim_params['enforce_velocity_limits']
                    ) as sim:
                        loop = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d,
                                          shaping=shaping if friction else frictionless)
                        run = run_sampled(loop, sim, 5.0, delay, q_goal, 0.1)
                    fp, fe = run.final()
                    print(f'    PyBullet delay {delay} friction {friction!s:5s}: last 0.5 s '
                          f'max |p_d - p| {fp * 1e3:.4f} mm, ||e|| {fe:.2e}; within 1 mm / '
                          f'0.01 from {run.settled_at_s():.2f} s; saturated ticks '
                          f'{run.saturated_ticks}; max |tau| {run.max_abs_torque_nm.max():.1f}')


if __name__ == '__main__':
    _report()

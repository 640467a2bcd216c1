"""
The pose regulator as the real system runs it, without ROS: sampled, delayed, saturated.

The ideal loop of ``reference_sim`` evaluates Eq. (24) / (32) continuously. Over ROS the
controller sees the joint state of one tick and its torque is applied, held constant (zero-order
hold), during a later tick of the 1 kHz simulator, clamped to the URDF effort limits, with
PyBullet's integrator and the simulator's friction. This module reproduces that loop in one
process on the simulator core (``wrist_sim.simulator.WristSimulator``) and gives the linearised
sampled-and-delayed loop around the goal, whose spectral radius was used to choose the xArm6
gains of ``config/xarm6_controller.yaml``.

    .venv/bin/python test/sampled_loop.py     # the figures quoted in config/xarm6_controller.yaml
"""
from pathlib import Path
import sys
from typing import Optional, Sequence

import numpy as np
from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop, run_sampled
from quat_jt_controller.resources import config_parameters


def xarm6_gains(potential: Optional[str] = None) -> cl.Gains:
    """Return the gains of ``config/xarm6_controller.yaml`` (its potential unless given)."""
    p = config_parameters('xarm6_controller.yaml')
    return cl.Gains.create(potential or p['potential'], p['kp'], p['kv'], p['lambda'],
                           cl.Task(p['task']), len(p['joints']),
                           p.get('gravity_compensation', True))


def goal_of(model: RobotModel, q_goal_rad: Sequence[float]):
    """Return the reachable goal (p_d, quaternion_d): the arm's pose at ``q_goal_rad`` (A1)."""
    p, R = model.forward_kinematics(q_goal_rad)
    return tuple(p), quat.from_rotation_matrix(R)


def linearized_spectral_radius(model: RobotModel, q_goal_rad: Sequence[float], gains: cl.Gains,
                               delay_ticks: int = 1, dt_s: float = 1e-3,
                               mass_matrix: Optional[np.ndarray] = None) -> float:
    """
    Spectral radius of the pose loop linearised at the goal, sampled and delayed.

    At y_tilde = 0 (eta_e = 1), Eq. (24) / (32) minus g(q) is tau = -K_q dq - K_v qdot with the
    joint stiffness K_q = J_G^T Q^T diag(s) Q J_G, Q = diag(I, I/2) (Eq. 15) and slopes
    s_i = k_pi (quadratic, Eq. 23) or k_pi lambda_i (log-cosh, Eq. 31). The plant is M(q_d)
    integrated with semi-implicit Euler (as PyBullet does) at ``dt_s``; the torque applied in
    step k is computed from the state of step k - ``delay_ticks`` and held over the step.
    Below 1: locally stable; the slowest mode decays with the time constant -dt / ln(rho).
    """
    n = model.n
    _, _, J = model.kinematics(q_goal_rad)
    QJ = np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5]) @ np.array(J)
    slope = np.array(gains.kp)
    if gains.potential is cl.Potential.TANH:
        slope = slope * np.array(gains.lam)
    K = QJ.T @ np.diag(slope) @ QJ
    M = model.mass_matrix(q_goal_rad) if mass_matrix is None else mass_matrix
    Minv = np.linalg.inv(M)
    size = 2 * n * (delay_ticks + 1)  # [q_k, v_k, q_k-1, v_k-1, ..., q_k-d, v_k-d]
    A = np.zeros((size, size))
    old = 2 * n * delay_ticks
    A[n:2 * n, n:2 * n] = np.eye(n)
    A[n:2 * n, old:old + n] -= dt_s * Minv @ K
    A[n:2 * n, old + n:old + 2 * n] -= dt_s * Minv @ np.diag(gains.kv)
    A[:n, :n] = np.eye(n)
    A[:n, :] += dt_s * A[n:2 * n, :]  # q_k+1 = q_k + dt v_k+1
    for j in range(1, delay_ticks + 1):
        A[2 * n * j:2 * n * (j + 1), 2 * n * (j - 1):2 * n * j] = np.eye(2 * n)
    return float(np.abs(np.linalg.eigvals(A)).max())


def time_constant_s(rho: float, dt_s: float = 1e-3) -> float:
    """Time constant of a discrete mode of modulus ``rho`` (inf if not decaying)."""
    return -dt_s / np.log(rho) if rho < 1.0 else float('inf')


def _report() -> None:  # pragma: no cover - the figures behind config/xarm6_controller.yaml
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from robots import xarm6_model, XARM6_URDF
    from wrist_sim.simulator import WristSimulator

    model = xarm6_model()
    sim_params = config_parameters('xarm6_sim.yaml')
    q0 = sim_params['initial_positions']
    goals = {
        'near (0.10 m, 0.25 rad)': [0.2, -0.4, -1.1, 0.2, 1.4, 0.3],
        'far (0.26 m, 0.48 rad)': [0.5, -0.1, -1.3, 0.4, 1.2, 0.6],
        'left-low (0.32 m, 0.51 rad)': [-0.6, 0.0, -1.1, -0.5, 1.3, -0.4],
    }
    for potential in ('quadratic', 'tanh'):
        gains = xarm6_gains(potential)
        for label, q_goal in goals.items():
            p_d, q_d = goal_of(model, q_goal)
            rho = [linearized_spectral_radius(model, q_goal, gains, d) for d in (1, 3, 6, 7)]
            print(f'{potential:9s} {label}: linearised rho (delay 1/3/6/7) '
                  + ' '.join(f'{r:.5f}' for r in rho)
                  + f', slowest time constant {time_constant_s(rho[0]):.3f} s (delay 1)')
            ideal = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d).run(q0, 5.0)
            y, _, _ = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d).error(ideal.q_rad[-1])
            print(f'    ideal 5 s: |p_d - p| {np.linalg.norm(y[:3]) * 1e3:.4f} mm, '
                  f'||e|| {np.linalg.norm(y[3:]):.2e}, V non-increasing: '
                  f'{bool(np.diff(ideal.lyapunov).max() <= 1e-9 * ideal.lyapunov[0])}')
            for delay in (1, 3, 6):
                for friction in (False, True):
                    with WristSimulator(
                            XARM6_URDF.read_text(), model.joint_names, initial_positions_rad=q0,
                            viscous_nm_s_per_rad=(sim_params['viscous_friction']
                                                  if friction else None),
                            coulomb_nm=sim_params['coulomb_friction'] if friction else None,
                            enforce_velocity_limits=sim_params['enforce_velocity_limits']
                    ) as sim:
                        loop = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d)
                        run = run_sampled(loop, sim, 5.0, delay)
                    fp, fe = run.final()
                    print(f'    PyBullet delay {delay} friction {friction!s:5s}: last 0.5 s '
                          f'max |p_d - p| {fp * 1e3:.4f} mm, ||e|| {fe:.2e}; within 1 mm / '
                          f'0.01 from {run.settled_at_s():.2f} s; saturated ticks '
                          f'{run.saturated_ticks}; max |tau| {run.max_abs_torque_nm.max():.1f}')


if __name__ == '__main__':
    _report()

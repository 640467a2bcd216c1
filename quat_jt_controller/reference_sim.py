"""
The ideal closed loop, Eq. (25) / (33): robot dynamics (1) + control law (24) / (32).

Integrated with classic RK4 on Pinocchio's dynamics, the law evaluated continuously at every
stage (no sampling, no delay, no friction, no torque limits), so the Lyapunov function of
Eq. (27) / (34) is non-increasing up to integration error (Eq. 28 / 35). It is the reference
the PyBullet + ROS runs are compared with, and a test of the control law's theory.
"""
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller.model import RobotModel


@dataclass
class Trajectory:
    t_s: np.ndarray  # (N,)
    q_rad: np.ndarray  # (N, n)
    qdot_rad_s: np.ndarray  # (N, n)
    error_norm: np.ndarray  # ||y_tilde|| (N,)
    lyapunov: np.ndarray  # V of Eq. (27) / (34), (N,)


class ClosedLoop:
    """Robot + regulator towards the goal ``(p_desired, q_desired)``, with gravity compensated."""

    def __init__(self, model: RobotModel, gains: cl.Gains, task: cl.Task,
                 q_desired: Sequence[float], p_desired: Optional[Sequence[float]] = None):
        self.model, self.gains, self.task = model, gains, cl.Task(task)
        self.q_desired, self.p_desired = tuple(q_desired), p_desired

    def error(self, q: Sequence[float]) -> tuple[tuple[float, ...], float, list[list[float]]]:
        p, R, J = self.model.kinematics(q)
        y, eta_e = cl.output_error(p, R, self.p_desired, self.q_desired, self.task)
        return y, eta_e, (J if self.task is cl.Task.POSE else J[3:])

    def torque(self, q: Sequence[float], qdot: Sequence[float]) -> list[float]:
        y, eta_e, rows = self.error(q)
        return cl.control_torque(rows, y, eta_e, qdot, self.model.gravity(q), self.gains)

    def lyapunov(self, q: np.ndarray, qdot: np.ndarray) -> float:
        """V = 1/2 qdot^T M(q) qdot + U_a(y_tilde(q)), Eq. (27) / (34)."""
        y, _, _ = self.error(q)
        return 0.5 * qdot @ self.model.mass_matrix(q) @ qdot + cl.potential_energy(y, self.gains)

    def _f(self, x: np.ndarray) -> np.ndarray:
        n = self.model.n
        q, qdot = x[:n], x[n:]
        qddot = self.model.forward_dynamics(q, qdot, self.torque(q, qdot))
        return np.concatenate((qdot, qddot))

    def run(self, q0: Sequence[float], duration_s: float, dt_s: float = 1e-3,
            qdot0: Optional[Sequence[float]] = None) -> Trajectory:
        n = self.model.n
        x = np.concatenate((np.asarray(q0, float),
                            np.zeros(n) if qdot0 is None else np.asarray(qdot0, float)))
        steps = int(round(duration_s / dt_s))
        xs = np.empty((steps + 1, 2 * n))
        xs[0] = x
        for k in range(steps):
            k1 = self._f(x)
            k2 = self._f(x + 0.5 * dt_s * k1)
            k3 = self._f(x + 0.5 * dt_s * k2)
            k4 = self._f(x + dt_s * k3)
            x = x + dt_s / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            xs[k + 1] = x
        q, qdot = xs[:, :n], xs[:, n:]
        err = np.array([np.linalg.norm(self.error(qi)[0]) for qi in q])
        lyap = np.array([self.lyapunov(qi, vi) for qi, vi in zip(q, qdot)])
        return Trajectory(np.arange(steps + 1) * dt_s, q, qdot, err, lyap)

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
from quat_jt_controller.regulator import Goal, Regulator


@dataclass
class Trajectory:
    t_s: np.ndarray  # (N,)
    q_rad: np.ndarray  # (N, n)
    qdot_rad_s: np.ndarray  # (N, n)
    error_norm: np.ndarray  # ||y_tilde|| (N,)
    lyapunov: np.ndarray  # V of Eq. (27) / (34), (N,)


class ClosedLoop:
    """
    Robot + regulator towards the goal ``(p_desired, q_desired)``, with gravity compensated.

    The law is the node's :class:`~quat_jt_controller.regulator.Regulator` tick; the ideal loop
    (:meth:`run`) gives it no effort limits, the sampled loop (:func:`run_sampled`) the URDF's.
    """

    def __init__(self, model: RobotModel, gains: cl.Gains, task: cl.Task,
                 q_desired: Sequence[float], p_desired: Optional[Sequence[float]] = None):
        self.model, self.gains, self.task = model, gains, cl.Task(task)
        goal = Goal(tuple(q_desired), tuple(p_desired) if p_desired is not None
                    else (0.0, 0.0, 0.0))
        self.regulator = Regulator(model, task, gains, [float('inf')] * model.n, goal)
        self.clamped = Regulator(model, task, gains, None, goal)

    def error(self, q: Sequence[float]) -> tuple[tuple[float, ...], float, list[list[float]]]:
        """Return y_tilde (Eq. 8), eta_e and the task Jacobian at ``q``."""
        y, eta_e, rows, _, _ = self.regulator.error(q)
        return y, eta_e, rows

    def torque(self, q: Sequence[float], qdot: Sequence[float]) -> list[float]:
        """Eq. (22) + g(q), unclamped: the ideal loop's torque."""
        return self.regulator.update(q, qdot).tau_nm

    def lyapunov(self, q: np.ndarray, qdot: np.ndarray) -> float:
        """V = 1/2 qdot^T M(q) qdot + U_a(y_tilde(q)), Eq. (27) / (34)."""
        return self.regulator.lyapunov(q, qdot)

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


@dataclass
class SampledRun:
    t_s: np.ndarray  # (N,)
    position_error_m: np.ndarray  # ||p_d - p|| (N,), zeros for the orientation task
    orientation_error: np.ndarray  # ||e|| of Eq. (10) (N,)
    max_abs_torque_nm: np.ndarray  # max_j |tau_j| applied (N,)
    saturated_ticks: int
    all_finite: bool

    def settled_at_s(self, position_m: float = 1e-3, orientation: float = 1e-2) -> float:
        """First time after which both errors stay below the tolerances (inf if never)."""
        ok = (self.position_error_m < position_m) & (self.orientation_error < orientation)
        if not ok[-1]:
            return float('inf')
        bad = np.flatnonzero(~ok)
        return float(self.t_s[bad[-1] + 1]) if bad.size else float(self.t_s[0])

    def final(self, window_s: float = 0.5) -> tuple[float, float]:
        """Largest position error (m) and ||e|| over the last ``window_s``."""
        k = max(1, int(round(window_s / max(self.t_s[1] - self.t_s[0], 1e-12))))
        return float(self.position_error_m[-k:].max()), float(self.orientation_error[-k:].max())


def run_sampled(loop: ClosedLoop, sim, duration_s: float, delay_ticks: int = 1) -> SampledRun:
    """
    Run ``loop``'s regulator on a simulator as the nodes do: sampled, delayed, held, clamped.

    ``sim`` is a simulator of the same URDF and joints (``wrist_sim.simulator.WristSimulator``
    or anything with ``q_rad``, ``qdot_rad_s``, ``dt_s`` and ``step(tau) -> applied``). Each
    step applies (zero-order hold) the torque of the node's tick (Regulator.update: Eq. (22) +
    g(q), clamped to the URDF effort limits) computed from the state measured ``delay_ticks``
    steps earlier. The nodes run
    with no extra delay (0) while every command arrives in time: the sim steps from the state
    it published with the command computed from it. Records the errors after each step.
    """
    history = [(sim.q_rad.tolist(), sim.qdot_rad_s.tolist())] * (delay_ticks + 1)
    steps = int(round(duration_s / sim.dt_s))
    pos, ori, tau_max = np.zeros(steps), np.empty(steps), np.empty(steps)
    saturated = 0
    finite = True
    for k in range(steps):
        q, qdot = history[-1 - delay_ticks]
        out = loop.clamped.update(q, qdot)
        saturated += out.saturated
        if not out.finite:
            finite = False
            break
        applied = sim.step(out.tau_nm)
        history.append((sim.q_rad.tolist(), sim.qdot_rad_s.tolist()))
        del history[0]
        y, _, _ = loop.error(history[-1][0])
        if loop.task is cl.Task.POSE:
            pos[k] = np.linalg.norm(y[:3])
        ori[k] = np.linalg.norm(y[-3:])
        tau_max[k] = np.abs(applied).max()
        finite = finite and bool(np.all(np.isfinite(sim.q_rad)))
    t = (np.arange(steps) + 1) * sim.dt_s
    return SampledRun(t, pos, ori, tau_max, saturated, finite)

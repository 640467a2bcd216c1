"""
The ideal closed loop, Eq. (25) / (33): robot dynamics (1) + control law (24) / (32).

Integrated with classic RK4 on Pinocchio's dynamics, the law evaluated continuously at every
stage (no sampling, no delay, no torque limits, and no friction unless asked for), so the
Lyapunov function of Eq. (27) / (34) -- with the joint-limit and large-error terms
when they are on (docs/lyapunov.md) -- is non-increasing up to integration error (Eq. 28 / 35).
It is the reference the PyBullet + ROS runs are compared with, and a test of the control law's
theory.

The optional plant friction is a smooth Coulomb model, ``-f tanh(qdot / v_s)``: with friction
compensation on, the law does work against it, and docs/lyapunov.md (section 4) shows why V
still decreases when the compensation never exceeds the plant's friction.
"""
from dataclasses import dataclass
from math import tanh
from typing import Callable, Optional, Sequence

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller.model import RobotModel
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_controller.shaping import Shaping


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
    ``coulomb_nm`` adds plant friction ``-f tanh(qdot / coulomb_velocity_rad_s)`` to the ideal
    loop (the sampled loop takes its friction from the simulator). ``shaping`` turns on the
    extensions, ``q_star`` gives the goal configuration to their joint-space term. ``plant``
    is the ideal loop's robot, the model by default: its dynamics are integrated and its
    ``M(q)`` is in ``V`` (a plant that is not the model the law reads).
    """

    def __init__(self, model: RobotModel, gains: cl.Gains, task: cl.Task,
                 q_desired: Sequence[float], p_desired: Optional[Sequence[float]] = None,
                 coulomb_nm: Optional[Sequence[float]] = None,
                 coulomb_velocity_rad_s: float = 0.01, shaping: Optional[Shaping] = None,
                 q_star: Optional[Sequence[float]] = None,
                 plant: Optional[RobotModel] = None):
        self.model, self.gains, self.task = model, gains, cl.Task(task)
        self.plant = model if plant is None else plant
        goal = Goal(tuple(q_desired), tuple(p_desired) if p_desired is not None
                    else (0.0, 0.0, 0.0))
        self.goal = goal
        self.regulator = Regulator(model, task, gains, [float('inf')] * model.n, goal, shaping)
        self.clamped = Regulator(model, task, gains, None, goal, shaping)
        if q_star is not None:
            self.set_goal_configuration(q_star)
        self.coulomb_nm = None if coulomb_nm is None else [float(f) for f in coulomb_nm]
        self.coulomb_velocity_rad_s = float(coulomb_velocity_rad_s)

    def set_goal_configuration(self, q_star: Optional[Sequence[float]]) -> None:
        """Give both regulators the goal configuration q* (docs/lyapunov.md, section 5)."""
        self.regulator.set_goal_configuration(self.goal, q_star)
        self.clamped.set_goal_configuration(self.goal, q_star)

    def plant_friction(self, qdot: Sequence[float]) -> list[float]:
        """Return the ideal loop's plant friction torque, -f tanh(qdot / v_s) (or zeros)."""
        if self.coulomb_nm is None:
            return [0.0] * self.model.n
        v_s = self.coulomb_velocity_rad_s
        return [-f * tanh(v / v_s) for f, v in zip(self.coulomb_nm, qdot)]

    def error(self, q: Sequence[float]) -> tuple[tuple[float, ...], float, list[list[float]]]:
        """Return y_tilde (Eq. 8), eta_e and the task Jacobian at ``q``."""
        y, eta_e, rows, _, _ = self.regulator.error(q)
        return y, eta_e, rows

    def torque(self, q: Sequence[float], qdot: Sequence[float]) -> list[float]:
        """Eq. (22) + g(q), unclamped: the ideal loop's torque."""
        return self.regulator.update(q, qdot).tau_nm

    def lyapunov(self, q: np.ndarray, qdot: np.ndarray) -> float:
        """V = 1/2 qdot^T M(q) qdot + U_a(y_tilde(q)) + U_lim(q), Eq. (27)/(34), M the plant's."""
        if self.plant is self.model:
            return self.regulator.lyapunov(q, qdot)
        v = np.asarray(qdot, float)
        return (0.5 * float(v @ self.plant.mass_matrix(list(q)) @ v)
                + self.regulator.potential_energy(q))

    def _f(self, x: np.ndarray) -> np.ndarray:
        n = self.model.n
        q, qdot = x[:n], x[n:]
        tau = self.torque(q, qdot)
        if self.coulomb_nm is not None:
            tau = [t + f for t, f in zip(tau, self.plant_friction(qdot))]
        qddot = self.plant.forward_dynamics(q, qdot, tau)
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
    orientation_error: np.ndarray  # ||e|| of Eq. (10) (N,), zeros for the position task
    max_abs_torque_nm: np.ndarray  # max_j |tau_j| applied (N,)
    saturated_ticks: int
    all_finite: bool
    q_rad: Optional[np.ndarray] = None  # (N, n) joint positions after each step
    tau_nm: Optional[np.ndarray] = None  # (N, n) torque applied in each step

    def settled_at_s(self, position_m: float = 1e-3, orientation: float = 1e-2) -> float:
        """First time after which both errors stay below the tolerances (inf if never)."""
        ok = (self.position_error_m < position_m) & (self.orientation_error < orientation)
        if not ok[-1]:
            return float('inf')
        bad = np.flatnonzero(~ok)
        return float(self.t_s[bad[-1] + 1]) if bad.size else float(self.t_s[0])

    def until(self, t_s: float) -> 'SampledRun':
        """
        Return the run up to time ``t_s`` (the samples at or before it).

        ``saturated_ticks`` and ``all_finite`` stay the whole run's (the cut cannot tell them
        apart): a verdict on the cut run is, if anything, stricter.
        """
        k = int(np.searchsorted(self.t_s, t_s + 1e-9, side='right'))
        cut = (lambda a: None if a is None else a[:k])
        return SampledRun(self.t_s[:k], self.position_error_m[:k], self.orientation_error[:k],
                          self.max_abs_torque_nm[:k], self.saturated_ticks, self.all_finite,
                          cut(self.q_rad), cut(self.tau_nm))

    def final(self, window_s: float = 0.5) -> tuple[float, float]:
        """Largest position error (m) and ||e|| over the last ``window_s``."""
        k = max(1, int(round(window_s / max(self.t_s[1] - self.t_s[0], 1e-12))))
        return float(self.position_error_m[-k:].max()), float(self.orientation_error[-k:].max())


def run_sampled(loop: ClosedLoop, sim, duration_s: float, delay_ticks: int = 1,
                q_star: Optional[Sequence[float]] = None,
                q_star_after_s: float = 0.0,
                on_step: Optional[Callable[[float, list], None]] = None) -> SampledRun:
    """
    Run ``loop``'s regulator on a simulator as the nodes do: sampled, delayed, held, clamped.

    ``sim`` is a simulator of the same URDF and joints (``wrist_sim.simulator.RobotSimulator``
    or anything with ``q_rad``, ``qdot_rad_s``, ``dt_s`` and ``step(tau) -> applied``; with a
    ``sensed_q_rad`` too, the regulator reads that, as from encoders, and the errors and the
    record are the plant's ``q_rad``). Each
    step applies (zero-order hold) the torque of the node's tick (Regulator.update: Eq. (22) +
    g(q), clamped to the URDF effort limits) computed from the state measured ``delay_ticks``
    steps earlier. The nodes run
    with no extra delay (0) while every command arrives in time: the sim steps from the state
    it published with the command computed from it. Records the errors after each step.
    ``q_star`` is given to the regulators as the goal configuration after ``q_star_after_s``
    (the node gets it from its goal-check worker a little after the goal). ``on_step(t_s, q)``,
    if given, is called after each step with its time and the state the regulator read, as a
    node's timers see them (a design again, ``redesign.py``).
    """
    q_star_step = int(round(q_star_after_s / sim.dt_s)) if q_star is not None else -1

    sensed = 'sensed_q_rad' if hasattr(sim, 'sensed_q_rad') else 'q_rad'

    def measured() -> tuple:
        return getattr(sim, sensed).tolist(), sim.qdot_rad_s.tolist()
    history = [measured()] * (delay_ticks + 1)
    steps = int(round(duration_s / sim.dt_s))
    pos, ori, tau_max = np.zeros(steps), np.empty(steps), np.empty(steps)
    qs, taus = np.zeros((steps, sim.n)), np.zeros((steps, sim.n))
    saturated = 0
    finite = True
    for k in range(steps):
        if k == q_star_step:
            loop.set_goal_configuration(q_star)
        q, qdot = history[-1 - delay_ticks]
        out = loop.clamped.update(q, qdot, sim.dt_s)
        saturated += out.saturated
        if not out.finite:
            finite = False
            break
        applied = sim.step(out.tau_nm)
        if on_step is not None:
            on_step((k + 1) * sim.dt_s, q)
        history.append(measured())
        del history[0]
        y, _, _ = loop.error(sim.q_rad.tolist())
        if loop.task.has_position:
            pos[k] = np.linalg.norm(y[:3])
        ori[k] = np.linalg.norm(cl.orientation_part(y, loop.task))
        tau_max[k] = np.abs(applied).max()
        qs[k] = sim.q_rad
        taus[k] = applied
        finite = finite and bool(np.all(np.isfinite(sim.q_rad)))
    t = (np.arange(steps) + 1) * sim.dt_s
    return SampledRun(t, pos, ori, tau_max, saturated, finite, qs, taus)

"""
ROS-free simulator core: a fixed-base serial robot from a URDF, torque driven, in an engine.

The physics engine is chosen by name (``ENGINES``): ``pybullet`` (the default) or ``mujoco``.

Stands in for the paper's CICESE direct-drive wrist (by default the bundled
``urdf/spherical_wrist.urdf``) but loads any fixed-base serial URDF given as an XML string.
:class:`RobotSimulator` is the same for both engines; what differs is behind
:class:`wrist_sim.engine.Engine` (:mod:`wrist_sim.pybullet_engine`,
:mod:`wrist_sim.mujoco_engine`, whose docstrings say how each simulates the plant).

Both simulate the URDF's inertias under gravity (-9.81 m/s^2 along z), the motor torque, and
the friction per joint: viscous ``-b qdot`` (``b`` in N m s/rad) and Coulomb with stiction (the
joint is held while the other torques on it stay below the level ``f_c``, N m, and resisted
with ``f_c`` when they exceed it). The rotor inertia per joint (``armature``, kg m^2) is added
to the diagonal of M(q) where the engine can (MuJoCo; PyBullet cannot, and
:attr:`RobotSimulator.supports_armature` says so).

The commanded torque is clamped to the URDF effort limits; that clamped torque is the
"applied" torque reported by :meth:`RobotSimulator.step` and :meth:`RobotSimulator.state`
(friction is not included in it: it is the motor torque, as a drive would report it). The
URDF velocity limits are enforced as a drive's speed limit would: each joint's speed is held
at its limit, so a huge torque cannot spin a joint faster. This can be turned off
(``enforce_velocity_limits``) for a model whose links are so light that one tick of torque
passes the limit (the xArm6's link 6 without armature): the clamp then acts as a switch and
makes the link chatter.

This module never imports rclpy.
"""
from dataclasses import dataclass
import math
from typing import Optional, Sequence

import numpy as np
from wrist_sim.quiet import pybullet  # noqa: F401 - first, so PyBullet loads without its banner
import pybullet_data  # noqa: I100 - after pybullet, which wrist_sim.quiet imports silenced
from wrist_sim.engine import Engine, NoDisplayError, SimulatorError
from wrist_sim.meshes import missing_meshes_note, PathLike, resolve_meshes
from wrist_sim.mujoco_engine import MuJoCoEngine, repaired_inertia_note
from wrist_sim.pybullet_engine import disconnect, PyBulletEngine, take_zero_inertia_warnings
from wrist_sim.pybullet_engine import zero_inertia_note

# The engines by name, the default first (the node's ``engine`` parameter).
ENGINES = (PyBulletEngine.name, MuJoCoEngine.name)

__all__ = ['at_limit', 'disconnect', 'ENGINES', 'missing_meshes_note', 'NoDisplayError',
           'per_joint', 'repaired_inertia_note', 'resolve_meshes', 'SimState',
           'SimulatorError', 'take_zero_inertia_warnings', 'RobotSimulator',
           'zero_inertia_note']


@dataclass(frozen=True)
class SimState:
    """A snapshot of the joints, in the simulator's joint order (copies, safe to keep)."""

    time_s: float
    q_rad: np.ndarray
    qdot_rad_s: np.ndarray
    tau_applied_nm: np.ndarray


def at_limit(values: Sequence[float], limits: Sequence[float]) -> bool:
    """Tell whether any of ``values`` is at or past its limit, either way (plain floats)."""
    for v, limit in zip(values, limits):
        if v >= limit or v <= -limit:
            return True
    return False


def per_joint(name: str, values: Sequence[float], n: int,
              nonnegative: bool = False) -> tuple[float, ...]:
    """Return ``n`` finite values (>= 0 if ``nonnegative``), or raise SimulatorError saying why."""
    try:
        vals = tuple(float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise SimulatorError(f'{name}: not a list of numbers ({exc})') from None
    if len(vals) != n:
        raise SimulatorError(f'{name}: expected {n} values (one per joint), got {len(vals)}')
    if not all(math.isfinite(v) for v in vals):
        raise SimulatorError(f'{name}: values must be finite, got {list(vals)}')
    if nonnegative and any(v < 0.0 for v in vals):
        raise SimulatorError(f'{name}: values must be >= 0, got {list(vals)}')
    return vals


def _as_vector(values: Optional[Sequence[float]], n: int, name: str,
               nonnegative: bool = False) -> np.ndarray:
    """Return :func:`per_joint` as an array; None gives zeros."""
    return np.zeros(n) if values is None else np.array(per_joint(name, values, n, nonnegative))


class RobotSimulator:
    """
    A fixed-base serial robot from a URDF, in a physics engine, torque controlled.

    :param urdf_xml: the URDF as an XML string.
    :param joint_names: the joints to drive, in the order of every vector of this class; by
        default the URDF's revolute/prismatic joints in tree order. Others stay at zero.
    :param dt_s: the fixed time step (s).
    :param use_gui: open the PyBullet window instead of a DIRECT (headless) client; its side
        panels are hidden and its camera looks at the robot. :meth:`show_frame` draws frames
        (e.g. a goal) in it. PyBullet's only.
    :param viscous_nm_s_per_rad: viscous friction ``b`` per joint (default zeros).
    :param coulomb_nm: Coulomb friction / stiction level per joint (default zeros).
    :param initial_positions_rad: where the robot starts, at rest (default zeros).
    :param search_dirs: extra directories in which meshes are looked for (before
        ``pybullet_data``; :func:`resolve_meshes`); the first also becomes PyBullet's
        additional search path. A shape whose mesh is found nowhere is left out, and its file
        is listed in :attr:`missing_meshes` (the robot still loads: the dynamics need only the
        inertias). MuJoCo simulates no shapes and looks for none. The links the engine
        simulates without the rotational inertia the URDF gives them are in
        :attr:`zero_inertia_links` (PyBullet's, for a tensor that is not physical; to be said
        once, :func:`zero_inertia_note`); those it simulates with a principal moment raised
        where the URDF's is negative in :attr:`repaired_inertia_links` (MuJoCo's;
        :func:`repaired_inertia_note`).
    :param solver_iterations: PyBullet constraint-solver iterations (for the friction motors).
    :param enforce_velocity_limits: hold each joint's speed at its URDF velocity limit, as a
        drive's speed limit would (see the module docstring).
    :param engine: ``'pybullet'`` (default) or ``'mujoco'`` (``ENGINES``).
    :param armature: rotor inertia per joint, kg m^2 (default zeros); simulated where the
        engine can (:attr:`supports_armature`), kept and reported otherwise.
    """

    def __init__(self, urdf_xml: str, joint_names: Optional[Sequence[str]] = None, *,
                 dt_s: float = 1e-3, use_gui: bool = False,
                 viscous_nm_s_per_rad: Optional[Sequence[float]] = None,
                 coulomb_nm: Optional[Sequence[float]] = None,
                 initial_positions_rad: Optional[Sequence[float]] = None,
                 search_dirs: Sequence[PathLike] = (),
                 solver_iterations: int = 50, enforce_velocity_limits: bool = True,
                 engine: str = ENGINES[0],
                 armature: Optional[Sequence[float]] = None) -> None:
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise SimulatorError(f'dt_s must be finite and > 0, got {dt_s}')
        if not urdf_xml or not urdf_xml.strip():
            raise SimulatorError('empty URDF')
        self.dt_s = float(dt_s)
        self._engine = self._make_engine(engine, urdf_xml, joint_names, use_gui, search_dirs,
                                         solver_iterations, enforce_velocity_limits)
        e = self._engine
        self.engine: str = e.name
        self.supports_armature: bool = e.supports_armature
        self.joint_names: tuple[str, ...] = e.joint_names
        self.n = e.n
        self.effort_limits_nm = e.effort_limits_nm
        self.velocity_limits_rad_s = e.velocity_limits_rad_s
        self.position_lower = e.position_lower
        self.position_upper = e.position_upper
        self.enforces_velocity_limits = e.enforces_velocity_limits
        self.missing_meshes = e.missing_meshes
        self.zero_inertia_links: tuple[str, ...] = e.zero_inertia_links
        self.repaired_inertia_links: tuple[str, ...] = e.repaired_inertia_links
        self.use_gui = bool(use_gui)
        self._q = e.q
        self._qdot = e.qdot
        self._applied = np.zeros(self.n)
        self._zeros = np.zeros(self.n)
        self._viscous = np.zeros(self.n)
        self._coulomb = np.zeros(self.n)
        self._step_count = 0
        try:
            self._armature = _as_vector(armature, self.n, 'armature', nonnegative=True)
            self._initial = _as_vector(initial_positions_rad, self.n, 'initial_positions_rad')
            e.set_armature(self._armature)
            self.set_friction(viscous_nm_s_per_rad, coulomb_nm)
            self.reset(self._initial)
        except Exception:
            self.close()
            raise

    def _make_engine(self, engine: str, urdf_xml: str, joint_names: Optional[Sequence[str]],
                     use_gui: bool, search_dirs: Sequence[PathLike], solver_iterations: int,
                     enforce_velocity_limits: bool) -> Engine:
        if engine == PyBulletEngine.name:
            dirs = [str(d) for d in search_dirs] + [pybullet_data.getDataPath()]
            return PyBulletEngine(urdf_xml, joint_names, self.dt_s, dirs, use_gui,
                                  solver_iterations, enforce_velocity_limits)
        if engine == MuJoCoEngine.name:
            if use_gui:
                raise SimulatorError("use_gui: the window is PyBullet's; engine 'mujoco' runs "
                                     "headless (use_gui false, or engine 'pybullet')")
            return MuJoCoEngine(urdf_xml, joint_names, self.dt_s, enforce_velocity_limits)
        raise SimulatorError(f'engine must be one of {list(ENGINES)}, got {engine!r}')

    # -- configuration -------------------------------------------------------------------

    @property
    def friction(self) -> tuple[np.ndarray, np.ndarray]:
        """(viscous N m s/rad, Coulomb N m) per joint (copies)."""
        return self._viscous.copy(), self._coulomb.copy()

    def set_friction(self, viscous_nm_s_per_rad: Optional[Sequence[float]] = None,
                     coulomb_nm: Optional[Sequence[float]] = None) -> None:
        """
        Set both friction vectors (None = zeros).

        Both are validated (length, finite, >= 0) first, then applied together, so a bad value
        changes nothing.
        """
        viscous = _as_vector(viscous_nm_s_per_rad, self.n, 'viscous friction',
                             nonnegative=True)
        coulomb = _as_vector(coulomb_nm, self.n, 'coulomb friction', nonnegative=True)
        self._viscous[:] = viscous
        self._coulomb[:] = coulomb
        self._engine.set_friction(viscous, coulomb)

    @property
    def armature(self) -> np.ndarray:
        """Rotor inertia per joint, kg m^2, as given (simulated if :attr:`supports_armature`)."""
        return self._armature.copy()

    @property
    def initial_positions_rad(self) -> np.ndarray:
        """Where :meth:`reset` without arguments puts the joints (copy)."""
        return self._initial.copy()

    # -- stepping ------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Return the simulation time (s): steps taken times ``dt_s``; :meth:`reset` keeps it."""
        return self._step_count * self.dt_s

    @property
    def step_count(self) -> int:
        """Return the number of steps taken since construction."""
        return self._step_count

    def step(self, tau_nm: Sequence[float]) -> np.ndarray:
        """
        Apply ``tau_nm`` (clamped to the effort limits) for one step of ``dt_s``.

        Returns the applied (clamped) torque, a copy. Raises SimulatorError on a wrong length
        or a non-finite value (nothing is stepped then).
        """
        tau = np.asarray(tau_nm, dtype=float)
        if tau.shape != (self.n,):
            raise SimulatorError(f'expected {self.n} torques, got shape {tau.shape}')
        if not np.all(np.isfinite(tau)):
            raise SimulatorError(f'torques must be finite, got {tau.tolist()}')
        np.clip(tau, -self.effort_limits_nm, self.effort_limits_nm, out=self._applied)
        self._advance()
        return self._applied.copy()

    def hold(self) -> None:
        """
        Let one step of time pass with the joints held at rest, as by engaged brakes.

        No physics is simulated: positions stay, velocities and the applied torque read zero.
        """
        self._applied[:] = 0.0
        self._qdot[:] = 0.0
        self._step_count += 1

    def step_zero(self) -> None:
        """One step with no motor torque (friction and gravity only)."""
        self._applied[:] = 0.0
        self._advance()

    def _advance(self) -> None:
        self._engine.step(self._applied)
        self._step_count += 1

    # -- state ---------------------------------------------------------------------------

    def state(self) -> SimState:
        """Joint positions (rad or m), velocities and the applied torque (copies)."""
        return SimState(self.time_s, self._q.copy(), self._qdot.copy(), self._applied.copy())

    @property
    def q_rad(self) -> np.ndarray:
        """Joint positions, the simulator's own buffer (read only; changes on each step)."""
        return self._q

    @property
    def qdot_rad_s(self) -> np.ndarray:
        """Joint velocities, the simulator's own buffer (read only)."""
        return self._qdot

    @property
    def tau_applied_nm(self) -> np.ndarray:
        """Return the torque applied in the last step, clamped, without friction (own buffer)."""
        return self._applied

    def reset(self, q0_rad: Optional[Sequence[float]] = None,
              qdot0_rad_s: Optional[Sequence[float]] = None) -> None:
        """
        Put the joints at ``q0_rad`` (default: the initial positions).

        The velocity becomes ``qdot0_rad_s`` (default: at rest); the applied torque reads zero.
        Time goes on.
        """
        q0 = self._initial if q0_rad is None else _as_vector(q0_rad, self.n, 'q0_rad')
        v0 = _as_vector(qdot0_rad_s, self.n, 'qdot0_rad_s')
        self._applied[:] = 0.0
        self._engine.reset(q0, v0)

    # -- the GUI window (PyBullet's) -----------------------------------------------------

    def show_frame(self, name: str, position_m: Sequence[float],
                   quaternion_xyzw: Sequence[float], length_m: float = 0.1) -> bool:
        """
        Draw a coordinate frame (e.g. the goal) in the GUI as three lines, RGB = xyz.

        ``position_m`` and ``quaternion_xyzw`` (ROS order) are in the world frame, where the
        URDF's root link is. Calling it again with the same ``name`` moves that frame. Returns
        False (and draws nothing) without a GUI.
        """
        return self._engine.show_frame(name, position_m, quaternion_xyzw, length_m)

    def gui_camera(self) -> Optional[tuple[int, int, list[float], list[float]]]:
        """Return the GUI's (width, height, view matrix, projection matrix), None without one."""
        return self._engine.gui_camera()

    def close(self) -> None:
        """Release the engine (idempotent)."""
        engine = getattr(self, '_engine', None)
        if engine is not None:
            engine.close()

    def __enter__(self) -> 'RobotSimulator':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

"""
What the simulator asks of a physics engine: one small interface, two engines (ROS-free).

:class:`wrist_sim.simulator.RobotSimulator` is the simulator the node and the experiments use,
whatever the engine: it validates what it is given, clamps the commanded torque to the URDF
effort limits, counts steps and time, and holds the joints before the first command. What
differs between engines is behind :class:`Engine`: loading the URDF, the friction and the
rotor inertia (armature), one step of ``dt`` under a motor torque, and putting the joints
somewhere. ``pybullet`` (:mod:`wrist_sim.pybullet_engine`) is the default; ``mujoco``
(:mod:`wrist_sim.mujoco_engine`, the optional ``mujoco`` package) compiles the same URDF.

Both engines simulate the same plant from the URDF: its inertias, gravity -9.81 m/s^2 along z,
the joint ranges as stops, the driven joints under the motor torque, viscous friction
``-b qdot`` and Coulomb friction with stiction from the simulator's parameters (the URDF's
``<dynamics damping friction>`` are not used: the friction is the simulator's parameter, the
same in both), the joints not driven locked at zero, and no contacts. Where an engine cannot
simulate something it says so through its class attributes (``supports_armature``), and the
node says it in its log.
"""
from abc import ABC, abstractmethod
from typing import ClassVar, Optional, Sequence

import numpy as np
from quat_jt_runtime.errors import QuatJtError

GRAVITY_MPS2 = 9.81


class SimulatorError(QuatJtError):
    """The URDF, the joints or the values asked of the simulator are not usable."""


class NoDisplayError(SimulatorError):
    """The PyBullet window was asked for where none can open: not a matter of the robot."""


class Engine(ABC):
    """
    A fixed-base serial URDF in one physics engine, torque driven, stepped by ``dt_s``.

    After construction, the attributes below describe the driven joints, in the simulator's
    joint order: ``joint_names``; ``effort_limits_nm`` and ``velocity_limits_rad_s`` (inf where
    the URDF gives none, or 0); ``position_lower`` and ``position_upper``; ``q`` and ``qdot``,
    the engine's own buffers of the state, updated in place by :meth:`step` and :meth:`reset`;
    ``missing_meshes``, the mesh files the URDF names that could not be found (shapes left
    out); ``enforces_velocity_limits``, whether the speed is held at the velocity limits;
    ``zero_inertia_links``, the links the engine simulates without the rotational inertia the
    URDF gives them (none by default); ``repaired_inertia_links``, those it simulates with a
    principal moment raised where the URDF's is negative (none by default).
    """

    name: ClassVar[str]
    supports_armature: ClassVar[bool]  # False: the rotor inertia is not simulated
    joint_names: tuple[str, ...]
    effort_limits_nm: np.ndarray
    velocity_limits_rad_s: np.ndarray
    position_lower: np.ndarray
    position_upper: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    missing_meshes: list[str]
    enforces_velocity_limits: bool
    zero_inertia_links: tuple[str, ...] = ()
    repaired_inertia_links: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        """Return the number of driven joints."""
        return len(self.joint_names)

    @abstractmethod
    def set_friction(self, viscous_nm_s_per_rad: np.ndarray, coulomb_nm: np.ndarray) -> None:
        """Apply viscous ``b`` (N m s/rad) and Coulomb levels (N m), checked, one per joint."""

    @abstractmethod
    def set_armature(self, armature: np.ndarray) -> None:
        """Apply the rotor inertia per joint (kg m^2, checked), where the engine can."""

    @abstractmethod
    def step(self, tau_nm: np.ndarray) -> None:
        """
        Advance ``dt_s`` with motor torque ``tau_nm`` (already clamped) plus friction, gravity.

        Updates ``q`` and ``qdot``.
        """

    @abstractmethod
    def reset(self, q_rad: np.ndarray, qdot_rad_s: np.ndarray) -> None:
        """Put the joints at ``q_rad`` with velocity ``qdot_rad_s``; updates ``q``, ``qdot``."""

    @abstractmethod
    def close(self) -> None:
        """Release the engine (idempotent)."""

    # -- a window, where the engine has one (PyBullet's) ---------------------------------

    def show_frame(self, name: str, position_m: Sequence[float],
                   quaternion_xyzw: Sequence[float], length_m: float) -> bool:
        """Draw a frame in the window; False (nothing drawn) without one."""
        return False

    def gui_camera(self) -> Optional[tuple[int, int, list[float], list[float]]]:
        """Return the window's (width, height, view, projection); None without one."""
        return None

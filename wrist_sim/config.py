"""
The simulator node's live settings as one validated, immutable object (ROS-free).

``wrist_sim_node`` declares these as live ROS parameters; a parameter set builds a new
:class:`SimConfig` through :meth:`SimConfig.create` (which raises SimulatorError naming the bad
value) and swaps it in whole, as the controller does with its Gains. The stepping loop reads
the snapshot, never a parameter.
"""
from dataclasses import dataclass
import math
from typing import Any, Mapping

from wrist_sim.simulator import per_joint, SimulatorError


@dataclass(frozen=True)
class SimConfig:
    """The live settings: start pose, friction, watchdog and lockstep pacing."""

    initial_positions_rad: tuple[float, ...]
    viscous_nm_s_per_rad: tuple[float, ...]
    coulomb_nm: tuple[float, ...]
    command_timeout_s: float  # 0 disables the command watchdog
    lockstep_timeout_s: float
    max_real_time_factor: float  # 0 = no limit

    @classmethod
    def create(cls, values: Mapping[str, Any], n_joints: int) -> 'SimConfig':
        """Build from parameter values keyed by parameter name; raise SimulatorError."""
        config = cls(
            initial_positions_rad=per_joint('initial_positions', values['initial_positions'],
                                            n_joints, nonnegative=False),
            viscous_nm_s_per_rad=per_joint('viscous_friction', values['viscous_friction'],
                                           n_joints, nonnegative=True),
            coulomb_nm=per_joint('coulomb_friction', values['coulomb_friction'], n_joints,
                                 nonnegative=True),
            command_timeout_s=float(values['command_timeout']),
            lockstep_timeout_s=float(values['lockstep_timeout']),
            max_real_time_factor=float(values['max_real_time_factor']))
        for name in ('command_timeout_s', 'lockstep_timeout_s', 'max_real_time_factor'):
            v = getattr(config, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise SimulatorError(f'{name}: must be finite and >= 0, got {v}')
        return config

    @property
    def command_timeout_ns(self) -> int:
        return int(self.command_timeout_s * 1e9)

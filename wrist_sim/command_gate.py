"""
The simulator's command path, ROS-free: validation, watchdog, hold until the first command.

``wrist_sim_node`` only marshals: it hands each ``effort_controller/commands`` message to
:meth:`CommandGate.offer` and logs the verdict, asks :meth:`CommandGate.torque` what to apply
at each step and logs the watchdog's events, and tells the gate when a state goes out
(:meth:`CommandGate.published`) and when ``~/reset`` runs (:meth:`CommandGate.reset`). Time is
the simulation's (steps x ``dt_ns``), so the watchdog behaves the same in real time and in
lockstep. The unit tests drive it with plain numbers.
"""
from math import isfinite
from typing import NamedTuple, Optional, Sequence

import numpy as np

TRIPPED = 'tripped'  # the watchdog zeroed the torque (no command for command_timeout)
RESUMED = 'resumed'  # commands are back after a trip


class Offer(NamedTuple):
    """The verdict on one command message."""

    applied: bool
    reason: str = ''  # why it was refused ('' if applied, or if it answered a pre-reset state)
    nonfinite: bool = False  # refused for a NaN or an infinity (else for its length)
    clamped: bool = False  # some value beyond its effort limit (applied clamped by the physics)
    first_since_state: bool = False  # the first command answering the last published state


class CommandGate:
    """
    What torque to apply, from the commands received (one per joint, N m).

    :param effort_limits_nm: per joint, to tell a clamped command (inf: no limit).
    :param dt_ns: the simulation step.
    :param hold_until_first_command: until the first valid command after start-up or a reset,
        :meth:`torque` returns None: hold the joints (brakes on).
    """

    def __init__(self, effort_limits_nm: Sequence[float], dt_ns: int,
                 hold_until_first_command: bool = True) -> None:
        self.n = len(effort_limits_nm)
        self._limits = [float(v) for v in effort_limits_nm]
        self._dt_ns = int(dt_ns)
        self._hold = bool(hold_until_first_command)
        self._cmd = np.zeros(self.n)
        self._zero = np.zeros(self.n)
        self._have_cmd = False
        self._seq = 0  # valid commands received
        self._seq_at_publish = 0  # _seq when the last state was published
        self._cmd_step = 0  # the step count when the last valid command arrived
        self._tripped = False
        self._reset_unpublished = False  # after reset(), until the reset state is published

    @property
    def commanded(self) -> bool:
        """Tell whether any valid command has arrived since start-up."""
        return self._seq > 0

    @property
    def answered(self) -> bool:
        """Tell whether a valid command has arrived since the last published state."""
        return self._seq != self._seq_at_publish

    def offer(self, data: Sequence[float], step_count: int) -> Offer:
        """
        Take a command message received at simulation step ``step_count``, or refuse it.

        Refused, with the reason: a wrong number of values, or a non-finite one (the last
        valid command stays). Not applied, silently: one that arrives after :meth:`reset` and
        before the reset state is published (it answers an older state).
        """
        if self._reset_unpublished:
            return Offer(False)
        if len(data) != self.n:
            return Offer(False, f'{len(data)} values for {self.n} joints')
        if not all(isfinite(v) for v in data):
            return Offer(False, f'non-finite values: {list(data)}', nonfinite=True)
        clamped = any(v > limit or v < -limit for v, limit in zip(data, self._limits))
        first = self._seq == self._seq_at_publish
        self._cmd[:] = data
        self._seq += 1
        self._cmd_step = step_count
        self._have_cmd = True
        return Offer(True, clamped=clamped, first_since_state=first)

    def torque(self, step_count: int, timeout_ns: int) -> tuple[Optional[np.ndarray], str]:
        """
        Return the torque to apply at ``step_count`` and the watchdog's event ('' if none).

        None: hold the joints (no command yet, with ``hold_until_first_command``). Zero torque
        once no valid command has come for ``timeout_ns`` of simulation time (0 = never),
        with the event TRIPPED once, and RESUMED when commands return. The array is the gate's
        own buffer: read it, do not keep it.
        """
        if not self._have_cmd and self._hold:
            return None, ''
        age_ns = (step_count - self._cmd_step) * self._dt_ns
        if self._have_cmd and (timeout_ns <= 0 or age_ns <= timeout_ns):
            if self._tripped:
                self._tripped = False
                return self._cmd, RESUMED
            return self._cmd, ''
        if self._have_cmd and not self._tripped:
            self._tripped = True
            return self._zero, TRIPPED
        return self._zero, ''

    def silence_s(self, step_count: int) -> float:
        """Return the simulation time since the last valid command (s)."""
        return (step_count - self._cmd_step) * self._dt_ns * 1e-9

    def published(self) -> None:
        """Note that a state went out: later commands answer it."""
        self._seq_at_publish = self._seq
        self._reset_unpublished = False

    def reset(self) -> None:
        """Forget the command (hold again until the next one) until the reset state is out."""
        self._cmd[:] = 0.0
        self._have_cmd = False
        self._tripped = False
        self._reset_unpublished = True

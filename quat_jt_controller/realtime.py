"""
Real-time settings of a node's process: CPU affinity and timer slack (Linux).

ROS-free. Both are what a real-time deployment of a 1 kHz loop sets (ros2_control's
controller_manager has a ``cpu_affinity`` parameter for the same reason):

* **CPU affinity.** A node pinned to a CPU of its own keeps its caches warm between ticks; on the
  2-core test machine, pinning the simulator and the controller to different CPUs halved the
  controller's in-loop compute time (README, 'Real-time loop'). Every thread of the process is
  pinned (the DDS threads too); threads started later inherit it.
* **Timer slack.** Linux lets a sleeping thread wake up to 50 us late (the default slack) so that
  wake-ups can be merged. The simulator's deadline loop sleeps until just before each tick and
  busy-waits the rest; with 1 ns of slack its sleeps end within the scheduler's latency, so the
  busy-wait, which costs a core while it lasts, can be short.
"""
import ctypes
import os
import sys
from typing import Iterable

PR_SET_TIMERSLACK = 29  # <linux/prctl.h>
PR_GET_TIMERSLACK = 30


def allowed_cpus() -> set[int]:
    """Return the CPUs this process may run on (its cpuset, e.g. from taskset or a container)."""
    if not hasattr(os, 'sched_getaffinity'):
        return set(range(os.cpu_count() or 1))
    return set(os.sched_getaffinity(0))


def check_cpus(cpus: Iterable[int]) -> tuple[int, ...]:
    """
    Return ``cpus`` sorted, or raise ValueError saying why they cannot be used.

    Empty means no pinning. Each entry must be a CPU this process may run on.
    """
    wanted = tuple(sorted({int(c) for c in cpus}))
    if not wanted:
        return ()
    if not hasattr(os, 'sched_setaffinity'):
        raise ValueError(f'cpu_affinity {list(wanted)}: this platform ({sys.platform}) cannot '
                         'pin threads; leave it empty')
    allowed = allowed_cpus()
    outside = [c for c in wanted if c not in allowed]
    if outside:
        raise ValueError(f'cpu_affinity {list(wanted)}: CPUs {outside} are not available to '
                         f'this process (it may use {sorted(allowed)})')
    return wanted


def pin_process(cpus: Iterable[int]) -> tuple[int, ...]:
    """
    Pin every thread of this process to ``cpus`` (checked by :func:`check_cpus`).

    Returns the CPUs pinned to; empty ``cpus`` changes nothing and returns ().
    """
    wanted = check_cpus(cpus)
    if not wanted:
        return ()
    try:
        threads = [int(t) for t in os.listdir('/proc/self/task')]
    except OSError:  # no /proc: the calling thread only
        threads = [0]
    for tid in threads:
        try:
            os.sched_setaffinity(tid, wanted)
        except ProcessLookupError:  # the thread ended meanwhile
            pass
    return wanted


def _prctl(option: int, value: int = 0) -> int:
    """Call prctl(2); -1 where there is none (not Linux) or it fails."""
    if not sys.platform.startswith('linux'):
        return -1
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(option, ctypes.c_ulong(value), 0, 0, 0))
    except (OSError, AttributeError):
        return -1


def set_timer_slack(slack_ns: int = 1) -> bool:
    """Set the calling thread's timer slack in ns (Linux); return whether it was set."""
    return _prctl(PR_SET_TIMERSLACK, int(slack_ns)) == 0


def timer_slack_ns() -> int:
    """Return the calling thread's timer slack in ns (-1 if it cannot be read)."""
    return _prctl(PR_GET_TIMERSLACK)

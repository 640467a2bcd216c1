"""What the CPU tests share: skips, and the CPUs and scheduling of each thread of a process."""
import os
from pathlib import Path
import subprocess
import sys

import pytest
from quat_jt_runtime import realtime

linux_only = pytest.mark.skipif(not sys.platform.startswith('linux'), reason='Linux only')
two_cpus = pytest.mark.skipif(len(realtime.allowed_cpus()) < 2,
                              reason='pinning to one CPU of one proves nothing')


def thread_cpus(pid: int) -> dict[int, str]:
    """Return ``{thread id: Cpus_allowed_list}`` of every thread of ``pid``."""
    out = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            status = (task / 'status').read_text()
        except FileNotFoundError:  # the thread ended meanwhile
            continue
        for line in status.splitlines():
            if line.startswith('Cpus_allowed_list:'):
                out[int(task.name)] = line.split(':', 1)[1].strip()
    return out


def thread_policy(tid: int = 0) -> tuple[str, int]:
    """Return a thread's scheduling policy ('fifo', 'other', ...) and priority (Linux)."""
    policy = os.sched_getscheduler(tid) & ~getattr(os, 'SCHED_RESET_ON_FORK', 0)
    names = {os.SCHED_OTHER: 'other', os.SCHED_FIFO: 'fifo', os.SCHED_RR: 'rr',
             getattr(os, 'SCHED_BATCH', -1): 'batch', getattr(os, 'SCHED_IDLE', -2): 'idle'}
    return names.get(policy, str(policy)), os.sched_getparam(tid).sched_priority


def thread_policies(pid: int) -> dict[int, tuple[str, int]]:
    """Return ``{thread id: (policy, priority)}`` of every thread of ``pid``."""
    out = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            out[int(task.name)] = thread_policy(int(task.name))
        except ProcessLookupError:  # the thread ended meanwhile
            continue
    return out


def fifo_allowed(priority: int = 1) -> bool:
    """Tell whether a process started here may run in SCHED_FIFO (root, or an rtprio limit)."""
    script = ('from quat_jt_runtime import realtime\n'
              f'print(repr(realtime.set_thread_priority({priority})))')
    out = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                         timeout=60, check=True).stdout
    return out.strip() == "''"

"""What the CPU tests share: skips, and the CPUs each thread of a process may run on."""
from pathlib import Path
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


def thread_policies(pid: int) -> dict[int, tuple[str, int]]:
    """Return ``{thread id: (policy, priority)}`` of every thread of ``pid``."""
    out = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            out[int(task.name)] = realtime.thread_policy(int(task.name))
        except ProcessLookupError:  # the thread ended meanwhile
            continue
    return out


def fifo_allowed(priority: int = 1) -> bool:
    """Tell whether a process started here may run in SCHED_FIFO (root, or an rtprio limit)."""
    import subprocess
    script = ('from quat_jt_runtime import realtime\n'
              f'print(repr(realtime.set_thread_priority({priority})))')
    out = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                         timeout=60, check=True).stdout
    return out.strip() == "''"

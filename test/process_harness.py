"""What the multi-process tests share: node logs, waits on conditions, teardown, /proc."""
import os
from pathlib import Path
import time
from typing import Callable

from experiments import local_ros
import pytest
import rclpy


class ProcessHarnessMixin:
    """
    Node logs, condition waits and teardown for a multi-process test harness.

    The harness has ``work_dir``, ``procs`` (name -> Popen), ``node``, ``executor`` and
    ``context``. Waits fail the test with the nodes' logs attached, as soon as a node process
    exits or the deadline passes.
    """

    def node_log(self) -> str:
        out = []
        for name in self.procs:
            path = self.work_dir / f'{name}.log'
            if path.exists():
                text = path.read_text(errors='replace')
                out.append(f'--- {name}.log (last 6000 chars) ---\n{text[-6000:]}')
        return '\n'.join(out)

    def spin_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            for name, proc in self.procs.items():
                if proc.poll() is not None:
                    pytest.fail(f'{name} exited with {proc.returncode} while waiting for '
                                f'{what}\n{self.node_log()}')
            if time.monotonic() > deadline:
                pytest.fail(f'timed out after {timeout} s waiting for {what}\n{self.node_log()}')
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        local_ros.stop_nodes(list(self.procs.values()))
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def call_service(executor, client, request, timeout_s: float = 5.0, attempts: int = 3):
    """
    Call a service and return its response, asking again if no answer comes in ``timeout_s``.

    With Fast DDS a request can reach a server whose reply writer has not yet matched the
    client's reply reader: the server logs 'failed to send response (timeout)' and the client
    waits forever. The services called here are idempotent, so the call is simply repeated.
    """
    for _ in range(attempts):
        future = client.call_async(request)
        deadline = time.monotonic() + timeout_s
        while not future.done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if future.done():
            return future.result()
        client.remove_pending_request(future)
    raise AssertionError(f'no reply from service {client.service_name!r} after {attempts} calls')


def children_of(pid: int, module: str = '') -> list[int]:
    """Return the processes whose parent is ``pid`` (from /proc), running ``module`` if given."""
    out = []
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                stat = Path(f'/proc/{entry}/stat').read_text()
                command = Path(f'/proc/{entry}/cmdline').read_bytes().split(b'\0')
            except OSError:
                continue
            if (int(stat.rsplit(')', 1)[1].split()[1]) == pid
                    and (not module or module.encode() in command)):
                out.append(int(entry))
    return out


def descendants_of(pid: int, module: str = '') -> list[int]:
    """Return the processes below ``pid`` at any depth, running ``module`` if given."""
    below, parents = [], [pid]
    while parents:
        parents = [child for parent in parents for child in children_of(parent)]
        below += parents
    return [child for parent in [pid] + below for child in children_of(parent, module)]


def alive(pid: int) -> bool:
    """Tell whether ``pid`` runs (exists and is not a zombie)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'

"""
PyBullet without its banner: its C code prints on import and on connect.

``pybullet build time: ...`` (to stderr, on import) and ``argv[0]=`` (to stdout, on each
connection) would otherwise open every simulator start, before the node's own lines.
:func:`c_output_silenced` points the given file descriptors at /dev/null for the duration. The
import here happens before any ROS thread exists (the entry points import the nodes before
``rclpy.init``); a connection only silences stdout, where ROS does not log. ROS-free.
"""
import contextlib
import ctypes
import os
import sys
from typing import Iterator, Sequence

_LIBC = ctypes.CDLL(None)  # fflush(NULL): C stdio's buffers


@contextlib.contextmanager
def c_output_silenced(fds: Sequence[int] = (1,)) -> Iterator[None]:
    """Send what is written to ``fds`` (default stdout) to /dev/null, then restore them."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in fds]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(devnull, fd)
        yield
    finally:
        _LIBC.fflush(None)  # what C wrote meanwhile goes to /dev/null, not later to the fds
        for fd, copy in zip(fds, saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)


with c_output_silenced((1, 2)):
    try:
        import pybullet  # noqa: E402, F401 - prints its build time on import
    except ModuleNotFoundError as exc:  # e.g. a colcon workspace whose rosdep skipped it
        raise ModuleNotFoundError(f"{exc}: install PyBullet, e.g. 'pip install pybullet'") \
            from exc

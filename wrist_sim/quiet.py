"""
PyBullet without its banner: its C code prints on import and on connect.

``pybullet build time: ...`` (to stderr, on import) and ``argv[0]=`` (to stdout, on each
connection) would otherwise open every simulator start, before the node's own lines.
:func:`c_output_silenced` points the given file descriptors at /dev/null for the duration. The
import here happens before any ROS thread exists (the entry points import the nodes before
``rclpy.init``); a connection only silences stdout, where ROS does not log.
:func:`c_output_captured` keeps what C code writes to stdout meanwhile instead, for the caller
to read (PyBullet's URDF loader prints its warnings there). ROS-free.
"""
import contextlib
import ctypes
import os
import sys
import tempfile
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


@contextlib.contextmanager
def c_output_captured() -> Iterator[list[str]]:
    """
    Collect what is written to stdout (fd 1, C code included) meanwhile.

    Yields a list that holds the text, as one string, once the block ends; stdout is restored
    whatever happens in the block.
    """
    sys.stdout.flush()
    captured: list[str] = []
    saved = os.dup(1)
    with tempfile.TemporaryFile() as sink:
        try:
            os.dup2(sink.fileno(), 1)
            yield captured
        finally:
            _LIBC.fflush(None)
            os.dup2(saved, 1)
            os.close(saved)
            sink.seek(0)
            captured.append(sink.read().decode(errors='replace'))


with c_output_silenced((1, 2)):
    try:
        import pybullet  # noqa: E402, F401 - prints its build time on import
    except ModuleNotFoundError as exc:  # e.g. a colcon workspace whose rosdep skipped it
        raise ModuleNotFoundError(f"{exc}: install PyBullet, e.g. 'pip install pybullet'") \
            from exc

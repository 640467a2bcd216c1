"""
Ctrl-C and SIGTERM as a request to stop: one flag per process, installed before anything else.

A terminal's Ctrl-C sends SIGINT to the whole foreground process group, ``ros2 launch`` sends
SIGINT to each process (and, when one exits with ``on_exit=Shutdown``, a second one to the
others), and Python's default handler raises KeyboardInterrupt wherever the process happens to
be: inside an import during start-up, inside a callback, or in the middle of the shutdown. So
this package's entry points install :func:`install` first, before the slow imports (rclpy,
numpy, Pinocchio, PyBullet), and keep it until the process exits: every SIGINT or SIGTERM, the
first or a later one, only sets the flag, and the node's loop ends cleanly at the next check.

Standard library only, so it can run before any other import.
"""
import signal
from typing import Optional

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopFlag:
    """Set by SIGINT / SIGTERM (any number of them); call it to ask whether to keep running."""

    def __init__(self) -> None:
        self.is_set = False
        self.signals_received = 0

    def on_signal(self, signum: int, frame: object) -> None:
        """Handle a stop signal: set the flag; a repeated signal changes nothing else."""
        self.is_set = True
        self.signals_received += 1

    def __call__(self) -> bool:
        """Return True while the process should keep running."""
        return not self.is_set


_flag: Optional[StopFlag] = None


def install() -> StopFlag:
    """Install the process's StopFlag as the SIGINT and SIGTERM handler (idempotent)."""
    global _flag
    if _flag is None:
        _flag = StopFlag()
    for sig in STOP_SIGNALS:
        signal.signal(sig, _flag.on_signal)
    return _flag


def requested() -> bool:
    """Return True once a stop signal came (False where no flag is installed, e.g. a test)."""
    return _flag is not None and _flag.is_set


def ignore_from_now_on() -> None:
    """
    Ignore SIGINT and SIGTERM for the rest of the process: call it once the node is shut down.

    At exit Python puts back the default action of every signal that has a Python handler, and
    the interpreter's finalization (DDS participants, PyBullet) then takes about 0.1 s, during
    which a second Ctrl-C (or the one ``ros2 launch`` sends when another process exits) would
    kill the process with status -2. An ignored signal stays ignored. SIGKILL still ends it.
    """
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)

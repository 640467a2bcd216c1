"""Rate limits for log lines that a flood of bad (or many good) inputs would repeat (ROS-free)."""
import re
import time
from typing import Callable, Hashable, Optional, Union

_NUMBERS = re.compile(r'[-+]?(\d+\.?\d*(e[-+]?\d+)?|nan|inf)', re.IGNORECASE)


def cause(reason: str) -> str:
    """Return the reason without its numbers: one cause for a flood of varying bad values."""
    return _NUMBERS.sub('#', reason)


class Throttle:
    """
    At most one pass per key and ``period_s``; counts what it held back.

    ``throttle(key)`` returns None to suppress, or the number of calls suppressed for that key
    since its last pass (0 usually), so the next line can say how many it stands for.
    """

    def __init__(self, period_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.period_s = period_s
        self._clock = clock
        self._last: dict[Hashable, float] = {}
        self._held: dict[Hashable, int] = {}

    def __call__(self, key: Hashable) -> Optional[int]:
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._held[key] = self._held.get(key, 0) + 1
            return None
        if len(self._last) > 256:  # a bounded table, whatever the input
            self._last.clear()
        self._last[key] = now
        return self._held.pop(key, 0)

    def line(self, key: Hashable, text: Union[str, Callable[[], str]],
             held_note: str = ' (and {} more like it)') -> Optional[str]:
        """
        Return ``text`` if ``key`` passes, saying how many it stands for; else None.

        ``text`` may be a function, called only when the line passes (no formatting for the
        lines held back).
        """
        held = self(key)
        if held is None:
            return None
        return (text() if callable(text) else text) + (held_note.format(held) if held else '')

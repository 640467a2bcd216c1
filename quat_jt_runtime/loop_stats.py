"""
Timing statistics of a 1 kHz loop, cheap to record and summarised off the hot path.

ROS-free and shared by both nodes: :class:`Ring` is a preallocated numpy ring of floats (one
item store per sample); :class:`TickStats` is the controller's per-window bookkeeping, read and
reset by its 1 Hz diagnostics; :class:`LoopStats` is the simulator's whole-run bookkeeping,
summarised once at shutdown. All times in seconds from ``time.perf_counter`` unless a name says
otherwise.
"""
import json
from math import nan
from pathlib import Path
import time
from typing import Sequence

import numpy as np


class Ring:
    """
    The last ``capacity`` floats pushed, in a preallocated numpy buffer.

    A push is one item store (tens of ns); :meth:`values` returns the window's finite samples
    sorted, so the 1 Hz summary of a 1 kHz ring costs tens of microseconds, not the
    milliseconds of Python-level sorting (which, on the composed mode's single thread, would
    hold up the loop for a tick).
    """

    __slots__ = ('capacity', '_buf', 'count')

    def __init__(self, capacity: int) -> None:
        self.capacity = int(capacity)
        self._buf = np.full(self.capacity, nan)
        self.count = 0  # samples pushed since the last clear

    def push(self, value: float) -> None:
        self._buf[self.count % self.capacity] = value
        self.count += 1

    def values(self) -> np.ndarray:
        """Return the window's finite samples, sorted ascending."""
        window = self._buf[:min(self.count, self.capacity)]
        finite = window[np.isfinite(window)]
        finite.sort()
        return finite

    def clear(self) -> None:
        self.count = 0


def percentile(sorted_values: Sequence[float], fraction: float) -> float:
    """Nearest-rank percentile of already sorted values (NaN if empty)."""
    n = len(sorted_values)
    if not n:
        return nan
    i = min(n - 1, max(0, int(round(fraction * (n - 1)))))
    return float(sorted_values[i])


def spread(values: np.ndarray) -> tuple[float, float]:
    """Mean and standard deviation (NaN, NaN if empty)."""
    if not len(values):
        return nan, nan
    return float(values.mean()), float(values.std())


class TickStats:
    """
    The controller's window of tick timings: compute, publish, period and state age (us).

    :meth:`record` is called once per tick; :meth:`window` returns the figures of the window
    and starts a new one.
    """

    def __init__(self, capacity: int = 2048) -> None:
        self.compute_us = Ring(capacity)
        self.publish_us = Ring(capacity)
        self.period_us = Ring(capacity)
        self.age_us = Ring(capacity)
        self.ticks = 0  # in the current window
        self.saturated = 0  # in the current window
        self.total_ticks = 0
        self._last_tick_ns = 0

    def record(self, t_start_ns: int, t_computed_ns: int, t_published_ns: int,
               age_us: float, saturated: bool) -> None:
        """One tick: perf_counter_ns at start, command ready, published; the state's age."""
        self.compute_us.push((t_computed_ns - t_start_ns) * 1e-3)
        self.publish_us.push((t_published_ns - t_computed_ns) * 1e-3)
        self.period_us.push((t_start_ns - self._last_tick_ns) * 1e-3 if self._last_tick_ns
                            else nan)
        self._last_tick_ns = t_start_ns
        self.age_us.push(age_us)
        self.ticks += 1
        self.total_ticks += 1
        if saturated:
            self.saturated += 1

    def window(self, window_s: float) -> dict[str, float]:
        """Figures of the window that lasted ``window_s``, then reset it."""
        compute = self.compute_us.values()
        publish = self.publish_us.values()
        periods = self.period_us.values()
        ages = self.age_us.values()
        mean_p, std_p = spread(periods)
        out = {
            'control_rate_hz': self.ticks / max(window_s, 1e-9),
            'ticks_in_window': self.ticks,
            'period_mean_us': mean_p,
            'period_jitter_std_us': std_p,
            'period_p99_us': percentile(periods, 0.99),
            'period_max_us': percentile(periods, 1.0),
            'compute_us_p50': percentile(compute, 0.5),
            'compute_us_p99': percentile(compute, 0.99),
            'compute_us_max': percentile(compute, 1.0),
            'publish_us_p50': percentile(publish, 0.5),
            'publish_us_p99': percentile(publish, 0.99),
            'state_age_us_p50': percentile(ages, 0.5),
            'state_age_us_max': percentile(ages, 1.0),
            'saturated_ticks': self.saturated,
            'total_ticks': self.total_ticks,
        }
        for ring in (self.compute_us, self.publish_us, self.period_us, self.age_us):
            ring.clear()
        self.ticks = 0
        self.saturated = 0
        return out


class LoopStats:
    """
    The simulator's stepping loop: counters plus preallocated ring buffers.

    Per step: wall time, compute time, lateness past the deadline, whether the command applied
    was fresh (arrived after the previous state was published). Per fresh command: latency from
    the state publish to its arrival.
    """

    def __init__(self, capacity: int = 10000) -> None:
        self.capacity = int(capacity)
        self._t = np.zeros(self.capacity)
        self._compute = np.zeros(self.capacity)
        self._late = np.zeros(self.capacity)
        self._fresh = np.zeros(self.capacity, dtype=bool)
        self._lat = np.zeros(self.capacity)
        self.steps = 0
        self.fresh_steps = 0
        self.latencies = 0
        self.missed_deadlines = 0
        self.rejected_commands = 0
        self.clamped_commands = 0
        self.watchdog_trips = 0
        self.lockstep_timeouts = 0
        self.start_s = time.perf_counter()

    def record_step(self, t_s: float, compute_s: float, late_s: float, fresh: bool) -> None:
        """One step: its wall time, compute time, lateness and freshness of its command."""
        k = self.steps % self.capacity
        self._t[k] = t_s
        self._compute[k] = compute_s
        self._late[k] = late_s
        self._fresh[k] = fresh
        self.steps += 1
        if fresh:
            self.fresh_steps += 1

    def record_latency(self, latency_s: float) -> None:
        """Wall time from a state publish to the arrival of the first command after it."""
        self._lat[self.latencies % self.capacity] = latency_s
        self.latencies += 1

    def _window(self, buf: np.ndarray, count: int) -> np.ndarray:
        return buf[:min(count, self.capacity)]

    def summary(self) -> dict:
        """Figures over the run and over the last ``capacity`` steps (the window)."""
        n = min(self.steps, self.capacity)
        out: dict = {
            'steps': self.steps,
            'elapsed_s': time.perf_counter() - self.start_s,
            'missed_deadlines': self.missed_deadlines,
            'fresh_steps': self.fresh_steps,
            'rejected_commands': self.rejected_commands,
            'clamped_commands': self.clamped_commands,
            'watchdog_trips': self.watchdog_trips,
            'lockstep_timeouts': self.lockstep_timeouts,
        }
        if n >= 2:
            t = self._window(self._t, self.steps)
            out['window_rate_hz'] = (n - 1) / max(float(t.max() - t.min()), 1e-12)
            c = self._window(self._compute, self.steps) * 1e6
            late = self._window(self._late, self.steps) * 1e6
            period = np.diff(np.sort(t)) * 1e6  # the ring is not in order once it wraps
            jitter = np.abs(period - np.median(period))
            fresh = self._window(self._fresh, self.steps)
            out.update({
                'window_steps': n,
                'window_stale_steps': int(n - np.count_nonzero(fresh)),
                'period_us_p50': float(np.percentile(period, 50)),
                'period_us_max': float(period.max()),
                'jitter_us_p50': float(np.percentile(jitter, 50)),
                'jitter_us_p99': float(np.percentile(jitter, 99)),
                'jitter_us_max': float(jitter.max()),
                'step_compute_us_p50': float(np.percentile(c, 50)),
                'step_compute_us_p99': float(np.percentile(c, 99)),
                'step_compute_us_max': float(c.max()),
                'lateness_us_p50': float(np.percentile(late, 50)),
                'lateness_us_p99': float(np.percentile(late, 99)),
                'lateness_us_max': float(late.max()),
                'window_late_steps': int(np.count_nonzero(late > 0.5 * float(np.median(period)))),
                'window_fresh_fraction': float(fresh.mean()),
                **fresh_command_figures(t, fresh),
            })
        if self.latencies:
            lat = self._window(self._lat, self.latencies) * 1e6
            out['cmd_latency_us_p50'] = float(np.percentile(lat, 50))
            out['cmd_latency_us_p99'] = float(np.percentile(lat, 99))
            out['cmd_latency_us_max'] = float(lat.max())
        return out


FRESH_WINDOW_S = 0.25


def fresh_command_figures(t_s: np.ndarray, fresh: np.ndarray) -> dict:
    """
    Describe the loop as the robot saw it: the steps that applied a fresh command, at ``t_s``.

    Returns the lowest rate of fresh steps in a whole FRESH_WINDOW_S window
    (``fresh_rate_hz_min``) and the largest gap between two fresh steps (``fresh_gap_ms_max``).
    """
    order = np.argsort(t_s)
    t_sorted = t_s[order]
    fresh_t = t_sorted[fresh[order].astype(bool)]
    out = {'fresh_gap_ms_max': float(np.diff(fresh_t).max() * 1e3) if fresh_t.size > 1
           else float('inf')}
    n_windows = int((t_sorted[-1] - t_sorted[0]) / FRESH_WINDOW_S)
    if n_windows >= 1:
        edges = t_sorted[0] + FRESH_WINDOW_S * np.arange(n_windows + 1)
        counts, _ = np.histogram(fresh_t, bins=edges)
        out['fresh_rate_hz_min'] = float(counts.min() / FRESH_WINDOW_S)
    return out


def write_summary(summary: dict, path: str) -> str:
    """Write a :meth:`LoopStats.summary` as JSON to ``path`` ('' = nowhere); say why not, or ''."""
    if not path:
        return ''
    try:
        Path(path).write_text(json.dumps(summary, indent=1, sort_keys=True))
    except OSError as exc:
        return f'cannot write stats_file {path}: {exc}'
    return ''

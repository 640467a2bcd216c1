"""
Where an experiment's independent cases run: here, on local processes, or on a Ray cluster.

Each case is a picklable job given to a module-level function; the results come back in the
order of the jobs, so a seeded experiment gives the same figures whichever runner ran it.

* ``serial``: one after the other in this process;
* ``local`` (the default): ``concurrent.futures.ProcessPoolExecutor`` with one worker per CPU;
* Ray (``ray_address``, e.g. ``auto`` or ``ray://head:10001``): ``ray.remote`` tasks on the
  cluster (``pip install ray``, the package's ``campaign`` extra); imported only when asked.
"""
from concurrent.futures import ProcessPoolExecutor
import os
from pathlib import Path
from typing import Callable, Optional, Sequence


SOURCE_TREE = Path(__file__).resolve().parents[1]  # the directory holding experiments/


class RunnerError(RuntimeError):
    """The runner asked for cannot run (Ray not installed, a bad worker count)."""


def cpu_count() -> int:
    """Return the CPUs this process may use (its affinity mask, else the machine's)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def run_all(function: Callable, jobs: Sequence, workers: Optional[int] = None,
            ray_address: Optional[str] = None, progress: Optional[Callable] = None) -> list:
    """
    Return ``[function(job) for job in jobs]``, computed by the runner asked for.

    ``ray_address`` set: on that Ray cluster. Else ``workers`` local processes (default one
    per CPU; 1 runs the jobs here, one after the other). ``progress(done, total)`` is called
    as results arrive (in the jobs' order).
    """
    jobs = list(jobs)
    if ray_address:
        return _run_ray(function, jobs, ray_address, progress)
    workers = cpu_count() if workers is None else int(workers)
    if workers < 1:
        raise RunnerError(f'workers must be >= 1, got {workers}')
    results = []
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            results.append(function(job))
            if progress:
                progress(len(results), len(jobs))
        return results
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs))) as pool:
        for result in pool.map(function, jobs):
            results.append(result)
            if progress:
                progress(len(results), len(jobs))
    return results


def _run_ray(function: Callable, jobs: list, address: str,
             progress: Optional[Callable]) -> list:
    try:
        import ray
    except ImportError as exc:
        raise RunnerError(f'--ray-address {address!r} needs Ray ({exc}): pip install ray (the '
                          "package's 'campaign' extra), or run without --ray-address (local "
                          'processes)') from None
    if not ray.is_initialized():
        # the workers import this package's modules: ship the source tree they come from
        ray.init(address=address, log_to_driver=False, runtime_env={
            'working_dir': str(SOURCE_TREE), 'excludes': ['.git', '__pycache__', 'results/']})
    remote = ray.remote(function)
    refs = [remote.remote(job) for job in jobs]
    results = []
    for ref in refs:  # in the jobs' order
        results.append(ray.get(ref))
        if progress:
            progress(len(results), len(jobs))
    return results

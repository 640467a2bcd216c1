"""
The package's one error base class (ROS-free).

Every error that says a value given to the package is unusable (a URDF, a gain, an extension, a
simulator setting) is a :class:`QuatJtError`, itself a ValueError: a caller can catch them all
at once, or each kind by its own class (``ModelError``, ``GainsError``, ``ShapingError``,
``SimulatorError``). The message names the bad value.

:func:`checked_vector` is the one validator of a vector of numbers (gains, per-joint
extensions, postures): its messages name the entry and say what it must be.
"""
from math import isfinite
from typing import Any, Optional


class QuatJtError(ValueError):
    """A value given to this package is unusable; the message says which and why."""


def checked_vector(name: str, values: Any, size: int, error: type = QuatJtError, *,
                   lower: Optional[float] = None, strict: bool = False,
                   upper: float = float('inf'), why: str = '',
                   per_joint: bool = False) -> tuple[float, ...]:
    """
    Return ``values`` as ``size`` finite floats, or raise ``error`` naming the bad entry.

    ``lower``: each value must be >= it (> it if ``strict``); ``upper``: at most it, ``why``
    saying where that ceiling comes from. ``per_joint`` says "(one per joint)" in the size
    message.
    """
    try:
        vals = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise error(f'{name} must be a list of numbers, got {values!r}') from None
    if len(vals) != size:
        raise error(f'{name} must have {size} values{" (one per joint)" if per_joint else ""}'
                    f', got {len(vals)}: {list(vals)}')
    bound = '' if lower is None else f' and {">" if strict else ">="} {lower:g}'
    for i, v in enumerate(vals):
        if not isfinite(v) or (lower is not None and (v <= lower if strict else v < lower)):
            raise error(f'{name}[{i}] must be finite{bound}, got {v}')
        if v > upper:
            raise error(f'{name}[{i}] = {v:g} is above {upper:g}: {why}')
    return vals

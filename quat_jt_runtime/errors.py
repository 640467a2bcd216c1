"""
The package's one error base class (ROS-free).

Every error that says a value given to the package is unusable (a URDF, a gain, an extension, a
simulator setting) is a :class:`QuatJtError`, itself a ValueError: a caller can catch them all
at once, or each kind by its own class (``ModelError``, ``GainsError``, ``ShapingError``,
``SimulatorError``). The message names the bad value.
"""


class QuatJtError(ValueError):
    """A value given to this package is unusable; the message says which and why."""

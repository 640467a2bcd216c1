"""Choosing the controlled joints of a URDF by name (shared by the model and the simulator)."""
from typing import Optional, Sequence


def select_joints(requested: Optional[Sequence[str]], movable: Sequence[str],
                  error: type = ValueError) -> list[str]:
    """
    Return the joints to use, in the caller's order; default all ``movable`` joints.

    Raises ``error`` naming the problem: an unknown or non-movable joint, a repeated one, none.
    """
    names = list(movable) if requested is None else [str(n) for n in requested]
    unknown = [n for n in names if n not in movable]
    if unknown:
        raise error(f'joints {unknown} are not movable joints of the URDF (it has '
                    f'{list(movable)})')
    if len(set(names)) != len(names):
        raise error(f'joint names repeat: {names}')
    if not names:
        raise error('no joints selected')
    return names

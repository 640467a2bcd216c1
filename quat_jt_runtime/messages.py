"""Messages both nodes build the same way (``/diagnostics``)."""
from typing import Iterable, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

# One status: (name, level, message, [(key, value), ...]).
Status = tuple[str, int, str, Sequence[tuple[str, str]]]


def diagnostic_array(node_name: str, hardware_id: str, statuses: Iterable[Status],
                     stamp) -> DiagnosticArray:
    """
    Return a DiagnosticArray of ``statuses``, each named ``'<node_name>: <name>'``.

    /diagnostics is one topic for the whole graph: each status carries the node's full name.
    """
    array = DiagnosticArray(status=[
        DiagnosticStatus(name=f'{node_name}: {name}', hardware_id=hardware_id,
                         level=bytes([level]), message=message,
                         values=[KeyValue(key=k, value=v) for k, v in values])
        for name, level, message, values in statuses])
    array.header.stamp = stamp
    return array

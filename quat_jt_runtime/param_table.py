"""
A node's parameter table, ROS-free: its rows, their rules, and their text.

A :class:`Spec` row is everything about one parameter: type, default, range, size rule and
description. From it come the declaration and the ``ParameterDescriptor`` (``params.py``, the
ROS side), the validation of the snapshot the parameter belongs to (:meth:`Spec.check`, here, so
a core that builds the snapshot from a config file applies the node's rules), the docs' table
(:func:`markdown_table`) and a parameter file's value (:func:`yaml_value`).
"""
from dataclasses import dataclass
import enum
from math import inf, isfinite
import re
from typing import Any, Mapping, Optional, Sequence

import numpy as np

from quat_jt_runtime.errors import checked_vector

# A string YAML reads as that string unquoted (a name; not a number, not a flag)
_PLAIN = re.compile(r'[A-Za-z_/][A-Za-z0-9_./-]*')


class Kind(enum.Enum):
    """A parameter's type: its number in rcl_interfaces/msg/ParameterType, and the docs' name."""

    BOOL = (1, 'bool')
    INT = (2, 'int')
    DOUBLE = (3, 'double')
    STRING = (4, 'string')
    INT_ARRAY = (7, 'int[]')
    DOUBLE_ARRAY = (8, 'double[]')
    STRING_ARRAY = (9, 'string[]')

    def __init__(self, descriptor_type: int, label: str) -> None:
        self.descriptor_type = descriptor_type  # also the value of rclpy's Parameter.Type
        self.label = label

    @property
    def is_array(self) -> bool:
        """Return True for the array types."""
        return self.label.endswith('[]')


@dataclass(frozen=True)
class Spec:
    """
    One row of a node's parameter table: everything about a parameter, in one place.

    The declaration, its ``ParameterDescriptor`` and the docs' table are generated from it. The
    ``description``, ``constraints`` and a callable ``default`` take the node's context (the
    number of joints ``n``, say): text through ``str.format``, the default called with it.

    The rules :meth:`check` applies: ``bounds`` is the closed range of a scalar (which rclpy
    also enforces on every set) or of each entry of an array (open below if ``strict``; a bound
    may name a number of the context, such as a ceiling from the effort limits, with ``why``
    saying where it comes from); ``size`` names the context entry that is an array's length
    (``'n'``: one per joint); ``empty_ok`` lets an array be empty (the snapshot then computes
    its own default); ``choices`` are the values a string may take. ``constraints`` is the
    docs' text of an array's rules, written from them unless given. ``field`` is the name of
    the attribute of the snapshot the row fills ('' = the parameter's name).
    """

    name: str
    kind: Kind
    default: Any  # a value, or a function of the context that returns it
    description: str
    read_only: bool = False
    bounds: Optional[tuple[float, float]] = None
    constraints: str = ''
    default_text: str = ''  # the docs' default when ``default`` is a function
    size: str = ''
    empty_ok: bool = False
    field: str = ''
    strict: bool = False  # an array's lower bound excluded
    why: str = ''  # why an array's entries have their upper bound (text, with the context)
    choices: tuple = ()  # the values a string may take

    @staticmethod
    def _bound(bound: Any, context: Mapping[str, Any]) -> Optional[float]:
        """Return a bound: a number, or the context's number named by a string."""
        return float(context[bound]) if isinstance(bound, str) else bound

    @staticmethod
    def _bound_text(bound: Any, context: Mapping[str, Any]) -> str:
        """Return a bound as the docs show it (a context's text as it is)."""
        value = context[bound] if isinstance(bound, str) else bound
        return value if isinstance(value, str) else f'{value:g}'

    @property
    def attribute(self) -> str:
        """Return the name of the snapshot's attribute this row fills."""
        return self.field or self.name

    def default_value(self, context: Mapping[str, Any]) -> Any:
        """Return the default for this node (a function default is called with the context)."""
        return self.default(context) if callable(self.default) else self.default

    def rule_text(self, context: Mapping[str, Any]) -> str:
        """Return the docs' text of the rules: the range of a scalar, or the array's rules."""
        if self.bounds is not None and not self.kind.is_array:
            return '[' + ', '.join(str(b) if isinstance(b, int) else f'{b:g}'
                                   for b in self.bounds) + ']'
        if self.choices:
            return 'one of ' + ', '.join(f"'{c}'" for c in self.choices)
        if self.constraints or not self.kind.is_array or not self.size:
            return self.constraints.format(**context)
        count = f'{{{self.size}}} finite values'
        if self.bounds is not None:
            low, high = (self._bound_text(b, context) for b in self.bounds)
            count += (f' {">" if self.strict else ">="} {low}' if high == 'inf'
                      else f' in {"(" if self.strict else "["}{low}, {high}]')
        return count.format(**context)

    def check(self, value: Any, context: Mapping[str, Any], error: type = ValueError) -> Any:
        """
        Return ``value`` checked by this row's rules (arrays as tuples); raise ``error``.

        The message names the parameter and the value. Sizes come from ``context``.
        """
        name = self.name
        if self.choices:
            if value not in self.choices:
                raise error(f'{name} must be one of {list(self.choices)}, got {value!r}')
            return value
        if self.kind in (Kind.DOUBLE, Kind.INT):
            if isinstance(value, bool):
                raise error(f'{name} must be a number, got {value!r}')
            try:
                v = float(value) if self.kind is Kind.DOUBLE else int(value)
            except (TypeError, ValueError):
                raise error(f'{name} must be a number, got {value!r}') from None
            if not isfinite(v):
                raise error(f'{name} must be finite, got {v}')
            if self.bounds is not None and not self.bounds[0] <= v <= self.bounds[1]:
                raise error(f'{name} must be in {self.rule_text(context)}, got {v}')
            return v
        if self.kind is Kind.DOUBLE_ARRAY:
            if isinstance(value, (str, bytes)) or not hasattr(value, '__iter__'):
                raise error(f'{name} must be a list of numbers, got {value!r}')
            values = list(value)
            if self.empty_ok and not values:
                return ()
            low, high = (self._bound(b, context) for b in self.bounds or (None, inf))
            size = int(context[self.size]) if self.size else len(values)
            why = self.why.format(**context) or f'the range of {name} is {self.rule_text(context)}'
            return checked_vector(name, values, size, error, lower=low, strict=self.strict,
                                  upper=high, why=why, per_joint=self.size == 'n')
        if self.kind is Kind.BOOL:
            if not isinstance(value, bool):
                raise error(f'{name} must be true or false, got {value!r}')
            return value
        return tuple(value) if self.kind.is_array else value


def names(specs: Sequence[Spec]) -> tuple[str, ...]:
    """Return the parameter names of a table, in order."""
    return tuple(spec.name for spec in specs)


def row(specs: Sequence[Spec], name: str) -> Spec:
    """Return the row of ``specs`` named ``name`` (KeyError if there is none)."""
    for spec in specs:
        if spec.name == name:
            return spec
    raise KeyError(name)


def check_all(specs: Sequence[Spec], values: Mapping[str, Any], context: Mapping[str, Any],
              error: type = ValueError) -> dict[str, Any]:
    """
    Return every row of ``specs`` checked, by name: the value given, or the row's default.

    A value of None is taken as not given. A name that is no row of ``specs`` raises ``error``.
    """
    unknown = sorted(set(values) - set(names(specs)))
    if unknown:
        raise error(f'no such parameter: {unknown} (the parameters: {list(names(specs))})')
    out = {}
    for spec in specs:
        given = values.get(spec.name)
        out[spec.name] = spec.check(spec.default_value(context) if given is None else given,
                                    context, error)
    return out


def joint_zeros(context: Mapping[str, Any]) -> list[float]:
    """Return a per-joint default of zeros, one per joint (``context['n']``), for a table row."""
    return [0.0] * context['n']


JOINT_ZEROS_TEXT = '`0` per joint'  # the docs' default of a ``joint_zeros`` row


def markdown_value(value: Any) -> str:
    """Return a parameter value as the docs' tables show it, in backticks (floats as ``:g``)."""
    if isinstance(value, str):
        return f"`'{value}'`" if value else "`''`"
    if isinstance(value, bool):
        return f'`{str(value).lower()}`'
    if isinstance(value, (list, tuple)):
        return '`[' + ', '.join(f'{v:g}' if isinstance(v, float) else str(v)
                                for v in value) + ']`'
    return f'`{value:g}`' if isinstance(value, float) else f'`{value}`'


def markdown_table(specs: Sequence[Spec], context: Mapping[str, Any]) -> str:
    """Return the table of ``specs`` as Markdown (the docs' parameter tables)."""
    rows = ['| name | type | default | range | live | description |', '|---|---|---|---|---|---|']
    for spec in specs:
        default = spec.default_text or markdown_value(spec.default_value(context))
        description = ' '.join(spec.description.format(**context).split()).replace('|', '\\|')
        rows.append(f'| `{spec.name}` | {spec.kind.label} | {default} | '
                    f'{spec.rule_text(context)} | {"no" if spec.read_only else "yes"} | '
                    f'{description} |')
    return '\n'.join(rows) + '\n'


def yaml_float(value: float) -> str:
    """
    Return a float for a parameter file: four significant digits, always with a decimal point.

    ROS 2 parameters are strictly typed: ``1`` would be an integer.
    """
    if abs(value) < 1e-9:
        return '0.0'
    return np.format_float_positional(float(value), precision=4, unique=True,
                                      fractional=False, trim='0')


def yaml_value(kind: Kind, value: Any) -> str:
    """Return ``value`` of a parameter of ``kind`` as a parameter file (YAML flow style) has it."""
    if kind is Kind.BOOL:
        return 'true' if value else 'false'
    if kind is Kind.DOUBLE:
        return yaml_float(value)
    if kind is Kind.INT:
        return str(int(value))
    if kind is Kind.STRING:
        return yaml_string(str(value))
    if kind is Kind.DOUBLE_ARRAY:
        return '[' + ', '.join(yaml_float(v) for v in value) + ']'
    if kind is Kind.STRING_ARRAY:
        return '[' + ', '.join(yaml_string(str(v)) for v in value) + ']'
    return '[' + ', '.join(str(v) for v in value) + ']'


def yaml_string(text: str) -> str:
    """Return ``text`` as YAML reads it back as that string: plain, or single-quoted."""
    plain = (_PLAIN.fullmatch(text) is not None
             and text.lower() not in ('true', 'false', 'yes', 'no', 'on', 'off', 'null'))
    return text if plain else "'" + text.replace("'", "''") + "'"


def yaml_lines(specs: Sequence[Spec], values: Mapping[str, Any],
               comments: Optional[Mapping[str, str]] = None, indent: str = '    ',
               column: int = 33) -> list[str]:
    """
    Return a parameter file's lines, ``name: value  # comment``, one per row given a value.

    In the order of ``specs``; the rows without a value in ``values`` are left out. A comment
    starts at ``column`` (or two spaces after a longer line).
    """
    lines = []
    for spec in specs:
        if spec.name not in values:
            continue
        text = f'{indent}{spec.name}: {yaml_value(spec.kind, values[spec.name])}'
        comment = (comments or {}).get(spec.name, '')
        if comment:
            text += ' ' * max(2, column - len(text)) + f'# {comment}'
        lines.append(text)
    return lines

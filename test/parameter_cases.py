"""
Values just outside and inside each live row's rules, written from the row (not by hand).

For the wrist with the paper's config: 3 joints, the orientation task. Each outside case is a
``(name, value, words)``: the value breaks one rule of the row, and ``words`` are what a refusal
must name (the parameter, and the value or its bad entry).
"""
from math import inf, nan

from quat_jt_controller import parameter_table as table
from quat_jt_controller.control_law import gain_ceiling, MAX_LAMBDA, SATURATING_ERROR, Task
from quat_jt_runtime.param_table import Kind, Spec


def wrist_context(effort_limits_nm) -> dict:
    """Return the rows' context for the wrist (3 joints, orientation), its ceilings included."""
    ceiling = gain_ceiling(effort_limits_nm)
    return {'task': Task.ORIENTATION, 'dim': 3, 'n': 3, 'ceiling': ceiling,
            'effort_max': f'{ceiling * SATURATING_ERROR:g}', 'lambda_ceiling': MAX_LAMBDA,
            'preferred_configuration': (0.0, 0.0, 0.0)}


def _bounds(spec: Spec, context: dict) -> tuple[float, float]:
    return tuple(float(context[b]) if isinstance(b, str) else float(b) for b in spec.bounds)


def outside(spec: Spec, context: dict) -> list[tuple]:
    """Return the values that break one rule of ``spec`` each, with the words to expect."""
    name = spec.name
    if spec.choices:
        return [(name, spec.choices[0] + '_not', [name, spec.choices[0] + '_not'])]
    if spec.kind is Kind.DOUBLE and spec.bounds is not None:
        low, high = _bounds(spec, context)
        step = 0.01 * (high - low)
        return [(name, v, [name, str(v)]) for v in (low - step, high + step)]
    if spec.kind is Kind.DOUBLE_ARRAY and spec.size:
        size = context[spec.size]
        good = inside(spec, context)
        cases = [(name, good + [good[0]], [name, str(size + 1)]),  # one value too many
                 (name, [nan] + good[1:], [f'{name}[0]', 'nan'])]
        if spec.bounds is not None:
            low, high = _bounds(spec, context)
            below = low if spec.strict else low - 0.01
            cases.append((name, [below] + good[1:], [f'{name}[0]', str(below)]))
            if high < inf:
                above = high * 1.01
                cases.append((name, good[:-1] + [above], [f'{name}[{size - 1}]', f'{above:g}']))
        return cases
    return []


def inside(spec: Spec, context: dict):
    """Return a value within every rule of ``spec`` (not its default, where it has a range)."""
    if spec.choices:
        return spec.choices[-1]
    if spec.kind is Kind.BOOL:
        return not spec.default_value(context)
    if spec.kind is Kind.DOUBLE and spec.bounds is not None:
        low, high = _bounds(spec, context)
        return low + 0.5 * (high - low)
    if spec.kind is Kind.DOUBLE_ARRAY and spec.size:
        default = [float(v) for v in spec.default_value(context)]
        if spec.bounds is None:
            return [v + 0.1 for v in default]
        low, _ = _bounds(spec, context)
        return [max(v, low) * 1.5 + 0.5 for v in default]
    return spec.default_value(context)


def live_rows() -> tuple[Spec, ...]:
    """Return the live rows: the Gains and the extensions."""
    return tuple(table.GAINS) + tuple(table.SHAPING)

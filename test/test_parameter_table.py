"""
The controller's parameter table is the one source of each parameter, ROS-free.

``controller_from_config`` (the tools' path) refuses, by name and value, a value just outside
any live row's rules, and takes one inside: the node's path is in test_controller_params.py,
with the same cases (parameter_cases.py, written from the rows). A row added to the table is
checked and written to the design's parameter file without another edit (declared and
documented: test_controller_params.py).
"""
import dataclasses

from parameter_cases import inside, live_rows, outside, wrist_context
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import gain_design as gd
from quat_jt_controller import gain_output as go
from quat_jt_controller import parameter_table as table
from quat_jt_controller import shaping as sh
from quat_jt_controller.controller_config import controller_from_package_config
from quat_jt_runtime.errors import QuatJtError
from quat_jt_runtime.param_table import Kind, names, Spec
from robots import wrist_model
import yaml

pytestmark = pytest.mark.unit

CONFIG = 'paper_wrist_controller.yaml'
CONTEXT = wrist_context(wrist_model().effort_limits)
OUTSIDE = [case for spec in live_rows() for case in outside(spec, CONTEXT)]


def test_every_live_row_with_a_rule_has_a_case_outside_it():
    ruled = {spec.name for spec in live_rows() if spec.kind is not Kind.BOOL}
    assert ruled == {name for name, _, _ in OUTSIDE}


@pytest.mark.parametrize('name, value, words', OUTSIDE,
                         ids=[f'{n}={v}' for n, v, _ in OUTSIDE])
def test_the_tools_refuse_a_value_just_outside_a_row_by_name_and_value(name, value, words):
    with pytest.raises(QuatJtError) as refused:
        controller_from_package_config(CONFIG, overrides={name: value})
    for word in words:
        assert word in str(refused.value), (word, str(refused.value))


@pytest.mark.parametrize('spec', live_rows(), ids=names(live_rows()))
def test_the_tools_take_a_value_inside_every_row(spec):
    value = inside(spec, CONTEXT)
    regulator = controller_from_package_config(CONFIG, overrides={spec.name: value})
    snapshot = regulator.gains if spec in table.GAINS else regulator.shaping
    attribute = {'lambda': 'lam'}.get(spec.name, spec.attribute)
    got = getattr(snapshot, attribute)
    assert (list(got) if isinstance(got, tuple) else got) == value


def test_every_extension_field_is_a_row_and_takes_its_default():
    rows = {spec.attribute: spec for spec in table.SHAPING}
    fields = {f.name: f for f in dataclasses.fields(sh.Shaping)}
    assert set(rows) == set(fields)
    for attribute, spec in rows.items():
        if spec.kind is Kind.DOUBLE:
            assert fields[attribute].default == spec.default, attribute


@pytest.fixture
def added_row(monkeypatch):
    """Add a live extension parameter: one row in the table, nothing else."""
    spec = Spec('test_added_gain', Kind.DOUBLE, 0.25, 'A row a test adds (N m). Live.',
                bounds=(0.0, 2.0))
    monkeypatch.setattr(table, 'SHAPING', (*table.SHAPING, spec))
    return spec


def test_an_added_row_is_checked_and_written(added_row):
    with pytest.raises(sh.ShapingError, match=r'test_added_gain must be in \[0, 2\], got 2.5'):
        sh.Shaping.create(3, test_added_gain=2.5)
    with pytest.raises(sh.ShapingError, match='test_added_gain'):  # a config file's path
        controller_from_package_config(CONFIG, overrides={'test_added_gain': -1.0})
    sh.Shaping.create(3, test_added_gain=1.5)
    design = gd.design(wrist_model(), cl.Task.ORIENTATION, delays=(1,))
    text = go.to_yaml(design)
    assert yaml.safe_load(text)['/**']['ros__parameters']['test_added_gain'] == 0.25
    assert 'posture_weight, test_added_gain; docs/lyapunov.md' in ' '.join(
        line.lstrip('# ') for line in text.splitlines() if line.startswith('#'))


def test_the_parameter_file_is_in_the_table_order_with_its_types():
    design = gd.design(wrist_model(), cl.Task.ORIENTATION, delays=(1,))
    written = yaml.safe_load(go.to_yaml(design))['/**']['ros__parameters']
    order = ['task', *names(table.GAINS), *names(table.SHAPING)]
    assert list(written)[:len(order)] == order
    rows = {spec.name: spec for spec in (table.STRUCTURE + table.GAINS + table.SHAPING
                                         + table.PAYLOAD)}
    context = {**CONTEXT, 'ceiling': float('inf')}  # the design's gains: no robot's ceiling
    for name, value in written.items():
        spec = rows[name]
        if spec.kind is Kind.DOUBLE:
            assert isinstance(value, float), name  # strictly typed: 1.0, not 1
        if not spec.read_only:
            spec.check(value, context)

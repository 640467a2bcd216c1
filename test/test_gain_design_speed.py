"""
The design's speed rule: far from the goal, the damping holds each joint below its limit.

The potentials push a joint with at most ``bound + T`` (the task term's a-priori bound plus
the goal-configuration term); the linear and cubic damping must meet that push at or below
``SPEED_MARGIN`` x the URDF velocity limit (docs/gain_design.md, "Speeds within the velocity
limits"). A URDF without a velocity limit leaves the rule out on that joint.
"""
import numpy as np
import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import gain_analysis as ga
from quat_jt_controller import gain_design as gd
from quat_jt_controller import gain_output as go
from quat_jt_controller import shaping as sh
from quat_jt_controller.model import RobotModel
from robots import small_arm_urdf, wrist_model

pytestmark = pytest.mark.unit

ARM_JOINTS = ('revolute', 'revolute', 'revolute', 'revolute')


def _brake_nm(d: gd.Design, speed_rad_s: np.ndarray, cap_rad_s: np.ndarray) -> np.ndarray:
    """Return the damping torque the regulator's law (K_v and the cubic part) gives at a speed."""
    tau = (-np.array(d.kv) * speed_rad_s).tolist()
    sh.add_speed_damping(speed_rad_s.tolist(), d.kv, d.shaping, tau, cap_rad_s.tolist())
    return -np.array(tau)


@pytest.fixture(scope='module')
def arm():
    model = RobotModel(small_arm_urdf(ARM_JOINTS), 'base_link', 'tool')
    return model, gd.design(model, cl.Task.POSE)


@pytest.mark.parametrize('which', ['arm', 'wrist'])
def test_the_damping_holds_the_largest_push_below_the_speed_ceiling(arm, which):
    """At SPEED_MARGIN x the limit the law's damping brakes at least the potentials' push."""
    model, d = arm if which == 'arm' else (wrist_model(), gd.design(
        wrist_model(), cl.Task.ORIENTATION, friction_nm=[1.8, 0.72, 0.45], delays=(1, 2)))
    f = d.figures
    limits = np.array(model.velocity_limits)
    assert np.all(limits > 0.0)
    ceiling = gd.SPEED_MARGIN * limits
    np.testing.assert_allclose(f['speed_ceiling_rad_s'], ceiling)
    push = f['task_bound_nm'] + f['guide_nm']
    # with the values as written to the file (rounded), through the regulator's own law
    assert np.all(_brake_nm(d, ceiling, limits) >= push * (1.0 - 1e-3))
    assert np.all(f['terminal_speed_rad_s'] <= ceiling * (1.0 + 1e-3))
    # the linear damping is raised to at most SPEED_DAMPING_SHARE of what the sampled loop
    # takes (b_max, the per-joint check) unless the design's own K_v was already above that
    for j, inertia in enumerate(f['inertia_min']):
        b_max = gd.DAMPER_SAFETY * ga.largest_stable_damping(
            inertia, ga.checked_delays(f['delays']), 1.0 / d.rate_hz)
        assert d.kv[j] <= b_max * (1.0 + 1e-3)
        if f['damping_ratio']['tanh'][j] > 1.1 * gd.DAMPING_RATIO:  # raised by the rule
            assert d.kv[j] <= gd.SPEED_DAMPING_SHARE * b_max * (1.0 + 1e-3)
    assert max(f['spectral_radius'].values()) < 1.0


def test_the_cruising_speed_is_where_the_law_meets_the_push():
    """cruising_speed inverts the law's damping, the cap v_m and no cubic term included."""
    push = np.array([2.0, 2.0, 2.0, 2.0])
    kv = np.array([1.0, 1.0, 1.0, 1.0])
    v_c = np.array([0.0, 1.0, 1.0, 1.0])
    cap = np.array([10.0, 10.0, 0.5, 1.0])
    v = ga.cruising_speed(push, kv, v_c, cap)
    np.testing.assert_allclose(v[0], 2.0, rtol=1e-9)  # linear only
    np.testing.assert_allclose(v[1] * (1.0 + v[1] ** 2), 2.0, rtol=1e-9)  # cubic: v = 1
    np.testing.assert_allclose(v[2] * 1.25, 2.0, rtol=1e-9)  # linear past the cap, slope 1.25
    np.testing.assert_allclose(v[3], 1.0, rtol=1e-9)
    shaping = sh.Shaping.create(4, damping_speed=v_c.tolist())
    tau = (-kv * v).tolist()
    sh.add_speed_damping(v.tolist(), kv.tolist(), shaping, tau, cap.tolist())
    np.testing.assert_allclose(-np.array(tau), push, rtol=1e-9)


def test_holding_damping_is_the_least_that_holds_the_push_within_the_slope_limit():
    """K_v raised just enough: with v_c at the slope limit the brake at the ceiling is the push."""
    b_max, cap = np.array([4.0, 4.0, 4.0]), np.array([3.0, 3.0, 3.0])
    ceiling = 0.8 * cap
    limit = gd.holding_limit(b_max, ceiling, cap)  # the most push the rule can hold
    push = np.array([1.0, 0.8 * limit[1], limit[2]])  # light, raised, the most it allows
    kv = gd.holding_damping(push, np.array([1.0, 0.5, 0.5]), b_max, ceiling, cap)
    assert kv[0] == 1.0  # already enough
    assert 0.5 < kv[1] < gd.SPEED_DAMPING_SHARE * b_max[1]
    assert kv[2] == pytest.approx(gd.SPEED_DAMPING_SHARE * b_max[2])
    for j in (1, 2):
        v_c = cap[j] * np.sqrt(3.0 * kv[j] / (b_max[j] - kv[j]))  # slope k_v (1 + 3 v^2/v_c^2)
        assert kv[j] * ceiling[j] * (1.0 + (ceiling[j] / v_c) ** 2) == pytest.approx(push[j])
    # more push than that is never asked: the design's push_max stops at holding_limit
    assert np.all(limit < b_max * ceiling)


def test_an_arm_without_velocity_limits_is_designed_without_the_rule():
    """A URDF velocity of 0 means none: no ceiling, and the rest of the design unchanged."""
    urdf = small_arm_urdf(ARM_JOINTS).replace('velocity="3"', 'velocity="0"')
    model = RobotModel(urdf, 'base_link', 'tool')
    assert all(v == 0.0 for v in model.velocity_limits)
    d = gd.design(model, cl.Task.POSE)
    f = d.figures
    assert np.all(np.isinf(f['speed_ceiling_rad_s']))
    np.testing.assert_allclose(f['velocity_limits_rad_s'], gd.DEFAULT_VELOCITY)
    assert np.all(np.isfinite(f['terminal_speed_rad_s']))
    assert max(f['spectral_radius'].values()) < 1.0
    assert np.all(np.array(d.kp) > 0.0)
    assert 'Expected time to a goal' in go.to_yaml(d)

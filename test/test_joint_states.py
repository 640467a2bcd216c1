"""Joint states as drivers send them: no velocities, names in any order, wrapped angles."""
import math

import numpy as np
import pytest

from quat_jt_runtime.joints import check_state_rate, StateCheck, VelocityEstimator, wrapped
from quat_jt_runtime.joints import velocity_estimator, WindowedVelocityEstimator

pytestmark = pytest.mark.unit

NOW_NS = 50_000_000_000


def test_the_estimate_follows_a_sine_with_the_lag_of_its_filter():
    """At 500 Hz, q = sin(w t): the estimate is w cos(w t) delayed by 1.08 periods."""
    rate, w = 500.0, 2.0 * math.pi * 2.0  # a 2 Hz motion
    h = 1.0 / rate
    est = VelocityEstimator(1, time_constant_s=h, max_gap_s=10 * h)
    errors = []
    for k in range(1000):
        t = k * h
        v = est.update([math.sin(w * t)], int(round(t * 1e9)))[0]
        if k > 50:
            # half a period of the difference, e^-1 / (1 - e^-1) = 0.58 of the filter
            lagged = w * math.cos(w * (t - 1.082 * h))
            errors.append(abs(v - lagged))
    assert max(errors) < 0.01 * w, max(errors)  # within 1% of the peak speed


def test_the_estimate_of_a_ramp_settles_on_its_slope_and_rejects_quantisation_noise():
    rate = 1000.0
    est = VelocityEstimator(2, 1.0 / rate, 10.0 / rate)
    rng = np.random.default_rng(0)
    count = 2.0 * math.pi / 2 ** 16  # a 16-bit encoder
    out = []
    for k in range(2000):
        q = [0.3 * k / rate, -0.1]
        q = [count * round(x / count) + count * rng.integers(-1, 2) for x in q]
        out.append(est.update(q, k * 1_000_000))
    out = np.array(out[1000:])
    assert abs(out[:, 0].mean() - 0.3) < 1e-3
    raw_noise = count * rate  # one count over one period
    assert out[:, 0].std() < raw_noise and out[:, 1].std() < raw_noise


def test_a_repeated_or_older_stamp_changes_nothing_and_a_gap_restarts():
    est = VelocityEstimator(1, 0.001, 0.01)
    assert est.update([0.0], 1_000_000) == [0.0]  # the first state: no difference yet
    v = est.update([0.001], 2_000_000)[0]
    assert v == pytest.approx(1.0 * (1.0 - math.exp(-1.0)))
    assert est.update([0.5], 2_000_000) == [v]  # the same stamp again
    assert est.update([0.5], 1_500_000) == [v]  # an older one
    assert est.update([0.2], 100_000_000) == [0.0]  # 98 ms later: restart at 0
    assert est.update([0.201], 101_000_000)[0] > 0.0


def test_the_state_check_estimates_velocities_when_a_driver_sends_none():
    check = StateCheck(('a', 'b'), max_age_s=0.5, rate_hz=100.0)
    q, qdot = check(['b', 'gripper', 'a'], [2.0, 0.0, 1.0], [], NOW_NS - 10_000_000, NOW_NS)
    assert (q, qdot) == ([1.0, 2.0], [0.0, 0.0]) and check.estimating
    q, qdot = check(['b', 'gripper', 'a'], [2.01, 0.0, 1.0], [], NOW_NS, NOW_NS)
    assert qdot[0] == 0.0 and qdot[1] == pytest.approx(1.0 * (1.0 - math.exp(-1.0)))
    q, qdot = check(['a', 'b'], [1.0, 2.0], [0.5, 0.25], NOW_NS, NOW_NS)  # velocities again
    assert qdot == [0.5, 0.25] and not check.estimating
    with pytest.raises(ValueError, match='2 names but 2 positions and 1 velocities'):
        check(['a', 'b'], [1.0, 2.0], [0.5], NOW_NS, NOW_NS)
    with pytest.raises(ValueError, match='non-finite position'):
        check(['a', 'b'], [1.0, math.nan], [], NOW_NS, NOW_NS)


def test_nan_velocities_as_ros2_control_publishes_them_are_estimated_joint_by_joint():
    """
    joint_state_broadcaster fills a velocity the hardware has no interface for with NaN.

    Those joints get the estimate, the others keep what the driver measured; Inf is refused.
    """
    check = StateCheck(('a', 'b'), max_age_s=0.5, rate_hz=100.0)
    nan = math.nan
    q, qdot = check(['b', 'gripper', 'a'], [2.0, 0.0, 1.0], [nan, nan, nan], NOW_NS, NOW_NS)
    assert (q, qdot) == ([1.0, 2.0], [0.0, 0.0]) and check.estimating
    assert check.unmeasured == ('a', 'b')
    q, qdot = check(['b', 'gripper', 'a'], [2.01, 0.0, 1.0], [nan, nan, 0.7],
                    NOW_NS + 10_000_000, NOW_NS + 10_000_000)
    assert qdot[0] == 0.7 and qdot[1] == pytest.approx(1.0 * (1.0 - math.exp(-1.0)))
    assert check.unmeasured == ('b',) and check.estimating
    q, qdot = check(['a', 'b'], [1.0, 2.0], [0.5, 0.25], NOW_NS, NOW_NS)  # all measured again
    assert qdot == [0.5, 0.25] and not check.estimating and check.unmeasured == ()
    with pytest.raises(ValueError, match=r'non-finite velocity: qdot = \[0.5, inf\] \(NaN '
                                         'marks a velocity not measured; Inf is refused'):
        check(['a', 'b'], [1.0, 2.0], [0.5, math.inf], NOW_NS, NOW_NS)
    with pytest.raises(ValueError, match='non-finite position'):
        check(['a', 'b'], [1.0, nan], [nan, nan], NOW_NS, NOW_NS)


def test_unstamped_states_without_velocities_use_their_arrival_time():
    check = StateCheck(('a',), max_age_s=0.0, rate_hz=1000.0)
    check(['a'], [0.0], [], 0, NOW_NS)
    _, qdot = check(['a'], [0.001], [], 0, NOW_NS + 1_000_000)
    assert qdot[0] == pytest.approx(1.0 - math.exp(-1.0))


def test_continuous_joints_are_unwrapped():
    check = StateCheck(('c', 'r'), max_age_s=0.5, rate_hz=1000.0, continuous=(True, False))
    angles = [3.1, 3.14, -3.12, -3.08, 3.1]  # the driver wraps joint c into (-pi, pi]
    seen = [check(['c', 'r'], [a, 0.0], [], NOW_NS + k * 1_000_000, NOW_NS + k * 1_000_000)
            for k, a in enumerate(angles)]
    q = [s[0][0] for s in seen]
    np.testing.assert_allclose(np.diff(q), [0.04, 2 * math.pi - 6.26, 0.04, 6.18 - 2 * math.pi],
                               atol=1e-12)
    assert all(abs(s[1][0]) < 110.0 for s in seen)  # the steps' speeds; a turn: 6283 rad/s
    assert wrapped(3 * math.pi) == pytest.approx(-math.pi)


@pytest.mark.parametrize('bad', [50.0, 1e4, math.nan, 'fast'])
def test_a_rate_outside_its_range_is_refused_by_value(bad):
    with pytest.raises(ValueError, match=f'state_rate.*{bad!r}'):
        check_state_rate(bad)
    with pytest.raises(ValueError, match='state_rate'):
        StateCheck(('a',), 0.5, rate_hz=bad)


COUNT = 2.0 * math.pi / 2 ** 17  # a 17-bit encoder's count, rad


def _counted(x: float) -> float:
    return round(x / COUNT) * COUNT


def test_a_count_from_rest_reads_0_and_a_creep_of_two_counts_a_window_is_found():
    """
    A count from rest reads 0 (a joint at rest explains it); two in the window: their slope.

    The one-period low-pass moves by 0.63 count / h on the first count. A joint hopping
    between two counts, as about a goal that lies between them, reads 0 throughout.
    """
    windowed = WindowedVelocityEstimator([COUNT, COUNT], max_gap_s=0.01)
    low_pass = VelocityEstimator(2, 1e-3, 0.01)
    for k in range(21):
        q = [0.0 if k < 20 else COUNT, 0.0]
        v, w = windowed.update(q, k * 1_000_000), low_pass.update(q, k * 1_000_000)
    assert v == [0.0, 0.0]
    assert w[0] == pytest.approx((1.0 - math.exp(-1.0)) * COUNT / 1e-3)
    for k in range(21, 60):  # hops between the two counts, at irregular ticks
        hop = COUNT if k % 3 == 0 or k % 7 == 0 else 0.0
        assert windowed.update([hop, 0.0], k * 1_000_000) == [0.0, 0.0]
    for k in range(60, 88):  # at rest, then a creep of a count every 8 ticks
        windowed.update([0.0 if k < 80 else COUNT, 0.0], k * 1_000_000)
    v = windowed.update([2.0 * COUNT, 0.0], 88_000_000)
    assert v[0] == pytest.approx(COUNT / 8e-3) and v[1] == 0.0  # two counts in 16 ticks
    for k in range(89, 105):  # ... and once the rest has left the window, a creep of a
        windowed.update([2.0 * COUNT, 0.0], k * 1_000_000)  # count every 17 ticks reads 0
    assert windowed.update([3.0 * COUNT, 0.0], 105_000_000) == [0.0, 0.0]


def test_the_windowed_estimate_follows_a_steady_speed_and_shortens_its_window_to_accelerate():
    """
    Counted positions: a steady speed is found within a count over the window.

    A steady 3.3 counts a tick, within a count over 16 ticks; a start at 2000 rad/s^2 lags
    half a tick, as the last difference does.
    """
    est = WindowedVelocityEstimator([COUNT], max_gap_s=0.01)
    for k in range(40):
        v = est.update([_counted((3.3 * k + 0.1) * COUNT)], k * 1_000_000)[0]
    assert v == pytest.approx(3.3 * COUNT / 1e-3, abs=COUNT / 16e-3)
    est.reset()
    for k in range(40):
        v = est.update([_counted(1000.0 * (k * 1e-3) ** 2)], k * 1_000_000)[0]
    assert v == pytest.approx(2000.0 * 38.5e-3, rel=0.02)


def test_the_windowed_estimate_restarts_after_a_gap_and_ignores_old_states():
    est = WindowedVelocityEstimator([COUNT], max_gap_s=0.01)
    assert est.update([0.0], 0) == [0.0]
    assert est.update([COUNT], 1_000_000) == [0.0]  # a count: at rest as far as it tells
    v = est.update([3 * COUNT], 2_000_000)
    assert v == [pytest.approx(1.5 * COUNT / 1e-3)]  # the line to the first state
    assert est.update([5.0], 2_000_000) == v and est.update([5.0], 500_000) == v
    assert est.update([0.2], 100_000_000) == [0.0]  # 99 ms later: restart at 0
    # an irregular rate: the states' own times
    assert est.update([0.2 + 2 * COUNT], 102_500_000)[0] == pytest.approx(2 * COUNT / 2.5e-3)


def test_exact_positions_keep_the_low_pass_and_a_bad_resolution_is_refused():
    assert isinstance(velocity_estimator(2, 1000.0), VelocityEstimator)
    assert isinstance(velocity_estimator(2, 1000.0, [0.0, 0.0]), VelocityEstimator)
    assert isinstance(velocity_estimator(2, 1000.0, [COUNT, 0.0]), WindowedVelocityEstimator)
    with pytest.raises(ValueError, match='position_resolution: expected 2 values, got 1'):
        velocity_estimator(2, 1000.0, [COUNT])
    for bad in (-COUNT, math.nan, math.inf):
        with pytest.raises(ValueError, match='resolution_rad must be finite and >= 0'):
            WindowedVelocityEstimator([bad], 0.01)


def test_the_state_check_estimates_on_the_window_its_resolution_allows():
    check = StateCheck(('a', 'b'), max_age_s=0.0, rate_hz=1000.0,
                       position_resolution=(COUNT, COUNT))
    for k in range(21):  # 'a' creeps a count every 8 states
        _, qdot = check(['b', 'a'], [0.0, COUNT * (0 if k < 12 else 1 if k < 20 else 2)], [], 0,
                        NOW_NS + k * 1_000_000)
    assert qdot == [pytest.approx(COUNT / 8e-3), 0.0] and check.estimating

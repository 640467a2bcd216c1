"""The simulator's command path (wrist_sim.command_gate), ROS-free, with plain numbers."""
import math

import numpy as np
import pytest
from wrist_sim.command_gate import CommandGate, RESUMED, TRIPPED

pytestmark = pytest.mark.unit

DT_NS = 1_000_000  # 1 kHz
TIMEOUT_NS = 5 * DT_NS


def test_the_joints_are_held_until_the_first_valid_command():
    gate = CommandGate([10.0, 5.0], DT_NS)
    assert gate.torque(0, TIMEOUT_NS) == (None, '')
    assert gate.offer([1.0], 0).reason == '1 values for 2 joints'
    assert 'non-finite' in gate.offer([1.0, math.nan], 0).reason
    assert gate.torque(1, TIMEOUT_NS) == (None, '')  # refused commands release nothing
    offer = gate.offer([1.0, -2.0], 1)
    assert offer.applied and not offer.clamped and offer.first_since_state
    tau, event = gate.torque(2, TIMEOUT_NS)
    assert tau.tolist() == [1.0, -2.0] and event == ''
    without_hold = CommandGate([10.0, 5.0], DT_NS, hold_until_first_command=False)
    assert without_hold.torque(0, TIMEOUT_NS)[0].tolist() == [0.0, 0.0]


def test_a_command_beyond_the_effort_limits_is_applied_and_said_clamped():
    gate = CommandGate([10.0, 5.0], DT_NS)
    offer = gate.offer([1.0, -7.0], 0)
    assert offer.applied and offer.clamped  # the physics clamps it; the node says so
    assert gate.torque(1, TIMEOUT_NS)[0].tolist() == [1.0, -7.0]


def test_the_watchdog_zeroes_the_torque_once_and_recovers():
    gate = CommandGate([10.0, 5.0], DT_NS)
    gate.offer([1.0, 2.0], 0)
    assert gate.torque(5, TIMEOUT_NS)[1] == ''  # 5 ms old: still applied
    tau, event = gate.torque(6, TIMEOUT_NS)
    assert event == TRIPPED and tau.tolist() == [0.0, 0.0]
    assert gate.silence_s(6) == pytest.approx(0.006)
    assert gate.torque(7, TIMEOUT_NS) == (gate.torque(8, TIMEOUT_NS)[0], '')  # said once
    gate.offer([3.0, 4.0], 9)
    tau, event = gate.torque(10, TIMEOUT_NS)
    assert event == RESUMED and tau.tolist() == [3.0, 4.0]
    gate.offer([3.0, 4.0], 10)
    assert gate.torque(10_000, 0)[1] == ''  # timeout 0: no watchdog


def test_only_the_first_command_after_a_state_counts_for_latency_and_freshness():
    gate = CommandGate([10.0, 5.0], DT_NS)
    assert not gate.answered
    assert gate.offer([1.0, 1.0], 0).first_since_state and gate.answered
    assert not gate.offer([1.0, 1.0], 0).first_since_state
    gate.published()
    assert not gate.answered and gate.offer([1.0, 1.0], 1).first_since_state


def test_after_a_reset_older_answers_are_dropped_until_the_reset_state_is_out():
    gate = CommandGate([10.0, 5.0], DT_NS)
    gate.offer([1.0, 1.0], 0)
    gate.reset()
    late = gate.offer([2.0, 2.0], 1)  # answers a state from before the reset
    assert not late.applied and late.reason == ''
    assert gate.torque(1, TIMEOUT_NS) == (None, '')  # held again, as after start-up
    gate.published()
    assert gate.offer([2.0, 2.0], 2).applied
    assert np.array_equal(gate.torque(3, TIMEOUT_NS)[0], [2.0, 2.0])

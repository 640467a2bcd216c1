"""The simulator's stepping loops (wrist_sim.pacing) with a fake stepper and executor."""
import pytest
from quat_jt_runtime.loop_stats import LoopStats
from wrist_sim.config import SimConfig
from wrist_sim.pacing import run_lockstep, run_real_time

pytestmark = pytest.mark.unit


class FakeStepper:
    """Counts steps and publications; a command 'arrives' when the executor spins."""

    def __init__(self, answers: bool, lockstep_timeout_s: float = 0.002) -> None:
        self.stats = LoopStats(capacity=1000)
        self.answers = answers
        self.pending = False
        self.steps = self.published = 0
        self.lines = []
        self._config = SimConfig.create({
            'initial_positions': [0.0], 'viscous_friction': [0.0], 'coulomb_friction': [0.0],
            'command_timeout': 0.5, 'lockstep_timeout': lockstep_timeout_s,
            'max_real_time_factor': 0.0}, 1)

    def answered(self) -> bool:
        return self.pending

    def published_at(self) -> float:
        return 0.0

    def advance(self) -> None:
        self.steps += 1

    def publish_state(self) -> None:
        self.published += 1
        self.pending = False

    def config(self) -> SimConfig:
        return self._config

    def every_second(self, line: str) -> None:
        self.lines.append(line)


class FakeExecutor:
    """Spins: a command arrives for the state out (if the stepper answers)."""

    def __init__(self, stepper: FakeStepper) -> None:
        self.stepper = stepper
        self.spins = 0

    def spin_once(self, timeout_sec: float) -> None:
        assert timeout_sec is not None and timeout_sec >= 0.0  # always a timeout
        self.spins += 1
        if self.stepper.answers:
            self.stepper.pending = True


def until(stepper: FakeStepper, steps: int):
    return lambda: stepper.steps < steps


def test_lockstep_steps_once_per_answer():
    # the answer comes at the first spin: a timeout far beyond any descheduling of a busy host
    stepper = FakeStepper(answers=True, lockstep_timeout_s=30.0)
    run_lockstep(stepper, FakeExecutor(stepper), 1e-3, until(stepper, 50))
    assert stepper.steps == stepper.published == 50
    assert stepper.stats.lockstep_timeouts == 0
    assert stepper.stats.fresh_steps == 50  # every step applied an answer


def test_lockstep_steps_anyway_after_its_timeout():
    stepper = FakeStepper(answers=False)
    run_lockstep(stepper, FakeExecutor(stepper), 1e-3, until(stepper, 5))
    assert stepper.steps == 5
    assert stepper.stats.lockstep_timeouts == 5 and stepper.stats.fresh_steps == 0


def test_real_time_publishes_one_state_per_tick():
    stepper = FakeStepper(answers=True)
    run_real_time(stepper, FakeExecutor(stepper), 1e-3, until(stepper, 20))
    assert stepper.published == stepper.stats.steps >= 19  # the last tick may be cut short
    assert stepper.stats.fresh_steps >= 19

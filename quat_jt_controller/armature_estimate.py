"""
The rotor inertia the joints show and the model lacks: an estimate while the arm moves.

A geared drive reflects its rotor's inertia about its joint times the square of the gear
ratio, often more than the links it moves; most URDFs leave it out. Not told it (``armature``
0), the damping that follows the inertia (docs/lyapunov.md, section 10), the speed guard and
the settling damping (section 11) are sized for joints lighter than the real ones, and the
friction learning (section 4) takes the push that accelerates the unseen rotor for a push a
friction holds: on such a plant the wrist joints swung about their goal and the learned push
kept them swinging (docs/reach.md, "rotor inertia nobody told").

Per joint ``j``, the torque of the last tick beyond gravity, ``u_j = tau_j - g_j(q)``, goes
into the accelerations of the model told and its moving links' Coriolis and centrifugal
torques (``M(q) qddot + C(q, qdot) qdot``, ``h`` below), into the rotor inertia it lacks,
``a_j qddot_j``, into a Coulomb friction ``f_j sgn(qdot_j)`` and into what else the model gets
wrong that changes slowly (``c_j``)::

    u_j - h_j + e_j qddot_j = a_j qddot_j + f_j sgn(qdot_j) + c_j

``M(q)`` holds the estimate in force ``e_j`` (added back on the left, so ``a_j`` is the whole
rotor inertia beyond the one told). ``qddot`` is the friction learning's filtered derivative
of ``qdot`` (``shaping.ACCELERATION_TIME_S``), so ``u`` and ``sgn(qdot)`` (as
``tanh(qdot / v_eps)``) are low-passed alike: the filter's lag is the same on both sides.
Both filters start from nothing (zero acceleration, zero torque) and are not sampled for
``WARM_UP_S``. Every ``SAMPLE_TICKS`` ticks the three regressors and the left side go into
per-joint least squares that forget in ``MEMORY_S``, for the joints that move at least at
``MOVING_SPEED_FACTOR v_eps`` (slower, stiction may hold a joint with any torque up to the
friction's level, which no regressor carries). Every ``SOLVE_S`` each joint's fit is
adopted if it is known: its standard error below ``TRUST_SHARE`` of the joint's inertia
``M_jj(q)`` with the fit in (the samples are not independent: the variance counts those one
filter memory spans as one). The estimate moves towards it in ``ADOPT_TIME_S``; one fit at
most doubles the joint's inertia, so a hundredfold takes 7 solves that agree; within
``[0, armature_estimation_limit_j]``: never below the armature told, never above the limit.
The regulator puts it on the diagonal of M(q) (``RobotModel.set_armature_estimate``).

The torque read is the regulator's own: while it does not reach the plant (a command not
published, a non-finite tick, a gap between states) the filters start again
(:meth:`restart`). A tick of transport delay between that torque and the state is not
modelled: a small bias. What it changes is damping only (the potential and ``g(q)`` do not
hold an inertia), so the argument of docs/lyapunov.md holds for any estimate (section 13);
an estimate too high makes the sampled loop's damping too strong for the joint, which the
trust test and the limit guard against. Plain floats: it runs in the tick.
"""
from math import sqrt, tanh
from typing import Sequence

from quat_jt_controller.shaping import ACCELERATION_TIME_S

SAMPLE_TICKS = 4  # the fits take every this many ticks (the signals are low-passed at 20 ms)
MEMORY_S = 5.0  # the fits forget with this time constant
# after the filters start, no sample for this long: they start from zero acceleration and zero
# torque beyond gravity, which the plant may not have had; 5 time constants forget it
WARM_UP_S = 5.0 * ACCELERATION_TIME_S
SOLVE_S = 0.05  # how often the fits are solved and adopted
ADOPT_TIME_S = 0.2  # the estimate moves to a fit in this time
TRUST_SHARE = 0.2  # a fit is adopted where its standard error is below this x M_jj(q) + it
MIN_SAMPLES = 50  # ... and the fit holds this many samples' weight (0.2 s of motion at 1 kHz)
# a joint's sample counts while its low-passed speed is at least this x v_eps (the friction
# learning's creep speed): slower, a friction may hold it (stiction)
MOVING_SPEED_FACTOR = 2.0
# a Gram determinant below this x the product of its diagonal: its regressors are collinear
COLLINEAR = 1e-6
# sums per joint: aa a1 as ss s1 11 ay sy 1y yy (a = qddot, s = sgn, 1, y the left side)
_SUMS = 10


class ArmatureEstimator:
    """
    Per joint, the rotor inertia beyond the model's that the motion shows (kg m^2 or kg).

    :meth:`track` every tick (True when a sample is due: :meth:`sample`), :meth:`solve` when
    :attr:`solve_due`. ``estimate`` is the value in force; it starts at 0 and :meth:`reset`
    returns it there; :meth:`restart` starts the filters again.
    """

    def __init__(self, n_joints: int) -> None:
        self.n = n_joints
        self._net = [0.0] * n_joints  # low-passed u_j = tau_j - g_j(q), N m
        self._sign = [0.0] * n_joints  # low-passed tanh(qdot_j / v_eps)
        self._warm_s = 0.0
        self._ticks = 0
        self._since_sample_s = 0.0
        self._interval_s = 0.0  # the time between the last two samples
        self.reset()

    def reset(self) -> None:
        """Forget the fits and the estimate; the filters start again."""
        self.estimate = [0.0] * self.n
        self._sums = [[0.0] * _SUMS for _ in range(self.n)]
        self._since_solve_s = 0.0
        self._seeded = False

    def restart(self) -> None:
        """Start the filters again, as the acceleration filter does; the fits are kept."""
        self._seeded = False

    def track(self, net_nm: Sequence[float], qdot: Sequence[float], v_eps: float,
              dt_s: float) -> bool:
        """
        Advance the low-passes of ``u`` and ``sgn(qdot)`` by one tick of ``dt_s``.

        The gain is ``dt_s / ACCELERATION_TIME_S`` (at most 1), the acceleration filter's.
        Return True on the ticks a sample is due (every ``SAMPLE_TICKS``).
        """
        net, sign = self._net, self._sign
        self._since_sample_s += dt_s
        if not self._seeded:  # as the acceleration filter: nothing before this tick
            for j, v in enumerate(qdot):
                net[j] = 0.0
                sign[j] = tanh(v / v_eps)
            self._seeded = True
            self._warm_s = 0.0
            self._since_sample_s = 0.0
            return False
        k = dt_s / ACCELERATION_TIME_S
        k = k if k < 1.0 else 1.0
        for j, u in enumerate(net_nm):
            net[j] += k * (u - net[j])
            sign[j] += k * (tanh(qdot[j] / v_eps) - sign[j])
        self._ticks += 1
        if self._warm_s < WARM_UP_S:  # what the seeds left is not yet forgotten
            self._warm_s += dt_s
            self._since_sample_s = 0.0
            return False
        if self._ticks < SAMPLE_TICKS:
            return False
        self._ticks = 0
        return True

    def sample(self, qddot: Sequence[float], inertial_nm: Sequence[float],
               in_model: Sequence[float], qdot_slow: Sequence[float], v_eps: float) -> None:
        """
        Add one sample: ``qddot`` (filtered, rad/s^2) and ``inertial_nm``, ``h`` of the fit.

        ``h = M(q) qddot + C(q, qdot) qdot`` (``RobotModel.inertial_torque``), ``M(q)`` with
        the rotor inertia estimate ``in_model`` in it (added back here). A joint counts the
        sample only while its low-passed velocity ``qdot_slow`` is at least
        ``MOVING_SPEED_FACTOR v_eps``: slower, a friction may hold it, with any torque up to its
        level, which no regressor carries (stiction). The sums forget at ``1 / MEMORY_S`` over
        the time since the last sample.
        """
        dt_s = self._since_sample_s
        self._since_sample_s = 0.0
        self._interval_s = dt_s
        keep = 1.0 - dt_s / MEMORY_S if dt_s < MEMORY_S else 0.0
        self._since_solve_s += dt_s
        moving = MOVING_SPEED_FACTOR * v_eps
        for j, s in enumerate(self._sums):
            for i in range(_SUMS):
                s[i] *= keep
            v = qdot_slow[j]
            if -moving < v < moving:
                continue
            a, g = qddot[j], self._sign[j]
            y = self._net[j] - inertial_nm[j] + in_model[j] * a
            s[0] += a * a
            s[1] += a
            s[2] += a * g
            s[3] += g * g
            s[4] += g
            s[5] += 1.0
            s[6] += a * y
            s[7] += g * y
            s[8] += y
            s[9] += y * y

    @property
    def solve_due(self) -> bool:
        """Return True once ``SOLVE_S`` has passed since the last :meth:`solve`."""
        return self._since_solve_s >= SOLVE_S

    def fit(self, j: int) -> tuple[float, float]:
        """
        Return joint ``j``'s least-squares ``a_j`` and its standard error (inf: no fit yet).

        Solves the 3 x 3 normal equations of ``(a_j, f_j, c_j)`` by Cramer's rule, or those of
        ``(a_j, c_j)`` where ``sgn(qdot_j)`` kept one sign (then it is the constant). The
        standard error is :meth:`_error`'s.
        """
        aa, a1, ag, gg, g1, w, ay, gy, y1, yy = self._sums[j]
        if w < MIN_SAMPLES:  # the weight of the samples this joint counted
            return 0.0, float('inf')
        # normal matrix [[aa, ag, a1], [ag, gg, g1], [a1, g1, w]]
        m00 = gg * w - g1 * g1
        if not m00 > COLLINEAR * gg * w:  # sgn(qdot) one way throughout: it is the constant
            det = aa * w - a1 * a1
            if not det > COLLINEAR * aa * w:
                return 0.0, float('inf')
            t_a = (ay * w - a1 * y1) / det
            t_c = (aa * y1 - a1 * ay) / det
            left = yy - (t_a * ay + t_c * y1)
            return t_a, self._error(left, w - 2.0, w / det)
        m01 = ag * w - a1 * g1
        m02 = ag * g1 - gg * a1
        det = aa * m00 - ag * m01 + a1 * m02
        if not det > COLLINEAR * aa * m00:  # the acceleration says nothing the others do not
            return 0.0, float('inf')
        # the solution, and the diagonal entry of the inverse for a_j
        t_a = (ay * m00 - ag * (gy * w - y1 * g1) + a1 * (gy * g1 - gg * y1)) / det
        t_f = (aa * (gy * w - y1 * g1) - ay * m01 + a1 * (ag * y1 - a1 * gy)) / det
        t_c = (aa * (gg * y1 - g1 * gy) - ag * (ag * y1 - a1 * gy) + ay * m02) / det
        left = yy - (t_a * ay + t_f * gy + t_c * y1)
        return t_a, self._error(left, w - 3.0, m00 / det)

    def _error(self, left: float, dof: float, inverse_00: float) -> float:
        """
        Return the standard error of ``a_j`` from the residual sum ``left``.

        ``inverse_00`` is the first diagonal entry of the inverse normal matrix. The samples
        one filter memory spans (``2 ACCELERATION_TIME_S``) count as one.
        """
        if not dof > 0.0:
            return float('inf')
        variance = (left if left > 0.0 else 0.0) / dof * inverse_00
        span = 2.0 * ACCELERATION_TIME_S
        if span > self._interval_s:  # the samples one filter memory spans count as one
            variance *= span / self._interval_s if self._interval_s > 0.0 else 1.0
        return sqrt(variance)

    def solve(self, own_inertia: Sequence[float], limit: Sequence[float]) -> bool:
        """
        Adopt each joint's fit that is known (:meth:`fit`); return True if the estimate moved.

        ``own_inertia`` is ``M_jj(q)`` now (kg m^2, the estimate in), ``limit`` the most the
        estimate may reach per joint (0: the joint is not estimated, its estimate 0).
        """
        step = self._since_solve_s / ADOPT_TIME_S
        step = step if step < 1.0 else 1.0
        self._since_solve_s = 0.0
        moved = False
        for j in range(self.n):
            old = self.estimate[j]
            top = limit[j]
            if top <= 0.0:
                new = 0.0
            else:
                a, error = self.fit(j)
                own = own_inertia[j]  # the estimate in force in it
                target = a if a > 0.0 else 0.0
                if not error < TRUST_SHARE * (own - old + target):  # M_jj with the fit in
                    continue
                new = old + step * (target - old)
                ceiling = old + own  # at most double the joint's inertia at a step
                new = new if new < ceiling else ceiling
                new = new if new < top else top
            if new != old:
                self.estimate[j] = new
                moved = True
        return moved

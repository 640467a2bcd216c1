"""
The paper's wrist experiment (Section 5) with docs/errata.md applied: one source for the code.

Gains Eqs. (43)-(45) (units: docs/errata.md note 7), the corrected desired quaternion of
Eq. (40) (note 2, scalar first) and the printed one, the joint angles where the wrist reaches the
corrected goal, and the final orientation errors the paper reports (note 5: 'former' and
'latter' swapped in print).
"""
from quat_jt_controller import quaternion as quat

KP = (4.5, 20.5, 17.5)  # Eq. (43), N m
KV = (1.0, 1.0, 1.0)  # Eq. (44), N m s/rad
LAMBDA = (30.0, 30.0, 30.0)  # Eq. (45)
Q_INITIAL_RAD = (0.0, 0.0, 0.0)  # q(0), a singular configuration (docs/errata.md note 4)
Q_DESIRED = quat.normalized((0.5566, 0.0, 0.4226, 0.7152))  # (eta_d, eps_d), errata note 2
Q_DESIRED_AS_PRINTED = (0.5566, 0.0, 0.4226, 0.7848)  # Eq. (40) as printed: norm 1.0509
Q_JOINT_DESIRED_RAD = (0.9095, 0.8727, 0.9095)  # where the wrist reaches Q_DESIRED
FINAL_ERROR = {'quadratic': 0.2043, 'tanh': 5.3184e-3}  # ||e|| at the end of Fig. 2

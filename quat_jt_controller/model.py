"""
The robot model, from a URDF (the single source of truth), through Pinocchio.

Gives what the control laws need, with joints addressed by name and in a caller-chosen order:
forward kinematics of a tip link in a base link, the geometric Jacobian J_G of Eq. (12) (linear
rows then angular rows, base-frame axes, tip-origin velocity), gravity torques g(q) of Eq. (1),
and the joint position, velocity and effort limits. Joints of the URDF that are not controlled
are locked at zero.

A URDF ``continuous`` joint is a revolute joint without stops. Pinocchio gives it two
configuration coordinates, (cos q, sin q), and one velocity; here it has one angle q like any
other joint (unwrapped: q and q + 2 pi are the same configuration), position limits of
-inf and +inf, and one column in J_G, g(q) and M(q).

The inertia is the URDF's links plus, per joint, the rotor inertia its drive reflects (the
``armature`` a, kg m^2 or kg): M(q) of Eq. (1) becomes M_links(q) + diag(a), in the mass matrix,
the forward dynamics and everything designed or checked from them. A URDF rarely carries it (a
geared drive's rotor, seen through the gear ratio r, adds r^2 I_rotor, often more than the
link), so it is given as a model input. So is a payload the URDF does not carry (a tool, a grasped
part): a point mass at a point of the tip link's frame, added to the body of the tip's joint
(:meth:`RobotModel.set_payload`, which may change it while the controller runs), in g(q), M(q)
and everything built on them.
"""
from math import cos, sin
from typing import Optional, Sequence
from xml.etree import ElementTree

import numpy as np
try:
    import pinocchio as pin
except ModuleNotFoundError as exc:  # e.g. a colcon workspace whose rosdep skipped it
    raise ModuleNotFoundError(
        f"{exc}: install Pinocchio, e.g. 'pip install pin' (the PyPI name; the 'pinocchio' "
        'package on PyPI is another project) or ros-jazzy-pinocchio from the ROS apt '
        'repository') from exc

from quat_jt_runtime.errors import checked_vector, QuatJtError
from quat_jt_runtime.joints import fixed_joints, joint_rows, movable_joints, select_joints
from quat_jt_runtime.payload import Payload, PAYLOAD_RADIUS_M

# sigma_min of the task Jacobian (J_o, J_G or J_p), its position rows divided by the arm's
# length (RobotModel.task_sigma_min: dimensionless), below this: near-singular (the paper's
# assumption A2 fails there), for the choice of q*, the goal check's verdict and the stall
# report alike
SINGULAR_SIGMA_MIN = 0.05
# the most of a joint's effort limit the gain design reserves for gravity (an arm whose URDF
# needs more somewhere within its limits is designed for the rest, with a warning), and past
# which the goal check warns that a goal's pose may not be held up
GRAVITY_RESERVE_SHARE = 0.75
# a link's rotational inertia may have an eigenvalue down to -(this x its trace + the floor):
# a CAD export's rounding; below, no body has it (inertial_problems)
INERTIA_TOLERANCE = 1e-6
INERTIA_FLOOR_KG_M2 = 1e-12
NOT_EXPANDED = ('it is a xacro file, not expanded: run xacro on it first (xacro FILE.xacro > '
                'FILE.urdf), or give the robot_description its launch file makes')


class ModelError(QuatJtError):
    """The URDF, or the links and joints asked of it, cannot make a controllable model."""


def _not_expanded(root: ElementTree.Element) -> bool:
    """Whether a parsed URDF is a xacro file not expanded: a xacro element, or ``${``."""
    return any('xacro' in str(e.tag).partition('}')[0]
               or any('${' in v for v in e.attrib.values()) for e in root.iter())


def limit_problems(urdf_xml: str) -> list[str]:
    """
    Return what the URDF parser refuses in a URDF's joints, one line each; [] if nothing.

    The URDF format asks each revolute and prismatic joint for a ``<limit>`` with ``effort``
    and ``velocity`` (``lower`` and ``upper`` default to 0), numbers all. urdfdom, which
    Pinocchio and ROS read a URDF with, refuses the whole file otherwise, and its message names
    neither the joint nor the attribute. A xacro file not expanded (an element in a namespace
    named xacro, or ``${`` in a value) is said so: nothing else of it is read.
    """
    try:
        root = ElementTree.fromstring(urdf_xml)
    except ElementTree.ParseError:
        return []
    if _not_expanded(root):
        return [NOT_EXPANDED]
    no_limit, missing, not_numbers = [], {'effort': [], 'velocity': []}, []
    for joint in root.iter('joint'):
        name = joint.get('name')
        if joint.get('type') not in ('revolute', 'prismatic'):
            continue
        limit = joint.find('limit')
        if limit is None:
            no_limit.append(name)
            continue
        for attribute, names in missing.items():
            if limit.get(attribute) is None:
                names.append(name)
        for attribute in ('effort', 'velocity', 'lower', 'upper'):
            try:
                float(limit.get(attribute, 0.0))
            except ValueError:
                not_numbers.append(f'{name} {attribute}="{limit.get(attribute)}"')
    asked = ' (the URDF format asks each revolute and prismatic joint for a <limit> with ' \
        'effort and velocity; 0 says none is given)'
    problems = [f'joints {no_limit} have no <limit>{asked}'] if no_limit else []
    problems += [f'joints {names} have no {attribute} in their <limit>{asked}'
                 for attribute, names in missing.items() if names]
    if not_numbers:
        problems.append(f'limits that are not numbers: {", ".join(not_numbers)}')
    return problems


def inertial_problems(urdf_xml: str, joints: Sequence[str]) -> list[str]:
    """
    Return the links that ``joints`` move whose ``<inertial>`` no body has, one line each.

    A mass or a moment that is not a number, is not finite, a negative mass, or a rotational
    inertia with a negative eigenvalue (below ``-INERTIA_TOLERANCE`` x its trace, less an
    absolute ``INERTIA_FLOOR_KG_M2``: a CAD export's rounding passes). Pinocchio takes such a
    link as it comes, or as a link without mass when the value is no number, so M(q) and g(q)
    would be wrong with no message. Links the joints do not move (a robot's base, its other
    limbs) are not read: a fault there does not reach the arm's model.
    """
    root = ElementTree.fromstring(urdf_xml)
    rows = joint_rows(urdf_xml)
    children: dict[str, list[str]] = {}
    for _, _, parent, child in rows:
        children.setdefault(parent, []).append(child)
    moved: set[str] = set()
    wanted = set(joints)
    stack = [child for name, _, _, child in rows if name in wanted]
    while stack:
        link = stack.pop()
        if link not in moved:
            moved.add(link)
            stack.extend(children.get(link, []))
    problems = []
    for link in root.iter('link'):
        name, inertial = link.get('name'), link.find('inertial')
        if name not in moved or inertial is None:
            continue
        mass_node, moments = inertial.find('mass'), inertial.find('inertia')
        try:
            mass = float(mass_node.get('value', 'nan') if mass_node is not None else 0.0)
            values = {k: float(moments.get(k, 0.0)) if moments is not None else 0.0
                      for k in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz')}
        except ValueError as exc:  # float's message quotes the text
            problems.append(f'link {name!r}: a value of its <inertial> is not a number ('
                            f'{str(exc).rpartition(": ")[2]})')
            continue
        if not (np.isfinite(mass) and mass >= 0.0):
            problems.append(f'link {name!r}: mass {mass:g} kg (a mass is finite and >= 0)')
            continue
        inertia = np.array([[values['ixx'], values['ixy'], values['ixz']],
                            [values['ixy'], values['iyy'], values['iyz']],
                            [values['ixz'], values['iyz'], values['izz']]])
        if not np.all(np.isfinite(inertia)):
            problems.append(f'link {name!r}: an inertia moment is not finite')
            continue
        lowest = float(np.linalg.eigvalsh(inertia)[0])
        if lowest < -(INERTIA_TOLERANCE * max(float(np.trace(inertia)), 0.0)
                      + INERTIA_FLOOR_KG_M2):
            problems.append(f'link {name!r}: its inertia has a negative principal moment '
                            f'({lowest:.3g} kg m^2)')
    return problems


class RobotModel:
    """
    A fixed-base serial manipulator between ``base_link`` and ``tip_link``.

    ``joint_names`` gives the order of q, qdot and tau everywhere in this package; by default
    the URDF's movable joints (``joints.movable_joints``) in document order. Each controlled
    joint is revolute, continuous or prismatic. ``base_link`` and ``tip_link`` are looked up
    as links (Pinocchio BODY frames), so a joint of the same name does not clash. ``armature``
    is the rotor inertia per joint, in that order (kg m^2, or kg for a prismatic joint; default
    zeros), added to the diagonal of M(q) (Pinocchio's ``model.armature``, at each joint's
    velocity index); ModelError names a value that is not finite and >= 0, or a length that is
    not one per joint. ``payload_kg`` (>= 0) at ``payload_com_tip_m`` (x, y, z in the tip
    link's frame, m) is a point mass the tip link carries that the URDF does not list
    (:meth:`set_payload`).
    """

    def __init__(self, urdf_xml: str, base_link: str, tip_link: str,
                 joint_names: Optional[Sequence[str]] = None,
                 armature: Optional[Sequence[float]] = None, payload_kg: float = 0.0,
                 payload_com_tip_m: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        try:
            movable = movable_joints(urdf_xml)
        except ValueError as exc:
            raise ModelError(f'cannot parse the URDF: {exc}') from exc
        joint_names = select_joints(joint_names, movable, ModelError)
        # Joints not controlled are locked at zero: made fixed in the URDF itself, which is
        # what Pinocchio's buildReducedModel computes, without its lookup of frames by name
        # alone (it stops on a link and a joint of the same name).
        locked = [n for n in movable if n not in joint_names]
        # a xacro left in: Pinocchio would skip what it cannot read (the text is XML: above)
        if _not_expanded(ElementTree.fromstring(urdf_xml)):
            raise ModelError(f'cannot parse the URDF: {NOT_EXPANDED}')
        try:
            model = pin.buildModelFromXML(fixed_joints(urdf_xml, locked) if locked
                                          else urdf_xml)
        except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
            why = '; '.join(limit_problems(urdf_xml)) or str(exc)
            raise ModelError(f'cannot parse the URDF: {why}') from exc
        unfit = inertial_problems(urdf_xml, joint_names)
        if unfit:
            raise ModelError(f'no body has these inertias: {"; ".join(unfit)}. Correct them in '
                             'the URDF')
        for name in (base_link, tip_link):
            if not model.existFrame(name, pin.BODY):
                what = (' (it names a joint; give the link)'
                        if model.existFrame(name, pin.JOINT) else '')
                raise ModelError(f'link {name!r} is not in the URDF{what}')
        self.model = model
        self.data = model.createData()
        self.joint_names: tuple[str, ...] = tuple(joint_names)
        self.base_link = base_link
        self.tip_link = tip_link
        self.n = len(joint_names)

        joint_ids = [model.getJointId(n) for n in joint_names]
        unbounded, sliding = [], []
        for name, jid in zip(joint_names, joint_ids):
            joint = model.joints[jid]
            if joint.nv != 1 or joint.nq not in (1, 2):
                raise ModelError(f'joint {name!r} has {joint.nq} coordinates and {joint.nv} '
                                 'velocities; only revolute, continuous and prismatic joints '
                                 'are supported')
            unbounded.append(joint.nq == 2)  # continuous: (cos q, sin q)
            kind = joint.shortname()  # JointModelPX..PZ, JointModelPrismaticUnaligned
            sliding.append(kind.startswith('JointModelP'))
        self.prismatic: tuple[bool, ...] = tuple(sliding)
        if model.nv != self.n:
            raise ModelError(f'model has {model.nv} velocities for {self.n} joints')
        # Our joint order -> Pinocchio's configuration index and velocity index.
        self._iq = [model.joints[jid].idx_q for jid in joint_ids]
        self._idx = [model.joints[jid].idx_v for jid in joint_ids]
        self._unbounded = tuple(unbounded)
        self.continuous: tuple[bool, ...] = self._unbounded
        self._any_unbounded = any(unbounded)
        self.armature: tuple[float, ...] = (
            (0.0,) * self.n if armature is None else checked_vector(
                'armature', armature, self.n, ModelError, lower=0.0, per_joint=True))
        model.armature[:] = 0.0
        for i, a in zip(self._idx, self.armature):  # velocity indices
            model.armature[i] = a
        # the rotor inertia the motion showed beyond it (set_armature_estimate)
        self.armature_estimate: tuple[float, ...] = (0.0,) * self.n
        self._identity_order = self._idx == list(range(self.n))
        # inertial_torque's gravity-free copy of the model (the armature in), its data and
        # buffers: made here, never in the tick
        free = pin.Model(model)
        free.gravity.setZero()
        self._inertial = (free, free.createData(), np.zeros(self.n), np.zeros(self.n))
        self._velocity = np.zeros(self.n)  # ... and inertial_torque's velocity, when given
        self._identity_q = self._identity_order and not self._any_unbounded
        self._base_id = model.getFrameId(base_link, pin.BODY)
        self._tip_id = model.getFrameId(tip_link, pin.BODY)
        if model.frames[self._base_id].parentJoint != 0:
            raise ModelError(f'base link {base_link!r} moves with joint '
                             f'{model.names[model.frames[self._base_id].parentJoint]!r}; '
                             'it must be fixed to the URDF root')
        # the body the tip moves with, as the URDF has it: set_payload adds to it
        tip_frame = model.frames[self._tip_id]
        self._tip_joint = tip_frame.parentJoint
        self._tip_placement = tip_frame.placement.copy()
        self._bare_tip_body = model.inertias[self._tip_joint].copy()
        self.payload = Payload()
        self.set_payload(payload_kg, payload_com_tip_m)
        self._q = pin.neutral(model)
        self._link_data = None  # link_pose's own, made when first asked
        pin.framesForwardKinematics(model, self.data, self._q)
        base = self.data.oMf[self._base_id]
        self._base_is_root = bool(np.allclose(base.homogeneous, np.eye(4)))
        self._R_root_base = base.rotation.copy()  # base orientation in the root frame
        # the acceleration of gravity, m/s^2, in base axes
        self.gravity_base_m_s2 = self._R_root_base.T @ model.gravity.linear
        self._p_root_base = base.translation.copy()

        inf = float('inf')
        self.position_lower = tuple(-inf if u else float(model.lowerPositionLimit[i])
                                    for i, u in zip(self._iq, self._unbounded))
        self.position_upper = tuple(inf if u else float(model.upperPositionLimit[i])
                                    for i, u in zip(self._iq, self._unbounded))
        self.velocity_limits = self._per_joint(model.velocityLimit)
        self.effort_limits = self._per_joint(model.effortLimit)
        # the URDF's <dynamics friction>, N m (0: not given); the simulator does not use it
        self.friction_nm = self._per_joint(model.friction)
        self.length_m = self._chain_length(joint_ids)
        # kg the controlled joints move: the URDF's links past the first of them, no payload
        self.link_mass_kg = float(sum(inertia.mass for inertia in model.inertias[1:])
                                  - (self.payload_kg if self._tip_joint else 0.0))

    def set_payload(self, payload_kg: float, payload_com_tip_m: Sequence[float]) -> None:
        """
        Carry ``payload_kg`` at ``payload_com_tip_m`` (m, in the tip link's frame) from now on.

        A point mass (a sphere of ``PAYLOAD_RADIUS_M``, as ``quat_jt_runtime.payload`` puts it
        in a URDF) added to the body of the joint that moves the tip, in place: g(q), M(q) and
        the dynamics have it from the next call. It replaces the payload before; 0 takes it
        away. ModelError names a mass that is not finite and >= 0, or a point that is not 3
        finite coordinates. A tip fixed to the base carries it on the base: nothing changes.
        """
        try:
            payload = Payload.create(payload_kg, payload_com_tip_m)
        except ValueError as exc:
            raise ModelError(str(exc)) from None
        mass = payload.mass_kg
        body = self._bare_tip_body + self._tip_placement.act(pin.Inertia(
            mass, np.array(payload.com_m), np.eye(3) * (0.4 * mass * PAYLOAD_RADIUS_M ** 2)))
        self.model.inertias[self._tip_joint] = body
        self._inertial[0].inertias[self._tip_joint] = body
        self.payload = payload

    def set_armature_estimate(self, extra: Sequence[float]) -> None:
        """
        Add ``extra`` (kg m^2 or kg per joint, >= 0) to the armature told, in M(q), from now on.

        The rotor inertia the motion shows beyond the armature told
        (``armature_estimate.ArmatureEstimator``; the regulator that estimates it sets it, and
        zeros when it starts): ``mass_matrix``, ``inertial_torque``, the inertias and the
        dynamics have it from the next call; ``armature`` stays the one told. In place, a
        write per joint: cheap enough for the tick, which alone calls it with checked values.
        """
        armature, free = self.model.armature, self._inertial[0].armature
        for i, told, e in zip(self._idx, self.armature, extra):
            armature[i] = told + e
            free[i] = told + e
        self.armature_estimate = tuple(extra)

    @property
    def payload_kg(self) -> float:
        """Return the mass of the payload the tip carries (kg; 0: none)."""
        return self.payload.mass_kg

    @property
    def payload_com_tip_m(self) -> tuple[float, ...]:
        """Return where the payload is, m, in the tip link's frame."""
        return self.payload.com_m

    def _chain_length(self, joint_ids: Sequence[int]) -> float:
        """
        Return the arm's length, m: from its first controlled joint to the tip, stretched.

        The sum of the distances between consecutive joint origins along the chain, from the
        first controlled joint (the nearest the root) to the tip link's origin: the joint
        placements of the URDF, so it does not depend on q, and it bounds the reach from
        above. 0 when the chain has no length (e.g. a wrist whose axes meet at the tip).
        """
        model = self.model
        tip = model.frames[self._tip_id]
        chain = []
        jid = tip.parentJoint
        while jid > 0:
            chain.append(jid)
            jid = model.parents[jid]
        controlled = [jid for jid in chain if jid in joint_ids]
        if not controlled:
            return 0.0
        first = min(controlled)  # Pinocchio numbers a parent before its children
        return float(np.linalg.norm(tip.placement.translation) + sum(
            np.linalg.norm(model.jointPlacements[jid].translation)
            for jid in chain if jid > first))

    def task_sigma_min(self, rows: np.ndarray, has_position: bool) -> float:
        """
        Return sigma_min of the task rows of J, its position rows in units of the arm's length.

        The near-singular test of assumption A2 compares this with SINGULAR_SIGMA_MIN. The
        position rows J_p (the first three rows of ``rows`` when ``has_position``) are in m/rad:
        the tip's speed per joint speed grows with the arm's size, so an arm twice as large,
        in the same configuration, has twice the sigma_min(J_p). Divided by ``length_m``
        (:meth:`_chain_length`) they are dimensionless, like the orientation rows J_o
        (rad/rad), which are left as they are: the test is then the same for an arm of any
        size, and an arm 1 m long keeps SINGULAR_SIGMA_MIN in m/rad. For the position task
        this is sigma_min(J_p) / L; for the pose task, sigma_min of [J_p / L; J_o]; for the
        orientation task, sigma_min(J_o). An arm of no length keeps its rows as given.
        """
        J = np.asarray(rows, dtype=float)
        if has_position and self.length_m > 0.0:
            J = J.copy()
            J[:3] /= self.length_m
        return float(np.linalg.svd(J, compute_uv=False)[-1])

    def link_names(self) -> tuple[str, ...]:
        """Return the names of the URDF's links (Pinocchio's body frames), in its order."""
        return tuple(f.name for f in self.model.frames if f.type == pin.FrameType.BODY)

    def link_pose(self, link: str, q: Sequence[float]) -> tuple[list[float], list[list[float]]]:
        """
        Return the position (m) and rotation of ``link`` in the base frame at ``q``.

        Works on a data object of its own, so it never disturbs the tick's. Raises ModelError
        for a name that is not a link of the URDF.
        """
        if link not in self.link_names():
            raise ModelError(f'link {link!r} is not in the URDF')
        if self._link_data is None:
            self._link_data = self.model.createData()
        pin.framesForwardKinematics(self.model, self._link_data, self.configuration(q))
        frame = self._link_data.oMf[self.model.getFrameId(link, pin.FrameType.BODY)]
        if self._base_is_root:
            return frame.translation.tolist(), frame.rotation.tolist()
        Rb = self._R_root_base.T
        return ((Rb @ (frame.translation - self._p_root_base)).tolist(),
                (Rb @ frame.rotation).tolist())

    def middle_of_ranges(self) -> tuple[float, ...]:
        """Return the middle of each joint's range, its limits taken within [-pi, pi] (rad)."""
        return tuple(0.5 * (max(lo, -np.pi) + min(hi, np.pi))
                     for lo, hi in zip(self.position_lower, self.position_upper))

    def _per_joint(self, vec: np.ndarray) -> tuple[float, ...]:
        """Pick one entry per joint from a Pinocchio velocity-sized vector (limits, friction)."""
        return tuple(float(vec[i]) for i in self._idx)

    def configuration(self, q: Sequence[float]) -> np.ndarray:
        """Return Pinocchio's configuration vector for the joint angles ``q`` (a copy)."""
        return self._set_q(q).copy()

    def _set_q(self, q: Sequence[float]) -> np.ndarray:
        if len(q) != self.n:
            raise ValueError(f'expected {self.n} joint positions, got {len(q)}')
        if self._identity_q:
            self._q[:] = q
        else:
            for i, qi, unbounded in zip(self._iq, q, self._unbounded):
                if unbounded:
                    self._q[i] = cos(qi)
                    self._q[i + 1] = sin(qi)
                else:
                    self._q[i] = qi
        return self._q

    def _reorder_columns(self, rows: list[list[float]]) -> list[list[float]]:
        if self._identity_order:
            return rows
        return [[row[i] for i in self._idx] for row in rows]

    def kinematics(self, q: Sequence[float]) -> tuple[list[float], list[list[float]],
                                                      list[list[float]]]:
        """
        One pass: tip position ``p`` (m), rotation ``R`` and ``J_G`` (6 x n), in the base frame.

        ``J_G`` rows are [J_p; J_o] of Eq. (12): linear velocity of the tip origin, then angular
        velocity, both in base-frame axes. Columns follow ``joint_names``.
        """
        qv = self._set_q(q)
        J = pin.computeFrameJacobian(self.model, self.data, qv, self._tip_id,
                                     pin.LOCAL_WORLD_ALIGNED)
        tip = self.data.oMf[self._tip_id]  # updated by computeFrameJacobian
        if self._base_is_root:
            p = tip.translation.tolist()
            R = tip.rotation.tolist()
            rows = J.tolist()
        else:
            Rb = self._R_root_base.T
            p = (Rb @ (tip.translation - self._p_root_base)).tolist()
            R = (Rb @ tip.rotation).tolist()
            rows = np.vstack((Rb @ J[:3], Rb @ J[3:])).tolist()
        return p, R, self._reorder_columns(rows)

    def forward_kinematics(self, q: Sequence[float]) -> tuple[list[float], list[list[float]]]:
        """Tip position (m) and rotation matrix in the base frame."""
        p, R, _ = self.kinematics(q)
        return p, R

    def gravity(self, q: Sequence[float]) -> list[float]:
        """g(q) of Eq. (1), N m, in ``joint_names`` order."""
        g = pin.computeGeneralizedGravity(self.model, self.data, self._set_q(q))
        return g.tolist() if self._identity_order else [float(g[i]) for i in self._idx]

    def payload_regressor(self, q: Sequence[float]) -> np.ndarray:
        """
        Return ``Y(q)`` (n x 4): the g(q) of a point payload ``m`` at ``c`` is ``Y [m; m c]``.

        ``c`` in the tip link's frame (m). With the tip's ``J_p``, ``J_o`` and ``R`` in the
        base frame and ``g0`` the acceleration of gravity reversed (m/s^2, base axes), the
        weight ``-m g0`` at ``p + R c`` needs ``J_c^T m g0``, ``J_c = J_p - [R c]x J_o``:
        ``m J_p^T g0 - J_o^T [g0]x R (m c)``. Linear in ``(m, m c)``, so a held torque can be
        fitted by least squares (the stall diagnosis's untold payload).
        """
        _, R, J = self.kinematics(q)
        return self.payload_regressor_at(np.array(R), np.array(J))

    def payload_regressor_at(self, R: np.ndarray, J: np.ndarray) -> np.ndarray:
        """Return :meth:`payload_regressor` from the tip's ``R`` and ``J_G`` (base frame)."""
        g0 = -self.gravity_base_m_s2
        cross = np.array([[0.0, -g0[2], g0[1]], [g0[2], 0.0, -g0[0]], [-g0[1], g0[0], 0.0]])
        return np.column_stack((J[:3].T @ g0, -J[3:].T @ cross @ R))

    def mass_matrix(self, q: Sequence[float]) -> np.ndarray:
        """M(q) of Eq. (1), the armature on its diagonal, in ``joint_names`` order."""
        M = pin.crba(self.model, self.data, self._set_q(q).copy())
        M = np.triu(M) + np.triu(M, 1).T
        return M[np.ix_(self._idx, self._idx)]

    def inertial_torque(self, q: Sequence[float], qddot: Sequence[float],
                        qdot: Optional[Sequence[float]] = None) -> list[float]:
        """
        Return ``M(q) qddot`` (+ ``C(q, qdot) qdot`` given ``qdot``), N m, in joint order.

        The armature is included. The torque that went into accelerating the joints at
        ``qddot``: the inverse dynamics at zero velocity and zero gravity (Pinocchio's RNEA on
        the model's gravity-free copy). With ``qdot``, at that velocity, so the Coriolis and
        centrifugal torques the moving links take are in too (the same one RNEA).
        """
        model, data, zero, a = self._inertial
        if self._identity_order:
            a[:] = qddot
        else:
            for i, v in zip(self._idx, qddot):
                a[i] = v
        v = zero
        if qdot is not None:
            v = self._velocity
            if self._identity_order:
                v[:] = qdot
            else:
                for i, w in zip(self._idx, qdot):
                    v[i] = w
        tau = pin.rnea(model, data, self._set_q(q), v, a)
        return tau.tolist() if self._identity_order else [float(tau[i]) for i in self._idx]

    def own_inertias(self, q: Sequence[float]) -> list[float]:
        """Return ``M_jj(q)`` per joint (kg m^2, armature included), in ``joint_names`` order."""
        own = pin.crba(self.model, self.data, self._set_q(q)).diagonal().tolist()
        return [own[i] for i in self._idx]

    def inertias(self, q: Sequence[float]) -> tuple[list[float], list[float]]:
        """
        Return per joint ``M_jj(q)`` and ``1 / (M(q)^-1)_jj`` (kg m^2), in ``joint_names`` order.

        ``M_jj`` is the inertia joint j moves while the other joints are held; ``1 / (M^-1)_jj``
        the one it sees while they move freely, at most ``M_jj``: what a torque on that joint
        alone accelerates first, and what bounds the damping the sampled loop tolerates on it
        (docs/gain_design.md). The armature is included in both.
        """
        own, seen, _ = self.inertias_and_inverse(q)
        return own, seen

    def inertias_and_inverse(
            self, q: Sequence[float]) -> tuple[list[float], list[float], list[list[float]]]:
        """
        Return :meth:`inertias` and :meth:`inverse_inertia` at ``q`` from one factorisation.

        The tick's inertial damping needs all three: ``M_jj``, ``I_j`` and, where its modes are
        capped or the speed guard acts, the whole ``M(q)^-1`` (Regulator.update).
        """
        qv = self._set_q(q)
        own = pin.crba(self.model, self.data, qv).diagonal().tolist()
        minv = pin.computeMinverse(self.model, self.data, qv)  # its upper triangle is filled
        rows = minv.tolist()
        for a in range(len(rows)):  # the lower triangle from the upper, in Pinocchio's order
            row = rows[a]
            for b in range(a):
                row[b] = rows[b][a]
        if self._identity_order:
            return own, [1.0 / rows[i][i] for i in range(self.n)], rows
        idx = self._idx
        rows = [[rows[i][k] for k in idx] for i in idx]
        return [own[i] for i in idx], [1.0 / rows[j][j] for j in range(self.n)], rows

    def inverse_inertia(self, q: Sequence[float]) -> list[list[float]]:
        """
        Return ``M(q)^-1`` as rows (n x n, symmetric; the armature included), in joint order.

        Row j maps the joints' torques to joint j's acceleration: the speed guard's damping of
        the guarded joints through their block of it, and its cancellation of the push the
        other joints give a joint within a stop's clearance, and the cap on the damping's modes
        (Regulator.update, docs/lyapunov.md, sections 6 and 10; the tick takes it with the
        inertias from :meth:`inertias_and_inverse`).
        """
        return self.inertias_and_inverse(q)[2]

    def forward_dynamics(self, q: Sequence[float], qdot: Sequence[float],
                         tau: Sequence[float]) -> np.ndarray:
        """
        Return qddot = M(q)^-1 (tau - C(q, qdot) qdot - g(q)), in ``joint_names`` order.

        M(q) includes the armature (Pinocchio's ABA adds ``model.armature``).
        """
        qv = self._set_q(q).copy()
        v = np.zeros(self.model.nv)
        t = np.zeros(self.model.nv)
        v[self._idx] = qdot
        t[self._idx] = tau
        a = pin.aba(self.model, self.data, qv, v, t)
        return a[self._idx]

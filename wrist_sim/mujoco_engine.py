"""
The MuJoCo engine of the simulator: the same URDF compiled by MuJoCo (``pip install mujoco``).

MuJoCo reads URDF itself (``MjModel.from_xml_string``). Before it does, the URDF is changed
only where the simulator's plant requires it:

- the ``<visual>`` and ``<collision>`` shapes are removed (no contacts, as in the PyBullet
  engine, and no mesh files to find: the dynamics need only the ``<inertial>`` elements);
- the movable joints that are not driven become fixed, at zero (the "locked" joints of the
  model);
- a ``<mujoco><compiler .../></mujoco>`` extension: ``fusestatic="false"`` keeps every link
  a body of its own (MuJoCo's fusion of links joined by fixed joints weighs their inertias by
  mass and so loses the rotational inertia of a link of mass 0, which the Panda's panda_link8
  has and Pinocchio keeps); ``balanceinertia="true"`` lets MuJoCo compile a physically
  impossible inertia tensor (principal moments that break the triangle inequality, as xArm6's
  link2 and link3 in pybullet_data have) by raising its smallest moments until it is
  possible, where Pinocchio keeps the tensor and PyBullet drops the link's rotational inertia.
  Valid tensors (the bundled wrist's, the Panda's) are untouched. A tensor with a principal
  moment at or below MuJoCo's 1e-15 (below 0, as the antenna links of TIAGo's URDF in
  example-robot-data have; 0, a rod; round-off, iCub's 1e-20), or none on a link a driven
  joint moves, gets those moments raised to a thousandth of its largest (at least
  ``m (1 mm)^2``), about the same principal axes, before the compiler balances it; those
  links are listed in ``repaired_inertia_links``, to be said once
  (:func:`repaired_inertia_note`). A tensor of zeros on a link that does not move (a point
  mass, which MuJoCo takes) is left as it is (:func:`_repair_inertias`). A link without mass
  that a driven joint moves and that carries links with mass (a frame between the axes of a
  shoulder split into three joints, as the human model's `left_upperarm_virtual`) gets
  ``MASSLESS_LINK_KG`` and ``m (1 mm)^2``, and is listed too: MuJoCo refuses a moving body
  without mass. One that carries none is left to MuJoCo's refusal (drive only the joints that
  move mass).

Then, per driven joint (MuJoCo's DOF fields, set after compiling, so the URDF's ``<dynamics
damping friction>`` are replaced by the simulator's parameters, as in the PyBullet engine):

- ``dof_armature``: the rotor inertia, on the diagonal of M(q) (``supports_armature``);
- ``dof_damping``: the viscous friction ``b``, integrated implicitly by MuJoCo's Euler
  integrator (stable for any ``b``);
- ``dof_frictionloss``: the Coulomb level with stiction, a constraint the solver bounds by the
  level. It is made as stiff as the step allows (``solreffriction`` time constant 2 dt,
  impedance 0.9999), so a joint held by it creeps at about 3e-6 rad/s under a load just below
  the level (PyBullet's velocity motor: none); the joint ranges get the same stiffness.

The step is MuJoCo's semi-implicit Euler at ``dt_s`` (the integrator the gain design's
sampled-loop check assumes), gravity -9.81 m/s^2 along z, the motor torque applied as
``qfrc_applied``. With ``enforce_velocity_limits`` each driven joint's speed is clamped to its
URDF velocity limit after the step and the position integrated with the clamped speed
(``q_k+1 = q_k + dt v_k+1``), the effect of PyBullet's ``maxJointVelocity``. The effort limits
are the simulator's clamp, the same for both engines. There is no window: ``use_gui`` is
PyBullet's.
"""
from typing import Any, Collection, Optional, Sequence
import xml.etree.ElementTree as ET

import numpy as np
from quat_jt_runtime.joints import link_masses, masses_below, movable_joints
from quat_jt_runtime.joints import MOVABLE_TYPES, select_joints
from wrist_sim.engine import Engine, GRAVITY_MPS2, SimulatorError

REPAIRED_MOMENT_SHARE = 1e-3  # of the largest principal moment, for one <= 0
POINT_MASS_RADIUS_M = 1e-3  # ... and at least m r^2: a link of mass m given no inertia
MUJOCO_MIN_MOMENT = 1e-15  # kg m^2, mjMINVAL: MuJoCo refuses a principal moment below it
MUJOCO_MIN_MASS_KG = 1e-15  # mjMINVAL: MuJoCo refuses a moving body of no more mass
MASSLESS_LINK_KG = 1e-6  # for a moving link without mass that carries links with mass
FRICTION_IMPEDANCE = 0.9999  # MuJoCo's largest: the stiffest constraint (least creep)
CONSTRAINT_TIME_STEPS = 2.0  # solref time constant, in steps: MuJoCo's smallest stable


def _import_mujoco() -> Any:
    try:
        import mujoco
    except ImportError as exc:
        raise SimulatorError(
            f"engine 'mujoco' needs the mujoco package ({exc}): pip install mujoco (the "
            "package's 'mujoco' extra), or use engine 'pybullet'") from None
    return mujoco


def repaired_inertia_note(links: Sequence[str]) -> str:
    """Say which links MuJoCo simulates with another inertia tensor than the URDF's, and why."""
    return (f'MuJoCo simulates {", ".join(links)} with a principal moment of inertia raised to '
            'a thousandth of the largest (at least their mass times (1 mm)^2): the '
            'inertia tensors robot_description gives them have one at or below 1e-15 (or none '
            'on a moving link), which MuJoCo refuses; a moving link without mass that carries '
            f'links with mass gets {MASSLESS_LINK_KG:g} kg. The model of the controller keeps '
            'them as given; the masses and centres of mass, hence gravity, agree to that '
            'milligram')


_INERTIA_KEYS = ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz')


def _repair_inertias(root: ET.Element, moving: Collection[str] = ()) -> tuple[str, ...]:
    """
    Raise the principal moments ~0 or below of the links' tensors; return those links.

    MuJoCo wants every moment above ``MUJOCO_MIN_MOMENT``. One at or below it is raised to a
    thousandth of the largest, or to ``m r^2`` (``POINT_MASS_RADIUS_M``) if that is more: a
    link of mass m whose tensor is round-off (iCub's 1e-20 moments), or none on a link in
    ``moving`` (the child of a driven joint), gets m (1 mm)^2. A tensor of zeros on a link that
    does not move (a point mass, which MuJoCo takes: the TALOS arm's force-torque sensor), or
    one too light for the floor to reach ``MUJOCO_MIN_MOMENT``, is left as it is.
    """
    try:
        masses = link_masses(root)
        below = masses_below(root, masses)
    except ValueError as exc:  # a mass that is not a number, named
        raise SimulatorError(str(exc)) from None
    repaired = list(_give_mass(root, moving, masses, below))
    for link in root.iter('link'):
        if link.get('name') in repaired:
            continue
        inertia = link.find('inertial/inertia')
        if inertia is None:
            continue
        try:
            xx, xy, xz, yy, yz, zz = (float(inertia.get(k, 0.0)) for k in _INERTIA_KEYS)
        except ValueError as exc:
            raise SimulatorError(f'link {link.get("name")!r}: an inertia value is not a '
                                 f'number ({exc})') from None
        tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.all(np.isfinite(tensor)):
            raise SimulatorError(f'link {link.get("name")!r}: the inertia tensor is not '
                                 f'finite ({dict(inertia.attrib)})')
        mass = masses.get(link.get('name'), 0.0)
        if not tensor.any() and link.get('name') not in moving:
            continue  # no tensor given, on a link that does not move: MuJoCo takes it
        moments, axes = np.linalg.eigh(tensor)
        floor = max(REPAIRED_MOMENT_SHARE * moments[-1], mass * POINT_MASS_RADIUS_M ** 2)
        if moments[0] > MUJOCO_MIN_MOMENT or floor <= MUJOCO_MIN_MOMENT:
            continue  # fine; or (nearly) massless, which MuJoCo takes where it does not move
        moments = np.maximum(moments, floor)
        fixed = axes @ np.diag(moments) @ axes.T
        for key, (i, j) in zip(_INERTIA_KEYS, ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2),
                                               (2, 2))):
            inertia.set(key, repr(float(fixed[i, j])))
        repaired.append(link.get('name'))
    return tuple(repaired)


def _give_mass(root: ET.Element, moving: Collection[str], masses: dict[str, float],
               below: dict[str, float]) -> tuple[str, ...]:
    """
    Give ``MASSLESS_LINK_KG`` to each moving link without mass that carries mass; return them.

    ``masses`` and ``below``: each link's mass and the mass below it (``joints.link_masses``,
    ``joints.masses_below``). Its inertia becomes ``m (1 mm)^2`` about its origin. A moving
    link without mass whose descendants have none either is left as it is (MuJoCo refuses it,
    and says which).
    """
    links = {link.get('name'): link for link in root.iter('link')}
    given = []
    for name in sorted(moving):
        link = links.get(name)
        if (link is None or masses.get(name, 0.0) > MUJOCO_MIN_MASS_KG
                or below.get(name, 0.0) <= 0.0):
            continue
        inertial = link.find('inertial')
        if inertial is None:
            inertial = ET.SubElement(link, 'inertial')
        for tag in ('mass', 'inertia'):
            if inertial.find(tag) is None:
                ET.SubElement(inertial, tag)
        inertial.find('mass').set('value', repr(MASSLESS_LINK_KG))
        moment = repr(MASSLESS_LINK_KG * POINT_MASS_RADIUS_M ** 2)
        for key in _INERTIA_KEYS:
            inertial.find('inertia').set(key, moment if key in ('ixx', 'iyy', 'izz') else '0')
        given.append(name)
    return tuple(given)


def mujoco_urdf(urdf_xml: str, driven: Sequence[str]) -> tuple[str, tuple[str, ...]]:
    """
    Return the URDF as MuJoCo is to compile it, and the links whose inertia was repaired.

    See the module docstring. The shapes go, the movable joints not in ``driven`` become
    fixed, a tensor MuJoCo would refuse is repaired (:func:`_repair_inertias`) and the compiler
    extension asks for ``balanceinertia``. Raises SimulatorError if the text is not XML or an
    inertia value is not a finite number.
    """
    try:
        root = ET.fromstring(urdf_xml)
    except ET.ParseError as exc:
        raise SimulatorError(f'the URDF is not valid XML: {exc}') from exc
    moving = {joint.find('child').get('link') for joint in root.iter('joint')
              if joint.get('type') in MOVABLE_TYPES and joint.get('name') in driven}
    repaired = _repair_inertias(root, moving)
    for link in root.iter('link'):
        for shape in [e for e in link if e.tag in ('visual', 'collision')]:
            link.remove(shape)
    for joint in root.iter('joint'):
        if joint.get('type') in MOVABLE_TYPES and joint.get('name') not in driven:
            joint.set('type', 'fixed')
    extension = root.find('mujoco')
    if extension is None:
        extension = ET.SubElement(root, 'mujoco')
    compiler = extension.find('compiler')
    if compiler is None:
        compiler = ET.SubElement(extension, 'compiler')
    compiler.set('balanceinertia', 'true')
    compiler.set('discardvisual', 'true')
    compiler.set('fusestatic', 'false')
    return ET.tostring(root, encoding='unicode'), repaired


def _urdf_limits(urdf_xml: str, names: Sequence[str]) -> dict[str, tuple[float, ...]]:
    """Return (lower, upper, effort, velocity) of each named joint's URDF ``<limit>``."""
    out = {}
    for joint in ET.fromstring(urdf_xml).findall('joint'):  # not a <transmission>'s joints
        name = joint.get('name')
        if name not in names:
            continue
        limit = joint.find('limit')
        get = (lambda key: float(limit.get(key, 0.0))) if limit is not None else (
            lambda key: 0.0)
        if joint.get('type') == 'continuous':
            lower, upper = -np.inf, np.inf
        else:
            lower, upper = get('lower'), get('upper')
        out[name] = (lower, upper, get('effort'), get('velocity'))
    return out


class MuJoCoEngine(Engine):
    """The URDF compiled by MuJoCo (see the module docstring); headless."""

    name = 'mujoco'
    supports_armature = True

    def __init__(self, urdf_xml: str, joint_names: Optional[Sequence[str]], dt_s: float,
                 enforce_velocity_limits: bool = True) -> None:
        mujoco = self._mujoco = _import_mujoco()
        try:
            movable = movable_joints(urdf_xml)
        except ValueError as exc:
            raise SimulatorError(str(exc)) from exc
        names = select_joints(joint_names, movable, SimulatorError)
        text, self.repaired_inertia_links = mujoco_urdf(urdf_xml, names)
        try:
            model = mujoco.MjModel.from_xml_string(text)
        except ValueError as exc:  # MuJoCo's compile errors
            hint = (' (a link without mass moved by a driven joint: drive only the joints '
                    'that move mass, joint_names)' if 'mass and inertia of moving bodies'
                    in str(exc) else '')
            raise SimulatorError(f'MuJoCo cannot compile the URDF: {exc}{hint}') from exc
        self.joint_names = tuple(names)
        self.missing_meshes: list[str] = []  # no shapes: no mesh is looked for
        model.opt.timestep = float(dt_s)
        model.opt.gravity[:] = (0.0, 0.0, -GRAVITY_MPS2)
        model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
        if any(j < 0 for j in jids) or model.nv != self.n:
            raise SimulatorError(f'MuJoCo compiled {model.nv} degrees of freedom for the joints '
                                 f'{list(names)}')
        self._qadr = np.array([model.jnt_qposadr[j] for j in jids])
        self._dadr = np.array([model.jnt_dofadr[j] for j in jids])
        limits = _urdf_limits(urdf_xml, names)
        lower, upper, effort, velocity = (np.array(v, dtype=float)
                                          for v in zip(*(limits[n] for n in names)))
        self.position_lower, self.position_upper = lower, upper
        # URDF effort or velocity 0 (or absent) means "no limit given", as in PyBullet.
        self.effort_limits_nm = np.where(effort > 0.0, effort, np.inf)
        self.velocity_limits_rad_s = np.where(velocity > 0.0, velocity, np.inf)
        self.enforces_velocity_limits = bool(enforce_velocity_limits)
        self._clamped = (np.isfinite(self.velocity_limits_rad_s)
                         if enforce_velocity_limits else np.zeros(self.n, dtype=bool))
        stiff = (CONSTRAINT_TIME_STEPS * dt_s, 1.0)
        model.dof_solref[:] = stiff  # the friction-loss constraints
        model.dof_solimp[:, :2] = FRICTION_IMPEDANCE
        model.jnt_solref[:] = stiff  # the joint ranges (stops)
        model.dof_damping[:] = 0.0
        model.dof_frictionloss[:] = 0.0
        model.dof_armature[:] = 0.0
        self._model = model
        self._data = mujoco.MjData(model)
        self.q = np.zeros(self.n)
        self.qdot = np.zeros(self.n)
        self._dt = float(dt_s)
        self._read()

    def set_friction(self, viscous_nm_s_per_rad: np.ndarray, coulomb_nm: np.ndarray) -> None:
        """Viscous as the DOF damping (implicit), Coulomb as the DOF friction loss."""
        self._model.dof_damping[self._dadr] = viscous_nm_s_per_rad
        self._model.dof_frictionloss[self._dadr] = coulomb_nm

    def set_armature(self, armature: np.ndarray) -> None:
        """Set the rotor inertia as the DOF armature, on the diagonal of M(q)."""
        self._model.dof_armature[self._dadr] = armature

    def step(self, tau_nm: np.ndarray) -> None:
        """One Euler step under the motor torque; the speeds clamped at their limits."""
        data = self._data
        data.qfrc_applied[self._dadr] = tau_nm
        self._mujoco.mj_step(self._model, data)
        if self._clamped.any():
            v = data.qvel[self._dadr]
            limit = self.velocity_limits_rad_s
            fast = self._clamped & (np.abs(v) > limit)
            if fast.any():
                clamped = np.clip(v, -limit, limit)
                # q_k+1 = q_k + dt v_k+1: integrate the clamped speed instead
                data.qpos[self._qadr[fast]] += self._dt * (clamped[fast] - v[fast])
                data.qvel[self._dadr[fast]] = clamped[fast]
        self._read()

    def _read(self) -> None:
        np.take(self._data.qpos, self._qadr, out=self.q)
        np.take(self._data.qvel, self._dadr, out=self.qdot)

    def reset(self, q_rad: np.ndarray, qdot_rad_s: np.ndarray) -> None:
        """Set the joints' positions and velocities; forces and warm starts cleared."""
        data = self._data
        data.qpos[self._qadr] = q_rad
        data.qvel[self._dadr] = qdot_rad_s
        data.qacc_warmstart[:] = 0.0
        data.qfrc_applied[:] = 0.0
        self._mujoco.mj_forward(self._model, data)
        self._read()

    def close(self) -> None:
        """Nothing to release (the model and data are freed with this object)."""

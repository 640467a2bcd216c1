"""
ROS-free simulator core: a fixed-base serial robot from a URDF in PyBullet, torque driven.

Stands in for the paper's CICESE direct-drive wrist (by default the bundled
``urdf/spherical_wrist.urdf``) but loads any fixed-base serial URDF given as an XML string.
Each :class:`WristSimulator` owns one ``BulletClient`` (DIRECT unless a GUI is asked for), so
several can live in one process.

Dynamics match Pinocchio's for the same URDF (``RobotModel.forward_dynamics``): inertias come
from the file (``URDF_USE_INERTIA_FROM_FILE``), PyBullet's default link damping (0.04) and joint
damping are zeroed, gravity is -9.81 m/s^2 along z, and the default velocity motors are
disabled, so a joint moves under the commanded torque, gravity and the friction below only.
One exception: PyBullet rejects a physically impossible inertia tensor (principal moments that
break the triangle inequality, as xArm6's link2 and link3 in pybullet_data have) and simulates
that link without rotational inertia, while Pinocchio keeps the tensor; masses and centres of
mass, hence gravity, still agree. The bundled wrist's inertias are valid. PyBullet's own
warnings about it (printed several times per link) are taken out of the output, and those
links are listed in :attr:`WristSimulator.zero_inertia_links`, to be said once
(:func:`zero_inertia_note`); whatever else the loader prints is passed on.

Friction, per joint:

- viscous ``-b qdot`` as an explicit joint torque (``b`` in N m s/rad; stable while
  ``b dt / I`` stays well below 2, i.e. for any realistic ``b`` at 1 kHz);
- Coulomb, with stiction, as a PyBullet velocity motor with target velocity 0 whose force is
  limited to the Coulomb level ``f_c`` (N m): the constraint solver holds the joint still while
  the other torques on it stay below ``f_c`` and resists with ``f_c`` when they exceed it, with no
  chattering around zero velocity. The solver runs its full iteration count (residual threshold
  0) so a held joint does not creep.

The commanded torque is clamped to the URDF effort limits; that clamped torque is the
"applied" torque reported by :meth:`WristSimulator.step` and :meth:`WristSimulator.state`
(friction is not included in it: it is the motor torque, as a drive would report it). The
URDF velocity limits are enforced as a drive's speed limit would: PyBullet's solver clamps each
joint's speed to its limit (``maxJointVelocity``), so a huge torque cannot spin a joint faster.
This can be turned off (``enforce_velocity_limits``) for a model whose links are so light that
one tick of torque passes the limit (the xArm6's link 6): the clamp then acts as a switch and
makes the link chatter.

This module never imports rclpy.
"""
from dataclasses import dataclass
import math
import os
from pathlib import Path
import re
import sys
import tempfile
from typing import Optional, Sequence, Union
import xml.etree.ElementTree as ET

import numpy as np
from wrist_sim.quiet import c_output_captured, c_output_silenced
from wrist_sim.quiet import pybullet  # noqa: I100 - imported without its banner
import pybullet_data  # noqa: I100 - after pybullet, which wrist_sim.quiet imports silenced
from pybullet_utils.bullet_client import BulletClient
from quat_jt_runtime.errors import QuatJtError
from quat_jt_runtime.joints import movable_joints, select_joints

GRAVITY_MPS2 = 9.81
# PyBullet's loader, on a link whose inertia tensor it replaces with zero (URDF2Bullet)
_ZERO_INERTIA = re.compile(r'(?:b3Warning\[[^\]\n]*\]:[ \t]*\n)?Bad inertia tensor properties, '
                           r'setting inertia to zero for link: *(\S*)[ \t]*\n?')
_PACKAGE_URI = re.compile(r'package://([^/"\'\s]+)/([^"\'\s<>]*)')

PathLike = Union[str, os.PathLike]


class SimulatorError(QuatJtError):
    """The URDF, the joints or the values asked of the simulator are not usable."""


class NoDisplayError(SimulatorError):
    """The PyBullet window was asked for where none can open: not a matter of the robot."""


@dataclass(frozen=True)
class SimState:
    """A snapshot of the joints, in the simulator's joint order (copies, safe to keep)."""

    time_s: float
    q_rad: np.ndarray
    qdot_rad_s: np.ndarray
    tau_applied_nm: np.ndarray


def ament_package_dirs(package: str) -> list[Path]:
    """
    Return ``<prefix>/share/<package>`` of each sourced workspace that has it.

    The prefixes are ``AMENT_PREFIX_PATH``'s, as ``ament_index_python`` reads them (a package
    is in the index if ``<prefix>/share/ament_index/resource_index/packages/<package>``
    exists); ROS-free, so a pip install without ROS finds nothing and goes on.
    """
    out = []
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if not prefix:
            continue
        marker = Path(prefix) / 'share' / 'ament_index' / 'resource_index' / 'packages'
        share = Path(prefix) / 'share' / package
        if (marker / package).is_file() and share.is_dir():
            out.append(share)
    return out


def _find_mesh(filename: str, dirs: list[Path]) -> Optional[str]:
    """Return the absolute path of a URDF mesh ``filename``, or None if it cannot be found."""
    match = _PACKAGE_URI.fullmatch(filename)
    if match:
        pkg, rest = match.group(1), match.group(2)
        candidates = [share / rest for share in ament_package_dirs(pkg)]
        for d in dirs:
            candidates.append(d / pkg / rest)
            candidates += [sub / pkg / rest for sub in sorted(d.iterdir()) if sub.is_dir()]
    else:
        path = filename[len('file://'):] if filename.startswith('file://') else filename
        if os.path.isabs(path):
            candidates = [Path(path)]
        else:  # relative to a file the XML string no longer has: try the search paths
            candidates = [d / path for d in dirs]
            for d in dirs:
                candidates += [sub / path for sub in sorted(d.iterdir()) if sub.is_dir()]
    for c in candidates:
        if c.is_file():
            return str(c.resolve())
    return None


def resolve_meshes(urdf_xml: str, search_dirs: Sequence[PathLike]) -> tuple[str, list[str]]:
    """
    Point every mesh of the URDF at a file that exists; drop the shapes whose mesh does not.

    A mesh ``filename`` is looked for:

    - ``package://pkg/rest``: in ``share/pkg/rest`` of the sourced workspaces (the ament index,
      :func:`ament_package_dirs`), then for each directory ``d`` of ``search_dirs`` in
      ``d/pkg/rest`` and ``d/*/pkg/rest`` (so ``pybullet_data`` resolves
      ``package://xarm_description/...`` through ``pybullet_data/xarm/xarm_description``);
    - a relative path: in ``d/path`` and ``d/*/path`` (the URDF's own folder is gone once it
      is a ``robot_description`` string);
    - an absolute path or ``file://`` URI: as it is.

    The first file found is taken: a generic name (``package://meshes/...``) could match another
    robot's folder one level down in a search directory, so give the URDF's own folder first.
    The ``<visual>`` or ``<collision>`` whose mesh is not found is removed: the dynamics need
    only the ``<inertial>`` elements. Returns the XML and the filenames not found (for one
    warning); the XML is unchanged when every mesh is found as written.
    """
    dirs = [Path(d) for d in search_dirs if d and Path(d).is_dir()]
    try:
        root = ET.fromstring(urdf_xml)
    except ET.ParseError as exc:
        raise SimulatorError(f'the URDF is not valid XML: {exc}') from exc
    missing: list[str] = []
    changed = False
    for link in root.iter('link'):
        for shape in [e for e in link if e.tag in ('visual', 'collision')]:
            mesh = shape.find('geometry/mesh')
            if mesh is None:
                continue
            filename = mesh.get('filename', '')
            found = _find_mesh(filename, dirs)
            if found is None:
                link.remove(shape)
                if filename not in missing:
                    missing.append(filename)
                changed = True
            elif found != filename:
                mesh.set('filename', found)
                changed = True
    return (ET.tostring(root, encoding='unicode') if changed else urdf_xml), missing


def missing_meshes_note(missing: Sequence[str]) -> str:
    """Say which meshes of a URDF were not found, and where they were looked for."""
    return (f'{len(missing)} mesh file(s) of robot_description not found, simulated without '
            f'those shapes (the dynamics need only the inertias): {", ".join(missing)}. '
            'package:// URIs are looked for in the sourced workspaces (AMENT_PREFIX_PATH) and '
            'in pybullet_data; relative paths in pybullet_data')


def zero_inertia_note(links: Sequence[str]) -> str:
    """Say which links PyBullet simulates without rotational inertia, and why."""
    return (f'PyBullet simulates {", ".join(links)} without rotational inertia (point masses at '
            'their centres of mass): the inertia tensors robot_description gives them are not '
            "physical (a principal moment exceeds the sum of the other two). The controller's "
            'model keeps them as given; masses and centres of mass, hence gravity, agree')


def take_zero_inertia_warnings(text: str) -> tuple[tuple[str, ...], str]:
    """Return the links PyBullet's loader gave zero inertia (once each), and the rest of text."""
    links = tuple(dict.fromkeys(m.group(1) for m in _ZERO_INERTIA.finditer(text)))
    return links, _ZERO_INERTIA.sub('', text)


def at_limit(values: Sequence[float], limits: Sequence[float]) -> bool:
    """Tell whether any of ``values`` is at or past its limit, either way (plain floats)."""
    for v, limit in zip(values, limits):
        if v >= limit or v <= -limit:
            return True
    return False


def per_joint(name: str, values: Sequence[float], n: int,
              nonnegative: bool = False) -> tuple[float, ...]:
    """Return ``n`` finite values (>= 0 if ``nonnegative``), or raise SimulatorError saying why."""
    try:
        vals = tuple(float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise SimulatorError(f'{name}: not a list of numbers ({exc})') from None
    if len(vals) != n:
        raise SimulatorError(f'{name}: expected {n} values (one per joint), got {len(vals)}')
    if not all(math.isfinite(v) for v in vals):
        raise SimulatorError(f'{name}: values must be finite, got {list(vals)}')
    if nonnegative and any(v < 0.0 for v in vals):
        raise SimulatorError(f'{name}: values must be >= 0, got {list(vals)}')
    return vals


def _as_vector(values: Optional[Sequence[float]], n: int, name: str,
               nonnegative: bool = False) -> np.ndarray:
    """Return :func:`per_joint` as an array; None gives zeros."""
    return np.zeros(n) if values is None else np.array(per_joint(name, values, n, nonnegative))


def disconnect(client: Optional[BulletClient]) -> None:
    """Disconnect a PyBullet client; None or an already dead server is fine."""
    if client is not None:
        try:
            client.disconnect()
        except pybullet.error:
            pass


class WristSimulator:
    """
    A fixed-base serial robot from a URDF, in its own PyBullet client, torque controlled.

    :param urdf_xml: the URDF as an XML string.
    :param joint_names: the joints to drive, in the order of every vector of this class; by
        default the URDF's revolute/prismatic joints in tree order. Others stay at zero.
    :param dt_s: the fixed time step (s).
    :param use_gui: open the PyBullet window instead of a DIRECT (headless) client; its side
        panels are hidden and its camera looks at the robot. :meth:`show_frame` draws frames
        (e.g. a goal) in it.
    :param viscous_nm_s_per_rad: viscous friction ``b`` per joint (default zeros).
    :param coulomb_nm: Coulomb friction / stiction level per joint (default zeros).
    :param initial_positions_rad: where the robot starts, at rest (default zeros).
    :param search_dirs: extra directories in which meshes are looked for (before
        ``pybullet_data``; :func:`resolve_meshes`); the first also becomes PyBullet's
        additional search path. A shape whose mesh is found nowhere is left out, and its file
        is listed in :attr:`missing_meshes` (the robot still loads: the dynamics need only the
        inertias).
    :param solver_iterations: PyBullet constraint-solver iterations (for the friction motors).
    :param enforce_velocity_limits: hold each joint's speed at its URDF velocity limit, as a
        drive's speed limit would (see the module docstring).
    """

    def __init__(self, urdf_xml: str, joint_names: Optional[Sequence[str]] = None, *,
                 dt_s: float = 1e-3, use_gui: bool = False,
                 viscous_nm_s_per_rad: Optional[Sequence[float]] = None,
                 coulomb_nm: Optional[Sequence[float]] = None,
                 initial_positions_rad: Optional[Sequence[float]] = None,
                 search_dirs: Sequence[PathLike] = (),
                 solver_iterations: int = 50, enforce_velocity_limits: bool = True) -> None:
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise SimulatorError(f'dt_s must be finite and > 0, got {dt_s}')
        if not urdf_xml or not urdf_xml.strip():
            raise SimulatorError('empty URDF')
        self.dt_s = float(dt_s)
        dirs = [str(d) for d in search_dirs] + [pybullet_data.getDataPath()]
        xml, self.missing_meshes = resolve_meshes(urdf_xml, dirs)

        if use_gui and not os.environ.get('DISPLAY'):
            # PyBullet would exit the whole process ('cannot connect to X server'): say why.
            raise NoDisplayError(
                'use_gui is true but DISPLAY is not set, so the PyBullet window cannot open: '
                'run without use_gui (headless), on a desktop session, or under a virtual '
                "display, e.g. 'xvfb-run -a ros2 launch ...'")
        with c_output_silenced():  # PyBullet prints 'argv[0]=' on each connection
            self._client = BulletClient(
                connection_mode=pybullet.GUI if use_gui else pybullet.DIRECT)
        try:
            self._setup(xml, dirs, joint_names, solver_iterations, enforce_velocity_limits)
        except Exception:
            self.close()
            raise
        self._q = np.zeros(self.n)
        self._qdot = np.zeros(self.n)
        self._applied = np.zeros(self.n)
        self._drive = np.zeros(self.n)
        self._viscous = np.zeros(self.n)
        self._coulomb = np.zeros(self.n)
        self._step_count = 0
        self._initial = _as_vector(initial_positions_rad, self.n, 'initial_positions_rad')
        self.set_friction(viscous_nm_s_per_rad, coulomb_nm)
        self.reset(self._initial)
        self.use_gui = bool(use_gui)
        self._frame_lines: dict[str, list[int]] = {}
        if self.use_gui:
            self._aim_gui_camera()

    def _setup(self, xml: str, dirs: list[str], joint_names: Optional[Sequence[str]],
               solver_iterations: int, enforce_velocity_limits: bool) -> None:
        c = self._client
        c.setAdditionalSearchPath(dirs[0])
        c.setGravity(0.0, 0.0, -GRAVITY_MPS2)
        c.setTimeStep(self.dt_s)
        # Residual threshold 0: always run every iteration, so a joint held by stiction does
        # not creep (with the default 1e-7 it drifts ~1e-4 rad/s).
        c.setPhysicsEngineParameter(numSolverIterations=int(solver_iterations),
                                    solverResidualThreshold=0.0, numSubSteps=0)
        # PyBullet reads URDFs from files only: write the XML to a temporary one.
        fd, path = tempfile.mkstemp(prefix='wrist_sim_', suffix='.urdf')
        try:
            with os.fdopen(fd, 'w') as f:
                f.write(xml)
            printed: list[str] = []
            try:
                with c_output_captured() as printed:  # its warnings: said once, below
                    self._body = c.loadURDF(path, useFixedBase=True,
                                            flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
            except pybullet.error as exc:
                raise SimulatorError(f'PyBullet cannot load the URDF: {exc}') from exc
            finally:
                self.zero_inertia_links, rest = take_zero_inertia_warnings(''.join(printed))
                if rest:
                    sys.stdout.write(rest)
                    sys.stdout.flush()
        finally:
            os.unlink(path)

        by_name: dict[str, int] = {}
        info_by_index = {}
        for j in range(c.getNumJoints(self._body)):
            info = c.getJointInfo(self._body, j)
            by_name[info[1].decode()] = j
            info_by_index[j] = info
            # Zero PyBullet's default damping (0.04 on every link) and joint damping.
            c.changeDynamics(self._body, j, linearDamping=0.0, angularDamping=0.0,
                             jointDamping=0.0)
        c.changeDynamics(self._body, -1, linearDamping=0.0, angularDamping=0.0)
        try:
            movable = [n for n in movable_joints(xml) if n in by_name]
        except ValueError as exc:
            raise SimulatorError(str(exc)) from exc
        names = select_joints(joint_names, movable, SimulatorError)
        self.joint_names: tuple[str, ...] = tuple(names)
        self.n = len(names)
        self._idx = [by_name[n] for n in names]
        infos = [info_by_index[j] for j in self._idx]
        # URDF effort 0 (or absent) means "no limit given": no clamping.
        self.effort_limits_nm = np.array([i[10] if i[10] > 0.0 else np.inf for i in infos])
        # PyBullet reports a joint without stops (URDF continuous) with lower > upper.
        stops = [i[8] <= i[9] for i in infos]
        self.position_lower = np.array([i[8] if s else -np.inf for i, s in zip(infos, stops)])
        self.position_upper = np.array([i[9] if s else np.inf for i, s in zip(infos, stops)])
        # URDF velocity limits, enforced as a drive's speed limit: the solver clamps the joint
        # speed there (0 or absent in the URDF: no limit).
        self.velocity_limits_rad_s = np.array([i[11] if i[11] > 0.0 else np.inf for i in infos])
        self.enforces_velocity_limits = bool(enforce_velocity_limits)
        for j, limit in zip(self._idx, self.velocity_limits_rad_s):
            if math.isfinite(limit) and enforce_velocity_limits:
                c.changeDynamics(self._body, j, maxJointVelocity=float(limit))
        # Joints not driven are held at zero by stiff motors (the "locked" joints of the model).
        others = [by_name[n] for n in movable if n not in names]
        if others:
            c.setJointMotorControlArray(self._body, others, pybullet.POSITION_CONTROL,
                                        targetPositions=[0.0] * len(others),
                                        forces=[1e6] * len(others))
        self._zero_forces = [0.0] * self.n

    # -- configuration -------------------------------------------------------------------

    @property
    def friction(self) -> tuple[np.ndarray, np.ndarray]:
        """(viscous N m s/rad, Coulomb N m) per joint (copies)."""
        return self._viscous.copy(), self._coulomb.copy()

    def set_friction(self, viscous_nm_s_per_rad: Optional[Sequence[float]] = None,
                     coulomb_nm: Optional[Sequence[float]] = None) -> None:
        """
        Set both friction vectors (None = zeros).

        Both are validated (length, finite, >= 0) first, then applied together, so a bad value
        changes nothing.
        """
        viscous = _as_vector(viscous_nm_s_per_rad, self.n, 'viscous friction',
                             nonnegative=True)
        coulomb = _as_vector(coulomb_nm, self.n, 'coulomb friction', nonnegative=True)
        self._viscous[:] = viscous
        self._coulomb[:] = coulomb
        self._has_viscous = bool(np.any(viscous > 0.0))
        # The velocity motor: target 0, force bounded by the Coulomb level (0 = disabled).
        self._client.setJointMotorControlArray(
            self._body, self._idx, pybullet.VELOCITY_CONTROL,
            targetVelocities=[0.0] * self.n, forces=coulomb.tolist())

    @property
    def initial_positions_rad(self) -> np.ndarray:
        """Where :meth:`reset` without arguments puts the joints (copy)."""
        return self._initial.copy()

    # -- stepping ------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Return the simulation time (s): steps taken times ``dt_s``; :meth:`reset` keeps it."""
        return self._step_count * self.dt_s

    @property
    def step_count(self) -> int:
        """Return the number of steps taken since construction."""
        return self._step_count

    def step(self, tau_nm: Sequence[float]) -> np.ndarray:
        """
        Apply ``tau_nm`` (clamped to the effort limits) for one step of ``dt_s``.

        Returns the applied (clamped) torque, a copy. Raises SimulatorError on a wrong length
        or a non-finite value (nothing is stepped then).
        """
        tau = np.asarray(tau_nm, dtype=float)
        if tau.shape != (self.n,):
            raise SimulatorError(f'expected {self.n} torques, got shape {tau.shape}')
        if not np.all(np.isfinite(tau)):
            raise SimulatorError(f'torques must be finite, got {tau.tolist()}')
        self._step(tau)
        return self._applied.copy()

    def hold(self) -> None:
        """
        Let one step of time pass with the joints held at rest, as by engaged brakes.

        No physics is simulated: positions stay, velocities and the applied torque read zero.
        """
        self._applied[:] = 0.0
        self._qdot[:] = 0.0
        self._step_count += 1

    def step_zero(self) -> None:
        """One step with no motor torque (friction and gravity only)."""
        self._applied[:] = 0.0
        self._advance(self._zero_forces if not self._has_viscous else None)

    def _step(self, tau: np.ndarray) -> None:
        np.clip(tau, -self.effort_limits_nm, self.effort_limits_nm, out=self._applied)
        self._advance(None)

    def _advance(self, forces: Optional[list[float]]) -> None:
        if forces is None:
            if self._has_viscous:
                np.multiply(self._viscous, self._qdot, out=self._drive)
                np.subtract(self._applied, self._drive, out=self._drive)
                forces = self._drive.tolist()
            else:
                forces = self._applied.tolist()
        c = self._client
        c.setJointMotorControlArray(self._body, self._idx, pybullet.TORQUE_CONTROL,
                                    forces=forces)
        c.stepSimulation()
        self._step_count += 1
        self._read()

    def _read(self) -> None:
        for i, s in enumerate(self._client.getJointStates(self._body, self._idx)):
            self._q[i] = s[0]
            self._qdot[i] = s[1]

    # -- state ---------------------------------------------------------------------------

    def state(self) -> SimState:
        """Joint positions (rad or m), velocities and the applied torque (copies)."""
        return SimState(self.time_s, self._q.copy(), self._qdot.copy(), self._applied.copy())

    @property
    def q_rad(self) -> np.ndarray:
        """Joint positions, the simulator's own buffer (read only; changes on each step)."""
        return self._q

    @property
    def qdot_rad_s(self) -> np.ndarray:
        """Joint velocities, the simulator's own buffer (read only)."""
        return self._qdot

    @property
    def tau_applied_nm(self) -> np.ndarray:
        """Return the torque applied in the last step, clamped, without friction (own buffer)."""
        return self._applied

    def reset(self, q0_rad: Optional[Sequence[float]] = None,
              qdot0_rad_s: Optional[Sequence[float]] = None) -> None:
        """
        Put the joints at ``q0_rad`` (default: the initial positions).

        The velocity becomes ``qdot0_rad_s`` (default: at rest); the applied torque reads zero.
        Time goes on.
        """
        q0 = self._initial if q0_rad is None else _as_vector(q0_rad, self.n, 'q0_rad')
        v0 = _as_vector(qdot0_rad_s, self.n, 'qdot0_rad_s')
        for j, qi, vi in zip(self._idx, q0, v0):
            self._client.resetJointState(self._body, j, float(qi), float(vi))
        self._applied[:] = 0.0
        self._read()

    # -- the GUI window ------------------------------------------------------------------

    def _aim_gui_camera(self) -> None:
        """Hide the window's side panels and look at the robot (all link origins in view)."""
        c = self._client
        c.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
        pts = np.array([(0.0, 0.0, 0.0)] + [
            c.getLinkState(self._body, j, computeForwardKinematics=True)[4]
            for j in range(c.getNumJoints(self._body))])
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        radius = float(np.linalg.norm(pts - centre, axis=1).max()) + 0.15
        c.resetDebugVisualizerCamera(cameraDistance=1.6 * radius, cameraYaw=50.0,
                                     cameraPitch=-25.0, cameraTargetPosition=centre.tolist())

    def show_frame(self, name: str, position_m: Sequence[float],
                   quaternion_xyzw: Sequence[float], length_m: float = 0.1) -> bool:
        """
        Draw a coordinate frame (e.g. the goal) in the GUI as three lines, RGB = xyz.

        ``position_m`` and ``quaternion_xyzw`` (ROS order) are in the world frame, where the
        URDF's root link is. Calling it again with the same ``name`` moves that frame. Returns
        False (and draws nothing) without a GUI.
        """
        if not self.use_gui:
            return False
        origin = [float(v) for v in position_m]
        R = np.array(pybullet.getMatrixFromQuaternion([float(v) for v in quaternion_xyzw]))
        R = R.reshape(3, 3)
        old = self._frame_lines.get(name, [-1, -1, -1])
        ids = []
        for axis, color in enumerate(([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])):
            end = (np.array(origin) + length_m * R[:, axis]).tolist()
            ids.append(self._client.addUserDebugLine(origin, end, color, lineWidth=3.0,
                                                     replaceItemUniqueId=old[axis]))
        self._frame_lines[name] = ids
        return True

    def gui_camera(self) -> Optional[tuple[int, int, list[float], list[float]]]:
        """Return the GUI's (width, height, view matrix, projection matrix), None without one."""
        if not self.use_gui:
            return None
        cam = self._client.getDebugVisualizerCamera()
        return int(cam[0]), int(cam[1]), list(cam[2]), list(cam[3])

    def close(self) -> None:
        """Disconnect the PyBullet client (idempotent)."""
        disconnect(getattr(self, '_client', None))
        self._client = None

    def __enter__(self) -> 'WristSimulator':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

"""
The PyBullet engine of the simulator (the default; the paper's wrist is simulated here).

Each :class:`PyBulletEngine` owns one ``BulletClient`` (DIRECT unless a window is asked for),
so several can live in one process.

Dynamics match Pinocchio's for the same URDF (``RobotModel.forward_dynamics``): inertias come
from the file (``URDF_USE_INERTIA_FROM_FILE``), PyBullet's default link damping (0.04) and joint
damping are zeroed, gravity is -9.81 m/s^2 along z, and the default velocity motors are
disabled, so a joint moves under the commanded torque, gravity and the friction below only.
One exception: PyBullet rejects a physically impossible inertia tensor (principal moments that
break the triangle inequality, as xArm6's link2 and link3 in pybullet_data have) and simulates
that link without rotational inertia, while Pinocchio keeps the tensor; masses and centres of
mass, hence gravity, still agree. The bundled wrist's inertias are valid. PyBullet's own
warnings about it (printed several times per link) are taken out of the output, and those
links are listed in ``zero_inertia_links``, to be said once (:func:`zero_inertia_note`);
whatever else the loader prints is passed on.

Friction, per joint:

- viscous ``-b qdot`` as an explicit joint torque (``b`` in N m s/rad; stable while
  ``b dt / I`` stays well below 2, i.e. for any realistic ``b`` at 1 kHz);
- Coulomb, with stiction, as a PyBullet velocity motor with target velocity 0 whose force is
  limited to the Coulomb level ``f_c`` (N m): the constraint solver holds the joint still while
  the other torques on it stay below ``f_c`` and resists with ``f_c`` when they exceed it, with no
  chattering around zero velocity. The solver runs its full iteration count (residual threshold
  0) so a held joint does not creep.

The URDF velocity limits are enforced as a drive's speed limit would: PyBullet's solver clamps
each joint's speed to its limit (``maxJointVelocity``), so a huge torque cannot spin a joint
faster. PyBullet has no joint armature: the rotor inertia is not simulated
(``supports_armature`` is False; the node says so when one is set).
"""
import os
import re
import sys
import tempfile
from typing import Optional, Sequence

import numpy as np
from wrist_sim.quiet import c_output_captured, c_output_silenced
from wrist_sim.quiet import pybullet  # noqa: I100 - imported without its banner
from pybullet_utils.bullet_client import BulletClient  # noqa: I100 - after wrist_sim.quiet
from quat_jt_runtime.joints import movable_joints, select_joints
from wrist_sim.engine import Engine, GRAVITY_MPS2, NoDisplayError, SimulatorError
from wrist_sim.meshes import resolve_meshes

# PyBullet's loader, on a link whose inertia tensor it replaces with zero (URDF2Bullet)
_ZERO_INERTIA = re.compile(r'(?:b3Warning\[[^\]\n]*\]:[ \t]*\n)?Bad inertia tensor properties, '
                           r'setting inertia to zero for link: *(\S*)[ \t]*\n?')


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


def disconnect(client: Optional[BulletClient]) -> None:
    """Disconnect a PyBullet client; None or an already dead server is fine."""
    if client is not None:
        try:
            client.disconnect()
        except pybullet.error:
            pass


class PyBulletEngine(Engine):
    """
    The URDF in its own PyBullet client (see the module docstring).

    ``dirs`` are the directories meshes are looked for in (:func:`resolve_meshes`); the first
    also becomes PyBullet's additional search path. ``use_gui`` opens the PyBullet window: its
    side panels hidden, its camera looking at the robot.
    """

    name = 'pybullet'
    supports_armature = False

    def __init__(self, urdf_xml: str, joint_names: Optional[Sequence[str]], dt_s: float,
                 dirs: Sequence[str], use_gui: bool = False, solver_iterations: int = 50,
                 enforce_velocity_limits: bool = True) -> None:
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
            self._setup(xml, list(dirs), joint_names, dt_s, solver_iterations,
                        enforce_velocity_limits)
        except Exception:
            self.close()
            raise
        self.q = np.zeros(self.n)
        self.qdot = np.zeros(self.n)
        self._drive = np.zeros(self.n)
        self._viscous = np.zeros(self.n)
        self._has_viscous = False
        self.use_gui = bool(use_gui)
        self._frame_lines: dict[str, list[int]] = {}
        if self.use_gui:
            self._aim_gui_camera()

    def _setup(self, xml: str, dirs: list[str], joint_names: Optional[Sequence[str]],
               dt_s: float, solver_iterations: int, enforce_velocity_limits: bool) -> None:
        c = self._client
        c.setAdditionalSearchPath(dirs[0])
        c.setGravity(0.0, 0.0, -GRAVITY_MPS2)
        c.setTimeStep(dt_s)
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
        self.joint_names = tuple(names)
        self._idx = [by_name[n] for n in names]
        try:  # a URDF PyBullet loads but cannot step (TIAGo++'s, in example-robot-data)
            c.getJointStates(self._body, self._idx)
        except pybullet.error as exc:
            raise SimulatorError(f'PyBullet loaded the URDF but cannot read its joints ({exc}); '
                                 "engine 'mujoco' may simulate it") from None
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
            if np.isfinite(limit) and enforce_velocity_limits:
                c.changeDynamics(self._body, j, maxJointVelocity=float(limit))
        # Joints not driven are held at zero by stiff motors (the "locked" joints of the model).
        others = [by_name[n] for n in movable if n not in names]
        if others:
            c.setJointMotorControlArray(self._body, others, pybullet.POSITION_CONTROL,
                                        targetPositions=[0.0] * len(others),
                                        forces=[1e6] * len(others))

    def set_friction(self, viscous_nm_s_per_rad: np.ndarray, coulomb_nm: np.ndarray) -> None:
        """Viscous as an explicit torque each step; Coulomb as a bounded velocity motor."""
        self._viscous[:] = viscous_nm_s_per_rad
        self._has_viscous = bool(np.any(self._viscous > 0.0))
        # The velocity motor: target 0, force bounded by the Coulomb level (0 = disabled).
        self._client.setJointMotorControlArray(
            self._body, self._idx, pybullet.VELOCITY_CONTROL,
            targetVelocities=[0.0] * self.n, forces=np.asarray(coulomb_nm).tolist())

    def set_armature(self, armature: np.ndarray) -> None:
        """Do nothing: PyBullet has no joint armature (``supports_armature`` is False)."""

    def step(self, tau_nm: np.ndarray) -> None:
        """Apply the motor torque minus the viscous friction for one step, then read."""
        if self._has_viscous:
            np.multiply(self._viscous, self.qdot, out=self._drive)
            np.subtract(tau_nm, self._drive, out=self._drive)
            forces = self._drive.tolist()
        else:
            forces = tau_nm.tolist()
        c = self._client
        c.setJointMotorControlArray(self._body, self._idx, pybullet.TORQUE_CONTROL,
                                    forces=forces)
        c.stepSimulation()
        self._read()

    def _read(self) -> None:
        for i, s in enumerate(self._client.getJointStates(self._body, self._idx)):
            self.q[i] = s[0]
            self.qdot[i] = s[1]

    def reset(self, q_rad: np.ndarray, qdot_rad_s: np.ndarray) -> None:
        """Reset each joint's state in PyBullet, then read it back."""
        for j, qi, vi in zip(self._idx, q_rad, qdot_rad_s):
            self._client.resetJointState(self._body, j, float(qi), float(vi))
        self._read()

    # -- the window ----------------------------------------------------------------------

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
                   quaternion_xyzw: Sequence[float], length_m: float) -> bool:
        """Draw a frame as three lines, RGB = xyz (replacing the one of the same name)."""
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
        """Return the window's (width, height, view matrix, projection matrix)."""
        if not self.use_gui:
            return None
        cam = self._client.getDebugVisualizerCamera()
        return int(cam[0]), int(cam[1]), list(cam[2]), list(cam[3])

    def close(self) -> None:
        """Disconnect the PyBullet client (idempotent)."""
        disconnect(getattr(self, '_client', None))
        self._client = None

"""
Animations of a robot from recorded joint positions, rendered offscreen after a run (ROS-free).

PyBullet's software renderer (``ER_TINY_RENDERER``) in a DIRECT client needs no display and no
GPU. A :class:`RobotRenderer` owns one ``BulletClient`` with the URDF loaded (meshes resolved
as the simulator does), sets the joints of each frame with ``resetJointState`` (kinematics
only, no physics) and renders, with the links in neutral colours. Frames are drawn as axes on
top of the image (RGB = xyz, projected through the camera's own view and projection matrices);
a few lines of text go in the top-left corner.

:func:`animate` subsamples a recorded trajectory at a fixed rate of its own time stamps
(25 fps of sim time by default), draws the goal frame and the tip frame, writes a looping GIF
(Pillow) and optionally one still PNG. It never runs during a control loop: the tools call it
on the recorded joint states after the run.
"""
from dataclasses import dataclass
import math
import os
from pathlib import Path
import tempfile
import time
from typing import Callable, Optional, Sequence, Union

import numpy as np
from PIL import Image, ImageDraw
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient
from wrist_sim.quiet import c_output_silenced
from wrist_sim.simulator import disconnect, resolve_meshes

AXIS_RGB = ((220, 20, 20), (20, 170, 20), (20, 60, 230))  # x, y, z
TEXT_RGB = (20, 20, 20)
# The links' colours, base first, in turn (the URDF's materials are not used): greys and orange,
# away from the axes' red, green and blue.
LINK_RGBA = ((0.30, 0.30, 0.33, 1.0), (0.95, 0.62, 0.15, 1.0), (0.62, 0.62, 0.66, 1.0),
             (0.90, 0.80, 0.55, 1.0), (0.45, 0.45, 0.50, 1.0), (0.85, 0.85, 0.85, 1.0))
FLOOR_RGBA = (0.93, 0.93, 0.90, 1.0)


@dataclass(frozen=True)
class Camera:
    """A camera looking at ``target_m`` (world frame) from ``distance_m`` away."""

    target_m: tuple[float, float, float]
    distance_m: float
    yaw_deg: float = 50.0
    pitch_deg: float = -25.0
    fov_deg: float = 45.0


@dataclass(frozen=True)
class AxesFrame:
    """A coordinate frame drawn as three axes: origin and rotation in the world frame."""

    p_world_m: tuple[float, float, float]
    R_world: np.ndarray  # 3 x 3, columns are the frame's x, y, z axes
    length_m: float = 0.1
    width_px: int = 2
    label: str = ''


@dataclass
class AnimationResult:
    path: Path
    frames: int
    render_s: float  # wall time to render and write the file
    size_bytes: int
    camera: Camera
    still_path: Optional[Path] = None


def rotation_from_xyzw(xyzw: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a unit quaternion in ROS order (x, y, z, w)."""
    return np.array(pybullet.getMatrixFromQuaternion(list(xyzw))).reshape(3, 3)


class RobotRenderer:
    """
    One robot from a URDF in its own DIRECT PyBullet client, rendered offscreen.

    :param urdf_xml: the URDF as an XML string; its root link is placed at the world origin.
    :param joint_names: the joints that :meth:`render` positions, in that order (default: the
        URDF's revolute/prismatic joints in tree order). Others stay at zero.
    :param width_px, height_px: image size.
    :param search_dirs: extra directories for ``package://`` meshes (then ``pybullet_data``).
    :param floor: draw a plain floor at z = 0.
    """

    def __init__(self, urdf_xml: str, joint_names: Optional[Sequence[str]] = None, *,
                 width_px: int = 320, height_px: int = 240, search_dirs: Sequence[str] = (),
                 floor: bool = True) -> None:
        self.width_px, self.height_px = int(width_px), int(height_px)
        dirs = [str(d) for d in search_dirs] + [pybullet_data.getDataPath()]
        with c_output_silenced():  # PyBullet prints 'argv[0]=' on each connection
            self._client = BulletClient(connection_mode=pybullet.DIRECT)
        c = self._client
        fd, path = tempfile.mkstemp(prefix='animation_', suffix='.urdf')
        try:
            with os.fdopen(fd, 'w') as f:
                f.write(resolve_meshes(urdf_xml, dirs)[0])
            self._body = c.loadURDF(path, useFixedBase=True)
        finally:
            os.unlink(path)
        if floor:
            shape = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=[5.0, 5.0, 0.001],
                                        rgbaColor=FLOOR_RGBA)
            c.createMultiBody(baseVisualShapeIndex=shape, basePosition=[0.0, 0.0, -0.001])
        self._joint_index: dict[str, int] = {}
        self.root_link = c.getBodyInfo(self._body)[0].decode()
        self._link_index: dict[str, int] = {self.root_link: -1}
        movable = []
        for j in range(c.getNumJoints(self._body)):
            info = c.getJointInfo(self._body, j)
            self._joint_index[info[1].decode()] = j
            self._link_index[info[12].decode()] = j
            if info[2] in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC):
                movable.append(info[1].decode())
        self.joint_names = tuple(joint_names if joint_names is not None else movable)
        unknown = [n for n in self.joint_names if n not in self._joint_index]
        if unknown:
            raise ValueError(f'joints {unknown} are not in the URDF')
        self._joints = [self._joint_index[n] for n in self.joint_names]
        # Neutral link colours, so that the RGB axes stand out (the xArm6's own are R, G, B).
        links = sorted({shape[1] for shape in c.getVisualShapeData(self._body)})
        for k, link in enumerate(links):
            c.changeVisualShape(self._body, link, rgbaColor=LINK_RGBA[k % len(LINK_RGBA)])
        self.camera: Optional[Camera] = None
        self._view = self._proj = None

    # -- kinematics ----------------------------------------------------------------------

    def set_joint_positions(self, q_rad: Sequence[float]) -> None:
        """Put the joints at ``q_rad`` (``joint_names`` order), at rest."""
        for j, qj in zip(self._joints, q_rad):
            self._client.resetJointState(self._body, j, float(qj), 0.0)

    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Return (p_world_m, R_world) of a URDF link frame at the current joint positions."""
        if link not in self._link_index:
            raise ValueError(f'link {link!r} is not in the URDF')
        if self._link_index[link] < 0:  # the root link: at the world origin
            return np.zeros(3), np.eye(3)
        s = self._client.getLinkState(self._body, self._link_index[link],
                                      computeForwardKinematics=True)
        return np.array(s[4]), rotation_from_xyzw(s[5])

    def link_origins(self) -> np.ndarray:
        """Return the world positions of every link frame at the current pose, shape (L, 3)."""
        return np.array([self.link_pose(name)[0] for name in self._link_index])

    # -- camera --------------------------------------------------------------------------

    def set_camera(self, camera: Camera) -> None:
        c = self._client
        self.camera = camera
        self._view = c.computeViewMatrixFromYawPitchRoll(
            list(camera.target_m), camera.distance_m, camera.yaw_deg, camera.pitch_deg, 0.0, 2)
        self._proj = c.computeProjectionMatrixFOV(
            camera.fov_deg, self.width_px / self.height_px, 0.02, 20.0)
        # OpenGL matrices are column-major lists: transpose to act on column vectors.
        self._clip_from_world = (np.array(self._proj).reshape(4, 4).T
                                 @ np.array(self._view).reshape(4, 4).T)

    def fit_camera(self, q_samples_rad: Sequence[Sequence[float]],
                   points_world_m: Sequence[Sequence[float]] = (), pad_m: float = 0.1,
                   yaw_deg: float = 50.0, pitch_deg: float = -25.0,
                   fov_deg: float = 45.0) -> Camera:
        """
        Aim a camera at the robot over the poses of ``q_samples_rad`` and at extra points.

        Every link origin at every pose, and every extra point, padded by ``pad_m`` (the links'
        own size and the axes drawn), lies within the vertical and the horizontal field of view,
        with a 10 % margin.
        """
        pts = [np.asarray(points_world_m, dtype=float).reshape(-1, 3)]
        for q in q_samples_rad:
            self.set_joint_positions(q)
            pts.append(self.link_origins())
        pts = np.vstack(pts)
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        radius = float(np.linalg.norm(pts - centre, axis=1).max()) + pad_m
        half_fov = 0.5 * math.radians(fov_deg) * min(1.0, self.width_px / self.height_px)
        camera = Camera(tuple(float(v) for v in centre), 1.1 * radius / math.sin(half_fov),
                        yaw_deg, pitch_deg, fov_deg)
        self.set_camera(camera)
        return camera

    def project(self, points_world_m: np.ndarray) -> np.ndarray:
        """Return the pixel coordinates (u right, v down) of world points, shape (N, 2)."""
        pts = np.asarray(points_world_m, dtype=float).reshape(-1, 3)
        clip = self._clip_from_world @ np.hstack((pts, np.ones((len(pts), 1)))).T
        ndc = clip[:2] / clip[3]
        return np.stack(((ndc[0] + 1.0) * 0.5 * self.width_px,
                         (1.0 - ndc[1]) * 0.5 * self.height_px), axis=1)

    # -- images --------------------------------------------------------------------------

    def render(self, q_rad: Sequence[float], frames: Sequence[AxesFrame] = (),
               text: Sequence[str] = ()) -> Image.Image:
        """Render the robot at ``q_rad`` with ``frames`` as axes and ``text`` top left."""
        if self.camera is None:
            self.fit_camera([q_rad])
        self.set_joint_positions(q_rad)
        w, h, rgba, _, _ = self._client.getCameraImage(
            self.width_px, self.height_px, self._view, self._proj,
            renderer=pybullet.ER_TINY_RENDERER)
        image = Image.fromarray(np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3])
        draw = ImageDraw.Draw(image)
        for frame in frames:
            self._draw_axes(draw, frame)
        if text:
            width = max(draw.textlength(line) for line in text)
            draw.rectangle((0, 0, width + 8, 12 * len(text) + 5), fill=(255, 255, 255))
            for k, line in enumerate(text):
                draw.text((4, 3 + 12 * k), line, fill=TEXT_RGB)
        return image

    def _draw_axes(self, draw: ImageDraw.ImageDraw, frame: AxesFrame) -> None:
        origin = np.asarray(frame.p_world_m, dtype=float)
        ends = origin + frame.length_m * np.asarray(frame.R_world, dtype=float).T
        uv = self.project(np.vstack((origin, ends)))
        if not np.all(np.isfinite(uv)):
            return
        for axis in range(3):
            draw.line([tuple(uv[0]), tuple(uv[axis + 1])], fill=AXIS_RGB[axis],
                      width=frame.width_px)
        if frame.label:
            draw.text((uv[0][0] + 4, uv[0][1] + 2), frame.label, fill=TEXT_RGB)

    def close(self) -> None:
        """Disconnect the PyBullet client (idempotent)."""
        disconnect(self._client)
        self._client = None

    def __enter__(self) -> 'RobotRenderer':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def frame_indices(t_s: Sequence[float], fps: float) -> np.ndarray:
    """Return the indices of the samples nearest to ``t_s[0] + k / fps``, up to ``t_s[-1]``."""
    t = np.asarray(t_s, dtype=float)
    wanted = np.arange(t[0], t[-1] + 0.5 / fps, 1.0 / fps)
    idx = np.clip(np.searchsorted(t, wanted), 0, len(t) - 1)
    before = np.clip(idx - 1, 0, len(t) - 1)
    closer = np.abs(t[before] - wanted) < np.abs(t[idx] - wanted)
    return np.where(closer, before, idx)


def animate(urdf_xml: str, joint_names: Sequence[str], t_s: Sequence[float],
            q_rad: np.ndarray, path: Path, *, tip_link: str, base_link: Optional[str] = None,
            goal: Union[None, tuple[Sequence[float], np.ndarray],
                        Callable[[int], Optional[tuple]]] = None,
            text: Optional[Callable[[int], Sequence[str]]] = None, fps: float = 25.0,
            width_px: int = 320, height_px: int = 240, axis_length_m: float = 0.1,
            hold_end_s: float = 1.0, still_at_s: Optional[float] = None,
            still_path: Optional[Path] = None, search_dirs: Sequence[str] = (),
            camera: Optional[Camera] = None) -> AnimationResult:
    """
    Write a GIF of a recorded run: the robot, the goal frame and the tip frame.

    :param t_s, q_rad: the recorded samples (N,) and joint positions (N, n) in ``joint_names``
        order; subsampled at ``fps`` of these time stamps.
    :param tip_link: the link whose frame is drawn as the current end-effector frame.
    :param base_link: the frame in which ``goal`` is given (default: the URDF root).
    :param goal: (p_base_m, R_base) of the goal frame, drawn thicker and labelled 'goal'; or a
        function of the sample index returning it (a sequence of goals), or None then.
    :param text: the lines written in the corner for sample index k (e.g. time and ||e||).
    :param hold_end_s: how long the last frame stays before the GIF loops.
    :param still_at_s, still_path: also save the frame nearest to this time as a PNG.
    """
    t0 = time.perf_counter()
    t = np.asarray(t_s, dtype=float)
    q = np.asarray(q_rad, dtype=float)
    indices = frame_indices(t, fps)
    path = Path(path)
    with RobotRenderer(urdf_xml, joint_names, width_px=width_px, height_px=height_px,
                       search_dirs=search_dirs) as renderer:
        p_base, R_base = renderer.link_pose(base_link or renderer.root_link)

        def in_world(g):
            return (p_base + R_base @ np.asarray(g[0], dtype=float),
                    R_base @ np.asarray(g[1], dtype=float))
        goal_at = goal if callable(goal) else (lambda i: goal)
        goal_world = None if goal is None or callable(goal) else in_world(goal)
        if camera is None:
            extra = [] if goal_world is None else [goal_world[0]]
            camera = renderer.fit_camera(q[indices[::max(1, len(indices) // 12)]], extra,
                                         pad_m=1.3 * axis_length_m)
        else:
            renderer.set_camera(camera)
        still_k = None if still_at_s is None else int(np.argmin(np.abs(t[indices] - still_at_s)))
        images = []
        for k, i in enumerate(indices):
            renderer.set_joint_positions(q[i])
            frames = []
            if callable(goal):
                goal_world = None if goal_at(i) is None else in_world(goal_at(i))
            if goal_world is not None:
                frames.append(AxesFrame(tuple(goal_world[0]), goal_world[1],
                                        1.3 * axis_length_m, 4, 'goal'))
            p_tip, R_tip = renderer.link_pose(tip_link)
            frames.append(AxesFrame(tuple(p_tip), R_tip, axis_length_m, 2))
            image = renderer.render(q[i], frames, text(i) if text else ())
            if k == still_k and still_path is not None:
                image.save(still_path, optimize=True)
            images.append(image)
    duration_ms = [int(round(1000.0 / fps))] * len(images)
    duration_ms[-1] += int(round(1000.0 * hold_end_s))
    palette = [im.quantize(colors=64, method=Image.Quantize.MEDIANCUT) for im in images]
    palette[0].save(path, save_all=True, append_images=palette[1:], duration=duration_ms,
                    loop=0, optimize=False, disposal=1)
    return AnimationResult(path, len(images), time.perf_counter() - t0, path.stat().st_size,
                           camera, Path(still_path) if still_path is not None
                           and still_k is not None else None)

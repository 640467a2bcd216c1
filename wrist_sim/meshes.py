"""
The meshes a URDF names, found on this machine or left out (ROS-free, engine-free).

A ``robot_description`` string has lost the folder its relative mesh paths were relative to,
and its ``package://`` URIs need a workspace: :func:`resolve_meshes` points each mesh at a file
that exists, or drops the shape (the dynamics need only the ``<inertial>`` elements).
"""
import os
from pathlib import Path
import re
from typing import Optional, Sequence, Union
import xml.etree.ElementTree as ET

from quat_jt_runtime.resources import ament_package_dirs
from wrist_sim.engine import SimulatorError

_PACKAGE_URI = re.compile(r'package://([^/"\'\s]+)/([^"\'\s<>]*)')

PathLike = Union[str, os.PathLike]


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

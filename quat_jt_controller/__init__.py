"""
Transpose-Jacobian pose regulators with unit quaternions (Campa and Kelly).

The modules ``quaternion``, ``control_law``, ``model`` and ``resources`` form the ROS-free core
(numpy and Pinocchio only); ``controller_node`` wraps it for ROS 2.
"""

"""
Transpose-Jacobian pose regulators with unit quaternions (Campa and Kelly).

The ROS-free core (numpy and Pinocchio only, never rclpy): ``regulator`` (the control tick,
written once), ``quaternion``, ``control_law``, ``shaping``, ``model``, ``goal_check``,
``gain_design``, ``stall``, ``diagnostics``, ``joints``, ``loop_stats``, ``realtime``,
``throttle``, ``reference_sim``, ``paper`` and ``resources``. The nodes (``controller_node``,
with ``parameters`` and ``lifecycle``; ``composed``) are ROS marshalling around it, and the tools
(``tools/``) use the nodes. See docs/ for the errata, the model and the stability arguments.
"""

"""
Transpose-Jacobian pose regulators with unit quaternions (Campa and Kelly).

The ROS-free core (numpy and Pinocchio only, never rclpy): ``regulator`` (the control tick,
written once), ``quaternion``, ``control_law``, ``shaping``, ``model``, ``goal_check``,
``gain_design``, ``stall``, ``diagnostics``, ``joints``, ``loop_stats``, ``realtime``,
``throttle``, ``reference_sim``, ``paper``, ``goal_motion``, ``shutdown_signals`` and
``resources``. The nodes (``controller_node``, with ``parameters`` and ``lifecycle``;
``composed``; ``entry_points``, the console scripts) are ROS marshalling around it. The
experiments and benchmarks live outside the installed package, in the repository's
``experiments/``, and use the nodes. See docs/ for the errata, the model and the stability
arguments.
"""

"""
Transpose-Jacobian pose regulators with unit quaternions (Campa and Kelly).

The ROS-free core (numpy and Pinocchio only, never rclpy): ``regulator`` (the control tick, written
once), ``controller`` (the goal and the decisions around the tick), ``quaternion``,
``control_law``, ``shaping``, ``model``, ``inverse_kinematics``, ``goal_check``, ``gain_design``
(the rules, with ``gain_analysis``: the sampled loop, ``gain_output``: its files, ``gain_cli``:
its command line), ``stall``, ``diagnostics``, ``reference_sim``, ``paper``, ``goal_motion`` and
``controller_config``. The node (``controller_node``, with ``parameters`` and ``reports``) is ROS
marshalling around it. Below it, the runtime shared with the simulator (``quat_jt_runtime``); above
both nodes, ``quat_jt_bringup`` (console scripts, composed). The experiments and benchmarks live
outside the installed package, in the repository's ``experiments/``, and use the nodes. See docs/
for the errata, the model and the stability arguments.
"""

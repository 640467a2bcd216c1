"""
The runtime both nodes share, below them both.

The controller never needs the simulator, and the simulator never imports the controller.
ROS-free floor (also used by the controller's core and the simulator): ``errors`` (the one error
base), ``joints`` (a URDF's movable joints, the joint-state layout), ``resources`` (the
package's data files), ``realtime`` (CPU affinity, timer slack, deadline waits),
``loop_stats``, ``throttle`` and ``shutdown_signals``. ROS floor: ``params`` (the parameter
schema and machinery), ``lifecycle`` (start, spin and stop a node the same way),
``prewarm_timer`` (the controller's throwaway tick) and ``messages`` (``/diagnostics``).
"""

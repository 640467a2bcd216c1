"""
Above both nodes: the console scripts and the composed process.

``entry_points`` holds the console scripts; ``composed`` runs the simulator and the controller
on one executor. Nothing in the package imports this.
"""

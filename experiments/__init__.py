"""
The experiments, benchmarks and their helpers: not part of the installed package.

Run from the repository's top folder (``make demo``, ``make bench``, ``python -m
experiments.<name>``). They start the package's nodes as processes on a private loopback graph
(``local_ros``) and use its ROS-free core; nothing in the package imports them. Their own
dependencies (matplotlib, mcap, Pillow, PyYAML) are the ``demo`` extra of setup.py.
"""

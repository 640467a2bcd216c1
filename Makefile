# Entry points for a machine without ROS: each target builds .venv from the project's own
# files (setup.py extras) and then runs. With a ROS 2 Jazzy install use colcon (see README).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: venv test test-unit demo panda bench soak flood lint docs clean

venv: $(STAMP)

$(STAMP): setup.py setup.cfg
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[core,sim,ros,demo,test,mujoco]'
	touch $(STAMP)

# The whole test suite (what CI runs).
test: $(STAMP)
	$(PY) -m pytest test

# The ROS-free unit tier alone (seconds).
test-unit: $(STAMP)
	$(PY) -m pytest -m unit test

# docs/parameters.md from the nodes' parameter tables (a test checks it is current).
docs: $(STAMP)
	$(PY) -m quat_jt_bringup.parameter_docs --output docs/parameters.md

# The main job: the paper's experiment, both potentials, real nodes over DDS.
# DEMO_ARGS go to the experiment, e.g. make demo DEMO_ARGS='--lockstep --duration 12 --composed'
# (--xarm6 and --panda add the ROS-free xArm6 and Panda demos)
DEMO_ARGS ?=
demo: $(STAMP)
	$(PY) -m experiments.paper_experiment $(DEMO_ARGS)

# The 7-DOF Panda through a sequence of goals (ROS-free, about 20 s): MCAP, GIF and a figure of
# the errors and the null-space speed in results/panda. PANDA_ARGS go to experiments/panda_demo.py.
PANDA_ARGS ?=
panda: $(STAMP)
	$(PY) -m experiments.panda_demo $(PANDA_ARGS)

# The 1 kHz loop benchmark (about 6 min): two processes pinned and not pinned, each beside a
# minimal pair, composed for 60 s, the Panda's two processes, the lockstep experiment in both
# modes, the core tick. It rewrites docs/benchmark_latest.md.
# BENCH_ARGS go to the benchmark, e.g. make bench BENCH_ARGS='--prewarm-lead 0'
BENCH_ARGS ?=
bench: $(STAMP)
	$(PY) -m experiments.benchmark --page docs/benchmark_latest.md $(BENCH_ARGS)

# Both nodes for DURATION seconds (10 minutes by default): RSS and rates per minute, the final
# error and the warnings seen. LOAD=N runs N busy processes beside them (a loaded host).
DURATION ?= 600
LOAD ?= 0
soak: $(STAMP)
	$(PY) -m experiments.soak --duration $(DURATION) --load $(LOAD)

# Goals must never delay a tick: 1000 singular goals/s for 3 s, with a no-goal control run
# (the paper config), then a moving goal streamed at 30, 100 and 1000 Hz with the product
# config, as a user streams it: the loop and the tracking error (experiments/goal_stream.py).
flood: $(STAMP)
	$(PY) -m experiments.goal_flood
	$(PY) -m experiments.goal_stream

lint: $(STAMP)
	$(VENV)/bin/ament_flake8 .
	$(VENV)/bin/ament_pep257 .

clean:
	rm -rf $(VENV) build install log *.egg-info results

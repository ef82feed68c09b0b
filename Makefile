# redrive — the two commands a new user runs.  Works on a fresh Debian machine with Python 3.11
# (as root it installs the Debian packages it needs when they are missing).
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
DEMO_DIR := .demo
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

# `make demo`'s figure: the run's speed from its manifest, and the whole `redrive run` command's
define DEMO_FIGURE
import json, sys
summary = json.load(open(sys.argv[1]))["summary"]
span_s, whole_s = summary["log_span_s"], float(sys.argv[3]) - float(sys.argv[2])
print(f"demo run: {summary['frames']} frames, {span_s:.1f} s of log at "
      f"{summary['realtime_factor']:.1f}x real time (target >= 10x); the whole command "
      f"{whole_s:.1f} s with its start-up: {span_s / whole_s:.1f}x")
endef
export DEMO_FIGURE

.PHONY: demo test lint venv clean clean-kernels bench bench-read system-test-deps gui screenshots

# Debian's python3 ships without venv/ensurepip: install python3-venv when it is missing.
$(BIN)/python:
	@if ! $(PYTHON) -c "import venv, ensurepip" >/dev/null 2>&1; then \
	  echo "installing python3-venv (Debian)"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq python3-venv python3-pip; \
	fi
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/pip install -q -e .
	@touch $@

$(VENV)/.installed-test: $(VENV)/.installed pyproject.toml
	$(BIN)/pip install -q -e '.[test,bench,gui,ray,ros2,foxglove,commonroad]'
	$(BIN)/pip install -q --no-deps 'commonroad-io>=2024.1,<2027'  # see pyproject: [commonroad]
	@touch $@

# The numba kernels of `redrive synth`, of the reference pipeline and of the closed loop's LQR
# tracker (`python -m redrive.closedloop.kernels`), compiled once after the
# install into numba's on-disk cache (src/**/__pycache__), so that the first `redrive run` loads
# them instead of compiling them; again when a file with kernels changes (numba would recompile
# it on first use anyway).  `make clean-kernels` drops them.
KERNEL_SOURCES := $(shell grep -rl --include='*.py' 'import numba' src/redrive)
$(VENV)/.kernels: $(VENV)/.installed $(KERNEL_SOURCES)
	$(BIN)/python -m redrive.closedloop.kernels
	@touch $@

venv: $(VENV)/.installed $(VENV)/.kernels

## demo: create .venv, install redrive, simulate 20 s of the built-in `urban` scenario, replay it
## through the reference pipeline (LiDAR detector → tracker → IDM planner → pure pursuit), print
## the run summary (frames, detections, latency per stage), evaluate it against the ground truth
## (detection, tracking, planning, control, latency) and write the HTML/Excel/CSV report; it
## prints the run's speed (frames, and the whole command with its start-up) against real time
demo: $(VENV)/.installed $(VENV)/.kernels
	@mkdir -p $(DEMO_DIR)
	$(BIN)/redrive synth urban --duration 20 -o $(DEMO_DIR)/urban.mcap
	rm -rf $(DEMO_DIR)/run
	@t0=$$(date +%s.%N); \
	echo "$(BIN)/redrive run $(DEMO_DIR)/urban.mcap --out $(DEMO_DIR)/run"; \
	$(BIN)/redrive run $(DEMO_DIR)/urban.mcap --out $(DEMO_DIR)/run || exit $$?; \
	$(BIN)/python -c "$$DEMO_FIGURE" $(DEMO_DIR)/run/manifest.json $$t0 $$(date +%s.%N)
	$(BIN)/redrive evaluate $(DEMO_DIR)/run
	$(BIN)/redrive report $(DEMO_DIR)/run
	@echo "HTML report: $(DEMO_DIR)/run/report/report.html"

## lint: ruff, mypy --strict on src/, import-linter (the layers of DESIGN.md)
lint: $(VENV)/.installed-test
	$(BIN)/ruff check src tests benchmarks docs scripts
	$(BIN)/ruff format --check src tests benchmarks docs scripts
	$(BIN)/mypy
	$(BIN)/lint-imports

# Debian's ROS 1 (ros_comm 1.15) for the live tests: a real roscore, and rospy publishers that run
# under /usr/bin/python3 (rospy does not import under the venv's Python; see NOTES.md "ROS 1").
ROS1_DEBS := ros-core python3-rospy python3-rosbag python3-rostopic python3-sensor-msgs \
  python3-std-msgs python3-geometry-msgs python3-nav-msgs python3-visualization-msgs \
  python3-tf2-msgs ros-sensor-msgs python3-numpy
ROS1_PY_CHECK := import rospy, rosbag, rostopic, numpy, sensor_msgs.msg, std_msgs.msg, \
  geometry_msgs.msg, nav_msgs.msg, visualization_msgs.msg, tf2_msgs.msg

# Qt's xcb platform plugin and Mesa's software GL under Xvfb, for the GUI tests (NOTES.md: xauth
# is only "recommended" by xvfb, but xvfb-run needs it).
GUI_DEBS := xvfb xauth libgl1 libegl1 libgl1-mesa-dri libglx-mesa0 libegl-mesa0 libfontconfig1 \
  libxkbcommon-x11-0 libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-randr0 \
  libxcb-render-util0 libxcb-shape0 libxcb-xfixes0 libxcb-xkb1

# Debian packages the tests use: Chromium renders the HTML report (headless screenshot test);
# ROS 1 runs the live-mode tests; libatomic1 gives the transport its memory fence; Xvfb and the
# GL/xcb libraries run the GUI tests.  Installs only what is missing, with one apt-get update.
system-test-deps:
	@debs=""; \
	if ! command -v chromium >/dev/null 2>&1; then \
	  echo "installing chromium (Debian) for the HTML report test"; debs="chromium"; \
	fi; \
	if [ ! -x /usr/bin/roscore ] || \
	   ! /usr/bin/python3 -c "$(ROS1_PY_CHECK)" >/dev/null 2>&1; then \
	  echo "installing ROS 1 (Debian: ros-core, rospy, message packages) for the live tests"; \
	  debs="$$debs $(ROS1_DEBS)"; \
	fi; \
	if ! ldconfig -p | grep -q 'libatomic.so.1 '; then \
	  echo "installing libatomic1 (Debian): the shared-memory transport's memory fence"; \
	  debs="$$debs libatomic1"; \
	fi; \
	missing_gui=$$(dpkg-query -W -f='$${db:Status-Abbrev} $${Package}\n' $(GUI_DEBS) 2>&1 | \
	  grep -v '^ii ' | wc -l); \
	if [ "$$missing_gui" != 0 ] || ! command -v xvfb-run >/dev/null 2>&1; then \
	  echo "installing Xvfb and the GL/xcb libraries (Debian) for the GUI tests"; \
	  debs="$$debs $(GUI_DEBS)"; \
	fi; \
	if [ -n "$$debs" ]; then \
	  $(SUDO) apt-get update -qq && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$debs >/dev/null; \
	fi

## test: install test needs, lint, run the whole suite (slow/soak tests run as benchmarks); the
## kernels are compiled first, as `make venv` does (≈ 45 s of CPU a fresh clone's suite spent on it),
## and the bytecode of src/, tests/ and benchmarks/: with PYTHONDONTWRITEBYTECODE set (as in CI's
## shell) no process writes its .pyc, and every `python -m redrive` the suite starts compiled each
## module it imported again (≈ 0.3 s of CPU a process); a .pyc that is there is still read
test: system-test-deps lint $(VENV)/.kernels
	$(BIN)/python -m compileall -q src tests benchmarks
	xvfb-run -a -s "-screen 0 1600x1000x24" $(BIN)/pytest -q -m "not slow" -p no:cacheprovider

## screenshots: the GUI images of README and docs/gui.md, from the demo run, under Xvfb
screenshots: demo
	$(BIN)/pip install -q -e '.[gui]'
	xvfb-run -a -s "-screen 0 1600x1000x24" $(BIN)/python scripts/gui_screenshots.py \
	  --log $(DEMO_DIR)/urban.mcap --run $(DEMO_DIR)/run --out docs/images

## gui: install redrive with its GUI extra and open the demo log (run `make demo` first for its run)
gui: $(VENV)/.installed
	$(BIN)/pip install -q -e '.[gui]'
	@test -f $(DEMO_DIR)/urban.mcap || $(BIN)/redrive synth urban --duration 20 -o $(DEMO_DIR)/urban.mcap
	$(BIN)/redrive gui $$( [ -d $(DEMO_DIR)/run ] && echo $(DEMO_DIR)/run || echo $(DEMO_DIR)/urban.mcap )

## bench: every benchmark once in a small configuration (under 15 minutes): `redrive bench engine`
## and `closed-loop`, and benchmarks/ at the root (peers, soak, fleet, GUI, …; `PYTHONPATH=src
## python -m benchmarks all --help` lists the set), one markdown summary table in bench-summary.md
bench: $(VENV)/.installed-test
	PYTHONPATH=src $(BIN)/python -m benchmarks all --out bench-summary.md

bench-read: $(VENV)/.installed
	$(BIN)/redrive bench read --help

clean: clean-kernels
	rm -rf $(VENV) $(DEMO_DIR) .mypy_cache .ruff_cache .pytest_cache

## clean-kernels: drop numba's cached compiled kernels (next to the sources, in __pycache__);
## numba checks only a kernel's own file, so after editing a kernel that another module's
## kernels call (sim/gaps.py, called by sim/stepper.py; motion/idm.py, called by the world's
## and the reference planner's kernels), the callers' caches are stale
clean-kernels:
	find src -path '*__pycache__*' \( -name '*.nbi' -o -name '*.nbc' \) -delete
	rm -f $(VENV)/.kernels

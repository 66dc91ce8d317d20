#!/usr/bin/env bash
# The test command (README): installs what it needs, builds the firmware and the
# simavr harness from source, lints (ruff, with the layering rule) and type-checks
# (mypy), and runs the whole suite. Works on a fresh Debian bookworm machine as root
# (or with sudo).
#
# Two depths, one command, both derandomized (a red run is red again on the same code):
#   bash scripts/test.sh            the fast profile ("default"), a short differential, and
#                                   not the packaging checks marked slow (the wheel builds)
#                                   nor the long repeats marked thorough
#   CI=true bash scripts/test.sh    the thorough profile ("ci"): 200 examples a test and
#                                   the full differential (what .ci/run runs)
# HYPOTHESIS_PROFILE=NAME overrides either; extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."

# cmake and g++: the stock ROS 2 Jazzy client's tf2_msgs is built from its .msg (tests/ros2/jazzy_env.py)
DEBIAN_PACKAGES=(gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev libelf-dev make gcc avrdude cmake g++)
# Python's headers, for the port's C fast path (wcdrive/avr/csrc/f32_fast.c), when the
# interpreter does not bring its own (Debian's python3 keeps them in python3-dev).
python3 -c 'import os, sysconfig, sys; sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' \
  || DEBIAN_PACKAGES+=(python3-dev)
missing=()
for pkg in "${DEBIAN_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "== installing Debian packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

echo "== installing wcdrive with its test dependencies"
python3 -m pip install -q --disable-pip-version-check -e ".[test]"

echo "== building the firmware"
make -s -C firmware/final_control
# and the builds the tests use (the per-user cache), once, before the workers start
python3 -c "from wcdrive.boards.simavr.build import firmware_elf, harness_library
from wcdrive._util.resources import firmware_dir
firmware_elf(); firmware_elf(firmware_dir('fpcheck')); harness_library()"

echo "== ruff"
python3 -m ruff check .

echo "== mypy"
python3 -m mypy

# The fast depth leaves out the packaging checks that build wheels (-m slow) and the
# long repeats of what a faster test covers (-m thorough).
DEPTH=(-m "not slow and not thorough")
if [ "${CI:-}" = "true" ]; then DEPTH=(); fi
if [ -z "${HYPOTHESIS_PROFILE:-}" ]; then
  if [ "${CI:-}" = "true" ]; then HYPOTHESIS_PROFILE=ci; else HYPOTHESIS_PROFILE=default; fi
fi
echo "== pytest (hypothesis profile: $HYPOTHESIS_PROFILE${DEPTH[*]:+, ${DEPTH[*]}})"
python3 -m pytest -n 2 --hypothesis-profile="$HYPOTHESIS_PROFILE" "${DEPTH[@]}" "$@"

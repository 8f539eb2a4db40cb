#!/usr/bin/env bash
# Idempotent set-up for a fresh clone: Debian packages (AVR toolchain, Arduino core, simavr,
# avrdude) and the Python package in .venv. Quick when everything is already there.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(gcc-avr avr-libc binutils-avr simavr libsimavr-dev libelf-dev arduino-core-avr
              avrdude
              libosmesa6  # MuJoCo's off-screen rendering (MUJOCO_GL=osmesa)
              clang libclang-rt-14-dev  # libFuzzer and the sanitizer runtimes (tests/fuzz)
              chromium chromium-driver)  # the dashboard's browser tests (tests/dashboard)
VENV=.venv
PYTHON=${PYTHON:-python3.11}

missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "setup: error: apt-get not found; install these packages by hand: ${missing[*]}" >&2
    exit 1
  fi
  SUDO=()
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
      SUDO=(sudo -n)
    else
      echo "setup: error: not root and no password-less sudo; run by hand:" >&2
      echo "  sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
      exit 1
    fi
  fi
  export DEBIAN_FRONTEND=noninteractive
  # A stale package index fails with 404s; refresh it once, then install.
  "${SUDO[@]}" apt-get update -qq
  if ! "${SUDO[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null; then
    echo "setup: error: apt-get could not install: ${missing[*]}" >&2
    echo "  run by hand: sudo apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
fi

if ! command -v "$PYTHON" >/dev/null 2>&1; then
  PYTHON=python3
fi
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "setup: error: Python 3.11 or newer is needed ($PYTHON is $("$PYTHON" --version 2>&1))" >&2
  exit 1
fi

stamp=$VENV/.utrf-installed
if [ ! -x "$VENV/bin/python" ]; then
  echo "setup: creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: installing the utrf package and its dependencies into $VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  if ! "$VENV/bin/python" -m pip install -q -e '.[dev]'; then
    echo "setup: error: pip could not install the package; run by hand:" >&2
    echo "  $VENV/bin/python -m pip install -e '.[dev]'" >&2
    exit 1
  fi
  touch "$stamp"
fi

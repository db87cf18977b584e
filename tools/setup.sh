#!/usr/bin/env bash
# One-command setup: .venv with ROS 2 Jazzy wheels + deps, then colcon build.
# Idempotent: each step is skipped when its inputs have not changed.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
REQ="$ROOT/tools/requirements.txt"
STAMP="$VENV/.tactile_sl_requirements.sha256"

log() { printf '[setup] %s (at %d s)\n' "$*" "$SECONDS"; }

# Serialise concurrent setups/builds of this checkout (parallel shells, helpers).
exec 9>"$ROOT/.setup.lock"
flock 9

# Building the interface package needs CMake, a C/C++ compiler and the Python headers.
missing=()
command -v cmake >/dev/null 2>&1 || missing+=(cmake)
command -v c++ >/dev/null 2>&1 || missing+=(g++)
command -v make >/dev/null 2>&1 || missing+=(make)
# tests/test_robot_network.py builds two network namespaces with `ip`.
command -v ip >/dev/null 2>&1 || missing+=(iproute2)
# The viewer's browser test drives the distribution's headless Chromium (playwright never
# downloads a browser of its own here): installed as root; otherwise only that test needs it.
if [ ! -x /usr/bin/chromium ]; then
  if [ "$(id -u)" = 0 ]; then
    missing+=(chromium)
  else
    echo "[setup] /usr/bin/chromium missing: the viewer's browser test needs it" \
         "(sudo apt-get install -y chromium)" >&2
  fi
fi
"$PY" -c 'import sysconfig, os, sys; sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' \
  || missing+=(python3-dev)
"$PY" -c 'import ensurepip' >/dev/null 2>&1 || missing+=(python3-venv)
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    log "installing system packages: ${missing[*]}"
    DEBIAN_FRONTEND=noninteractive apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "[setup] missing system packages: ${missing[*]}" >&2
    echo "[setup] install them with: sudo apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
fi

if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), "Python 3.11 is required (the ros-jazzy wheels are cp311)"'
  log "creating $VENV"
  "$PY" -m venv "$VENV"
fi

want="$(sha256sum "$REQ" | cut -d' ' -f1)"
have="$(cat "$STAMP" 2>/dev/null || true)"
if [ "$want" != "$have" ]; then
  log "installing Python dependencies (tools/requirements.txt)"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip 'setuptools<80'
  # torch first and alone, pinned, so nothing else can resolve it to a CUDA build.
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check torch==2.13.0
  PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 \
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r "$REQ"
  echo "$want" > "$STAMP"
else
  log "Python dependencies up to date"
fi

# The ros-jazzy wheels' CMake exports hard-code their build machine's Python and numpy include
# directories; point them at this venv's (idempotent: only files still naming /opt/python change).
"$VENV/bin/python" "$ROOT/tools/fix_cmake_exports.py" "$VENV"

touch "$VENV/local_setup.sh"  # an ament prefix marker; silences colcon's warning about the venv
log "colcon build"
# shellcheck disable=SC1091
source "$ROOT/tools/venv_env.sh"
cd "$ROOT"
colcon --log-base "$ROOT/log" build --symlink-install \
  --base-paths "$ROOT/src" --build-base "$ROOT/build" --install-base "$ROOT/install" \
  --event-handlers console_direct- summary+ \
  --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python"
# compile the numba kernels into their on-disk cache now, so that no node compiles at start
( set +u; source "$ROOT/install/local_setup.bash" && python -m tactile_sl_decoder.jit )
log "done"

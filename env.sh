# Source me: `source env.sh` (bash or zsh).
# Activates .venv (ROS 2 Jazzy from wheels), overlays the colcon install/ space, keeps DDS on
# loopback, and puts `tactile-sl` on PATH. Run `make setup` (or `make test`) once first.
if [ -n "${BASH_SOURCE[0]:-}" ]; then _tsl_here="${BASH_SOURCE[0]}"; else _tsl_here="${(%):-%x}"; fi
TACTILE_SL_ROOT="$(cd "$(dirname "$_tsl_here")" && pwd)"
export TACTILE_SL_ROOT
unset _tsl_here
if [ -f "$TACTILE_SL_ROOT/.venv/bin/python" ]; then
  . "$TACTILE_SL_ROOT/tools/venv_env.sh"
else
  echo "env.sh: no .venv here; run 'make setup' first (or use a system ROS 2 Jazzy install)" >&2
fi
if [ -f "$TACTILE_SL_ROOT/install/local_setup.bash" ] && [ -n "${BASH_VERSION:-}" ]; then
  . "$TACTILE_SL_ROOT/install/local_setup.bash"
elif [ -f "$TACTILE_SL_ROOT/install/local_setup.sh" ]; then
  COLCON_CURRENT_PREFIX="$TACTILE_SL_ROOT/install" . "$TACTILE_SL_ROOT/install/local_setup.sh"
fi
# DDS discovery must never leave this machine (contract): loopback only, own domain.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-42}"
# Fast DDS: 16 MB shared-memory segments (stereo images at 30 Hz) and UDP on loopback only.
export FASTRTPS_DEFAULT_PROFILES_FILE="${FASTRTPS_DEFAULT_PROFILES_FILE:-$TACTILE_SL_ROOT/config/fastdds.xml}"
case ":$PATH:" in *":$TACTILE_SL_ROOT/bin:"*) ;; *) export PATH="$TACTILE_SL_ROOT/bin:$PATH" ;; esac

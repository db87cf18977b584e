# Source me: `source env.sh` (bash or zsh).
# Activates .venv (ROS 2 Jazzy from wheels), overlays the colcon install/ space, keeps DDS on
# loopback (or, with TACTILE_SL_NETWORK=robot set first, on the robot's network, see below),
# and puts `tactile-sl` on PATH. Run `make setup` (or `make test`) once first.
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
# DDS (contract): by default discovery and data stay on this machine (loopback, own domain),
# as the project's tests, demo, benchmarks and CI require. On a robot, set the switch before
# sourcing, `TACTILE_SL_NETWORK=robot source env.sh`: subnet discovery, your ROS_DOMAIN_ID
# (ROS's default 0 if unset) and config/fastdds_robot.xml, so the robot's other computers
# receive the sensor's topics. Both profiles enlarge Fast DDS's shared-memory segments to
# 16 MB (stereo images at 30 Hz); the loopback one also pins UDP to 127.0.0.1.
_tsl_mode="${TACTILE_SL_NETWORK:-loopback}"
case "$_tsl_mode" in
  robot)
    export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET
    # The robot's domain id is yours; drop only the 42 an earlier loopback `source` set.
    if [ -n "${TACTILE_SL_DEFAULT_DOMAIN:-}" ] && [ "${ROS_DOMAIN_ID:-}" = "$TACTILE_SL_DEFAULT_DOMAIN" ]; then
      unset ROS_DOMAIN_ID
    fi
    unset TACTILE_SL_DEFAULT_DOMAIN
    _tsl_profile="$TACTILE_SL_ROOT/config/fastdds_robot.xml"
    _tsl_domain="${ROS_DOMAIN_ID:-0 (ROS default; unset)}"
    ;;
  *)
    if [ "$_tsl_mode" != loopback ]; then
      echo "env.sh: TACTILE_SL_NETWORK='$_tsl_mode' is neither 'loopback' nor 'robot'; using loopback" >&2
      _tsl_mode=loopback
    fi
    export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    if [ -z "${ROS_DOMAIN_ID:-}" ]; then
      export ROS_DOMAIN_ID=42 TACTILE_SL_DEFAULT_DOMAIN=42
    fi
    _tsl_profile="$TACTILE_SL_ROOT/config/fastdds_loopback.xml"
    _tsl_domain="$ROS_DOMAIN_ID"
    ;;
esac
# A profile of your own is kept; one of ours is replaced (switching modes in one shell works).
case "${FASTRTPS_DEFAULT_PROFILES_FILE:-}" in
  ""|"$TACTILE_SL_ROOT"/config/fastdds*.xml) export FASTRTPS_DEFAULT_PROFILES_FILE="$_tsl_profile" ;;
esac
echo "env.sh: network mode $_tsl_mode: ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_DOMAIN_ID=$_tsl_domain, Fast DDS profile $FASTRTPS_DEFAULT_PROFILES_FILE" >&2
if [ "${ROS_LOCALHOST_ONLY:-0}" = 1 ] && [ "$_tsl_mode" = robot ]; then
  echo "env.sh: ROS_LOCALHOST_ONLY=1 keeps discovery on this machine; unset it on a robot" >&2
fi
unset _tsl_mode _tsl_profile _tsl_domain
case ":$PATH:" in *":$TACTILE_SL_ROOT/bin:"*) ;; *) export PATH="$TACTILE_SL_ROOT/bin:$PATH" ;; esac

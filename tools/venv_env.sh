# Sourced: make the venv an ament/CMake prefix (the ros-jazzy wheels install into it).
_TSL_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_TSL_VENV="$_TSL_ROOT/.venv"
export VIRTUAL_ENV="$_TSL_VENV"
case ":$PATH:" in *":$_TSL_VENV/bin:"*) ;; *) export PATH="$_TSL_VENV/bin:$PATH" ;; esac
case ":${AMENT_PREFIX_PATH:-}:" in *":$_TSL_VENV:"*) ;; *) export AMENT_PREFIX_PATH="$_TSL_VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;; esac
case ":${CMAKE_PREFIX_PATH:-}:" in *":$_TSL_VENV:"*) ;; *) export CMAKE_PREFIX_PATH="$_TSL_VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" ;; esac
case ":${LD_LIBRARY_PATH:-}:" in *":$_TSL_VENV/lib:"*) ;; *) export LD_LIBRARY_PATH="$_TSL_VENV/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" ;; esac
unset _TSL_ROOT _TSL_VENV

"""Point the ros-jazzy wheels' CMake exports at this venv's Python and numpy include dirs.

The wheels were built under /opt/python/cp311-cp311 and their generated *Export.cmake files
name that machine's include directories; CMake then refuses to configure any interface
package that links against them. Rewriting is idempotent: files already fixed are untouched.
"""
import pathlib
import sys
import sysconfig

import numpy

BUILD_PY_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
BUILD_NUMPY_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def main(prefix: str) -> int:
    replacements = {
        BUILD_NUMPY_INCLUDE: numpy.get_include(),
        BUILD_PY_INCLUDE: sysconfig.get_paths()["include"],
    }
    changed = 0
    for path in pathlib.Path(prefix, "share").glob("*/cmake/*.cmake"):
        text = path.read_text()
        if "/opt/python/cp311-cp311" not in text:
            continue
        for old, new in replacements.items():
            text = text.replace(old, new)
        path.write_text(text)
        changed += 1
    if changed:
        print(f"[setup] fixed include paths in {changed} CMake export files")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))

"""Every numba kernel is warmed by `make setup` (its module is listed in jit.KERNEL_MODULES)."""
import importlib
import pkgutil
from pathlib import Path

from tactile_sl_decoder import jit

PACKAGE = Path(jit.__file__).parent


def test_every_kernel_module_is_warmed_at_setup():
    for info in pkgutil.walk_packages([str(PACKAGE)], "tactile_sl_decoder."):
        if ".nodes" in info.name or ".cli" in info.name or info.name.endswith("__main__"):
            continue                      # rclpy and command-line shells: no kernels there
        importlib.import_module(info.name)
    defined = {k.py_func.__module__ for k in jit.compiled_kernels()}
    assert defined, "no kernel found"
    assert defined == set(jit.KERNEL_MODULES)
    for kernel in jit.compiled_kernels():   # compiled eagerly, without fastmath
        assert kernel.signatures and not kernel.targetoptions.get("fastmath")


def test_the_parallel_warm_up_groups_hold_every_kernel_module_once():
    grouped = [name for group in jit.WARM_GROUPS for name in group]
    assert sorted(grouped) == sorted(jit.KERNEL_MODULES)

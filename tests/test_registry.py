"""The one registry (backbones, heads, IIL algorithms, environments): duplicates raise, an unknown
name gets one line listing the valid ones, a catalogue restricts and orders the names."""

import subprocess
import sys

import pytest

from crossing_assist.registry import Registry


class KindError(ValueError):
    pass


def test_register_get_names_and_errors():
    reg: Registry[int] = Registry("widget", error=KindError)
    reg.register("b", 2)

    @reg.register("a")
    def a():
        return 1

    assert reg.get("b") == 2 and reg.get("a") is a and reg.names() == ("b", "a") and "a" in reg and len(reg) == 2
    with pytest.raises(KindError, match=r"^Widget 'a' is already registered$"):
        reg.register("a", 3)
    with pytest.raises(KindError, match=r"^Unknown widget: 'c'; valid: b, a$"):
        reg.get("c")
    with pytest.raises(KindError, match="Unknown widget"):
        reg.get(["unhashable"])


def test_a_catalogue_restricts_and_orders_the_names():
    reg = Registry("algorithm", catalogue=("x", "y", "z"), catalogue_name="CATALOGUE")
    reg.register("z", 26)
    reg.register("x", 24)
    assert reg.names() == ("x", "z") and list(reg) == ["x", "z"]
    with pytest.raises(ValueError, match="list it in CATALOGUE first"):
        reg.register("w", 0)


def test_the_registry_and_the_environment_list_import_no_torch():
    code = ("import sys, crossing_assist.registry, crossing_assist.iil.envs as e; "
            "assert e.ENV_NAMES == ('toy', 'crossing', 'crossing-synthetic', 'duckietown'), e.ENV_NAMES; "
            "sys.exit(3 if 'torch' in sys.modules else 0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr

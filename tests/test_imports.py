"""The deployable parts of the package must never pull in torch."""

import subprocess
import sys

import pytest

TORCH_FREE = ["crossing_assist", "crossing_assist.actions"]


@pytest.mark.parametrize("module", TORCH_FREE)
def test_module_does_not_import_torch(module):
    code = f"import sys, {module}; sys.exit(3 if 'torch' in sys.modules else 0)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, f"{module} imported torch (rc={proc.returncode}): {proc.stderr}"

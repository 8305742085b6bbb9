"""scripts/compare_gates.py: two held-out gate choices side by side."""

import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import compare_gates as cgs  # noqa: E402

SCRIPT = Path(cgs.__file__)


def _view(scale: float, wrong: list[float]) -> dict:
    """A choose_gate.py view: scales 1, 2, 3 with beacon on 0.2, 0.5, 0.8 and these wrong rates."""
    curve = [{"scale": s, "beacon_on": on, "beacon_on_goal_in_view": on / 2, "confidently_wrong": w,
              "confidently_wrong_frames": round(w * 1000), "frames": 1000, "silence_no_crossing": 1.0}
             for s, on, w in zip((1.0, 2.0, 3.0), (0.2, 0.5, 0.8), wrong)]
    return {"scale": scale, "curve": curve}


def _gate(measure: str | None, land: float, port: float) -> dict:
    g = _view(land, [0.001, 0.004, 0.009]) | {"portrait": _view(port, [0.0, 0.003, 0.006]),
                                               "portrait_window": _view(1.0, [0.002, 0.007, 0.012])}
    return g | ({"measure": measure} if measure else {})


def test_rows_read_each_view_at_its_thresholds_choice_and_windows_at_the_portrait_one(tmp_path):
    a, b = tmp_path / "gate.json", tmp_path / "gate_far_mass.json"
    a.write_text(json.dumps(_gate(None, 2.0, 1.0)))
    b.write_text(json.dumps(_gate("far_mass", 3.0, 2.0)))
    r = subprocess.run([sys.executable, str(SCRIPT), a, b, "--out", tmp_path / "c.png"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "| landscape | entropy (gate.json) | 50.0 % (25.0 %) | 0.40 % (4 of 1000) | 100.00 % |" in r.stdout
    assert "| landscape | far_mass (gate_far_mass.json) | 80.0 % (40.0 %) | 0.90 % (9 of 1000) |" in r.stdout
    # a window's own "scale" (1) is ignored: it takes the portrait threshold (1 and 2)
    assert "| portrait_window | entropy (gate.json) | 20.0 % (10.0 %) | 0.20 % (2 of 1000) |" in r.stdout
    assert "| portrait_window | far_mass (gate_far_mass.json) | 50.0 % (25.0 %) | 0.70 % (7 of 1000) |" in r.stdout
    assert (tmp_path / "c.png").stat().st_size > 1000
    # --narrow: a window at its own choice (scale 1), as a bundle with a narrow camera's threshold gates it
    r = subprocess.run([sys.executable, str(SCRIPT), a, b, "--narrow"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "| portrait_window | far_mass (gate_far_mass.json) | 20.0 % (10.0 %) | 0.20 % (2 of 1000) |" in r.stdout
    assert "| portrait | far_mass (gate_far_mass.json) | 50.0 % (25.0 %) | 0.30 % (3 of 1000) |" in r.stdout


def test_a_file_that_is_no_gate_choice_is_one_line(tmp_path):
    (tmp_path / "x.json").write_text("{}")
    r = subprocess.run([sys.executable, str(SCRIPT), tmp_path / "x.json"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and "not a scripts/choose_gate.py result" in r.stderr
    r = subprocess.run([sys.executable, str(SCRIPT), tmp_path / "missing.json"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and r.stderr.startswith("error:")

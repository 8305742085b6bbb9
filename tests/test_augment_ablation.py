"""scripts/augment_ablation.py: a variant's CV is compared fold by fold with the full recipe's."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "augment_ablation.py"


def _cv(folder: Path, accs: dict[str, float], far_x: float = 0.035, epochs: int = 2) -> None:
    folder.mkdir(parents=True)
    folds = [{"source": s, "n": 100, "accuracy": a, "bin_mae": 1 - a, "far_x_error": far_x} for s, a in accs.items()]
    (folder / "cv.json").write_text(json.dumps({"cv": "source", "folds": folds, "config": {"epochs": epochs},
                                                "accuracy": {"mean": sum(accs.values()) / len(accs), "sd": 0.01},
                                                "bin_mae": {"mean": 0.4, "sd": 0.0},
                                                "far_x_error": {"mean": far_x, "sd": 0.0}}))


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=120)


def test_differences_are_paired_by_held_out_photographer(tmp_path):
    _cv(tmp_path / "base", {"ptl:a": 0.60, "ptl:b": 0.70, "ptl:c": 0.65})
    _cv(tmp_path / "abl" / "no_roll" / "cv", {"ptl:c": 0.62, "ptl:a": 0.58, "ptl:b": 0.71}, far_x=0.040)
    r = _run("--out", str(tmp_path / "abl"), "--baseline", str(tmp_path / "base"), "--variants", "no_roll,no_rain")
    assert r.returncode == 0, r.stderr
    got = json.loads((tmp_path / "abl" / "ablation.json").read_text())["variants"]["no_roll"]
    assert got["per_fold_delta_accuracy"] == pytest.approx({"ptl:a": -0.02, "ptl:b": 0.01, "ptl:c": -0.03})
    assert got["delta_accuracy"][0] == pytest.approx(-0.04 / 3)
    assert got["folds_better_accuracy"] == 1 and got["folds_better_far_x_error"] == 0
    assert got["delta_far_x_error"][0] == pytest.approx(0.005)
    assert "| camera roll (up to 15 deg) | 0.637 ± 0.067 | -0.013 ± 0.021 | 1/3 |" in r.stdout
    assert "not trained yet: no_rain" in r.stdout
    assert "Field conditions" not in r.stdout   # no robustness tables: no second table


def test_field_conditions_are_set_side_by_side_when_both_have_them(tmp_path):
    _cv(tmp_path / "base", {"ptl:a": 0.60, "ptl:b": 0.70})
    _cv(tmp_path / "abl" / "no_corruption" / "cv", {"ptl:a": 0.61, "ptl:b": 0.69})
    for folder, night in ((tmp_path / "base", 0.65), (tmp_path / "abl" / "no_corruption" / "cv", 0.58)):
        (folder / "robustness_mirror.json").write_text(json.dumps({"frames_per_fold": 60, "conditions": {
            "clean": {"accuracy": 0.67, "confidently_wrong": 0.03, "silence_no_crossing": 1.0},
            "night": {"accuracy": night, "confidently_wrong": 0.04, "silence_no_crossing": night + 0.3}}}))
    r = _run("--out", str(tmp_path / "abl"), "--baseline", str(tmp_path / "base"), "--variants", "no_corruption")
    assert r.returncode == 0, r.stderr
    assert "| night | 0.650 | 0.580 | -7.0 | 4.00 % | 4.00 % | 95.0 % | 88.0 % |" in r.stdout
    assert "| clean | 0.670 | 0.670 | +0.0 |" in (tmp_path / "abl" / "ablation.md").read_text()
    assert (tmp_path / "abl" / "ablation.png").stat().st_size > 0


@pytest.mark.parametrize("args, message", [
    (["--variants", "no_sky"], "unknown variant no_sky"),
    ([], "no variant trained yet"),
])
def test_bad_input_is_one_line_and_non_zero(tmp_path, args, message):
    _cv(tmp_path / "base", {"ptl:a": 0.6, "ptl:b": 0.7})
    r = _run("--out", str(tmp_path / "abl"), "--baseline", str(tmp_path / "base"), *args)
    assert r.returncode == 2 and message in r.stderr

"""crossing-train --cv source: one fold per train source, cv.json with per-fold figures and
mean +- sd; a rerun reads finished folds back instead of retraining them."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from test_models_train import make_tiny_dataset

from crossing_assist.models.config import ConfigError, TrainConfig
from crossing_assist.models.crossval import cross_validate

TRAIN = [sys.executable, "-c", "import sys; from crossing_assist.models.cli import train_main as m; sys.exit(m(sys.argv[1:]))"]


def _args(data, out):
    return [*TRAIN, "--data", str(data), "--out", str(out), "--cv", "source", "--backbone", "mobilenet_v3_small",
            "--weights", "none", "--epochs", "1", "--batch-size", "4", "--input-size", "48x64",
            "--cache-dir", str(out.parent / "cache"), "--threads", "1", "--quiet", "--no-mirror"]


def test_cv_source_writes_folds_and_mean_sd_and_keeps_finished_folds(tmp_path, capsys):
    data = make_tiny_dataset(tmp_path / "data", n_train=9, n_val=3, size=48)   # sources src:0..2
    out = tmp_path / "cv"
    r = subprocess.run(_args(data, out), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "cv.json").read_text())
    assert summary["cv"] == "source"
    folds = summary["folds"]
    assert sorted(f["source"] for f in folds) == ["src:0", "src:1", "src:2"]
    assert all(f["n"] == 3 and 0.0 <= f["accuracy"] <= 1.0 for f in folds)    # each held-out source's frames
    accs = [f["accuracy"] for f in folds]
    assert summary["accuracy"]["mean"] == pytest.approx(sum(accs) / 3)
    assert summary["accuracy"]["sd"] == pytest.approx(float(np.std(accs, ddof=1)))
    maes = [f["bin_mae"] for f in folds if f["bin_mae"] is not None and not math.isnan(f["bin_mae"])]
    assert summary["bin_mae"]["mean"] == (pytest.approx(float(np.mean(maes))) if maes else None)  # NaN folds left out
    assert (out / "cv.csv").read_text().count("\n") == 4
    assert "leave-one-source-out over 3 folds" in r.stdout
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("fold-*/weights/last.pt")}
    assert len(stamps) == 3

    # rerun (in-process, same config): nothing retrained, same figures
    cfg = TrainConfig(data=str(data), out=str(out), backbone="mobilenet_v3_small", weights="none", epochs=1,
                      batch_size=4, input_size=(48, 64), mirror=False, cache_dir=str(tmp_path / "cache"),
                      threads=1, progress=False)
    again = cross_validate(cfg)
    assert "holding out" not in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in out.glob("fold-*/weights/last.pt")} == stamps
    assert json.dumps(again["folds"]) == json.dumps(folds)

    # a fold that did not finish is trained again, only it
    victim = sorted(stamps)[1]
    victim.unlink()
    (victim.parent / "best.pt").unlink(missing_ok=True)
    cross_validate(cfg)
    assert capsys.readouterr().out.count("holding out") == 1 and victim.is_file()
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items() if p != victim)


def test_cv_refuses_one_source_and_holdout(tmp_path):
    data = make_tiny_dataset(tmp_path / "data", n_train=3, n_val=1, size=32)
    base = dict(data=str(data), out=str(tmp_path / "cv"), backbone="mobilenet_v3_small", weights="none",
                epochs=1, input_size=(32, 32), progress=False, cache_dir=str(tmp_path / "cache"))
    with pytest.raises(ConfigError, match="holdout"):
        cross_validate(TrainConfig(**base, holdout=("src:0",), select_on="holdout"))
    one = make_tiny_dataset(tmp_path / "one", n_train=1, n_val=1, size=32)
    with pytest.raises(ConfigError, match="need >= 2"):
        cross_validate(TrainConfig(**{**base, "data": str(one)}))


def test_format_cv_survives_undefined_figures():
    from crossing_assist.models.crossval import format_cv

    nan = float("nan")
    summary = {"folds": [{"source": "a", "n": 3, "accuracy": 0.5, "bin_mae": nan, "far_x_error": None,
                          "majority_accuracy": 0.0}],
               "accuracy": {"mean": 0.5, "sd": None}, "bin_mae": {"mean": None, "sd": None},
               "far_x_error": {"mean": 0.0, "sd": None}}
    text = format_cv(summary)
    assert "accuracy 0.500" in text and "bin MAE n/a" in text and "far-x error 0.0000" in text


def test_cv_jobs_trains_folds_side_by_side_with_the_serial_runs_figures(tmp_path):
    """--cv-jobs 2: the three folds in two worker processes give the figures the one-process CV
    gives (same seeded folds, same cache); bad values fail in one line."""
    data = make_tiny_dataset(tmp_path / "data", n_train=9, n_val=3, size=48)
    serial = subprocess.run(_args(data, tmp_path / "serial"), capture_output=True, text=True)
    assert serial.returncode == 0, serial.stderr
    r = subprocess.run([*_args(data, tmp_path / "side"), "--cv-jobs", "2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("holding out") == 6 and r.stdout.count(": done") == 3   # submitted, then finished
    one = json.loads((tmp_path / "serial" / "cv.json").read_text())
    two = json.loads((tmp_path / "side" / "cv.json").read_text())
    assert [f["source"] for f in two["folds"]] == [f["source"] for f in one["folds"]]
    for a, b in zip(one["folds"], two["folds"]):
        for k, v in a.items():
            assert b[k] == (v if v is None or isinstance(v, str) else pytest.approx(v, rel=1e-6, abs=1e-9)), (k, a, b)
    assert len(list((tmp_path / "side").glob("fold-*/weights/last.pt"))) == 3
    no_cv = [a for a in _args(data, tmp_path / "y") if a not in ("--cv", "source")]
    for args, says in (([*_args(data, tmp_path / "x"), "--cv-jobs", "0"], "--cv-jobs 0"),
                       ([*no_cv, "--cv-jobs", "2"], "without --cv")):
        r = subprocess.run(args, capture_output=True, text=True)
        assert r.returncode != 0 and r.stderr.startswith("error:") and says in r.stderr and "Traceback" not in r.stderr

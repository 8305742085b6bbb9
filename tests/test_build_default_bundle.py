"""scripts/build_default_bundle.sh end to end on a tiny run: the held-out gate choice it reads
(with VIEW_ZOOM, choose_gate.py --zoom's file), the schema-4 view zoom it exports, the far-mass gate
chosen held out stamped over the fitted one, and one error line without a run."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from crossing_assist.bundle import read_bundle
from crossing_assist.models.config import TrainConfig
from crossing_assist.models.train import train
from test_models_train import make_tiny_dataset
from test_stamp_bundle import _far_mass_gate, _gate   # choose_gate.py results at one scale / far-mass threshold

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "build_default_bundle.sh"


def _build(tmp_path: Path, **env) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT)], capture_output=True, text=True,
                          env={**os.environ, "PY": sys.executable, "TMPDIR": str(tmp_path), "MIN_CALIB": "2", **env})


def _tiny_run(tmp_path: Path) -> tuple[Path, Path, Path]:
    """A tiny dataset, a one-epoch letterbox run on it and an empty CV folder."""
    data = make_tiny_dataset(tmp_path / "data", n_train=8, n_val=8)
    run = train(TrainConfig(data=str(data), out=str(tmp_path / "run"), backbone="mobilenet_v3_small", weights="none",
                            head="spatial", epochs=1, batch_size=4, input_size=(48, 64), fit="letterbox",
                            cache_dir=str(tmp_path / "cache"), progress=False))
    cv = tmp_path / "cv"
    cv.mkdir()
    return data, run, cv


def test_build_default_bundle_without_a_run_says_so_in_one_line(tmp_path):
    r = _build(tmp_path, RUN=str(tmp_path / "nope"), OUT=str(tmp_path / "out"))
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0
    assert r.stderr.startswith("error:") and "build_default_model.sh" in r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_build_default_bundle_exports_the_zoomed_view_with_the_held_out_gate(tmp_path):
    data, run, cv = _tiny_run(tmp_path)
    (cv / "cv.json").write_text(json.dumps({"config": {"epochs": 1}, "folds": [], "accuracy": {"mean": 0.6, "sd": 0.01},
                                            "bin_mae": {"mean": 0.4, "sd": 0.02},
                                            "far_x_error": {"mean": 0.03, "sd": 0.001}, "majority_accuracy": 0.3}))
    # the un-zoomed choice must not be the one taken
    (cv / "gate_mirror.json").write_text(json.dumps(_gate(2.0) | {"portrait": _gate(2.0)}))
    (cv / "gate_mirror_zoom1.3.json").write_text(json.dumps(_gate(0.5) | {"portrait": _gate(0.75)}))
    (cv / "gate_mirror_zoom1.3_far_mass.json").write_text(json.dumps(_far_mass_gate(0.007) | {
        "portrait": _far_mass_gate(0.015), "portrait_window": _far_mass_gate(0.038)}))
    out = tmp_path / "bundle"
    r = _build(tmp_path, RUN=str(run), DATA=str(data), OUT=str(out), CV_DIR=str(cv), VIEW_ZOOM="1.3", SAMPLES="4")
    assert r.returncode == 0, r.stderr
    assert "gate threshold scale: landscape 0.5, portrait 0.75" in r.stderr
    b = read_bundle(out)
    assert b.schema_version == 4 and b.geometry.view_crop and b.geometry.view_zoom == pytest.approx(1.3)
    unc = b.calibration.uncertainty   # the far-mass gate chosen held out replaces the fitted entropy gate
    assert "gate measure: far_mass" in r.stderr
    assert (unc.measure, unc.threshold, unc.portrait_threshold, unc.fitted_threshold) == ("far_mass", 0.007, 0.015, None)
    assert (unc.narrow_threshold, unc.narrow_fov_deg) == (0.038, 42.0)   # the windows' choice, NARROW_FOV's default
    assert unc.wide_fov_deg == 60.0 and unc.threshold_for("landscape", 52.8) == 0.015   # WIDE_FOV's default
    assert b.metrics["gate_held_out"]["threshold"] == 0.007 and b.metrics["gate_held_out"]["portrait"]["threshold"] == 0.015
    assert b.metrics["leave_one_photographer_out"]["accuracy"]["mean"] == 0.6
    q = b.metrics.get("int8_vs_fp32")   # int8 kept only within 1 point of fp32 and not slower, else fp32
    if q is None:
        assert "shipping fp32" in r.stderr
    else:
        assert q["accuracy_fp32"] - q["accuracy_int8"] <= 0.01 and q["ms_int8"] <= 1.10 * q["ms_fp32"]
    assert not list(tmp_path.glob("default_bundle.*"))   # its scratch folder is removed


@pytest.mark.slow
def test_build_default_bundle_with_members_ships_their_ensemble_at_its_held_out_gate(tmp_path):
    """MEMBERS: each run exported as RUN is, a folder holding a bundle taken as it is, the bundle
    their ensemble (mc.members), stamped with the thresholds choose_gate.py --ensemble chose
    (gate…_ensembleK.json), not the one model's."""
    data, run, cv = _tiny_run(tmp_path)
    fm = _far_mass_gate
    (cv / "gate_mirror_far_mass.json").write_text(json.dumps(fm(0.007) | {"portrait": fm(0.015)}))
    (cv / "gate_mirror_far_mass_ensemble3.json").write_text(json.dumps(fm(0.02) | {"portrait": fm(0.03)}))
    env = dict(RUN=str(run), DATA=str(data), CV_DIR=str(cv), SAMPLES="2", MAX_INT8_DROP="1", MAX_INT8_SLOWDOWN="100")
    one = tmp_path / "one"
    assert _build(tmp_path, OUT=str(one), **env).returncode == 0
    r = _build(tmp_path, OUT=str(tmp_path / "ens"), MEMBERS=f"{run} {one}", **env)
    assert r.returncode == 0, r.stderr
    assert "an ensemble of 3: gate thresholds from" in r.stderr
    b = read_bundle(tmp_path / "ens")
    assert b.mc.members == 3 and b.precision == read_bundle(one).precision
    assert len(b.training["ensemble"]) == 3 and b.training["ensemble"][2]["bundle"] == str(one)
    unc = b.calibration.uncertainty
    assert (unc.measure, unc.threshold, unc.portrait_threshold) == ("far_mass", 0.02, 0.03)
    assert b.metrics["gate_held_out"]["threshold"] == 0.02
    # GATE_TOP=16: the choice of the sweep carried on to x16, the narrow camera's threshold with it
    (cv / "gate_mirror_far_mass_top16_ensemble3.json").write_text(json.dumps(
        fm(0.02) | {"portrait": fm(0.03), "portrait_window": fm(0.0617)}))
    r = _build(tmp_path, OUT=str(tmp_path / "top"), MEMBERS=f"{run} {one}", GATE_TOP="16", WIDE_FOV="", **env)
    assert r.returncode == 0, r.stderr
    assert "gate_mirror_far_mass_top16_ensemble3.json" in r.stderr
    unc = read_bundle(tmp_path / "top").calibration.uncertainty
    assert (unc.threshold, unc.portrait_threshold, unc.narrow_threshold, unc.narrow_fov_deg) == (0.02, 0.03, 0.0617, 42.0)
    assert unc.wide_fov_deg is None and unc.threshold_for("landscape", 52.8) == 0.02   # WIDE_FOV=: by orientation
    # a seed added to a shipped ensemble: the ensemble bundle counts as its 3 members, the choice for 4 is taken
    (cv / "gate_mirror_far_mass_ensemble4.json").write_text(json.dumps(fm(0.025) | {"portrait": fm(0.035)}))
    r = _build(tmp_path, OUT=str(tmp_path / "four"), MEMBERS=str(tmp_path / "ens"), **env)
    assert r.returncode == 0, r.stderr
    assert "an ensemble of 4: gate thresholds from" in r.stderr
    four = read_bundle(tmp_path / "four")
    assert four.mc.members == 4 and len(four.training["ensemble"]) == 4
    assert (four.calibration.uncertainty.threshold, four.calibration.uncertainty.portrait_threshold) == (0.025, 0.035)

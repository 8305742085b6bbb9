"""scripts/stamp_bundle.py: held-out figures, held-out gate scales on the fitted threshold and the
schema-3 view crop stamped into a bundle without re-exporting it; the graph's embedded copy follows."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from runtime_toy import make_toy_bundle

from crossing_assist.bundle import read_bundle
from crossing_assist.geometry import Geometry

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "stamp_bundle.py"


def _stamp(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True)


def _gate(scale: float) -> dict:
    point = {"scale": scale, "beacon_on": 0.5, "confidently_wrong": 0.0, "silence_no_crossing": 1.0, "per_fold": {}}
    return {"scale": scale, "targets_met": True, "folds": [], "accuracy": 0.6, "bin_mae": 0.5,
            "at_scale": point, "at_fitted_threshold": point}


def _far_mass_gate(threshold: float) -> dict:
    """A choose_gate.py --measure far_mass result at one absolute threshold (0.01 x its scale)."""
    return _gate(threshold / 0.01) | {"measure": "far_mass", "threshold": threshold}


@pytest.fixture
def shipped(tmp_path):
    """A letterboxed schema-2-style bundle (no view crop) whose landscape threshold 0.5 is its
    fitted threshold 1.0 times a recorded held-out scale of 0.5, and a CV folder."""
    src = make_toy_bundle(tmp_path / "src", geometry=Geometry(fit="letterbox"), threshold=0.5)
    meta = json.loads((src / "bundle.json").read_text())
    meta["metrics"]["gate_held_out"] = {"scale": 0.5}
    (src / "bundle.json").write_text(json.dumps(meta))
    cv = tmp_path / "cv"
    cv.mkdir()
    pooled = {"pooled_runs": [str(cv), str(tmp_path / "cv_seed1")]}   # choose_gate.py --also
    (cv / "gate.json").write_text(json.dumps(_gate(0.25) | pooled | {"portrait": _gate(1.5) | pooled,
                                                                     "portrait_window": _gate(2.0) | pooled}))
    (cv / "cv.json").write_text(json.dumps({"config": {"epochs": 2}, "folds": [], "accuracy": {"mean": 0.6, "sd": 0.01},
                                            "bin_mae": {"mean": 0.4, "sd": 0.02}, "far_x_error": {"mean": 0.03, "sd": 0.001},
                                            "majority_accuracy": 0.3}))
    (cv / "cv_bundles.json").write_text(json.dumps({"folds": {}, "accuracy": {"mean": 0.62, "sd": 0.02}}))
    return src, cv


def test_stamp_rescales_the_gate_and_turns_the_view_crop_on(shipped, tmp_path):
    from crossing_assist.runtime.engine import Engine

    src, cv = shipped
    assert not read_bundle(src).geometry.view_crop
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--rescale-gate", "--view-crop")
    assert r.returncode == 0, r.stderr
    b = read_bundle(tmp_path / "out")
    assert b.schema_version == 3 and b.geometry.view_crop
    unc = b.calibration.uncertainty
    assert unc.threshold == pytest.approx(0.25) and unc.portrait_threshold == pytest.approx(1.5)   # fitted 1.0 x scales
    assert unc.fitted_threshold == pytest.approx(1.0)                    # recorded for the next re-scale
    assert b.metrics["leave_one_photographer_out"]["accuracy"]["mean"] == 0.6
    assert b.metrics["leave_one_photographer_out_bundle"]["accuracy"]["mean"] == 0.62   # scripts/cv_bundles.py
    assert set(b.metrics["gate_held_out"]) >= {"scale", "accuracy", "portrait", "portrait_window"}
    assert b.metrics["gate_held_out"]["portrait"]["pooled_runs"] == [str(cv), str(tmp_path / "cv_seed1")]
    assert len(b.provenance["stamped"]) == 1 and len(b.provenance["stamped"][0]["what"]) == 3
    assert b.provenance["stamped"][0]["what"][0] == f"held-out figures from {cv} (cv.json, cv_bundles.json, gate.json)"
    Engine(tmp_path / "out")          # the graph's embedded copy matches the new bundle.json
    r = _stamp(tmp_path / "out", tmp_path / "again", "--cv", cv, "--sensor-aspect", "4:3")
    assert r.returncode == 0, r.stderr
    history = read_bundle(tmp_path / "again").provenance["stamped"]
    assert [len(h["what"]) for h in history] == [3, 2] and "view_crop" in history[0]["what"][2]
    # a stamp of the figures alone is recorded too
    r = _stamp(tmp_path / "again", tmp_path / "figures", "--cv", cv)
    assert r.returncode == 0, r.stderr
    last = read_bundle(tmp_path / "figures").provenance["stamped"][-1]
    assert len(read_bundle(tmp_path / "figures").provenance["stamped"]) == 3 and last["what"] == [
        f"held-out figures from {cv} (cv.json, cv_bundles.json, gate.json)"]


def test_rescale_starts_from_the_recorded_fitted_threshold_not_a_stale_scale(shipped, tmp_path):
    """A bundle exported at the fitted threshold whose metrics already name a newer held-out scale (the
    gate choice rewritten while the export ran) must not have that scale undone from its threshold."""
    src, cv = shipped
    meta = json.loads((src / "bundle.json").read_text())
    meta["calibration"]["uncertainty"]["fitted_threshold"] = 0.5     # threshold 0.5 = fitted x 1, metrics say 0.5
    (src / "bundle.json").write_text(json.dumps(meta))
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--rescale-gate")
    assert r.returncode == 0, r.stderr
    unc = read_bundle(tmp_path / "out").calibration.uncertainty
    assert unc.fitted_threshold == pytest.approx(0.5)
    assert unc.threshold == pytest.approx(0.125) and unc.portrait_threshold == pytest.approx(0.75)


def test_stamp_refuses_what_it_cannot_do(shipped, tmp_path):
    src, cv = shipped
    r = _stamp(src, tmp_path / "a", "--cv", tmp_path, "--rescale-gate")          # no gate.json there
    assert r.returncode == 2 and "choose_gate" in r.stderr
    stretch = make_toy_bundle(tmp_path / "s", geometry=Geometry(fit="stretch"))
    r = _stamp(stretch, tmp_path / "b", "--cv", cv, "--view-crop")
    assert r.returncode == 2 and "not letterboxed" in r.stderr
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_stamp_on_a_folder_that_is_no_bundle_is_one_line(tmp_path):
    r = _stamp(tmp_path, tmp_path / "out", "--cv", tmp_path)
    assert r.returncode == 2 and r.stderr.startswith("error:") and len(r.stderr.strip().splitlines()) == 1


def test_stamp_sets_the_sensor_aspect_in_the_json_and_the_graph(shipped, tmp_path):
    """--sensor-aspect gives an existing bundle geometry.sensor_aspect (its schema kept): 9:16
    frames then get their crop's default FOV; the embedded copy agrees (the engine opens it)."""
    from crossing_assist.runtime.engine import Engine

    src, cv = shipped
    assert read_bundle(src).geometry.sensor_aspect is None and read_bundle(src).camera_fov(1080, 1920) == 53.0
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--sensor-aspect", "4:3")
    assert r.returncode == 0, r.stderr
    b = read_bundle(tmp_path / "out")
    assert b.geometry.sensor_aspect == 4 / 3 and b.schema_version == read_bundle(src).schema_version
    assert b.camera_fov(1080, 1920) == pytest.approx(41.005, abs=1e-3) and b.camera_fov(480, 640) == 53.0
    assert any("sensor_aspect" in s for s in b.provenance["stamped"][-1]["what"])
    engine = Engine(tmp_path / "out")        # check_session: bundle.json and the graph's copy agree
    assert engine.camera_fov(1080, 1920) == b.camera_fov(1080, 1920)
    r = _stamp(src, tmp_path / "num", "--cv", cv, "--sensor-aspect", repr(16 / 9))    # a number works too
    assert r.returncode == 0 and read_bundle(tmp_path / "num").geometry.sensor_aspect == 16 / 9, r.stderr


@pytest.mark.parametrize("bad", ["0.5", "3:4", "3.5", "wide", "nan", "4:0"])
def test_stamp_refuses_a_bad_sensor_aspect_in_one_line(shipped, tmp_path, bad):
    src, cv = shipped
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--sensor-aspect", bad)
    assert r.returncode == 2 and r.stderr.startswith("error: --sensor-aspect") and "1..3" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_stamp_sets_the_far_mass_gate_chosen_held_out(shipped, tmp_path):
    """A gate file of ``choose_gate.py --measure far_mass`` (absolute thresholds) makes the bundle
    gate with far mass at those thresholds, in bundle.json and the graph's copy alike, and the
    runtime follows; an entropy gate file of scales is then refused for it in one line."""
    from crossing_assist.runtime.engine import Engine

    src, cv = shipped
    fm = _far_mass_gate
    (cv / "gate_far_mass.json").write_text(json.dumps(fm(0.007) | {"portrait": fm(0.015), "portrait_window": fm(0.015)}))
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--rescale-gate", "--gate-json", "gate_far_mass.json")
    assert r.returncode == 0, r.stderr
    assert "gate measure far_mass, held-out thresholds 0.007 (landscape), 0.015 (portrait)" in r.stdout
    b = read_bundle(tmp_path / "out")
    unc = b.calibration.uncertainty
    assert (unc.measure, unc.threshold, unc.portrait_threshold, unc.fitted_threshold) == ("far_mass", 0.007, 0.015, None)
    assert b.metrics["gate_held_out"]["threshold"] == 0.007 and b.metrics["gate_held_out"]["measure"] == "far_mass"
    cfg = Engine(tmp_path / "out").decision_config("portrait")   # check_session: the graph's copy agrees
    assert (cfg.measure, cfg.threshold, cfg.learner_threshold) == ("far_mass", 0.015, 0.015)
    r = _stamp(tmp_path / "out", tmp_path / "again", "--cv", cv, "--rescale-gate")
    assert r.returncode == 2 and "gates with far_mass" in r.stderr.strip() and len(r.stderr.strip().splitlines()) == 1


def test_narrow_fov_stamps_the_windows_threshold_for_narrow_portrait_frames(shipped, tmp_path):
    """``--narrow-fov DEG``: the threshold chosen on the 3:4 windows becomes the narrow camera's
    (absolute for far mass, fitted x scale for the bundle's own measure); the runtime gives it to
    portrait frames at most DEG across (9:16 video, ~41 deg) and the portrait threshold to a
    3:4 frame (53 deg). A re-scale without it drops the narrow threshold; a window choice that
    missed the targets, or the option without --rescale-gate, is refused in one line."""
    from crossing_assist.runtime.engine import Engine

    src, cv = shipped
    fm = _far_mass_gate
    scan = {"scale": 3.8, "threshold": 0.038, "capped_from": {"scale": 5.0, "threshold": 0.05}}   # scan_gate.py --cap
    (cv / "gate_far_mass.json").write_text(json.dumps(fm(0.007) | {"portrait": fm(0.015),
                                                                   "portrait_window": fm(0.038) | {"scan": scan}}))
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--rescale-gate", "--gate-json", "gate_far_mass.json",
               "--narrow-fov", 45, "--sensor-aspect", "4:3")
    assert r.returncode == 0, r.stderr
    assert "0.038 (portrait frames at most 45 deg)" in r.stdout
    unc = read_bundle(tmp_path / "out").calibration.uncertainty
    assert (unc.narrow_threshold, unc.narrow_fov_deg) == (0.038, 45.0)
    # the scans' check (and the still choice it capped) is kept beside the window's figures
    assert read_bundle(tmp_path / "out").metrics["gate_held_out"]["portrait_window"]["scan"] == scan
    eng = Engine(tmp_path / "out")
    assert [eng.decision_config("portrait", eng.camera_fov(w, h)).threshold for w, h in ((720, 1280), (480, 640))] == [0.038, 0.015]
    r = _stamp(src, tmp_path / "scaled", "--cv", cv, "--rescale-gate", "--narrow-fov", 44)
    assert r.returncode == 0, r.stderr     # the bundle's own measure: fitted 1.0 x the window's scale 2.0
    meta = json.loads((tmp_path / "scaled" / "bundle.json").read_text())
    assert meta["calibration"]["uncertainty"]["narrow_threshold"] == pytest.approx(2.0)
    r = _stamp(tmp_path / "scaled", tmp_path / "plain", "--cv", cv, "--rescale-gate")
    assert r.returncode == 0, r.stderr
    assert read_bundle(tmp_path / "plain").calibration.uncertainty.narrow_threshold is None
    (cv / "gate.json").write_text(json.dumps(_gate(0.25) | {"portrait_window": _gate(2.0) | {"targets_met": False}}))
    r = _stamp(src, tmp_path / "bad", "--cv", cv, "--rescale-gate", "--narrow-fov", 45)
    assert r.returncode == 2 and "no 3:4-window choice that meets the targets" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = _stamp(src, tmp_path / "bad", "--cv", cv, "--narrow-fov", 45)
    assert r.returncode == 2 and "--narrow-fov needs --rescale-gate" in r.stderr
    assert not (tmp_path / "bad").exists()


def test_wide_fov_stamps_the_width_rule_and_a_square_frame_takes_the_portrait_threshold(shipped, tmp_path):
    """``--wide-fov DEG`` (alone or beside a re-scale): ``wide_fov_deg`` in bundle.json and the
    graph's copy; a square frame (~53 deg with the 4:3 sensor) then takes the portrait threshold
    and a 3:4 frame the user set to 65 deg the landscape one. Not above the narrow FOV, or out of
    20..170: one line, nothing written."""
    from crossing_assist.runtime.engine import Engine

    src, cv = shipped
    fm = _far_mass_gate
    (cv / "gate_far_mass.json").write_text(json.dumps(fm(0.007) | {"portrait": fm(0.015), "portrait_window": fm(0.038)}))
    r = _stamp(src, tmp_path / "out", "--cv", cv, "--rescale-gate", "--gate-json", "gate_far_mass.json",
               "--narrow-fov", 42, "--wide-fov", 60, "--sensor-aspect", "4:3")
    assert r.returncode == 0, r.stderr
    assert "frames under 60 deg take the portrait one" in r.stdout
    eng = Engine(tmp_path / "out")   # check_session: the graph's copy agrees
    assert eng.bundle.calibration.uncertainty.wide_fov_deg == 60.0
    square, portrait = eng.camera_fov(480, 480), eng.camera_fov(480, 640, 65.0)
    assert eng.decision_config("landscape", square).threshold == 0.015
    assert eng.decision_config("portrait", portrait).threshold == 0.007
    r = _stamp(tmp_path / "out", tmp_path / "again", "--wide-fov", 55)   # alone: the rest is kept
    assert r.returncode == 0, r.stderr
    unc = read_bundle(tmp_path / "again").calibration.uncertainty
    assert (unc.wide_fov_deg, unc.narrow_threshold, unc.portrait_threshold) == (55.0, 0.038, 0.015)
    r = _stamp(tmp_path / "again", tmp_path / "plain", "--cv", cv, "--rescale-gate", "--gate-json", "gate_far_mass.json")
    assert r.returncode == 0, r.stderr   # a re-chosen gate keeps no rule it was not given
    assert read_bundle(tmp_path / "plain").calibration.uncertainty.wide_fov_deg is None
    for flag, said in ((["--wide-fov", 40], "--wide-fov 40: must exceed the bundle's narrow_fov_deg 42"),
                       (["--wide-fov", 200], "--wide-fov 200: valid 20..170 degrees")):
        r = _stamp(tmp_path / "out", tmp_path / "bad", *flag)
        assert r.returncode == 2 and said in r.stderr.strip().splitlines()[-1], r.stderr   # argparse's usage above
        assert not (tmp_path / "bad").exists()


def test_gate_from_judges_a_bundle_at_another_bundles_gate(shipped, tmp_path):
    """``--gate-from REF`` (no CV needed) gives SRC REF's gate, measure and thresholds, in bundle.json
    and the graph's copy alike, and leaves SRC's figures alone; a REF that fits frames otherwise, or
    --rescale-gate beside it, or nothing to stamp at all, is refused in one line and writes nothing."""
    from crossing_assist.runtime.engine import Engine

    src, cv = shipped
    fm = _far_mass_gate
    (cv / "gate_far_mass.json").write_text(json.dumps(fm(0.007) | {"portrait": fm(0.015)}))
    assert _stamp(src, tmp_path / "ref", "--cv", cv, "--rescale-gate", "--gate-json", "gate_far_mass.json").returncode == 0
    r = _stamp(src, tmp_path / "out", "--gate-from", tmp_path / "ref")
    assert r.returncode == 0, r.stderr
    assert f"gate of {tmp_path / 'ref'} (far_mass, threshold 0.007)" in r.stdout
    b = read_bundle(tmp_path / "out")
    assert b.calibration.uncertainty == read_bundle(tmp_path / "ref").calibration.uncertainty
    assert b.metrics == read_bundle(src).metrics        # no held-out figures without --cv
    cfg = Engine(tmp_path / "out").decision_config("portrait")
    assert (cfg.measure, cfg.threshold) == ("far_mass", 0.015)
    stretch = make_toy_bundle(tmp_path / "s", geometry=Geometry(fit="stretch"))
    for args, says in (((stretch, tmp_path / "a", "--gate-from", tmp_path / "ref"), "geometry differs"),
                       ((src, tmp_path / "a", "--gate-from", tmp_path / "ref", "--cv", cv, "--rescale-gate"),
                        "one gate at a time"),
                       ((src, tmp_path / "a", "--rescale-gate"), "needs --cv"),
                       ((src, tmp_path / "a"), "nothing to stamp")):
        r = _stamp(*args)
        last = r.stderr.strip().splitlines()[-1]   # argparse's usage lines come before its error line
        assert r.returncode == 2 and last.count("error:") == 1 and says in last, r.stderr
    assert not (tmp_path / "a").exists()


def test_share_alike_rewrites_an_ensemble_merged_side_by_side_to_run_its_shared_nodes_once(tmp_path):
    """A bundle merged before its members' shared nodes ran once (as the default until 2026-12-07):
    --share-alike rewrites its graph, and nothing else changes, the outputs least of all."""
    import onnx

    from crossing_assist.bundle import write_bundle
    from crossing_assist.export.ensemble import merge_graphs
    from crossing_assist.export.graph import model_bytes, set_metadata
    from runtime_toy import bar_frame, graph_outputs, seeded

    members = [make_toy_bundle(tmp_path / n, gain=g, drop_p=0.3, samples=4) for n, g in (("a", 12.0), ("b", 3.0))]
    meta = json.loads((members[0] / "bundle.json").read_text())
    meta["mc"]["members"] = 2
    apart = merge_graphs([onnx.load(str(m / "model.onnx")) for m in members], share=False)
    set_metadata(apart, meta)
    src = write_bundle(tmp_path / "src", model_bytes(apart), meta)
    r = _stamp(src, tmp_path / "out", "--share-alike")
    assert r.returncode == 0, r.stderr
    assert "nodes computed alike run once" in r.stdout
    out = read_bundle(tmp_path / "out")
    shared = onnx.load(str(out.model_path))
    assert len(shared.graph.node) < len(apart.graph.node) and out.model_size < read_bundle(src).model_size
    frames = [bar_frame(x) for x in (0.2, 0.7)]
    for got, want in zip(graph_outputs(seeded(shared), frames), graph_outputs(seeded(apart), frames)):
        np.testing.assert_array_equal(got, want)
    stamped = json.loads((tmp_path / "out" / "bundle.json").read_text())
    assert "--share-alike" in stamped["provenance"].pop("stamped")[-1]["by"]
    for m in (stamped, meta):
        for k in ("model_sha256", "model_size"):
            m.pop(k, None)
    assert stamped == meta

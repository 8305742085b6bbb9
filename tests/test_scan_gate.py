"""scripts/scan_gate.py: the gate checked on held-out photographers' scans, and capped by them."""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import scan_gate as sg  # noqa: E402


@pytest.fixture()
def two_runs(tmp_path, monkeypatch):
    """Two CV runs, each with a finished fold for photographers src:0 and src:1 whose bundle is the
    toy bundle, and the photographers' unseen bar photos: ``(runs, ptl, neg)``."""
    from runtime_toy import TOY2, bar_dataset, make_toy_bundle

    ptl = bar_dataset(tmp_path / "ptl", 8, split="train")
    neg = bar_dataset(tmp_path / "neg", 4, unknown=True, split="train")
    bundle = make_toy_bundle(tmp_path / "bundle", TOY2)
    runs = [tmp_path / "a" / "cv", tmp_path / "b" / "cv"]
    for cv in runs:
        for s in ("src_0", "src_1"):
            (cv / f"fold-{s}").mkdir(parents=True)
    monkeypatch.setattr(sg, "finished_folds", lambda cv: [(cv / "fold-src_0", "src:0"), (cv / "fold-src_1", "src:1")])
    monkeypatch.setattr(sg, "fold_bundle", lambda *a, **k: bundle)
    return runs, ptl, neg


def _args(runs, ptl, neg, *more):
    return [str(runs[0]), "--also", str(runs[1]), "--ptl", str(ptl), "--neg", str(neg), "--used-neg", str(neg),
            "--frames", "3", "--amplitude", "30", "--grid", "2", "--min-scale", "0.25", "--max-scale", "4", *more]


def test_scans_of_each_photographer_are_played_once_averaged_over_runs_and_pooled(two_runs, monkeypatch, capsys):
    from crossing_assist.runtime.engine import Engine

    runs, ptl, neg = two_runs
    assert sg.main(_args(runs, ptl, neg)) == 0
    res = json.loads((runs[0] / "scan_gate_a30_r30.json").read_text())
    for cv in runs:   # each fold's held-out photos scanned and saved in the fold
        assert sorted(p.name for p in cv.glob("fold-*/scanned*.npz")) == ["scanned_3_0_a30_r30.npz"] * 2
    assert [f["source"] for f in res["folds"]] == ["src:0", "src:1"] and res["view"] == "landscape"
    assert [f["photos"] for f in res["folds"]] == [3, 3]
    frames = sum(f["frames"] for f in res["folds"])
    assert res["at_scale"]["frames"] == frames > 0
    assert [c["scale"] for c in res["curve"]] == [0.25, 2 ** -1.5, 0.5, 2 ** -0.5, 1, 2 ** 0.5, 2, 2 ** 1.5, 4]
    # the toy places bars: on and right at a loose gate, the curve climbs with the threshold
    assert res["curve"][-1]["beacon_on"] > 0.8 and res["curve"][-1]["confidently_wrong"] < 0.01
    assert res["curve"][0]["beacon_on"] <= res["curve"][-1]["beacon_on"]
    assert res["targets_met"] and res["scale"] == max(res["curve"], key=lambda c: c["beacon_on"])["scale"]
    assert {r["photographer"] for r in res["leave_one_photographer_out"]["per_photographer"]} == {"src:0", "src:1"}
    for c in res["curve"]:   # the wrong frames' photos: none without a wrong frame, never more than frames or photos
        assert c["confidently_wrong_photos"] <= min(c["confidently_wrong_frames"], 6)
        assert (c["confidently_wrong_photos"] == 0) == (c["confidently_wrong_frames"] == 0)
    out = capsys.readouterr().out
    assert "| far mass | beacon on | confidently wrong (frames) | photos with a wrong frame, of 6 |" in out
    assert "chosen: far mass" in out and "of 6 photos)" in out

    def no_model(*a, **k):
        raise AssertionError("a second call replays the saved scans")

    monkeypatch.setattr(Engine, "predict", no_model)
    assert sg.main(_args(runs, ptl, neg)) == 0
    assert json.loads((runs[0] / "scan_gate_a30_r30.json").read_text())["curve"] == res["curve"]


def test_a_phone_held_in_portrait_checks_the_portrait_threshold(two_runs):
    """--phone: the photographers' photos scanned by a phone held in portrait, cached apart, their
    curve for choose_gate's portrait view; with --window, refused."""
    runs, ptl, neg = two_runs
    assert sg.main(_args(runs, ptl, neg, "--phone")) == 0
    res = json.loads((runs[0] / "scan_gate_phone_a30_r30.json").read_text())
    assert res["view"] == "portrait" and res["at_scale"]["frames"] > 0
    assert sorted(p.name for p in runs[0].glob("fold-*/scanned_phone*.npz")) == ["scanned_phone_3_0_a30_r30.npz"] * 2
    with pytest.raises(SystemExit):
        sg.main(_args(runs, ptl, neg, "--phone", "--window"))


def test_a_walkers_sway_is_scanned_apart_with_its_own_defaults(two_runs):
    """--sway: the photos swung either side by a walker's sway (2.5 deg at a fastest 14 deg/s by
    default) instead of swept, cached and written apart from the sweep."""
    import numpy as np

    from crossing_assist.runtime.listen import SCAN_FPS, SCAN_STILL_S, sway_yaw

    runs, ptl, neg = two_runs
    args = [a for a in _args(runs, ptl, neg) if a not in ("--amplitude", "30")]
    assert sg.main([*args, "--sway", "--heard-after", "0.2"]) == 0
    res = json.loads((runs[0] / "scan_gate_sway_a2.5_r14_heard0.2.json").read_text())
    assert res["scanned"] == {"amplitude_deg": 2.5, "rate_dps": 14.0, "sway": True}
    assert sorted(p.name for p in runs[0].glob("fold-*/scanned*.npz")) == ["scanned_3_0_sway_a2.5_r14.npz"] * 2
    saved = np.load(runs[0] / "fold-src_0" / "scanned_3_0_sway_a2.5_r14.npz")
    psi = saved["psi"]
    np.testing.assert_array_equal(psi, sway_yaw(2.5, 14.0))
    still = int(round(SCAN_STILL_S * SCAN_FPS))
    assert not psi[:still].any() and abs(psi).max() == pytest.approx(2.5, abs=0.05)
    assert np.abs(np.diff(psi)).max() * SCAN_FPS == pytest.approx(14.0, rel=0.05)   # the fastest turn
    assert np.sum(np.diff(np.sign(psi[still + 1:])) != 0) in (5, 6)                 # three periods
    assert res["at_scale"]["frames"] > 0 and "beacon_on_read_stale" in res["at_scale"]


def test_heard_late_counts_the_worse_of_the_turned_readings(two_runs):
    runs, ptl, neg = two_runs
    assert sg.main(_args(runs, ptl, neg, "--heard-after", "0.3")) == 0
    res = json.loads((runs[0] / "scan_gate_a30_r30_heard0.3.json").read_text())
    for f in res["folds"]:
        for c in f["curve"]:
            r = c["readings"]
            assert set(r) == {"gyro_turned", "camera_turned", "gyro", "camera", "camera_stale", "camera_read_stale"}
            turned = [r["gyro_turned"], r["camera_turned"]]
            assert c["confidently_wrong"] * f["frames"] == pytest.approx(max(g["wrong"] for g in turned))
            assert c["beacon_on"] * f["frames"] == pytest.approx(min(g["on"] for g in turned))
            # the same decisions not turned (a player without a gyroscope) and stopped once half a strip
            # stale (the app while its gyroscope is not followed), kept apart
            assert c["confidently_wrong_unturned_frames"] == max(r["gyro"]["wrong"], r["camera"]["wrong"])
            assert (c["confidently_wrong_stale_frames"], c["beacon_on_stale_frames"]) == (
                r["camera_stale"]["wrong"], r["camera_stale"]["on"])
            assert (c["confidently_wrong_read_stale_frames"], c["beacon_on_read_stale_frames"]) == (
                r["camera_read_stale"]["wrong"], r["camera_read_stale"]["on"])
    for i, c in enumerate(res["curve"]):
        for rate in ("confidently_wrong_unturned", "confidently_wrong_stale", "beacon_on_stale",
                     "confidently_wrong_read_stale", "beacon_on_read_stale"):
            n = sum(f["curve"][i][f"{rate}_frames"] for f in res["folds"])
            assert c[rate] == pytest.approx(n / c["frames"])
    # a turn of 30°/s heard 0.3 s late, 9° (1.6 strips), not turned: the toy's right headings go wrong;
    # stopped once half a strip stale, the beacon is off while the camera turns and never wrong
    top = res["curve"][-1]
    assert top["confidently_wrong_unturned"] > top["confidently_wrong"]
    assert top["confidently_wrong_stale"] == 0 and top["beacon_on_stale"] < top["beacon_on"] / 2


def _gate(path: Path, scale: float) -> Path:
    curve = [{"scale": m, "beacon_on": m / 10, "confidently_wrong": 0.0} for m in (1.0, 2 ** 0.5, 2.0, 4.0)]
    view = {"scale": scale, "threshold": scale * 0.01, "at_scale": curve[-1], "curve": curve}
    path.write_text(json.dumps({**view, "portrait_window": dict(view)}))
    return path


def test_cap_lowers_a_view_to_the_scans_choice_only_where_that_is_lower(tmp_path):
    gate = _gate(tmp_path / "gate.json", 4.0)
    scanned = {"scale": 2.0, "threshold": 0.02, "targets_met": True, "at_scale": {"beacon_on": 0.3}, "heard_after_s": 0}
    out, threshold = sg.cap(gate, "portrait_window", scanned)
    assert out.name == "gate_scan.json" and threshold == 0.02
    g = json.loads(out.read_text())
    w = g["portrait_window"]
    assert (w["scale"], w["threshold"], w["at_scale"]["beacon_on"]) == (2.0, 0.02, 0.2)   # still figures at the cap
    assert w["scans"][0]["capped_from"] == {"scale": 4.0, "threshold": 0.04} and g["scale"] == 4.0   # landscape untouched
    # a second cap (landscape) stacks on the first file; a looser scan choice leaves the view as it was
    again, threshold = sg.cap(out, "landscape", {**scanned, "scale": 8.0, "threshold": 0.08})
    assert threshold == 0.04   # landscape kept its own
    g2 = json.loads(again.read_text())
    assert again == out and g2["scale"] == 4.0 and "capped_from" not in g2["scans"][0]
    assert g2["portrait_window"]["scale"] == 2.0
    # a slower sweep heard late caps the capped view further; both checks are kept, each named by its sweep
    slow = {**scanned, "scale": 2 ** 0.5, "threshold": 0.01414, "heard_after_s": 0.2,
            "scanned": {"amplitude_deg": 20.0, "rate_dps": 15.0}}
    w3 = json.loads(sg.cap(out, "portrait_window", slow)[0].read_text())["portrait_window"]
    assert w3["scale"] == 2 ** 0.5 and w3["at_scale"]["beacon_on"] == pytest.approx(2 ** 0.5 / 10)
    assert [c.get("scanned", {}).get("rate_dps") for c in w3["scans"]] == [None, 15.0]
    assert w3["scans"][1]["capped_from"] == {"scale": 2.0, "threshold": 0.02}
    # the same sweep checked again replaces its record instead of adding one
    w4 = json.loads(sg.cap(out, "portrait_window", {**slow, "scale": 4.0})[0].read_text())["portrait_window"]
    assert len(w4["scans"]) == 2 and w4["scale"] == 2 ** 0.5 and "capped_from" not in w4["scans"][1]
    with pytest.raises(ValueError, match="not swept at scale"):
        sg.cap(gate, "landscape", {**scanned, "scale": 3.0})
    with pytest.raises(ValueError, match="no portrait choice"):
        sg.cap(gate, "portrait", scanned)


def test_saved_caps_from_the_sweeps_result_without_replaying(two_runs, tmp_path, monkeypatch, capsys):
    from crossing_assist.runtime.engine import Engine

    runs, ptl, neg = two_runs
    assert sg.main(_args(runs, ptl, neg, "--saved", "--cap", "gate.json")) == 2   # no gate to cap
    _gate(runs[0] / "gate.json", 4.0)
    assert sg.main(_args(runs, ptl, neg, "--saved", "--cap", "gate.json")) == 2   # nothing saved yet
    assert "run this sweep once without --saved" in capsys.readouterr().err
    assert sg.main(_args(runs, ptl, neg)) == 0
    chosen = json.loads((runs[0] / "scan_gate_a30_r30.json").read_text())["scale"]

    def no_model(*a, **k):
        raise AssertionError("--saved replays nothing")

    monkeypatch.setattr(Engine, "predict", no_model)
    monkeypatch.setattr(sg, "judge_scans", no_model)
    assert sg.main(_args(runs, ptl, neg, "--saved", "--cap", "gate.json")) == 0
    g = json.loads((runs[0] / "gate_scan.json").read_text())
    assert g["scale"] == min(4.0, chosen) and g["scans"][0]["scanned"] == {"amplitude_deg": 30.0, "rate_dps": 30.0}
    assert "capped: " in capsys.readouterr().out
    # a saved result pooled over other runs is not this check
    assert sg.main([str(runs[0]), *_args(runs, ptl, neg)[3:], "--saved", "--cap", "gate.json"]) == 2
    assert "pooled" in capsys.readouterr().err


def test_bad_runs_and_options_are_one_line(tmp_path, capsys):
    assert sg.main([str(tmp_path / "none")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    (tmp_path / "cv").mkdir()
    assert sg.main([str(tmp_path / "cv"), "--cap", "gate.json"]) == 2
    assert "not found" in capsys.readouterr().err
    for bad in (["--heard-after", "5"], ["--min-scale", "64"], ["--mirror"], ["--amplitude", "0"],
                ["--sway", "--rate", "-3"]):
        with pytest.raises(SystemExit):
            sg.main([str(tmp_path / "cv"), *bad])
        assert "error:" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sg.main([str(tmp_path / "cv"), "--sway", "--amplitude", "95"])
    assert "--amplitude 95" in capsys.readouterr().err

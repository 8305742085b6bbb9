"""What the user hears (issue 13): summarise / choose_threshold on hand-made lists, a Listener
over the toy bundles, and crossing-eval --bundle with listen numbers and risk_coverage.png."""

import json
import subprocess
import sys

import pytest
from runtime_toy import TOY2, bar_dataset, bar_frame, make_toy_bundle, toy_bundle  # noqa: F401  (fixture)

from crossing_assist.actions import UNKNOWN, bin_center_x, x_to_heading
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.listen import Heard, Listener, choose_threshold, error_stats, heading_errors, summarise


def test_summarise_rates_on_a_hand_made_list():
    heard = [Heard(5, True, 5), Heard(5, True, 6), Heard(5, True, 8), Heard(3, False, 0),
             Heard(UNKNOWN, False, 0), Heard(UNKNOWN, True, 4)]
    s = summarise(heard)
    assert s["frames_with_crossing"] == 4 and s["frames_without_crossing"] == 2
    assert s["beacon_on"] == pytest.approx(3 / 4)
    assert s["confidently_wrong"] == pytest.approx(1 / 4)      # only the one 3 strips off
    assert s["accuracy_heard"] == pytest.approx(1 / 4)
    assert s["strip_mae_on"] == pytest.approx(4 / 3)
    assert s["silence_no_crossing"] == pytest.approx(1 / 2)
    s = summarise([Heard(7, True, 9), Heard(7, True, 5)])       # exactly 2 strips off is wrong
    assert s["confidently_wrong"] == 1.0 and s["silence_no_crossing"] is None
    s = summarise([Heard(UNKNOWN, False, 0)])
    assert s["beacon_on"] is None and s["strip_mae_on"] is None and s["silence_no_crossing"] == 1.0


def test_heading_errors_are_degrees_to_the_goal_at_each_clips_fov_on_and_in_view_only():
    heard = [Heard(6, True, 6, 5.0, 67.0), Heard(6, True, 6, 5.0, 40.0), Heard(6, False, 0, None, 67.0),
             Heard(1, True, 1, -30.0, 53.0), Heard(UNKNOWN, True, 4, -10.0, 67.0), Heard(UNKNOWN, True, 4, -10.0, 67.0)]
    far_x = [0.6, 0.6, 0.6, -0.2, None, float("nan")]   # off, out of view and no goal (None or NaN) are left out
    e = heading_errors(heard, far_x)
    assert e == pytest.approx([abs(5.0 - x_to_heading(0.6, 67.0)), abs(5.0 - x_to_heading(0.6, 40.0))])
    assert e[0] > e[1] > 0        # the same x is a wider angle on the wider camera
    s = error_stats([1.0, 2.0, 3.0, 10.0])
    assert (s["n"], s["median"], s["mean"]) == (4, 2.5, 4.0) and s["p90"] == pytest.approx(7.9)
    assert error_stats([]) == {"n": 0, "median": None, "mean": None, "p90": None}
    with pytest.raises(ValueError, match="goal positions"):
        heading_errors(heard, far_x[:2])


def _pt(t, on, wrong, silence):
    return {"threshold": t, "beacon_on": on, "confidently_wrong": wrong, "silence_no_crossing": silence}


def test_choose_threshold_takes_the_most_beacon_within_the_limits():
    curve = [_pt(0.5, 0.2, 0.0, 1.0), _pt(1.0, 0.5, 0.004, 0.99), _pt(1.5, 0.7, 0.01, 0.99),
             _pt(2.0, 0.8, 0.0, 0.9)]
    assert choose_threshold(curve)["threshold"] == 1.0
    assert choose_threshold(curve, max_wrong=0.02)["threshold"] == 1.5
    assert choose_threshold(curve, max_wrong=0.02, min_silence=0.8)["threshold"] == 2.0
    assert choose_threshold([_pt(1.0, 0.5, 0.1, 1.0)]) is None
    assert choose_threshold([_pt(1.0, 0.5, 0.0, None)])["threshold"] == 1.0   # no negatives: no limit
    tie = [_pt(2.0, 0.5, 0.0, 1.0), _pt(1.0, 0.5, 0.0, 1.0)]
    assert choose_threshold(tie)["threshold"] == 1.0                           # the lower of equals


def test_listener_puts_the_beacon_on_the_bars_strip_and_is_silent_on_flat(toy_bundle):  # noqa: F811
    lis = Listener(Engine(toy_bundle), seconds=0.5)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip)), strip)
    lis.add(bar_frame(None), UNKNOWN)
    lis.add(bar_frame(None, noise=0.3), UNKNOWN)
    assert all(len(c) == 5 for c in lis.clips)
    heard = lis.heard()
    assert [(h.label, h.on, h.strip) for h in heard[:3]] == [(2, True, 2), (6, True, 6), (11, True, 11)]
    assert [h.on for h in heard[3:]] == [False, False]
    s = summarise(heard)
    assert s["beacon_on"] == 1.0 and s["confidently_wrong"] == 0.0 and s["silence_no_crossing"] == 1.0
    # the gate threshold decides: nothing passes a tiny one; the curve replays the same clips
    assert not any(h.on for h in lis.heard(threshold=1e-6))
    curve = lis.risk_coverage([1e-6, 1.0, 100.0])
    assert [c["threshold"] for c in curve] == [1e-6, 1.0, 100.0]
    assert curve[0]["beacon_on"] == 0.0 and curve[1]["beacon_on"] == 1.0
    assert curve[2]["silence_no_crossing"] < 1.0       # everything passes a huge one: noise speaks too


def test_listener_reads_strips_with_the_frames_fov(tmp_path):
    lis = Listener(Engine(make_toy_bundle(tmp_path / "b", TOY2)), seconds=0.5)
    for strip in (1, 3, 10, 12):
        lis.add(bar_frame(bin_center_x(strip), h=128, w=96), strip)    # portrait frames
        lis.add(bar_frame(bin_center_x(strip), h=72, w=96), strip)     # landscape frames
    heard = lis.heard()
    assert all(h.on and h.strip == h.label for h in heard), heard


def test_crossing_eval_bundle_writes_listen_numbers_and_risk_coverage(tmp_path, toy_bundle):  # noqa: F811
    data = bar_dataset(tmp_path / "data")
    neg = bar_dataset(tmp_path / "neg", n=3, unknown=True)
    out = tmp_path / "eval"
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                        "--data", str(data), "--split", "val", "--negatives", str(neg), "--portrait", "2",
                        "--clip-seconds", "0.5", "--examples", "0", "--out", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "landscape (6 + 3 no-crossing frames" in r.stdout
    assert "portrait (12 + 6 no-crossing frames" in r.stdout
    assert "portrait_window (12 + 6 no-crossing frames" in r.stdout
    m = json.loads((out / "metrics.json").read_text())
    lis = m["listen"]
    land, port, win = lis["landscape"], lis["portrait"], lis["portrait_window"]
    # the first frame's argmax is the model's figure; what is heard is the last decision's strip
    assert f"model, first frame: accuracy {land['accuracy']:.3f}" in r.stdout
    assert f"on the right strip {land['accuracy_heard']:.3f}" in r.stdout
    assert land["frames_with_crossing"] == 6 and land["frames_without_crossing"] == 3
    assert port["frames_with_crossing"] == 12 and port["frames_without_crossing"] == 6
    assert win["frames_with_crossing"] == 12 and win["bundle_threshold"] == port["bundle_threshold"]
    assert land["accuracy"] == 1.0 and land["beacon_on"] == 1.0 and land["confidently_wrong"] == 0.0
    assert land["silence_no_crossing"] == 1.0 and land["beacon_on_goal_in_view"] == 1.0
    assert port["silence_no_crossing"] == 1.0 and 0 < port["beacon_on"] <= 1.0
    assert port["beacon_on_goal_in_view"] == 1.0
    # the toy bundle puts the beacon on the bar's strip: off by at most half a strip, in degrees
    assert land["heading_error_deg"]["n"] == 6 and land["heading_error_deg"]["p90"] < 67.0 / 24
    assert 0 < port["heading_error_deg"]["n"] <= 12 and port["heading_error_deg"]["p90"] < 53.0 / 24
    assert "heading played vs the goal" in r.stdout
    for view in (land, port):   # each view's curve around its own (orientation's) threshold
        thresholds = [c["threshold"] for c in view["risk_coverage"]]
        assert thresholds == sorted(thresholds) and view["bundle_threshold"] in thresholds
        assert view["best_threshold_here"] is None or view["best_threshold_here"]["threshold"] in thresholds
    for png in ("risk_coverage.png", "risk_coverage_portrait.png", "risk_coverage_portrait_window.png"):
        assert (out / png).stat().st_size > 0


def test_crossing_eval_bad_listen_options_are_one_line(tmp_path, toy_bundle):  # noqa: F811
    data = bar_dataset(tmp_path / "data", n=2)
    for args in (["--portrait", "13"], ["--clip-seconds", "0"], ["--seed", "-1"]):
        r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                            "--data", str(data), "--split", "val", "--out", str(tmp_path / "e"), *args],
                           capture_output=True, text=True)
        assert r.returncode != 0
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:"), r.stderr


def test_crossing_eval_seed_reproduces_its_figures(tmp_path):
    """The MC-dropout masks come from ``seed`` (recorded in metrics.json): the same seed gives the
    same figures, model and heard, another seed other ones (a noisy toy: every sample differs)."""
    from crossing_assist.models.evaluate import EvalConfig, evaluate

    bundle = make_toy_bundle(tmp_path / "noisy", noise=1.5)
    data = bar_dataset(tmp_path / "data")

    def run(seed):
        _, m = evaluate(EvalConfig(data=str(data), bundle=str(bundle), examples=0, portrait=1, seed=seed,
                                   out=str(tmp_path / f"eval{seed}"), progress=False))
        assert json.loads((tmp_path / f"eval{seed}" / "metrics.json").read_text())["seed"] == seed
        return m["nll"], [c["beacon_on"] for c in m["listen"]["landscape"]["risk_coverage"]]

    first = run(3)
    assert run(3) == first and run(4) != first


def test_listener_saved_and_loaded_replays_the_same_decisions(tmp_path, toy_bundle):  # noqa: F811
    """``save`` / ``load``: the predictions kept on disk replay every gate threshold exactly as the
    clips listened to, a failed inference and a portrait frame's FOV included, without the model."""
    import numpy as np

    engine = Engine(toy_bundle)
    lis = Listener(engine, seconds=0.3)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip)), strip)
    lis.add(bar_frame(None, noise=0.3), UNKNOWN)
    lis.add(np.ascontiguousarray(bar_frame(bin_center_x(9)).transpose(1, 0, 2)), 9, fov_deg=50.0)  # portrait
    lis.add(np.zeros((4, 4), np.uint8), 4)                                                     # fails
    assert not any(p.ok for p in lis.clips[-1]) and lis.clips[-2][0].orientation == "portrait"
    lis.save(tmp_path / "heard.npz", in_view=np.asarray([0, 2]))
    with pytest.raises(ValueError, match="named like saved fields"):   # would overwrite the labels
        lis.save(tmp_path / "bad.npz", labels=np.zeros(6))
    assert not (tmp_path / "bad.npz").exists()

    class NoModel(Engine):
        def predict(self, *a, **k):
            raise AssertionError("replayed from disk, not run")

    again, extra = Listener.load(NoModel(toy_bundle), tmp_path / "heard.npz")
    assert list(extra) == ["in_view"] and extra["in_view"].tolist() == [0, 2]
    assert again.labels == lis.labels and (again.seconds, again.fps) == (lis.seconds, lis.fps)
    assert again.clips[-2][0].fov_deg == 50.0 and not again.clips[-1][0].ok
    for t in (None, 0.01, 0.5, 2.0):
        assert again.heard(t) == lis.heard(t)
    assert again.risk_coverage([0.1, 1.0], idx=[0, 2]) == lis.risk_coverage([0.1, 1.0], idx=[0, 2])


def test_listener_load_replays_another_measure_from_the_saved_probabilities(tmp_path, toy_bundle):  # noqa: F811
    """``load(measure="far_mass")``: each saved frame's uncertainty becomes its far mass and the
    decisions are taken with that measure (the bundle's threshold scale is the caller's)."""
    from crossing_assist.runtime import belief as bf

    lis = Listener(Engine(toy_bundle), seconds=0.3)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip)), strip)
    lis.add(bar_frame(None, noise=0.3), UNKNOWN)
    lis.save(tmp_path / "heard.npz")
    fm, _ = Listener.load(Engine(toy_bundle), tmp_path / "heard.npz", measure="far_mass")
    assert fm.measure == "far_mass"
    for clip, saved in zip(fm.clips, lis.clips):
        for p, q in zip(clip, saved):
            assert p.uncertainty == pytest.approx(bf.far_mass(q.probs))
    t = max(p.uncertainty for clip in fm.clips[:3] for p in clip) * 1.01   # every bar frame passes
    heard = fm.heard(t)
    assert [h.on for h in heard[:3]] == [True] * 3 and [h.strip for h in heard[:3]] == [2, 6, 11]
    assert not heard[3].on                                                   # noise stays silent
    assert heard != lis.heard(t)    # the bundle's own measure (entropy) at that threshold decides otherwise
    with pytest.raises(ValueError, match="cannot replay measure 'variance'"):
        Listener.load(Engine(toy_bundle), tmp_path / "heard.npz", measure="variance")



def test_eval_bundle_gives_the_graph_what_the_runtime_does_for_a_portrait_photo(tmp_path, monkeypatch):
    """crossing-eval --bundle's model figures on a portrait photo: the graph gets the view crop's
    rows at the portrait FOV, as Engine.predict gives it, not the whole frame; a landscape photo
    at the training FOV keeps every row."""
    from crossing_assist import inference
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.geometry import Geometry, view_rows
    from crossing_assist.models.evaluate import EvalConfig, _eval_bundle, _split

    geo = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0, view_crop=True)
    bundle = make_toy_bundle(tmp_path / "b", TOY2, size=(36, 48), geometry=geo)
    data = bar_dataset(tmp_path / "d", n=2)
    cfg = EvalConfig(bundle=str(bundle), data=str(data), split="val")
    part = _split(cfg)
    for r, (h, w) in zip(part.rows, ((128, 96), (96, 128))):          # one portrait, one landscape photo
        save_rgb(part.image_path(r), bar_frame(0.5, h=h, w=w))
    seen, real = [], inference.predict
    monkeypatch.setattr(inference, "predict",
                        lambda sess, n, images, **kw: (seen.extend(i.shape for i in images), real(sess, n, images, **kw))[1])
    probs, _, _ = _eval_bundle(cfg, part)
    top, rows = view_rows(128, 96, 53.0, (36, 48), 67.0)
    assert rows < 128 and seen == [(rows, 96, 3), (96, 128, 3)]
    assert probs.shape[0] == 2


def test_eval_bundle_refuses_a_frame_too_narrow_for_any_camera_in_one_line(tmp_path):
    """A 1:4 photo from a 4:3 sensor's phone would be a camera under 20 degrees across, which the
    runtime refuses (stop cue): crossing-eval names the photo in one line and exits 2."""
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.geometry import Geometry
    from crossing_assist.models.evaluate import EvalConfig, _split

    geo = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0, view_crop=True, sensor_aspect=4 / 3)
    bundle = make_toy_bundle(tmp_path / "b", TOY2, size=(36, 48), geometry=geo)
    data = bar_dataset(tmp_path / "d", n=2)
    part = _split(EvalConfig(bundle=str(bundle), data=str(data), split="val"))
    save_rgb(part.image_path(part.rows[0]), bar_frame(0.5, h=160, w=40))
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(bundle), "--data",
                        str(data), "--split", "val", "--portrait", "0", "--out", str(tmp_path / "e"), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0, r.stderr
    assert part.rows[0].image.split("/")[-1] in r.stderr and "too narrow" in r.stderr


def _portrait_strict_toy(tmp_path):
    """A toy bundle whose portrait frames never pass the gate (threshold 1e-6) and landscape ones do."""
    import dataclasses

    return make_toy_bundle(tmp_path / "strict", dataclasses.replace(TOY2, threshold=1.0, portrait_threshold=1e-6))


def test_a_sweep_by_scale_keeps_each_clips_own_threshold(tmp_path):
    """Landscape and portrait clips mixed: scale 1 plays as the bundle plays (portrait silent here),
    where one threshold for all (the landscape one) would have put the portrait beacon on."""
    lis = Listener(Engine(_portrait_strict_toy(tmp_path)), seconds=0.5)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip), h=72, w=96), strip)      # landscape
        lis.add(bar_frame(bin_center_x(strip), h=128, w=96), strip)     # portrait
    assert [h.on for h in lis.heard()] == [True, False] * 3
    assert [h.on for h in lis.heard(scale=1.0)] == [True, False] * 3
    assert all(h.on for h in lis.heard(threshold=1.0))
    (one,) = lis.risk_coverage(scales=[1.0])
    assert one["scale"] == 1.0 and one["beacon_on"] == summarise(lis.heard())["beacon_on"] == 0.5
    assert lis.risk_coverage(scales=[1e7])[0]["beacon_on"] == 1.0    # everything passes a huge scale
    with pytest.raises(ValueError, match="not both"):
        lis.heard(threshold=1.0, scale=1.0)


def test_crossing_eval_on_portrait_photos_sweeps_around_the_portrait_threshold(tmp_path):
    """A researcher's portrait photos as taken: the curve is around the portrait threshold and its
    x 1 point is what the summary says the user heard; the summary names them portrait."""
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest

    data = tmp_path / "data"
    rows = []
    for i, strip in enumerate((2, 6, 11)):
        save_rgb(data / "images" / f"p{i}.png", bar_frame(bin_center_x(strip), h=128, w=96))
        rows.append(Row(f"images/p{i}.png", strip, bin_center_x(strip), "src:0", "val", {}, ()))
    write_manifest(data, rows)
    out = tmp_path / "eval"
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(_portrait_strict_toy(tmp_path)),
                        "--data", str(data), "--split", "val", "--portrait", "0", "--clip-seconds", "0.5",
                        "--examples", "0", "--out", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "as taken (3 portrait) (3 + 0 no-crossing frames" in r.stdout
    view = json.loads((out / "metrics.json").read_text())["listen"]["landscape"]
    assert view["orientations"] == {"portrait": 3} and view["bundle_threshold"] == pytest.approx(1e-6)
    at_one = next(c for c in view["risk_coverage"] if c["scale"] == 1.0)
    assert at_one["beacon_on"] == view["beacon_on"] == 0.0 and at_one["threshold"] == pytest.approx(1e-6)


def test_crossing_eval_cuts_portrait_views_from_landscape_photos_only(tmp_path):
    """--portrait 2 on a researcher's portrait photos: no "portrait views" of a portrait photo
    (they assumed it spanned the landscape camera's 67 deg and counted each photo 4 times)."""
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest

    data = tmp_path / "data"
    rows = []
    for i, (strip, h, w) in enumerate(((2, 128, 96), (6, 128, 96), (11, 72, 96))):   # two portrait, one landscape
        save_rgb(data / "images" / f"p{i}.png", bar_frame(bin_center_x(strip), h=h, w=w))
        rows.append(Row(f"images/p{i}.png", strip, bin_center_x(strip), "src:0", "val", {}, ()))
    write_manifest(data, rows)
    out = tmp_path / "eval"
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(make_toy_bundle(tmp_path / "b", TOY2)),
                        "--data", str(data), "--split", "val", "--portrait", "2", "--clip-seconds", "0.5",
                        "--examples", "0", "--out", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lis = json.loads((out / "metrics.json").read_text())["listen"]
    assert lis["landscape"]["frames_with_crossing"] == 3 and lis["landscape"]["orientations"] == {"landscape": 1, "portrait": 2}
    assert lis["portrait"]["frames_with_crossing"] == 2 == lis["portrait_window"]["frames_with_crossing"]   # the landscape photo's only
    data2 = tmp_path / "data2"
    save_rgb(data2 / "images" / "p.png", bar_frame(bin_center_x(6), h=128, w=96))
    write_manifest(data2, [Row("images/p.png", 6, bin_center_x(6), "src:0", "val", {}, ())])
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(tmp_path / "b"),
                        "--data", str(data2), "--split", "val", "--portrait", "2", "--clip-seconds", "0.5",
                        "--examples", "0", "--out", str(tmp_path / "eval2"), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr   # only portrait photos: no portrait views at all, no crash
    assert set(json.loads((tmp_path / "eval2" / "metrics.json").read_text())["listen"]) == {"landscape", "clip_seconds", "fps"}


def test_crossing_eval_plays_each_frame_at_its_cameras_fov(tmp_path):
    """A researcher's 3:4 portrait frames from a narrow camera (40 deg): a row's ``fov=40`` flag
    (crossing-data frames --fov) or ``--fov 40`` plays them at 40 deg, where the narrow camera's
    threshold lets the toy speak; unflagged they play at the toy bundle's 50 deg and its portrait
    threshold silences them. Such frames are not cut into portrait views."""
    import dataclasses

    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest

    bundle = make_toy_bundle(tmp_path / "narrow", dataclasses.replace(TOY2, threshold=1.0, portrait_threshold=1e-6),
                             narrow_threshold=1.0, narrow_fov_deg=42.0)
    data = tmp_path / "data"
    rows = []
    for i, strip in enumerate((2, 6, 11, 3, 7, 10)):
        save_rgb(data / "images" / f"p{i}.png", bar_frame(bin_center_x(strip), h=128, w=96))
        rows.append(Row(f"images/p{i}.png", strip, bin_center_x(strip), "src:0", "val", {}, ("fov=40",) if i < 3 else ()))
    write_manifest(data, rows)

    def run(*extra):
        out = tmp_path / f"eval{len(extra)}"
        r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(bundle),
                            "--data", str(data), "--split", "val", "--portrait", "2", "--clip-seconds", "0.5",
                            "--examples", "0", "--out", str(out), "--quiet", *extra], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        return r.stdout, json.loads((out / "metrics.json").read_text())["listen"]

    text, lis = run()
    land = lis["landscape"]
    assert land["camera_fov_deg"] == {"40": 3, "50": 3} and "camera FOV 40 deg (3), 50 deg (3)" in text
    assert land["beacon_on"] == 0.5 and land["confidently_wrong"] == 0.0     # the three flagged frames speak
    _, lis = run("--fov", "40")
    assert lis["landscape"]["camera_fov_deg"] == {"40": 6} and lis["landscape"]["beacon_on"] == 1.0
    assert "portrait" not in lis   # frames of a known camera are played as they are
    for bad, args in (("fov=500", ()), (None, ("--fov", "5")), (None, ("--run", str(tmp_path), "--fov", "40"))):
        if bad:
            write_manifest(data, [dataclasses.replace(rows[0], flags=(bad,))])
        argv = [sys.executable, "-m", "crossing_assist.models.cli", "eval", "--data", str(data), "--split", "val",
                "--out", str(tmp_path / "bad"), *args]
        r = subprocess.run(argv if "--run" in args else [*argv, "--bundle", str(bundle)], capture_output=True, text=True)
        lines = r.stderr.strip().splitlines()
        assert r.returncode != 0 and len(lines) == 1 and lines[0].startswith("error:") and "fov" in lines[0].lower(), r.stderr


def test_a_photo_of_the_training_camera_is_cut_into_portrait_views_even_when_its_fov_is_known(tmp_path):
    """A landscape photo whose EXIF gave 67.3 deg (a 26 mm phone camera: the training camera) is
    still cut into portrait views, as an unflagged one is; one from a 40 deg camera is played as it
    is, at its FOV, and not cut."""
    from types import SimpleNamespace

    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, read_manifest, write_manifest
    from crossing_assist.geometry import letterbox_geometry
    from crossing_assist.models.evaluate import _views

    data = tmp_path / "data"
    flags = ((), ("fov=67.3",), ("fov=40",))
    for i, f in enumerate(flags):
        save_rgb(data / "images" / f"p{i}.png", bar_frame(bin_center_x(6), h=120, w=160))
    write_manifest(data, [Row(f"images/p{i}.png", 6, bin_center_x(6), "src:0", "val", {}, f) for i, f in enumerate(flags)])
    ds = read_manifest(data)
    views = _views(SimpleNamespace(portrait=2, fov_deg=None), [(ds, r) for r in ds.rows], letterbox_geometry())
    assert [v[4] for v in views["landscape"]] == [None, 67.3, 40.0]
    assert len(views["portrait"]) == len(views["portrait_window"]) == 4   # 2 views of each of the first two
    assert {v[4] for v in views["portrait"]} == {53.0}


def test_adding_negatives_leaves_the_figures_on_crossings_as_they_were(tmp_path):
    """A noisy toy (every MC sample differs): crossing-eval with --negatives gives the same
    figures on the frames with a crossing, every view, as without (the negatives' draws used to
    come before the portrait views', so adding them changed the portrait figures)."""
    from crossing_assist.models.evaluate import EvalConfig, evaluate

    bundle = make_toy_bundle(tmp_path / "noisy", noise=1.5)
    data = bar_dataset(tmp_path / "data")
    neg = bar_dataset(tmp_path / "neg", n=3, unknown=True)
    keys = ("accuracy", "beacon_on", "confidently_wrong", "accuracy_heard", "heading_error_deg")

    def run(name, negatives):
        _, m = evaluate(EvalConfig(data=str(data), bundle=str(bundle), examples=0, portrait=1, negatives=negatives,
                                   out=str(tmp_path / name), progress=False))
        return {v: {k: m["listen"][v][k] for k in keys} for v in ("landscape", "portrait", "portrait_window")}, m

    alone, _ = run("alone", None)
    with_neg, m = run("neg", str(neg))
    assert with_neg == alone
    assert m["listen"]["portrait"]["frames_without_crossing"] == 3 and m["listen"]["landscape"]["frames_without_crossing"] == 3


def test_crossing_eval_scan_judges_every_frame_of_a_turning_camera(tmp_path, toy_bundle):  # noqa: F811
    """``--scan 30``: each photo played as a camera turning 0 -> +20 -> -20 -> 0 deg, told the turn
    and not; the toy places the moving bar, so the beacon is on while it is in view and the
    summary says so."""
    from crossing_assist.runtime.listen import scan_yaw

    from crossing_assist.geometry import window_fov

    data = bar_dataset(tmp_path / "data", n=4)
    neg = bar_dataset(tmp_path / "neg", n=2, unknown=True)
    out = tmp_path / "eval"
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                        "--data", str(data), "--split", "val", "--portrait", "0", "--scan", "30", "--examples", "0",
                        "--clip-seconds", "0.5", "--out", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    scan = json.loads((out / "metrics.json").read_text())["listen"]["scan"]
    assert scan["photos"] == 4 and scan["rate_dps"] == 30 and scan["frames"] == len(scan_yaw(20, 30)) == 39
    assert scan["camera_fov_deg"] == {"90": 4}   # the toy's camera
    for k in ("gyro", "camera", "no_yaw"):
        assert scan[k]["in_view"] > 0 and scan[k]["beacon_on"] >= 0.9 and scan[k]["confidently_wrong"] <= 0.05
    assert "scan (4 photos" in r.stdout and "turn read from the frames: beacon on" in r.stdout
    assert "portrait_window" not in scan and "no_crossing" not in scan and "narrow camera" not in r.stdout

    # with portrait views and negatives: the same scans by a narrow camera (the middle 3:4 of each
    # turned view, at its own FOV), and the no-crossing frames scanned (all silent)
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                        "--data", str(data), "--split", "val", "--portrait", "1", "--scan", "30", "--examples", "0",
                        "--negatives", str(neg), "--clip-seconds", "0.5", "--out", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    scan2 = json.loads((out / "metrics.json").read_text())["listen"]["scan"]
    assert scan2["photos"] == 4 and all(scan2[k]["in_view"] == scan[k]["in_view"] for k in ("gyro", "camera", "no_yaw"))
    win, none = scan2["portrait_window"], scan2["no_crossing"]
    assert win["photos"] == 4 and win["camera_fov_deg"] == {f"{window_fov(54 / 96, 90.0):.1f}": 4}
    for k in ("gyro", "camera", "no_yaw"):
        # the toy sees only bars inside the window: a bar beside it (its edge strip) stays silent, so
        # the narrow camera is on less often, never wrong; no-crossing frames are never heard
        assert 0 < win[k]["beacon_on"] < scan[k]["beacon_on"] and win[k]["confidently_wrong"] <= 0.05
        assert none["photos"] == 2 and none[k]["in_view"] == 0 and none[k]["out_of_view"] == 2 * (39 - 10)
        assert none[k]["silence"] == 1.0
    assert "narrow camera, a 3:4 window" in r.stdout and "2 no-crossing frames scanned the same way, beacon off: " \
        "turn from a gyroscope 1.000" in r.stdout
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                        "--data", str(data), "--split", "val", "--scan", "-1", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode != 0 and r.stderr.strip().count("\n") == 0 and "--scan" in r.stderr

    # --heard-after: each decision judged when heard (0.3 s: 9 deg of a 30 deg/s turn, over a strip
    # of the toy's 90 deg camera), and played turned with the gyroscope
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                        "--data", str(data), "--split", "val", "--portrait", "0", "--scan", "30", "--heard-after", "0.3",
                        "--examples", "0", "--clip-seconds", "0.5", "--out", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    late = json.loads((out / "metrics.json").read_text())["listen"]["scan"]
    assert late["heard_after_s"] == 0.3 and late["gyro"]["confidently_wrong"] > scan["gyro"]["confidently_wrong"] + 0.05
    assert late["gyro_turned"]["confidently_wrong"] <= 0.05 and late["camera_turned"]["in_view"] > 0
    assert "judged 0.3 s after its frame's capture" in r.stdout and "the beacon turned with it until heard" in r.stdout
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(toy_bundle),
                        "--data", str(data), "--split", "val", "--scan", "30", "--heard-after", "5", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode != 0 and r.stderr.strip().count("\n") == 0 and "--heard-after" in r.stderr


def test_judge_scans_counts_each_frame_against_the_goal_in_that_frame(toy_bundle):  # noqa: F811
    """A hand-made scan: the model always sees strip 9 (it ignores the turn); after the still second
    the goal is at strip 9 for 5 frames, strip 3 for 5 (the beacon at 9: confidently wrong), then
    out of view on the left while the camera is turned right (the beacon at 9 points right: the
    wrong side)."""
    import numpy as np

    from crossing_assist.runtime.engine import Prediction
    from crossing_assist.runtime.listen import judge_scans

    engine = Engine(toy_bundle)
    p = np.full(13, 0.01)
    p[9] = 1 - 0.12
    pred = Prediction(ok=True, probs=p, uncertainty=0.0, action=9, fov_deg=67.0, orientation="landscape")
    labels = np.asarray([[9] * 10 + [9] * 5 + [3] * 5 + [0] * 5])
    psi = np.asarray([0.0] * 10 + [5.0] * 15)
    g = judge_scans(engine, [[pred] * 25], labels, psi, np.zeros((1, 25)))["no_yaw"]
    assert (g["in_view"], g["on"], g["wrong"], g["wrong_hold"], g["wrong_photos"]) == (10, 10, 5, 0, 1)
    assert (g["out_of_view"], g["out_on"], g["out_wrong_side"]) == (5, 5, 5)
    assert g["confidently_wrong"] == 0.5 and g["out_of_view_wrong_side"] == 1.0
    # a second photo whose goal stays at strip 9: its frames add to the counts, not to the wrong photos
    both = judge_scans(engine, [[pred] * 25] * 2, np.vstack([labels, np.full((1, 25), 9)]), psi,
                       np.zeros((2, 25)))["no_yaw"]
    assert (both["in_view"], both["wrong"], both["wrong_photos"]) == (25, 5, 1)


def test_judge_scans_heard_late_counts_the_turn_since_the_capture(toy_bundle):  # noqa: F811
    """The model places a still goal exactly in every frame of a 60 deg/s turn (strip 12 at the
    start, one strip less each ~5.6 deg). Judged 0.2 s after each capture, the beacon lags the turn
    by two strips; turned with the gyroscope's turn since the capture (``gyro_turned``) it does not.
    (The toy's scan has no texture to read the turn from: ``camera`` is judged, not tested.)"""
    import numpy as np
    import pytest

    from crossing_assist.actions import heading_to_x, x_to_bin
    from crossing_assist.runtime.engine import Prediction
    from crossing_assist.runtime.listen import TURNED_READINGS, judge_scans

    engine = Engine(toy_bundle)
    psi = np.asarray([0.0] * 10 + [6.0 * i for i in range(1, 11)])
    labels = np.asarray([[x_to_bin(heading_to_x(28.0 - a, 67.0)) for a in psi]])

    def pred(k):
        p = np.full(13, 0.001)
        p[k] = 1 - 0.012
        return Prediction(ok=True, probs=p, uncertainty=0.0, action=k, fov_deg=67.0, orientation="landscape")

    clip = [pred(int(k)) for k in labels[0]]
    now = judge_scans(engine, [clip], labels, psi, np.zeros((1, 20)))
    assert not set(TURNED_READINGS) & set(now) and now["gyro"]["confidently_wrong"] == 0.0
    late = judge_scans(engine, [clip], labels, psi, np.zeros((1, 20)), heard_after_s=0.2)
    assert late["gyro"]["in_view"] == 8 and late["gyro"]["confidently_wrong"] > 0.5
    assert late["gyro_turned"]["beacon_on"] == late["gyro"]["beacon_on"] == 1.0
    assert late["gyro_turned"]["confidently_wrong"] == 0.0
    # no gyroscope (camera_read_stale): the rate read at each frame, carried to the end of its play
    # (0.2 s heard + a frame), decides, and so do the frames read after it by the moment heard;
    # 60 deg/s read makes every turning frame a stop, never wrong, even the first one, whose own
    # frame read no turn (the next one did), while a rate read as 5 deg/s (1.5 deg, under half a
    # 5.6 deg strip) lets the lagging heading play
    read = np.asarray([[0.0] * 11 + [60.0] * 9])
    stopped = judge_scans(engine, [clip], labels, psi, read, heard_after_s=0.2)["camera_read_stale"]
    assert stopped["in_view"] == 8 and stopped["on"] == 0 and stopped["wrong"] == 0
    slow = judge_scans(engine, [clip], labels, psi, read / 12, heard_after_s=0.2)["camera_read_stale"]
    assert slow["on"] == 8 and slow["confidently_wrong"] > 0.5
    with pytest.raises(ValueError, match="heard_after_s"):
        judge_scans(engine, [clip], labels, psi, np.zeros((1, 20)), heard_after_s=5.0)
    # a gyroscope reporting, not followed (camera_stale): its turn since the capture, carried on at its
    # rate to the end of the play. At 12 deg/s, 0.2 s after capture the turn is 2.4 deg, under half a
    # 5.6 deg strip, but 3.6 deg by the end of the play: a stop (judged as it stood, it played)
    slow_psi = np.asarray([0.0] * 10 + [1.2 * i for i in range(1, 11)])
    slow_labels = np.asarray([[x_to_bin(heading_to_x(28.0 - a, 67.0)) for a in slow_psi]])
    slow_clip = [pred(int(k)) for k in slow_labels[0]]
    carried = judge_scans(engine, [slow_clip], slow_labels, slow_psi, np.zeros((1, 20)), heard_after_s=0.2)
    assert carried["camera_stale"]["in_view"] == 8 and carried["camera_stale"]["on"] == 0
    assert carried["gyro_turned"]["on"] == 8 and carried["gyro_turned"]["wrong"] == 0


def test_the_embedded_bundle_is_never_written_into(tmp_path, monkeypatch):
    """crossing-eval --bundle <the embedded default> without --out writes runs/default_bundle/eval_val
    under the working folder (it wrote into the installed package); another bundle keeps BUNDLE/eval_val."""
    from pathlib import Path

    from crossing_assist.models.evaluate import _bundle_eval_out
    from crossing_assist.runtime.demo import DEFAULT_BUNDLE

    assert _bundle_eval_out(Path(DEFAULT_BUNDLE), "val") == Path("runs") / Path(DEFAULT_BUNDLE).name / "eval_val"
    assert _bundle_eval_out(tmp_path / "b", "test") == tmp_path / "b" / "eval_test"

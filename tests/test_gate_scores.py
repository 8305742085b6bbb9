"""scripts/gate_scores.py: per-frame scores and confidently-wrong rates at fixed beacon-on rates."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import gate_scores as gs  # noqa: E402


def _probs(rows):
    p = np.full((len(rows), 13), 1e-6)
    for i, row in enumerate(rows):
        for k, v in row.items():
            p[i, k] = v
    return p / p.sum(1, keepdims=True)


def test_window_mass_sums_the_argmax_neighbours_and_is_zero_for_unknown():
    p = _probs([{5: 0.5, 6: 0.3, 9: 0.2}, {0: 0.6, 3: 0.4}, {1: 0.7, 2: 0.2, 12: 0.1}])
    m = gs.window_mass(p)
    assert m[0] == pytest.approx(0.8, abs=1e-4)     # strips 4..6
    assert m[1] == 0.0                               # argmax unknown
    assert m[2] == pytest.approx(0.9, abs=1e-4)     # strips 1..2 (the edge clips the window)


def test_wrong_at_coverage_turns_on_the_surest_frames_and_counts_two_strips_off():
    labels = np.array([5, 5, 5, 5, 0, 0])
    pred = np.array([5, 7, 6, 0, 3, 0])             # right, 2 off, 1 off, unknown; two no-crossing frames
    score = np.array([0.1, 0.2, 0.3, 0.0, 0.15, 0.0])
    rows = gs.wrong_at_coverage(score, pred, labels, coverages=(0.5, 0.75))
    # on 50 %: the two lowest crossing scores among known argmaxes (0.1, 0.2): one of them 2 strips off
    assert rows[0]["beacon_on"] == 0.5 and rows[0]["confidently_wrong"] == 0.25
    # the no-crossing frame scored 0.15 (argmax 3) is on too; the unknown one stays silent
    assert rows[0]["silence_no_crossing"] == 0.5
    assert rows[1]["beacon_on"] == 0.75 and rows[1]["confidently_wrong"] == 0.25


def test_a_score_that_ranks_the_wrong_frames_last_gives_fewer_wrong_at_the_same_beacon_on():
    # two frames spread over neighbouring strips (right within one strip), two confident but 3 strips off
    p = _probs([{6: 0.45, 7: 0.45}, {6: 0.45, 5: 0.45}, {9: 0.8}, {3: 0.8}, {6: 0.9}])
    labels = np.array([6, 6, 6, 6, 6])
    pred = p.argmax(1)
    s = gs.scores(p)
    by_entropy = gs.wrong_at_coverage(s["entropy"], pred, labels, coverages=(0.6,))[0]
    by_window = gs.wrong_at_coverage(s["1 - P(argmax +- 1)"], pred, labels, coverages=(0.6,))[0]
    assert by_entropy["confidently_wrong"] == 0.4 and by_window["confidently_wrong"] == 0.0


def test_members_disagreement_is_zero_when_they_agree_and_ranks_a_split_ensemble_last():
    # frame 0: both members sure of strip 6; frame 1: each sure of a different strip, 4 apart, so the
    # mean is as unsure as frame 2 whose members agree on the same spread
    a = _probs([{6: 0.97, 7: 0.03}, {3: 0.9, 4: 0.1}, {3: 0.45, 4: 0.05, 7: 0.45, 8: 0.05}])
    b = _probs([{6: 0.97, 7: 0.03}, {7: 0.9, 8: 0.1}, {3: 0.45, 4: 0.05, 7: 0.45, 8: 0.05}])
    d = gs.member_disagreement([a, b])
    assert d[0] == pytest.approx(0.0, abs=1e-9) and d[2] == pytest.approx(0.0, abs=1e-9)
    assert d[1] == pytest.approx(np.log(2), abs=0.01)       # two sure members, no overlap: one bit
    s = gs.scores(np.mean([a, b], 0), disagreement=d, weights=(0.1,))
    combined = s["1 - P(argmax +- 1) + 0.1 x members' disagreement"]
    assert s["1 - P(argmax +- 1)"][1] == pytest.approx(s["1 - P(argmax +- 1)"][2])   # far mass cannot tell them apart
    assert combined[1] > combined[2] > combined[0]


def test_cv_bundles_fold_metrics_counts_failures_as_wrong_and_skips_no_crossing_frames():
    """scripts/cv_bundles.py: accuracy, bin MAE and far-x over the frames with a crossing; a failed
    inference (None) is a wrong answer, never a dropped frame."""
    import cv_bundles

    right, off = _probs([{4: 1.0}])[0].tolist(), _probs([{7: 1.0}])[0].tolist()
    out = {"labels": [4, 4, 4, 4, 0], "probs": [right, right, off, None, off]}
    m = cv_bundles.fold_metrics(out, [0.29, 0.29, 0.29, 0.29])
    assert m["n"] == 4 and m["failed"] == 1
    assert m["accuracy"] == 0.5                       # the failure counts against it
    from crossing_assist.actions import get_space
    c = get_space(13).action_center_x
    # the failure has no E[x] (all its mass on unknown): far-x over the three answered frames
    assert m["far_x_error"] == pytest.approx((2 * abs(c(4) - 0.29) + abs(c(7) - 0.29)) / 3, abs=1e-4)


def test_miss_strips_is_the_distance_from_the_far_point_to_the_predicted_centre_in_strip_widths():
    # a far point at the right edge of strip 4 (x 0.332) with the beacon on strip 6 (centre 5.5/12):
    # 2 strips off by label, 1.5 strip widths off where the user is sent
    miss = gs.miss_strips([0.332, 0.5, 0.04], np.array([6, 7, 1]), 13)
    assert miss == pytest.approx([1.516, 0.5, 0.02], abs=1e-3)


def test_the_wrong_sheet_lists_the_confidently_wrong_frames_and_draws_them(tmp_path, monkeypatch):
    from types import SimpleNamespace

    p = _probs([{6: 0.9}, {6: 0.9}, {9: 0.9}, {6: 0.4, 7: 0.4}, {0: 0.9}])
    labels = np.array([6, 6, 6, 6, 0])
    far_x = [0.45, 0.46, 0.47, 0.45, None]
    img = np.zeros((30, 40, 3), np.uint8)
    ds = SimpleNamespace(image_path=lambda r: r.image)
    rows = [(ds, SimpleNamespace(image=f"f{i}.jpg", far_x=x, flags=())) for i, x in enumerate(far_x)]
    monkeypatch.setattr(gs, "load_frame", lambda path, flags: img)
    out = gs.wrong_sheet(p, labels, rows, tmp_path / "sheet.png", coverage=0.75)
    # the three surest crossing frames are on; the one at strip 9 is 3 strips off its label
    assert out["frames"] == 1 and out["images"] == ["f2.jpg"]
    assert out["miss_strips_max"] == pytest.approx(abs(0.47 - 8.5 / 12) * 12)
    assert (tmp_path / "sheet.png").stat().st_size > 0


def test_choose_gate_model_accuracy_reports_the_goal_in_view_frames_apart():
    import choose_gate
    from types import SimpleNamespace as NS

    frame = lambda a, ok=True: [NS(action=a, ok=ok)]   # noqa: E731  (a clip: its first frame)
    # four portrait views with a crossing (two with the goal in view) and one no-crossing view
    lis = NS(labels=[6, 1, 12, 6, 0], clips=[frame(6), frame(3), frame(12), frame(6, ok=False), frame(0)])
    out = choose_gate.model_accuracy(lis, in_view=[0, 3])
    assert out["accuracy"] == 0.5                      # 6 and 12 right; 3 for 1 wrong; a failure wrong
    assert out["accuracy_goal_in_view"] == 0.5         # of views 0 (right) and 3 (failed)
    assert out["bin_mae"] == (0 + 2 + 0 + 7) / 4
    assert "accuracy_goal_in_view" not in choose_gate.model_accuracy(lis)


def test_choose_gate_also_pools_another_runs_folds_before_choosing(tmp_path, monkeypatch):
    """``--also CV2``: the folds of a second CV run of the recipe are pooled with CV's, so a scale
    that one run allows but the pooled frames do not is not chosen."""
    import json

    import choose_gate as cg

    scales = cg.gate_scales(cg.GRID)
    n = len(scales)
    hi = scales.index(1.0)

    def curve(source, wrong_from):    # beacon on rises with the scale; wrong 2 % from index wrong_from
        pts = [{"scale": m, "beacon_on": (i + 1) / n, "confidently_wrong": 0.02 if i >= wrong_from else 0.0,
                "silence_no_crossing": 1.0, "beacon_on_goal_in_view": (i + 1) / n} for i, m in enumerate(scales)]
        return {"landscape": {"source": source, "frames": 100, "no_crossing_frames": 50, "goal_in_view_frames": 100,
                              "accuracy": 0.7, "bin_mae": 0.3, "curve": pts}}

    runs = {tmp_path / "a": hi + 1, tmp_path / "b": hi}   # run b's folds go wrong one step earlier
    for cv in runs:
        cv.mkdir()
    monkeypatch.setattr(cg, "read_manifest", lambda path: type("M", (), {"rows": []})())
    monkeypatch.setattr(cg, "finished_folds", lambda cv: [(cv / "fold-ptl_x", "ptl:x"), (cv / "fold-ptl_y", "ptl:y")])
    monkeypatch.setattr(cg, "fold_curve", lambda fold, source, *a, **k: curve(source, runs[fold.parent]))

    assert cg.main([str(tmp_path / "a"), "--portrait", "0"]) == 0
    alone = json.loads((tmp_path / "a" / "gate.json").read_text())
    assert alone["scale"] == scales[hi] and "pooled_runs" not in alone

    assert cg.main([str(tmp_path / "a"), "--also", str(tmp_path / "b"), "--portrait", "0"]) == 0
    pooled = json.loads((tmp_path / "a" / "gate.json").read_text())
    # pooled, scale 1 is 1 % wrong (2 % in half the folds): the step below is chosen
    assert pooled["scale"] == scales[hi - 1] and pooled["at_scale"]["confidently_wrong"] == 0.0
    at_one = next(c for c in pooled["curve"] if c["scale"] == 1.0)
    assert at_one["confidently_wrong"] == pytest.approx(0.01)
    assert (at_one["confidently_wrong_frames"], at_one["frames"]) == (4, 400)   # the count the rate rests on
    assert at_one["confidently_wrong_95"] == pytest.approx((0.0039, 0.0254), abs=1e-4)   # Wilson, 4 of 400
    assert pooled["at_scale"]["confidently_wrong_95"] == pytest.approx((0.0, 0.0095), abs=1e-4)   # 0 of 400
    assert len(pooled["at_scale"]["per_fold"]) == 4 and len(pooled["folds"]) == 4
    assert pooled["pooled_runs"] == [str(tmp_path / "a"), str(tmp_path / "b")]
    # each run at the scale the rule picks on the other: a at b's (hi - 1), never wrong; b at a's (hi), 2 % wrong
    loro = pooled["leave_one_run_out"]
    assert [(r["run"], r["scale"], r["confidently_wrong"]) for r in loro["per_run"]] == [
        (str(tmp_path / "a"), scales[hi - 1], 0.0), (str(tmp_path / "b"), scales[hi], 0.02)]
    assert (loro["confidently_wrong_frames"], loro["frames"]) == (4, 400) and loro["confidently_wrong"] == 0.01
    assert "leave_one_run_out" not in alone


def test_choose_gate_measures_each_photographer_at_the_scale_chosen_on_the_others(tmp_path, monkeypatch):
    """``leave_one_photographer_out``: each photographer's folds (every run's, grouped) measured at
    the scale the rule picks on the other photographers', as a user the choice never saw is."""
    import json

    import choose_gate as cg

    scales = cg.gate_scales(cg.GRID)
    n = len(scales)
    hi = scales.index(1.0)
    wrong_from = {"ptl:x": hi + 1, "ptl:y": hi - 1}   # y's photos go wrong two steps earlier than x's

    def curve(source):    # beacon on rises with the scale; 2 % wrong from the photographer's index
        pts = [{"scale": m, "beacon_on": (i + 1) / n, "confidently_wrong": 0.02 if i >= wrong_from[source] else 0.0,
                "silence_no_crossing": 1.0, "beacon_on_goal_in_view": (i + 1) / n} for i, m in enumerate(scales)]
        return {"landscape": {"source": source, "frames": 100, "no_crossing_frames": 50, "goal_in_view_frames": 100,
                              "curve": pts}}

    for cv in ("a", "b"):
        (tmp_path / cv).mkdir()
    monkeypatch.setattr(cg, "read_manifest", lambda path: type("M", (), {"rows": []})())
    monkeypatch.setattr(cg, "finished_folds", lambda cv: [(cv / "fold-ptl_x", "ptl:x"), (cv / "fold-ptl_y", "ptl:y")])
    monkeypatch.setattr(cg, "fold_curve", lambda fold, source, *a, **k: curve(source))
    assert cg.main([str(tmp_path / "a"), "--portrait", "0"]) == 0
    lopo = json.loads((tmp_path / "a" / "gate.json").read_text())["leave_one_photographer_out"]
    # x is measured at y's choice (hi - 2): never wrong; y at x's (hi): 2 % wrong
    assert [(r["photographer"], r["scale"], r["confidently_wrong"]) for r in lopo["per_photographer"]] == [
        ("ptl:x", scales[hi - 2], 0.0), ("ptl:y", scales[hi], 0.02)]
    assert (lopo["confidently_wrong_frames"], lopo["frames"]) == (2, 200)
    # another run's folds of a photographer are that photographer's, not another one
    assert cg.main([str(tmp_path / "a"), "--also", str(tmp_path / "b"), "--portrait", "0"]) == 0
    pooled = json.loads((tmp_path / "a" / "gate.json").read_text())["leave_one_photographer_out"]
    assert [r["photographer"] for r in pooled["per_photographer"]] == ["ptl:x", "ptl:y"]
    assert (pooled["confidently_wrong_frames"], pooled["frames"]) == (4, 400)


def _toy_fold(tmp_path, monkeypatch, photos: int, no_crossing: int):
    """choose_gate with a finished fold ``fold-ptl_x`` whose bundle is the toy bundle, and the
    held-out photographer's ``photos`` and ``no_crossing`` views: ``(choose_gate, ptl, neg, fold)``."""
    import choose_gate as cg
    from runtime_toy import TOY2, bar_dataset, make_toy_bundle

    from crossing_assist.data_tools.manifest import read_manifest

    ptl = read_manifest(bar_dataset(tmp_path / "ptl", photos, split="train", source="ptl:x"))
    neg = read_manifest(bar_dataset(tmp_path / "neg", no_crossing, unknown=True, split="train", source="ptl:x"))
    fold = tmp_path / "cv" / "fold-ptl_x"
    fold.mkdir(parents=True)
    bundle = make_toy_bundle(tmp_path / "bundle", TOY2)
    monkeypatch.setattr(cg, "fold_bundle", lambda *a, **k: bundle)
    return cg, ptl, neg, fold


def test_choose_gate_draws_portrait_views_from_their_own_number_of_photos(tmp_path, monkeypatch):
    """``--portrait-frames``: the landscape curve plays ``--frames`` held-out photos, the portrait
    curves a draw of their own size; each is cached under its own draw."""
    cg, ptl, neg, fold = _toy_fold(tmp_path, monkeypatch, photos=6, no_crossing=4)
    curves = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 6, 0, 1, portrait_frames=2)
    assert curves["landscape"]["frames"] == 6 and curves["landscape"]["no_crossing_frames"] == 3
    for view in ("portrait", "portrait_window"):   # 2 photos and 1 no-crossing view, one view of each kind
        assert curves[view]["frames"] == 2 and curves[view]["no_crossing_frames"] == 1
    assert {p.name for p in fold.glob("gate_curve*.json")} == {
        "gate_curve_6.json", "gate_curve_2_portrait1.json", "gate_curve_2_portrait_window1.json"}
    # without it, both come from the same draw
    again = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 6, 0, 1)
    assert again["portrait"]["frames"] == 6


def test_choose_gate_grid_sweeps_a_finer_grid_under_its_own_cache(tmp_path, monkeypatch):
    """``--grid 16``: twice as many gate scales (crossing-eval's grid every other point), cached
    apart from the default grid's curve; another grid is swept from the predictions saved when the
    fold was listened to, without the model; curves of two grids are never pooled."""
    from crossing_assist.runtime.engine import Engine

    cg, ptl, neg, fold = _toy_fold(tmp_path, monkeypatch, photos=4, no_crossing=2)
    fine = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 4, 0, 0, grid=16)["landscape"]
    scales = [c["scale"] for c in fine["curve"]]
    assert len(scales) == 65 and scales[::2] == list(cg.gate_scales(cg.GRID)) and 2 ** (1 / 16) in scales
    assert {p.name for p in fold.glob("gate_curve*.json")} == {"gate_curve_4_grid16.json"}
    assert (fold / "listened_4.npz").is_file()

    def no_model(*a, **k):
        raise AssertionError("another grid replays the saved predictions")

    monkeypatch.setattr(Engine, "predict", no_model)
    coarse = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 4, 0, 0)["landscape"]
    assert coarse["curve"] == fine["curve"][::2]     # the same clips, decided again at every other scale
    assert (fold / "gate_curve_4.json").is_file()
    assert len(cg.pool([fine, fine])) == 65
    with pytest.raises(ValueError, match="different gate grids"):
        cg.pool([fine, coarse])
    with pytest.raises(SystemExit):
        cg.main([str(tmp_path / "cv"), "--grid", "0"])


def test_choose_gate_says_a_choice_at_the_top_of_the_sweep_and_sweeps_further(tmp_path, monkeypatch, capsys):
    """A curve still within the limits at its largest scale was cut short: the choice says so
    (``at_sweep_top``, a warning naming ``--max-scale``); ``--max-scale 16`` sweeps the same clips
    on to 16 (the points up to 4 unchanged), cached and written apart; a top that is not a power of
    two is refused."""
    import json

    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import Listener

    cg, ptl, neg, fold = _toy_fold(tmp_path, monkeypatch, photos=4, no_crossing=2)
    short = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 4, 0, 0)["landscape"]
    monkeypatch.setattr(Engine, "predict", lambda *a, **k: pytest.fail("another top replays the saved predictions"))
    longer = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 4, 0, 0, top=16.0)["landscape"]
    scales = [c["scale"] for c in longer["curve"]]
    assert scales[0] == 0.25 and scales[-1] == 16.0 and len(scales) == len(short["curve"]) + 2 * cg.GRID
    assert longer["curve"][:len(short["curve"])] == short["curve"]
    lis, extra = Listener.load(Engine(cg.fold_bundle()), fold / "listened_4.npz")
    assert longer["curve"][-1] == {"scale": 16.0, **cg.sweep_point(lis.heard(16 * longer["threshold"]),
                                                                    extra["in_view"].tolist())}
    assert {p.name for p in fold.glob("gate_curve*.json")} == {"gate_curve_4.json", "gate_curve_4_top16.json"}

    def never_wrong(fold, source, *a, **k):   # beacon on rises with the scale, never wrong: the top is chosen
        pts = [{"scale": m, "beacon_on": min(1.0, m / 32), "confidently_wrong": 0.0, "confidently_wrong_frames": 0,
                "silence_no_crossing": 1.0, "beacon_on_goal_in_view": min(1.0, m / 32)}
               for m in cg.gate_scales(cg.GRID, k["top"])]   # main passes --max-scale as top
        return {"landscape": {"source": source, "frames": 100, "no_crossing_frames": 50, "goal_in_view_frames": 100,
                              "curve": pts}}

    monkeypatch.setattr(cg, "read_manifest", lambda path: type("M", (), {"rows": []})())
    monkeypatch.setattr(cg, "finished_folds", lambda cv: [(cv / "fold-ptl_x", "ptl:x")])
    monkeypatch.setattr(cg, "fold_curve", never_wrong)
    cv = tmp_path / "cv"
    assert cg.main([str(cv), "--portrait", "0"]) == 0
    chosen = json.loads((cv / "gate.json").read_text())
    assert chosen["scale"] == 4.0 and chosen["targets_met"] and chosen["at_sweep_top"]
    assert "sweep further with --max-scale 8" in capsys.readouterr().out
    assert cg.main([str(cv), "--portrait", "0", "--max-scale", "16"]) == 0
    further = json.loads((cv / "gate_top16.json").read_text())
    assert further["scale"] == 16.0 and further["at_sweep_top"]
    assert json.loads((cv / "gate.json").read_text()) == chosen      # the default sweep's record kept
    with pytest.raises(SystemExit):
        cg.main([str(cv), "--max-scale", "3"])


def test_choose_gate_measure_far_mass_replays_the_saved_clips_at_absolute_thresholds(tmp_path, monkeypatch):
    """``--measure far_mass``: the fold's saved predictions decided again with the far-mass gate at
    :data:`FAR_MASS_REFERENCE` times each scale, without the model, cached apart from the bundle's
    own (entropy) curve; the curve's result says which measure and reference it swept."""
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import Listener

    cg, ptl, neg, fold = _toy_fold(tmp_path, monkeypatch, photos=4, no_crossing=2)
    own = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 4, 0, 0)["landscape"]

    def no_model(*a, **k):
        raise AssertionError("another measure replays the saved predictions")

    monkeypatch.setattr(Engine, "predict", no_model)
    fm = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 4, 0, 0, measure="far_mass")["landscape"]
    assert (own["measure"], fm["measure"], fm["threshold"]) == ("entropy", "far_mass", cg.FAR_MASS_REFERENCE)
    assert {p.name for p in fold.glob("gate_curve*.json")} == {"gate_curve_4.json", "gate_curve_4_far_mass.json"}
    lis, extra = Listener.load(Engine(cg.fold_bundle()), fold / "listened_4.npz", "far_mass")
    at = {c["scale"]: c for c in fm["curve"]}
    for m in (0.25, 1.0, 4.0):   # each point is the saved clips decided with the far-mass gate at 0.01 x m
        want = cg.sweep_point(lis.heard(m * cg.FAR_MASS_REFERENCE), extra["in_view"].tolist())
        assert {k: at[m][k] for k in want} == want


def test_choose_gate_zoom_magnifies_narrow_frames_up_to_z_and_caches_them_apart(tmp_path, monkeypatch):
    """``--zoom Z``: the engine's geometry gets ``view_zoom`` Z, so a frame narrower than the training
    camera keeps the rows of a view magnified ``min(t, Z)`` times (``t = tan(train / 2) / tan(fov / 2)``)
    and a large Z fills the canvas; a 4:3 frame at the training FOV is not touched; the views are
    still cut for the bundle's own geometry; portrait curves under a zoom are cached apart, the
    landscape one is shared."""
    import math
    from dataclasses import dataclass
    from types import SimpleNamespace

    from crossing_assist.geometry import Geometry

    import choose_gate as cg

    @dataclass(frozen=True)
    class _Bundle:
        geometry: Geometry

    geo, canvas = Geometry(fit="letterbox", view_crop=True), (168, 224)
    t = math.tan(math.radians(67.0) / 2) / math.tan(math.radians(53.0) / 2)
    for zoom in (1.0, 1.2, 4.0):
        engine = SimpleNamespace(bundle=_Bundle(geo))
        assert cg.magnify_view_crop(engine, zoom) is geo
        seen = engine.bundle.geometry
        assert seen.view_zoom == zoom
        assert seen.rows_seen(640, 480, 53.0, canvas)[1] == math.floor(480 * 168 / 224 * max(1.0, t / zoom) + 0.5)
        assert seen.rows_seen(480, 640, 67.0, canvas) == (0, 480)
    assert geo.rows_seen(640, 480, 53.0, canvas)[1] == 478 and seen.rows_seen(640, 480, 53.0, canvas)[1] == 360

    from runtime_toy import make_toy_bundle

    from crossing_assist.testing.toy_bundle import Toy

    cg, ptl, neg, fold = _toy_fold(tmp_path, monkeypatch, photos=2, no_crossing=2)
    cropped = make_toy_bundle(tmp_path / "cropped", Toy(samples=1, drop_p=0.0, geometry=geo))
    monkeypatch.setattr(cg, "fold_bundle", lambda *a, **k: cropped)
    plain = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 2, 0, 1)
    zoomed = cg.fold_curve(fold, "ptl:x", ptl, neg, set(), 2, 0, 1, zoom=1.5)
    assert zoomed["landscape"] == plain["landscape"] and zoomed["portrait"]["frames"] == 2
    assert {p.name for p in fold.glob("gate_curve*.json")} == {
        "gate_curve_2.json", "gate_curve_2_portrait1.json", "gate_curve_2_portrait_window1.json",
        "gate_curve_2_portrait1_zoom1.5.json", "gate_curve_2_portrait_window1_zoom1.5.json"}
    with pytest.raises(SystemExit):
        cg.main([str(tmp_path / "cv"), "--zoom", "0.5"])


def test_choose_gate_calibration_subset_reads_its_photos_through_a_linked_cv_folder(tmp_path):
    """A fold reached through a link (a CV split across machines or processes) writes its
    calibration subset relative to where the fold really is, so it reads back from either path."""
    import choose_gate as cg
    from runtime_toy import bar_dataset

    from crossing_assist.data_tools.manifest import read_manifest

    ds = read_manifest(bar_dataset(tmp_path / "data" / "ptl", 3, split="val", source="ptl:y"))
    real = tmp_path / "runs" / "cv" / "fold-ptl_x"
    real.mkdir(parents=True)
    link = tmp_path / "elsewhere" / "deeper" / "still" / "fold-ptl_x"
    link.parent.mkdir(parents=True)
    link.symlink_to(real)
    cg._subset(ds, ds.rows, link / "calib_data")
    for path in (real / "calib_data", link / "calib_data"):
        sub = read_manifest(path)
        assert [sub.image_path(r).resolve() for r in sub.rows] == [ds.image_path(r).resolve() for r in ds.rows]


def test_robustness_table_also_pools_the_folds_of_another_run_weighted_by_frames(tmp_path, monkeypatch):
    """``robustness_table.py --also CV2``: every fold of both runs enters each condition's pooled rate,
    weighted by its frame count, and each keeps its own key in the per-fold figures."""
    import json

    import robustness_table as rt

    def table(source, accuracy, frames):
        row = {"accuracy": accuracy, "bin_mae": 0.5, "beacon_on": 0.8, "confidently_wrong": 0.01,
               "silence_no_crossing": 1.0, "frames_with_crossing": frames, "frames_without_crossing": frames // 2}
        return {"source": source, **{c: row for c in rt.CONDITIONS}}

    acc = {tmp_path / "a": 0.6, tmp_path / "b": 0.9}
    for cv in acc:
        cv.mkdir()
    monkeypatch.setattr(rt, "read_manifest", lambda path: type("M", (), {"rows": []})())
    monkeypatch.setattr(rt, "finished_folds", lambda cv: [(cv / "fold-ptl_x", "ptl:x")])
    monkeypatch.setattr(rt, "fold_table", lambda fold, source, *a: table(source, acc[fold.parent], 30 if fold.parent.name == "a" else 10))

    assert rt.main([str(tmp_path / "a"), "--also", str(tmp_path / "b")]) == 0
    out = json.loads((tmp_path / "a" / "robustness.json").read_text())
    assert out["folds"] == ["ptl:x", f"ptl:x ({tmp_path / 'b'})"]
    assert out["pooled_runs"] == [str(tmp_path / "a"), str(tmp_path / "b")]
    clean = out["conditions"]["clean"]
    assert clean["accuracy"] == pytest.approx((0.6 * 30 + 0.9 * 10) / 40)
    assert clean["accuracy_per_fold"] == {"ptl:x": 0.6, f"ptl:x ({tmp_path / 'b'})": 0.9}


def test_saved_outputs_read_the_first_frames_of_choose_gates_clips_goal_in_view_and_no_crossing(tmp_path):
    """--view: the clips scripts/choose_gate.py saved (``Listener.save``), each clip's first frame;
    a portrait view keeps its no-crossing clips and those whose goal is in view, a failed frame is None."""
    from runtime_toy import bar_frame, make_toy_bundle

    from crossing_assist.actions import UNKNOWN, bin_center_x
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import Listener

    lis = Listener(Engine(make_toy_bundle(tmp_path / "toy")), seconds=0.2)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip)), strip)
    lis.add(bar_frame(None), UNKNOWN)
    lis.add(np.zeros((4, 4), np.uint8), 4)          # fails
    fold = tmp_path / "fold-ptl_a"
    fold.mkdir()
    lis.save(fold / f"listened{gs.view_tag(True, 7, 0, 'portrait_window', 3)}.npz", in_view=np.asarray([0, 2, 4]))
    out = gs.saved_outputs(fold, "portrait_window", 7, 0, True, 3)
    assert out["labels"] == [2, 11, UNKNOWN, 4] and out["mutual_info"] is None   # strip 6's goal is out of view
    assert [int(np.argmax(p)) for p in out["probs"][:2]] == [2, 11] and out["probs"][2] is not None
    assert np.allclose(out["probs"][0], lis.clips[0][0].probs) and out["probs"][3] is None
    assert gs.saved_outputs(fold, "portrait", 7, 0, True, 3) is None            # not listened to


def test_robustness_table_replays_saved_plays_with_another_bundles_gate(tmp_path, monkeypatch):
    """``robustness_table.py --gate BUNDLE``: each condition's saved plays are decided again with
    that bundle's measure and thresholds, without the model: a far-mass gate that trusts nothing
    silences the beacon, one that trusts everything plays it for every crossing; the fold's own
    gate is cached apart; a gate whose measure saved plays cannot replay is one error line."""
    from runtime_toy import bar_frame, make_toy_bundle

    import robustness_table as rt
    from crossing_assist.actions import UNKNOWN, bin_center_x
    from crossing_assist.bundle import UncertaintySpec
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.listen import Listener

    toy = make_toy_bundle(tmp_path / "toy")
    lis = Listener(Engine(toy), seconds=0.3)
    for strip in (2, 6, 11):
        lis.add(bar_frame(bin_center_x(strip)), strip)
    lis.add(bar_frame(None), UNKNOWN)
    fold = tmp_path / "cv" / "fold-ptl_a"
    fold.mkdir(parents=True)
    for condition in rt.CONDITIONS:
        lis.save(fold / f"listened_robustness{rt.draw_tag(True, 7, 0)}_{condition}.npz")
    monkeypatch.setattr(rt, "fold_bundle", lambda *a: toy)
    monkeypatch.setattr(rt, "held_out_rows", lambda *a: pytest.fail("saved plays must be replayed, not listened again"))

    def table(gate):
        return rt.fold_table(fold, "ptl:a", None, None, set(), 7, 0, True, gate)

    never, always = UncertaintySpec("far_mass", 1e-12), UncertaintySpec("far_mass", 1.0)
    assert all(table(never)[c]["beacon_on"] == 0.0 for c in rt.CONDITIONS)
    loud = table(always)
    assert all(loud[c]["beacon_on"] == 1.0 for c in rt.CONDITIONS)
    assert not (fold / "robustness_mirror_7.json").exists()       # only the fold's own gate is cached
    own = table(None)
    assert (fold / "robustness_mirror_7.json").is_file() and own["clean"]["accuracy"] == loud["clean"]["accuracy"]
    mi = make_toy_bundle(tmp_path / "mi")
    meta = json.loads((mi / "bundle.json").read_text())
    meta["calibration"]["uncertainty"]["measure"] = "mutual_info"
    (mi / "bundle.json").write_text(json.dumps(meta))
    monkeypatch.setattr(rt, "read_manifest", lambda path: type("M", (), {"rows": []})())
    monkeypatch.setattr(rt, "read_bundle", lambda path: type("B", (), {"calibration": type("C", (), {
        "uncertainty": UncertaintySpec("mutual_info", 0.2)})()})())
    assert rt.main([str(tmp_path / "cv"), "--gate", str(mi)]) == 2


def test_robustness_table_ensemble_averages_each_photographers_plays_across_runs(tmp_path, monkeypatch):
    """``robustness_table.py --also … --ensemble --gate BUNDLE``: per photographer, the runs' saved
    plays of each condition are averaged frame by frame and decided with the gate, so two runs that
    place every goal right outvote a third that hears no crossing anywhere (pooled: 2 of 3 right);
    the table is written apart, naming the runs it merged."""
    import shutil

    from runtime_toy import bar_frame, make_toy_bundle

    import robustness_table as rt
    from crossing_assist.actions import UNKNOWN, bin_center_x
    from crossing_assist.bundle import UncertaintySpec
    from crossing_assist.runtime.engine import Engine

    toy = make_toy_bundle(tmp_path / "toy")
    strips = (2, 6, 11)
    runs = [tmp_path / name for name in ("a", "b", "c")]
    for cv, right in zip(runs, (True, True, False)):
        fold = cv / "fold-ptl_x"
        shutil.copytree(toy, fold / "bundle")
        lis = rt.Listener(Engine(toy), seconds=0.3)
        for strip in strips:
            lis.add(bar_frame(bin_center_x(strip) if right else None), strip)
        lis.add(bar_frame(None), UNKNOWN)
        for condition in rt.CONDITIONS:
            lis.save(fold / f"listened_robustness{rt.draw_tag(False, 7, 0)}_{condition}.npz")
    monkeypatch.setattr(rt, "read_manifest", lambda path: type("M", (), {"rows": []})())
    monkeypatch.setattr(rt, "finished_folds", lambda cv: [(cv / "fold-ptl_x", "ptl:x")])
    monkeypatch.setattr(rt, "fold_bundle", lambda fold, *a: fold / "bundle")
    monkeypatch.setattr(rt, "held_out_rows", lambda *a: pytest.fail("saved plays must be replayed, not listened again"))
    monkeypatch.setattr(rt, "read_bundle", lambda path: type("B", (), {"calibration": type("C", (), {
        "uncertainty": UncertaintySpec("far_mass", 1.0)})()})())
    also = [arg for cv in runs[1:] for arg in ("--also", str(cv))]

    assert rt.main([str(runs[0]), *also, "--frames", "7", "--gate", str(toy)]) == 0
    pooled = json.loads((runs[0] / "robustness_gate.json").read_text())["conditions"]
    assert pooled["clean"]["accuracy"] == pytest.approx(2 / 3)
    assert rt.main([str(runs[0]), *also, "--frames", "7", "--gate", str(toy), "--ensemble"]) == 0
    out = json.loads((runs[0] / "robustness_gate_ensemble3.json").read_text())
    assert out["folds"] == ["ptl:x"] and out["ensemble_of_runs"] == [str(cv) for cv in runs]
    assert all(out["conditions"][c]["accuracy"] == 1.0 and out["conditions"][c]["beacon_on"] == 1.0
               for c in rt.CONDITIONS)
    with pytest.raises(SystemExit):   # an ensemble needs the other runs and a gate to decide with
        rt.main([str(runs[0]), "--ensemble", "--gate", str(toy)])

"""Choose the default bundle's gate thresholds, one per orientation, on photographers the model never trained on.

For each fold of a leave-one-photographer-out run (``crossing-train --cv source``, folder
``CV/fold-<source>``): export the fold's model as a bundle, calibrated on PTL val *without* the
held-out photographer; play the held-out photographer's unseen photos (their train-split
photos, which the fold never saw) and unseen no-crossing views (the ``negatives`` rows that no
model trained on) through the runtime (:mod:`crossing_assist.runtime.listen`), as taken
(landscape) and in portrait (``--portrait`` views a photo, :func:`portrait_sets`): ``portrait``,
what a phone held in portrait at the bundle's portrait FOV sees from the same spot (the user's
case, which sets the portrait threshold), and ``portrait_window``, 3:4 windows of the photo (a
narrower camera, reported only); a goal out of view lies in the edge strip. Sweep the gate
threshold as a multiple ``m`` of the bundle's own fitted threshold. Per orientation the folds' rates are pooled per ``m``, and ``m*``
is the largest beacon-on rate with confidently wrong <= 0.5 % and silence on no-crossing frames
>= 98 % (else the point nearest those targets). A portrait strip is 0.75 of a landscape one on
the canvas (0.56 for a 3:4 window), so
the same angular doubt spreads over more strips and one landscape-fitted threshold silences
portrait frames: hence a scale per orientation. Writes ``CV/gate.json`` and
``CV/gate_risk_coverage.png`` (``--mirror``: the folds' bundles with mirror test-time
augmentation, ``CV/gate_mirror.json``); ``scripts/build_default_bundle.sh`` exports with
``--gate-scale m*_landscape --gate-scale-portrait m*_portrait``. ``--also CV2`` pools the folds of
another CV run of the same recipe (another ``--seed``) with CV's before choosing; with more than
one run, each view also records ``leave_one_run_out``: each run measured at the scale the rule
picks on the others (how far a threshold chosen this way carries to another model). Each view
also records ``leave_one_photographer_out``: each photographer measured at the scale the rule
picks on the other photographers (how far the choice carries to a user it never saw).
``--portrait-frames N`` draws the portrait views from N photos a fold instead of ``--frames``: a
landscape photo is one clip, its portrait views 2 x ``--portrait`` clips, so ``--frames 100000
--portrait-frames 200`` chooses landscape on every held-out photo without playing every photo's
portrait views too. ``--grid 16`` sweeps twice as many scales as crossing-eval (16 a doubling), for
a curve that jumps between neighbouring scales; ``--max-scale 16`` sweeps on past crossing-eval's
largest scale (4), for a view whose choice sits there (said as a warning: the curve was cut short,
not the limit reached), deciding only the clips at the new scales. ``--zoom Z`` is for models trained with
``crossing-train --field-zoom``: the portrait views are shown magnified up to Z instead of at the
training scale, as ``crossing-export --view-zoom Z`` bundles show them (:func:`magnify_view_crop`),
cached and written apart. ``--measure far_mass`` replays the saved plays with the far-mass gate (the
probability beyond one strip of the argmax) at absolute thresholds, ``FAR_MASS_REFERENCE`` (0.01) x
the scales (the folds' records carry it as ``threshold``), written to ``gate…_far_mass.json``, which
``scripts/stamp_bundle.py --rescale-gate`` and ``scripts/build_default_bundle.sh`` stamp.

    .venv/bin/python scripts/choose_gate.py runs/default/cv --ptl runs/data/ptl --neg runs/data/neg \
        --used-neg runs/data/neg_half --frames 200 --portrait 3
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from crossing_assist.data_tools.augment import PORTRAIT_SETS, user_views
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest, write_manifest
from crossing_assist.fileio import atomic_write_text
from crossing_assist.geometry import VIEW_ZOOM_RANGE
from crossing_assist.runtime.listen import Listener, summarise

from crossing_assist.models.evaluate import GATE_TOP as TOP, gate_scales  # noqa: E402  (crossing-eval's grid by default)

GRID = 8                    # gate scales a doubling, as crossing-eval sweeps
#: ``--measure far_mass``: the threshold its scales multiply (1 % of the mass beyond one strip of the
#: argmax); the folds' bundles fitted an entropy threshold, not this, so far mass is swept absolutely.
FAR_MASS_REFERENCE = 0.01


def measure_tag(measure: str | None) -> str:
    """File-name suffix of what was measured with a gate measure other than the bundle's (``_far_mass``)."""
    return f"_{measure}" if measure else ""


def reference_threshold(engine, measure: str | None) -> float:
    """The threshold the sweep's scales multiply: the bundle's own fitted one for its own measure,
    :data:`FAR_MASS_REFERENCE` for far mass."""
    return FAR_MASS_REFERENCE if measure == "far_mass" else engine.decision_config().threshold


def _subset(ds, rows, out: Path) -> Path:
    """A dataset folder holding ``rows`` of ``ds`` (image paths re-rooted, nothing copied; relative
    to where the folder really is, so a CV folder reached through a link reads them too)."""
    out.mkdir(parents=True, exist_ok=True)
    real = out.resolve()
    fixed = [r.__class__(os.path.relpath(os.path.realpath(ds.image_path(r)), real), r.label, r.far_x, r.source, r.split,
                         r.votes, r.flags)
             for r in rows]
    write_manifest(out, fixed)
    return out


def top_tag(top: float) -> str:
    """File-name suffix of a sweep that tops out at another scale than crossing-eval's (``--max-scale``)."""
    return "" if top == TOP else f"_top{top:g}"


def upper_tag(upper: bool) -> str:
    """File-name suffix of a choice made at the confidently-wrong rate's upper 95 % bound (:func:`choose`)."""
    return "_upper" if upper else ""


def tag(mirror: bool) -> str:
    """File-name suffix of what was measured with the folds' mirror-TTA bundles."""
    return "_mirror" if mirror else ""


def zoom_tag(zoom: float) -> str:
    """File-name suffix of portrait views magnified up to ``zoom`` (:func:`magnify_view_crop`)."""
    return f"_zoom{zoom:g}" if zoom > 1 else ""


def draw_tag(mirror: bool, frames: int, seed: int) -> str:
    """File-name suffix of a fold's cached measurement on one held-out draw (:func:`held_out_rows`):
    another ``--frames`` or ``--seed`` is another draw, never a stale cache."""
    return f"{tag(mirror)}_{frames}" + (f"_seed{seed}" if seed else "")


def view_tag(mirror: bool, frames: int, seed: int, view: str, portrait: int, zoom: float = 1.0) -> str:
    """File-name suffix of a fold's cached measurement of ``view`` on one held-out draw: the
    portrait kinds add their name, views a photo and zoom (``listened…npz``, ``gate_curve…json``)."""
    return draw_tag(mirror, frames, seed) + ("" if view == "landscape" else f"_{view}{portrait}{zoom_tag(zoom)}")


def view_draws(n_frames: int, portrait_frames: int | None, seed: int, portrait: int, mirror: bool, zoom: float):
    """``(view, photos drawn, draw tag)`` of each view a fold is listened to as: landscape on
    ``n_frames`` photos, the portrait kinds (with ``portrait`` views a photo) on ``portrait_frames``
    (default ``n_frames``)."""
    for view in ("landscape", *(PORTRAIT_SETS if portrait else ())):
        n = n_frames if view == "landscape" or portrait_frames is None else portrait_frames
        yield view, n, view_tag(mirror, n, seed, view, portrait, zoom)


def curve_cache(fold: Path, draw: str, grid: int, measure: str | None, extra: str = "", top: float = TOP) -> Path:
    """Where a fold's swept curve of one draw (:func:`view_tag`) is cached: another grid, top,
    measure or ``extra`` (an ensemble's ``_ensembleK``) is a file of its own."""
    return fold / (f"gate_curve{draw}{'' if grid == GRID else f'_grid{grid}'}{top_tag(top)}"
                   f"{measure_tag(measure)}{extra}.json")


def fold_bundle(fold: Path, source: str, ptl, mirror: bool = False) -> Path:
    """The fold's model exported as a bundle (once), calibrated on PTL val without ``source``;
    ``mirror``: with mirror test-time augmentation (folder ``bundle_mirror``)."""
    from crossing_assist.export.exporter import ExportConfig, export_bundle

    bundle = fold / f"bundle{tag(mirror)}"
    if not (bundle / "bundle.json").is_file():
        cal = _subset(ptl, [r for r in ptl.rows if r.split == "val" and r.source != source], fold / "calib_data")
        export_bundle(ExportConfig(run=str(fold), out=str(bundle), calib_data=str(cal), calib_split="val",
                                   progress=False, threads=1, mirror=mirror), log=lambda s: print(f"  {s}", file=sys.stderr))
    return bundle


def held_out_rows(ptl, neg, source: str, used: set[str], n_frames: int, seed: int) -> tuple[list, list]:
    """``n_frames`` photos of ``source`` that its fold never trained on (its train-split photos)
    and half as many no-crossing views no model trained on; the same draw for every script."""
    pos = [r for r in ptl.rows if r.split == "train" and r.source == source]
    negs = [r for r in neg.rows if r.source == source and r.image not in used]
    pick_pos, pick_neg = draw_indices(len(pos), len(negs), n_frames, seed)
    return [pos[i] for i in pick_pos], [negs[i] for i in pick_neg]


def draw_indices(n_pos: int, n_neg: int, n_frames: int, seed: int) -> tuple[list[int], list[int]]:
    """The draw of :func:`held_out_rows`, as indices (sorted) into a photographer's ``n_pos``
    unseen photos and ``n_neg`` unseen no-crossing views: ``n_frames`` photos and half as many views."""
    rng = np.random.default_rng(seed)
    pos = sorted(rng.choice(n_pos, min(n_frames, n_pos), replace=False))
    neg = sorted(rng.choice(n_neg, min(n_frames // 2, n_neg), replace=False))
    return [int(i) for i in pos], [int(i) for i in neg]


def model_accuracy(lis: Listener, in_view: list[int] | None = None) -> dict:
    """The model's own accuracy and bin MAE over the clips with a crossing: the argmax of each
    clip's first frame (a failed inference counts as wrong), no decision logic; with ``in_view``
    (clip indices) also over the clips whose goal is in view (``accuracy_goal_in_view``)."""
    labels = np.asarray(lis.labels)
    first = np.asarray([clip[0].action if clip[0].ok else -1 for clip in lis.clips])
    err = np.abs(first - labels)
    out = {"accuracy": float((err[labels != 0] == 0).mean()), "bin_mae": float(err[labels != 0].mean())}
    if in_view:
        out["accuracy_goal_in_view"] = float((err[in_view] == 0).mean())
    return out


def listen(engine, view: str, ptl, neg, rows: tuple[list, list], portrait: int,
           geometry=None) -> tuple[Listener, list[int]]:
    """The held-out ``rows`` (photos, no-crossing views) played through ``engine`` as ``view``
    (landscape, or ``portrait`` views a photo of a portrait kind), and the indices of the clips
    whose goal is in view. The views are cut for ``geometry`` (default: the engine's bundle's)."""
    lis, in_view = Listener(engine), []
    for ds, part in zip((ptl, neg), rows):
        for r in part:
            img = load_frame(ds.image_path(r), r.flags)
            for win, _, lab, inside, fov in user_views(img, r.far_x, r.label, 0 if view == "landscape" else portrait,
                                                       geometry or engine.bundle.geometry)[view]:
                if inside:
                    in_view.append(len(lis.labels))
                lis.add(win, lab, fov)
    return lis, in_view


def magnify_view_crop(engine, zoom: float):
    """``--zoom``: ``engine`` shows a frame narrower than the training camera magnified by up to
    ``zoom`` instead of at the training scale, as a bundle exported with ``crossing-export
    --view-zoom`` would (``geometry.view_zoom``, :func:`crossing_assist.geometry.view_rows`), without
    exporting the fold again: the engine's copy of the geometry is replaced in this process.
    Returns the bundle's own geometry (to cut the views with)."""
    geometry = engine.bundle.geometry
    engine.bundle = replace(engine.bundle, geometry=replace(geometry, view_zoom=zoom))
    return geometry


def sweep_point(heard: list, in_view: list[int]) -> dict:
    """One point of a curve: the rates of ``heard`` (:func:`summarise`) and the beacon-on rate
    over the clips whose goal is in view (``in_view``, indices into ``heard``)."""
    return {**summarise(heard), "beacon_on_goal_in_view": summarise([heard[i] for i in in_view])["beacon_on"]}


def fold_curve(fold: Path, source: str, ptl, neg, used: set[str], n_frames: int, seed: int, portrait: int,
               mirror: bool = False, portrait_frames: int | None = None, grid: int = GRID, zoom: float = 1.0,
               measure: str | None = None, top: float = TOP) -> dict:
    """The fold's held-out curves: ``{"landscape": {...}, "portrait": {...}, "portrait_window": {...}}``
    (the portrait ones only with ``portrait`` > 0 views a photo, on a draw of ``portrait_frames``
    photos, default ``n_frames``), swept over :func:`gate_scales` ``(grid, top)``; each curve cached in
    the fold folder (another grid or top is another cache), and the predictions listened to too
    (``listened…npz``, :meth:`Listener.save`), so another grid is swept without the model.
    ``zoom`` > 1: the portrait views magnified up to it (:func:`magnify_view_crop`), cached apart;
    landscape frames at the training FOV are not magnified, so their curve is the same.
    ``measure``: the gate replayed with this measure (``far_mass``) instead of the bundle's, its
    thresholds :data:`FAR_MASS_REFERENCE` times the scales, from the same listened predictions."""
    from crossing_assist.runtime.engine import Engine

    bundle = fold_bundle(fold, source, ptl, mirror)
    engine = geometry = None
    out = {}
    for view, n, draw in view_draws(n_frames, portrait_frames, seed, portrait, mirror, zoom):
        done = curve_cache(fold, draw, grid, measure, top=top)
        if done.is_file():   # listened to already (the fold does not change once finished)
            out[view] = json.loads(done.read_text())
            continue
        if engine is None:
            engine = Engine(bundle, threads=1)
            geometry = magnify_view_crop(engine, zoom)
        heard = fold / f"listened{draw}.npz"
        lis = None
        if not heard.is_file():
            lis, in_view = listen(engine, view, ptl, neg, held_out_rows(ptl, neg, source, used, n, seed), portrait,
                                  geometry)
            lis.save(heard, in_view=np.asarray(in_view, np.int64))
        if lis is None or measure:   # listened before, or another measure: recomputed from the saved probabilities
            lis, extra = Listener.load(engine, heard, measure)
            in_view = extra["in_view"].tolist()
        out[view] = curve_result(lis, in_view, engine, source, view, measure, grid, top,
                                 curve_cache(fold, draw, grid, measure))
        atomic_write_text(done, json.dumps(out[view], indent=1))
    return out


def curve_result(lis: Listener, in_view: list[int], engine, source: str, view: str, measure: str | None,
                 grid: int, top: float = TOP, known: Path | None = None) -> dict:
    """A fold's record of one view: its counts, the model's own accuracy and the curve swept over
    :func:`gate_scales` ``(grid, top)`` times :func:`reference_threshold`. ``known``: the cached
    curve of the same clips swept to another top, whose points are taken as they are (a sweep
    carried further decides only the clips at its new scales)."""
    t0 = reference_threshold(engine, measure)
    labels = np.asarray(lis.labels)
    swept = {c["scale"]: c for c in json.loads(known.read_text())["curve"]} if known and known.is_file() else {}
    return {"source": source, "view": view, "measure": measure or engine.measure, "threshold": t0,
            "frames": int((labels != 0).sum()),
            "no_crossing_frames": int((labels == 0).sum()), "goal_in_view_frames": len(in_view),
            **model_accuracy(lis, in_view),
            "curve": [swept.get(m) or {"scale": m, **sweep_point(lis.heard(m * t0), in_view)}
                      for m in gate_scales(grid, top)]}


def ensemble_curves(run_folds: list[tuple[Path, str]], n_frames: int, seed: int, portrait: int, mirror: bool,
                    portrait_frames: int | None, grid: int, zoom: float, measure: str | None,
                    top: float = TOP) -> dict:
    """One held-out photographer's curves for the ensemble of the runs' folds that held it out
    (``run_folds``: (fold folder, source), one a run, each listened to already by :func:`fold_curve`):
    their saved plays averaged frame by frame (:meth:`Listener.average`), as an ensemble bundle of
    the folds' bundles would play them (``crossing-export ensemble``); no model runs. Cached in the
    first run's fold folder (``gate_curve…_ensembleK.json``)."""
    from crossing_assist.runtime.engine import Engine

    fold, source = run_folds[0]
    engine, out, k = None, {}, f"_ensemble{len(run_folds)}"
    for view, _, draw in view_draws(n_frames, portrait_frames, seed, portrait, mirror, zoom):
        done = curve_cache(fold, draw, grid, measure, k, top)
        if done.is_file():
            out[view] = json.loads(done.read_text())
            continue
        if engine is None:
            engine = Engine(fold / f"bundle{tag(mirror)}", threads=1)
            magnify_view_crop(engine, zoom)
        lis, extra = Listener.average(engine, [f / f"listened{draw}.npz" for f, _ in run_folds], measure)
        out[view] = curve_result(lis, extra["in_view"].tolist(), engine, source, view, measure, grid, top,
                                 curve_cache(fold, draw, grid, measure, k))
        atomic_write_text(done, json.dumps(out[view], indent=1))
    return out


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval (95 % with z = 1.96) of a rate of ``k`` in ``n``: how far a
    confidently-wrong rate measured on n frames may be from the rate on many more."""
    if n <= 0:
        return 0.0, 1.0
    p, d = k / n, 1 + z * z / n
    mid, half = (p + z * z / (2 * n)) / d, z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return float(max(0.0, mid - half)), float(min(1.0, mid + half))


def pool(folds: list[dict]) -> list[dict]:
    """Per scale, the folds' rates weighted by their frame counts (the folds share one grid)."""
    scales = [c["scale"] for c in folds[0]["curve"]]
    if any([c["scale"] for c in f["curve"]] != scales for f in folds):
        raise ValueError("the folds' curves were swept over different gate grids")
    out = []
    for i, m in enumerate(scales):
        pts = [(f["curve"][i], f["frames"], f["no_crossing_frames"]) for f in folds]
        frames = sum(a for _, a, _ in pts)
        on = sum(c["beacon_on"] * a for c, a, _ in pts) / frames
        wrong_frames = round(sum(c["confidently_wrong"] * a for c, a, _ in pts))
        sil_n = sum(b for _, _, b in pts)
        sil = sum((c["silence_no_crossing"] or 0) * b for c, _, b in pts) / sil_n if sil_n else None
        vis = [(f["curve"][i].get("beacon_on_goal_in_view"), f.get("goal_in_view_frames", 0)) for f in folds]
        vis_n = sum(n for v, n in vis if v is not None)
        out.append({"scale": m, "beacon_on": on, "confidently_wrong": wrong_frames / frames,
                    "confidently_wrong_frames": wrong_frames, "frames": frames,
                    "confidently_wrong_95": wilson(wrong_frames, frames), "silence_no_crossing": sil,
                    "beacon_on_goal_in_view": sum(v * n for v, n in vis if v is not None) / vis_n if vis_n else None,
                    "per_fold": {f["source"]: f["curve"][i] for f in folds}})
    return out


def leave_one_out(folds: list[dict], group_of: list[str], name: str, upper: bool = False) -> dict | None:
    """How far the rule carries to data it never chose on: each group's folds (``group_of``: each
    fold's group) measured at the scale :func:`choose` picks on the other groups' folds; the
    groups' rates (``per_<name>``) and their pooled beacon-on and confidently-wrong rates. None
    with a single group."""
    groups = list(dict.fromkeys(group_of))
    if len(groups) < 2:
        return None
    per = []
    for group in groups:
        best, met = choose(pool([f for f, g in zip(folds, group_of) if g != group]), upper=upper)
        point = next(c for c in pool([f for f, g in zip(folds, group_of) if g == group]) if c["scale"] == best["scale"])
        per.append({name: group, "scale": best["scale"], "targets_met_on_the_others": met,
                    **{k: point[k] for k in ("beacon_on", "confidently_wrong", "confidently_wrong_frames", "frames")}})
    frames = sum(r["frames"] for r in per)
    wrong = sum(r["confidently_wrong_frames"] for r in per)
    return {"beacon_on": sum(r["beacon_on"] * r["frames"] for r in per) / frames, "confidently_wrong": wrong / frames,
            "confidently_wrong_frames": wrong, "frames": frames, "confidently_wrong_95": wilson(wrong, frames),
            f"per_{name}": per}


def leave_one_run_out(folds: list[dict], run_of: list[str], upper: bool = False) -> dict | None:
    """How far the rule carries to another model: each CV run's folds (``run_of``: each fold's
    run) measured at the scale :func:`choose` picks on the other runs' folds (:func:`leave_one_out`)."""
    return leave_one_out(folds, run_of, "run", upper)


def leave_one_photographer_out(folds: list[dict], upper: bool = False) -> dict | None:
    """How far the rule carries to a photographer it never chose on, as a user is: each held-out
    photographer's folds (every run's) measured at the scale :func:`choose` picks on the other
    photographers' folds (:func:`leave_one_out`)."""
    return leave_one_out(folds, [f["source"].split(" (")[0] for f in folds], "photographer", upper)


def pooled_accuracy(folds: list[dict]) -> dict:
    """The model's own accuracy and bin MAE (argmax of each clip's first frame), weighted by frames."""
    n = sum(f["frames"] for f in folds)
    out = {k: sum(f[k] * f["frames"] for f in folds) / n for k in ("accuracy", "bin_mae") if all(k in f for f in folds)}
    if all("accuracy_goal_in_view" in f for f in folds):
        n = sum(f["goal_in_view_frames"] for f in folds)
        out["accuracy_goal_in_view"] = sum(f["accuracy_goal_in_view"] * f["goal_in_view_frames"] for f in folds) / n
    return out


def choose(curve: list[dict], max_wrong: float = 0.005, min_silence: float = 0.98,
           upper: bool = False) -> tuple[dict, bool]:
    """The pooled curve point with the most beacon-on whose confidently-wrong rate is at most
    ``max_wrong`` and whose silence off-crossing is at least ``min_silence``, and True; else the
    point nearest to those targets, and False. ``upper``: the confidently-wrong rate read is the
    upper end of its 95 % interval (:func:`wilson`) instead of the rate measured, so the point
    chosen is one whose rate on the next photos is unlikely to be over the limit (the measured
    rate at the largest qualifying beacon-on is biased low: ``scripts/fresh_check.py``)."""
    wrong = (lambda c: wilson(c["confidently_wrong_frames"], c["frames"])[1]) if upper else \
        (lambda c: c["confidently_wrong"])  # noqa: E731
    ok = [c for c in curve if wrong(c) <= max_wrong and (c["silence_no_crossing"] or 1) >= min_silence]
    if ok:
        return max(ok, key=lambda c: (c["beacon_on"], -c["scale"])), True
    # nearest to the targets: the smallest excess over them, then the most beacon-on
    excess = lambda c: max(0, wrong(c) - max_wrong) / max_wrong + \
        max(0, min_silence - (c["silence_no_crossing"] or 1)) / (1 - min_silence)  # noqa: E731
    return min(curve, key=lambda c: (excess(c), -c["beacon_on"])), False


def held_out_parser(description: str, frames: int) -> argparse.ArgumentParser:
    """The options every held-out script over a ``--cv source`` run shares."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("cv", type=Path, help="the --cv source run folder (fold-* inside)")
    ap.add_argument("--ptl", default="runs/data/ptl")
    ap.add_argument("--neg", default="runs/data/neg")
    ap.add_argument("--used-neg", default="runs/data/neg_half", help="negatives the models trained on (excluded)")
    ap.add_argument("--frames", type=int, default=frames, help="held-out photos per fold (half as many negatives)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mirror", action="store_true", help="the folds' bundles with mirror test-time augmentation")
    return ap


def add_also(ap: argparse.ArgumentParser) -> None:
    """``--also CV2`` (repeatable): pool the folds of more runs of the same recipe with CV's."""
    ap.add_argument("--also", type=Path, action="append", default=[], metavar="CV2",
                    help="another --cv source run of the same recipe (e.g. another --seed): its folds are pooled "
                         "with CV's, so the figures average over training noise; the result is written in CV")


def finished_folds(cv: Path):
    """``(fold folder, held-out source)`` of each finished fold (a CV still running: those done so far)."""
    import yaml

    from crossing_assist.models.crossval import _fold_metrics

    for fold in sorted(cv.glob("fold-*")):
        args = yaml.safe_load((fold / "args.yaml").read_text()) if (fold / "args.yaml").is_file() else None
        if not args or _fold_metrics(fold, int(args["epochs"])) is None:
            print(f"{fold.name}: not finished, left out", file=sys.stderr)
            continue
        yield fold, args["holdout"][0]


def ensemble_members(by_source: dict[str, list[tuple[Path, str]]], runs: int) -> list[list[tuple[Path, str]]]:
    """The ``(fold, source)`` lists of the photographers every one of ``runs`` runs held out in a
    finished fold (``by_source``: each source's folds, a run each); the others are said and left
    out, and an empty list says so as an error."""
    members = [f for f in by_source.values() if len(f) == runs]
    for source in sorted(set(by_source) - {f[0][1] for f in members}):
        print(f"ensemble: {source} was not held out by every run's finished folds, left out", file=sys.stderr)
    if not members:
        print("error: no photographer held out by every run", file=sys.stderr)
    return members


def main(argv=None) -> int:
    ap = held_out_parser(__doc__.split("\n\n")[0], frames=200)
    ap.add_argument("--portrait", type=int, default=3, help="portrait views a photo, of each kind (0: landscape only)")
    ap.add_argument("--portrait-frames", type=int, metavar="N",
                    help="held-out photos per fold for the portrait views (default: --frames); e.g. --frames 100000 "
                         "chooses landscape on every held-out photo (one view a photo) and portrait on a draw "
                         "(2 x --portrait views a photo)")
    ap.add_argument("--grid", type=int, default=GRID, metavar="STEPS",
                    help=f"gate scales a doubling, from x1/4 to x4 (default {GRID}, crossing-eval's grid); another grid "
                         "is a curve cache of its own, swept from the fold's saved predictions (listened*.npz)")
    add_also(ap)
    ap.add_argument("--measure", choices=("far_mass",),
                    help="replay the gate with this measure instead of the bundles' own (entropy), from the saved "
                         f"predictions: far_mass, the probability beyond one strip of the argmax, at absolute "
                         f"thresholds ({FAR_MASS_REFERENCE:g} x the scales); results are written apart (gate…_far_mass.json) "
                         "and scripts/stamp_bundle.py --rescale-gate --gate-json gate…_far_mass.json stamps them")
    ap.add_argument("--ensemble", action="store_true",
                    help="also choose for the ensemble of the runs (CV and each --also): each photographer's folds' "
                         "plays averaged frame by frame, as crossing-export ensemble of the folds' bundles would "
                         "play them (no model runs); written apart (gate…_ensembleK.json)")
    ap.add_argument("--upper", action="store_true",
                    help="choose where the upper end of the confidently-wrong rate's 95 %% interval, not the rate "
                         "measured, is within the limit: a threshold the next photos are unlikely to push over it "
                         "(scripts/fresh_check.py --upper measures that); written apart (gate…_upper.json)")
    ap.add_argument("--zoom", type=float, default=1.0, metavar="Z",
                    help="portrait frames (narrower than the training camera) shown magnified up to Z instead of at "
                         "the training scale, as crossing-export --view-zoom Z bundles show them (for models trained "
                         "with crossing-train --field-zoom); results are written apart (gate…_zoomZ.json)")
    ap.add_argument("--max-scale", type=float, default=TOP, metavar="M",
                    help=f"the largest gate scale swept (a power of two; default {TOP:g}, crossing-eval's); a choice at "
                         "the top of the sweep is said, since a larger threshold may then hear more within the limits; "
                         "another top is a curve cache of its own, swept from the saved predictions")
    a = ap.parse_args(argv)
    if a.grid < 1:
        ap.error(f"--grid {a.grid}: at least 1 scale a doubling")
    try:
        gate_scales(a.grid, a.max_scale)
    except ValueError as exc:
        ap.error(f"--max-scale: {exc}")
    if not VIEW_ZOOM_RANGE[0] <= a.zoom <= VIEW_ZOOM_RANGE[1]:
        ap.error(f"--zoom {a.zoom}: valid {VIEW_ZOOM_RANGE[0]:g}..{VIEW_ZOOM_RANGE[1]:g}")
    if a.ensemble and not a.also:
        ap.error("--ensemble: pass the other runs of the recipe with --also")
    ptl, neg = read_manifest(a.ptl), read_manifest(a.neg)
    used = {r.image for r in read_manifest(a.used_neg).rows}   # same names: neg_half links neg's images
    folds, run_of, by_source = [], [], {}
    for i, cv in enumerate([a.cv, *a.also]):
        for fold, source in finished_folds(cv):
            print(f"{cv} fold {source}: export + listen", file=sys.stderr, flush=True)
            curves = fold_curve(fold, source, ptl, neg, used, a.frames, a.seed, a.portrait, a.mirror, a.portrait_frames,
                                a.grid, a.zoom, a.measure, top=a.max_scale)
            if i:   # one key per fold in the pooled per-fold figures
                curves = {view: {**c, "source": f"{source} ({cv})"} for view, c in curves.items()}
            folds.append(curves)
            run_of.append(str(cv))
            by_source.setdefault(source, []).append((fold, source))
    if not folds:
        print(f"error: no finished fold in {a.cv}", file=sys.stderr)
        return 2
    report(a, folds, run_of)
    if a.ensemble:
        runs = 1 + len(a.also)
        members = ensemble_members(by_source, runs)
        if not members:
            return 2
        print(f"the ensemble of the {runs} runs:")
        report(a, [ensemble_curves(f, a.frames, a.seed, a.portrait, a.mirror, a.portrait_frames, a.grid, a.zoom,
                                   a.measure, top=a.max_scale) for f in members], [str(a.cv)] * len(members), f"_ensemble{runs}")
    return 0


def report(a: argparse.Namespace, folds: list[dict], run_of: list[str], suffix_extra: str = "") -> None:
    """Pool the folds' curves per view, choose each view's scale, print it and write
    ``CV/gate….json`` and its risk-coverage plots (``suffix_extra`` in their names)."""
    from crossing_assist.models.plots import plot_risk_coverage

    fmt = lambda c: (f"beacon on {c['beacon_on']:.3f} (goal in view {c.get('beacon_on_goal_in_view') or float('nan'):.3f}), "  # noqa: E731
                     f"confidently wrong {100 * c['confidently_wrong']:.2f} % ({c['confidently_wrong_frames']} of {c['frames']}; "
                     f"95 % interval {100 * c['confidently_wrong_95'][0]:.2f}-{100 * c['confidently_wrong_95'][1]:.2f} %), "
                     f"silence off-crossing {c['silence_no_crossing'] if c['silence_no_crossing'] is None else round(c['silence_no_crossing'], 3)}")
    result: dict = {}
    for view in folds[0]:
        curve = pool([f[view] for f in folds])
        best, met = choose(curve, upper=a.upper)
        one = next(c for c in curve if c["scale"] == 1.0)
        model = pooled_accuracy([f[view] for f in folds])
        # the loudest scale swept still within the limits: the curve was cut short, not the limit reached
        at_top = met and best["scale"] == curve[-1]["scale"]
        result[view] = {"scale": best["scale"], "targets_met": met, "at_sweep_top": at_top, "at_scale": best,
                        "at_fitted_threshold": one,
                        "measure": a.measure or folds[0][view].get("measure", "entropy"),   # older caches: entropy
                        **({"threshold": best["scale"] * FAR_MASS_REFERENCE} if a.measure else {}),
                        **model, "curve": curve, "folds": [{k: v for k, v in f[view].items() if k != "curve"} for f in folds]}
        if a.also:
            result[view]["pooled_runs" if not suffix_extra else "ensemble_of_runs"] = [str(cv) for cv in (a.cv, *a.also)]
        carried = {"photographer": leave_one_photographer_out([f[view] for f in folds], a.upper),
                   "run": leave_one_run_out([f[view] for f in folds], run_of, a.upper)}
        for name, rec in carried.items():
            if rec:
                result[view][f"leave_one_{name}_out"] = rec
                print(f"{view}: chosen on the other {name}s, measured on each: beacon on {rec['beacon_on']:.3f}, "
                      f"confidently wrong {100 * rec['confidently_wrong']:.2f} % ({rec['confidently_wrong_frames']} "
                      f"of {rec['frames']}; per {name} " + " / ".join(f"{100 * r['confidently_wrong']:.2f} %"
                                                                   for r in rec[f"per_{name}"]) + ")")
        suffix = (tag(a.mirror) + ("" if view == "landscape" else f"_{view}") + zoom_tag(a.zoom) + measure_tag(a.measure)
                  + upper_tag(a.upper) + top_tag(a.max_scale) + suffix_extra)
        plot_risk_coverage([{"threshold": c["scale"], **c} for c in curve], best["scale"],
                           a.cv / f"gate_risk_coverage{suffix}.png",
                           f"held out, {view}: " + (f"far mass threshold / {FAR_MASS_REFERENCE:g}" if a.measure
                                                    else "gate threshold x scale"))
        if model:
            print(f"{view}: the model's own accuracy {model['accuracy']:.3f}, bin MAE {model['bin_mae']:.3f}"
                  + (f", goal in view {model['accuracy_goal_in_view']:.3f}" if "accuracy_goal_in_view" in model else ""))
        ref = f"far mass {FAR_MASS_REFERENCE:g}" if a.measure else "fitted threshold"
        print(f"{view}: {ref} (scale 1): {fmt(one)}")
        print(f"{view}: chosen scale {best['scale']:g}" + (f" (far mass {best['scale'] * FAR_MASS_REFERENCE:.4g})" if a.measure else "")
              + f" ({'targets met' if met else 'targets NOT met; nearest point'}): {fmt(best)}")
        if at_top:
            print(f"{view}: warning: the largest scale swept ({best['scale']:g}) is still within the limits, so a larger "
                  f"threshold may hear more; sweep further with --max-scale {2 * a.max_scale:g}")
    # landscape stays at the top level (what build_default_bundle.sh and older readers take)
    portrait = {k: result[k] for k in PORTRAIT_SETS if k in result}   # "portrait" sets the portrait threshold
    (a.cv / f"gate{tag(a.mirror)}{zoom_tag(a.zoom)}{measure_tag(a.measure)}{upper_tag(a.upper)}{top_tag(a.max_scale)}"
            f"{suffix_extra}.json").write_text(
        json.dumps({**result["landscape"], **portrait}, indent=1))


if __name__ == "__main__":
    sys.exit(main())

"""How each field condition moves the held-out figures: the leave-one-photographer-out folds'
bundles on their unseen photographer's photos, clean and under each corruption, roll and
portrait, measured as the user meets them.

For each finished fold of a ``crossing-train --cv source`` run (``CV/fold-<source>``): its bundle
(exported once by :mod:`choose_gate`'s ``fold_bundle``, calibrated without that photographer),
the same held-out draw as ``choose_gate.py`` (photos of the photographer the fold never saw, and
no-crossing views no model trained on), each rendered under one condition at a time:
``clean``, every corruption of :mod:`crossing_assist.data_tools.corrupt` (the training's field
views use them all), ``roll`` (10..15 degrees either way), ``portrait`` (what a phone held in
portrait at the bundle's portrait FOV sees from the same spot) and ``portrait_window`` (a 3:4
window of the photo, a narrower camera), each at one of three offsets
(:func:`~crossing_assist.data_tools.augment.portrait_sets`; a goal out of view lies in the edge strip). Each view is played as a 1 s still
clip through the runtime (:class:`~crossing_assist.runtime.listen.Listener`, the bundle's own
gate thresholds). Per condition, pooled over folds: the model's accuracy and bin MAE (argmax of
the clip's first frame), beacon on, confidently wrong and silence on no-crossing views; the
change against ``clean`` beside each; ``--also CV2`` pools the folds of more runs of the recipe
(other seeds) with CV's, and ``--ensemble`` measures their ensemble instead (each photographer's
folds' plays averaged, decided with ``--gate``'s). Writes ``CV/robustness[_mirror].json`` and prints a
markdown table. Each condition's plays are saved in the fold folder
(``listened_robustness…_CONDITION.npz``), so ``--gate BUNDLE`` replays them with that bundle's
gate (its measure, recomputed from the saved probabilities, and its thresholds per orientation
and camera FOV, e.g. the shipped default's) instead of each fold's own, without running the
model again; written to ``CV/robustness[_mirror]_gate.json``.

    .venv/bin/python scripts/robustness_table.py runs/default/cv [--mirror] [--frames 100] [--also CV2 ...] \
        [--gate crossing_assist/assets/default_bundle] [--ensemble]
"""

from __future__ import annotations

import copy
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import (  # noqa: E402  (a sibling script)
    add_also, draw_tag, ensemble_members, finished_folds, fold_bundle, held_out_parser, held_out_rows, model_accuracy,
    tag,
)

from crossing_assist.bundle import BundleError, UncertaintySpec, read_bundle  # noqa: E402
from crossing_assist.data_tools.augment import PORTRAIT_SETS, roll, user_views  # noqa: E402
from crossing_assist.data_tools.corrupt import CORRUPTIONS, corrupt  # noqa: E402
from crossing_assist.data_tools.images import flag_value, load_frame  # noqa: E402
from crossing_assist.data_tools.manifest import read_manifest  # noqa: E402
from crossing_assist.runtime.belief import PROBS_MEASURES  # noqa: E402
from crossing_assist.runtime.listen import Listener, summarise  # noqa: E402

CONDITIONS = ("clean", *CORRUPTIONS, "roll", *PORTRAIT_SETS)


def render(condition: str, img: np.ndarray, far_x: float | None, far_y: float, label: int,
           rng: np.random.Generator, geometry) -> tuple[np.ndarray, int, float | None]:
    """``img`` as seen under ``condition``: (view, its label, its camera FOV or None = the bundle's)."""
    if condition == "clean":
        return img, label, None
    if condition == "roll":
        view, _, lab = roll(img, far_x, far_y, label, float(rng.choice([-1, 1]) * rng.uniform(10, 15)), fill="reflect")
        return view, lab, None
    if condition in PORTRAIT_SETS:
        views = user_views(img, far_x, label, 3, geometry)[condition]
        view, _, lab, _, fov = views[int(rng.integers(len(views)))]
        return view, lab, fov
    return corrupt(img, condition, rng), label, None


def gated(engine, gate: UncertaintySpec | None):
    """``engine`` measuring and deciding with ``gate``'s measure and thresholds (None: its bundle's
    own); a copy, the engine itself is untouched."""
    if gate is None:
        return engine
    out = copy.copy(engine)
    out.bundle = replace(engine.bundle, calibration=replace(engine.bundle.calibration, uncertainty=gate))
    out.measure = gate.measure
    return out


def fold_table(fold: Path, source: str, ptl, neg, used: set[str], n_frames: int, seed: int, mirror: bool,
               gate: UncertaintySpec | None = None) -> dict:
    """Per condition, the fold's rates, decided by the fold's own gate or ``gate``; each
    condition's plays are saved in the fold folder and replayed, and the own-gate table is cached."""
    from crossing_assist.runtime.engine import Engine

    draw = draw_tag(mirror, n_frames, seed)
    done = fold / f"robustness{draw}.json"
    if gate is None and done.is_file():
        return json.loads(done.read_text())
    engine = Engine(fold_bundle(fold, source, ptl, mirror), threads=1)
    images = None
    out = {"source": source}
    for c, condition in enumerate(CONDITIONS):
        saved = fold / f"listened_robustness{draw}_{condition}.npz"
        if not saved.is_file():
            if images is None:
                pos, negs = held_out_rows(ptl, neg, source, used, n_frames, seed)
                images = [(ds, r, load_frame(ds.image_path(r), r.flags)) for ds, rows in ((ptl, pos), (neg, negs))
                          for r in rows]
            rng = np.random.default_rng([seed, c])
            lis = Listener(engine)
            for ds, r, img in images:
                far_y = float(flag_value(r.flags, "far_y") or 0.5)
                view, label, fov = render(condition, img, r.far_x, far_y, r.label, rng, engine.bundle.geometry)
                lis.add(view, label, fov)
            lis.save(saved)
        lis, _ = Listener.load(gated(engine, gate), saved, None if gate is None else gate.measure)
        out[condition] = {**model_accuracy(lis), **summarise(lis.heard())}
        print(f"  {source} {condition}: accuracy {out[condition]['accuracy']:.3f}, beacon on "
              f"{out[condition]['beacon_on']:.3f}, wrong {out[condition]['confidently_wrong']:.4f}", file=sys.stderr, flush=True)
    if gate is None:
        done.write_text(json.dumps(out, indent=1))
    return out


def ensemble_table(run_folds: list[tuple[Path, str]], n_frames: int, seed: int, mirror: bool,
                   gate: UncertaintySpec) -> dict:
    """Per condition, what the ensemble of the runs' folds that held one photographer out hears
    (``run_folds``: (fold, source), a run each, each played already by :func:`fold_table`): their
    saved plays averaged frame by frame (:meth:`Listener.average`, as ``crossing-export ensemble``
    pools its members) and decided with ``gate``; no model runs."""
    from crossing_assist.runtime.engine import Engine

    fold, source = run_folds[0]
    draw = draw_tag(mirror, n_frames, seed)
    engine = gated(Engine(fold / f"bundle{tag(mirror)}", threads=1), gate)
    out = {"source": source}
    for condition in CONDITIONS:
        lis, _ = Listener.average(engine, [f / f"listened_robustness{draw}_{condition}.npz" for f, _ in run_folds],
                                  gate.measure)
        out[condition] = {**model_accuracy(lis), **summarise(lis.heard())}
    return out


def pool(folds: list[dict]) -> dict:
    """Per condition: each rate weighted by its fold's frame count."""
    out = {}
    for condition in CONDITIONS:
        rows = [f[condition] for f in folds]
        row = {}
        for key, count in (("accuracy", "frames_with_crossing"), ("bin_mae", "frames_with_crossing"),
                           ("beacon_on", "frames_with_crossing"), ("confidently_wrong", "frames_with_crossing"),
                           ("silence_no_crossing", "frames_without_crossing")):
            n = sum(r[count] for r in rows)
            row[key] = sum((r[key] or 0) * r[count] for r in rows) / n if n else None
        row["accuracy_per_fold"] = {f["fold"]: f[condition]["accuracy"] for f in folds}
        out[condition] = row
    return out


def markdown(table: dict) -> str:
    clean = table["clean"]
    lines = ["| condition | accuracy | bin MAE | beacon on | confidently wrong | silence, no crossing |",
             "|---|---|---|---|---|---|"]
    for condition, r in table.items():
        d = "" if condition == "clean" else f" ({100 * (r['accuracy'] - clean['accuracy']):+.1f})"
        lines.append(f"| {condition} | {r['accuracy']:.3f}{d} | {r['bin_mae']:.3f} | {100 * r['beacon_on']:.1f} % | "
                     f"{100 * r['confidently_wrong']:.2f} % | {100 * r['silence_no_crossing']:.1f} % |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = held_out_parser(__doc__.split("\n\n")[0], frames=100)
    add_also(ap)
    ap.add_argument("--gate", type=Path, metavar="BUNDLE",
                    help="decide with this bundle's gate (measure and thresholds, e.g. the shipped default's) "
                         "instead of each fold's own, replaying the saved plays")
    ap.add_argument("--ensemble", action="store_true",
                    help="the table of the ensemble of the runs (CV and each --also) instead of their pooled folds: "
                         "each photographer's folds' plays averaged frame by frame, as crossing-export ensemble of "
                         "the folds' bundles plays them, decided with --gate's (e.g. the shipped ensemble's); "
                         "written to CV/robustness…_gate_ensembleK.json")
    a = ap.parse_args(argv)
    if a.ensemble and not (a.also and a.gate):
        ap.error("--ensemble: pass the other runs of the recipe with --also and the gate to decide with (--gate)")
    gate = None
    if a.gate is not None:
        try:
            gate = read_bundle(a.gate).calibration.uncertainty
        except BundleError as exc:
            print(f"error: --gate: {exc}", file=sys.stderr)
            return 2
        if gate.measure not in PROBS_MEASURES:
            print(f"error: --gate: {a.gate} gates with {gate.measure}, which saved plays cannot replay "
                  f"(valid: {', '.join(PROBS_MEASURES)})", file=sys.stderr)
            return 2
    ptl, neg = read_manifest(a.ptl), read_manifest(a.neg)
    used = {r.image for r in read_manifest(a.used_neg).rows}
    folds, by_source = [], {}
    for i, cv in enumerate([a.cv, *a.also]):
        for fold, source in finished_folds(cv):
            print(f"{cv} fold {source}", file=sys.stderr, flush=True)
            # one key per fold in the pooled per-fold figures
            folds.append({**fold_table(fold, source, ptl, neg, used, a.frames, a.seed, a.mirror, gate),
                          "fold": f"{source} ({cv})" if i else source})
            by_source.setdefault(source, []).append((fold, source))
    if not folds:
        print(f"error: no finished fold in {a.cv}", file=sys.stderr)
        return 2
    runs = [str(cv) for cv in (a.cv, *a.also)]
    suffix = "" if gate is None else "_gate"
    if a.ensemble:
        members = ensemble_members(by_source, len(runs))
        if not members:
            return 2
        folds = [{**ensemble_table(m, a.frames, a.seed, a.mirror, gate), "fold": m[0][1]} for m in members]
        suffix += f"_ensemble{len(runs)}"
    table = pool(folds)
    (a.cv / f"robustness{tag(a.mirror)}{suffix}.json").write_text(
        json.dumps({"frames_per_fold": a.frames, "folds": [f["fold"] for f in folds], "conditions": table,
                    **({"ensemble_of_runs" if a.ensemble else "pooled_runs": runs} if a.also else {}),
                    **({} if gate is None else {"gate": {"bundle": str(a.gate), **gate.to_json()}})}, indent=1))
    print(markdown(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())

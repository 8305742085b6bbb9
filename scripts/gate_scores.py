"""Is the gate's uncertainty measure, or the model, what keeps the beacon confidently wrong?

For each fold of one or more leave-one-photographer-out runs (``crossing-train --cv source``), play
the held-out photographer's unseen photos once through the fold's bundle (the same photos as
``scripts/choose_gate.py``) and rank the frames by several per-frame scores: the bundle's entropy
(what the gate uses), the mutual information, ``1 - max p`` and ``1 - P(argmax +- 1 strip)`` (the
model's own probability of *not* being >= 2 strips off, the confidently-wrong criterion). For each
score and beacon-on rate (the beacon on for the frames with the lowest scores; an ``unknown`` argmax
is always off) it prints the confidently-wrong rate (on and >= 2 strips off the label). With several
runs (``--with``) it scores their ensemble too: the mean of the members' probabilities, and the
far mass plus ``--disagreement`` times how much the members disagree (their mutual information:
the entropy of the mean less the members' mean entropy). ``--sheet``
draws the frames confidently wrong at 90 % beacon on and says how far each misses the far point.

``--view portrait|portrait_window|landscape`` scores the clips ``scripts/choose_gate.py`` saved
for that view instead (goal in view; no mutual information); ``--coverages`` sets the beacon-on
rates read.

Frame-level ranking, the first frame's outputs without the decision logic's filter: a still clip
through the runtime sharpens the belief but keeps this order. ``scripts/choose_gate.py`` measures
what is heard.

    .venv/bin/python scripts/gate_scores.py runs/default/cv --mirror --frames 200 \
        --with runs/ablation/no_corruption/cv
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from crossing_assist.actions import N_BINS, get_space
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.runtime.belief import entropy
from crossing_assist.runtime.listen import WRONG_STRIPS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import (draw_tag, finished_folds, fold_bundle, held_out_parser, held_out_rows,  # noqa: E402  (a sibling script)
                         tag, view_tag)

COVERAGES = (0.5, 0.6, 0.7, 0.8, 0.9)


def window_mass(probs: np.ndarray, k: int = 1) -> np.ndarray:
    """Per frame, the probability of the strips within ``k`` of the argmax (0 when the argmax is unknown)."""
    a = probs.argmax(1)
    out = np.zeros(len(probs))
    for i, j in enumerate(a):
        if j:
            out[i] = probs[i, max(1, j - k):min(probs.shape[1] - 1, j + k) + 1].sum()
    return out


def member_disagreement(members: list[np.ndarray]) -> np.ndarray:
    """Per frame, how much ensemble members' probabilities (each ``[frames, A]``) disagree: the
    entropy of their mean less their mean entropy (the mutual information between the prediction
    and the member, as ``crossing_assist.models.mc`` computes it over MC samples, without torch;
    0 when all agree)."""
    ent = lambda p: np.array([entropy(q) for q in p])  # noqa: E731
    return np.maximum(0.0, ent(np.mean(members, 0)) - np.mean([ent(m) for m in members], 0))


def scores(probs: np.ndarray, mutual_info: np.ndarray | None = None, disagreement: np.ndarray | None = None,
           weights: tuple[float, ...] = ()) -> dict[str, np.ndarray]:
    """The per-frame scores compared (lower = surer); with the members' ``disagreement``, the far
    mass plus each of ``weights`` times it."""
    far = 1.0 - window_mass(probs)
    out = {"entropy": np.array([entropy(p) for p in probs]), "1 - max p": 1.0 - probs.max(1), "1 - P(argmax +- 1)": far}
    if mutual_info is not None:
        out["mutual information"] = np.asarray(mutual_info, float)
    if disagreement is not None:
        for w in weights:
            out[f"1 - P(argmax +- 1) + {w:g} x members' disagreement"] = far + w * disagreement
    return out


def beacon_on(score: np.ndarray, pred: np.ndarray, labels: np.ndarray, coverage: float) -> np.ndarray:
    """Per frame, whether the beacon is on when it is on for the frames with a crossing whose score is
    among the lowest ``coverage`` of them (an unknown argmax stays off; no-crossing frames under the
    same threshold are on too)."""
    pos, known = labels != 0, pred != 0
    s = np.where(known, score, np.inf)
    return known & (s <= np.quantile(s[pos], coverage, method="lower"))


def confidently_wrong(on: np.ndarray, pred: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Per frame: the beacon on, a crossing in view and the argmax >= 2 strips off its label."""
    return on & (labels != 0) & (np.abs(pred - labels) >= WRONG_STRIPS)


def miss_strips(far_x: np.ndarray, pred: np.ndarray, n_actions: int) -> np.ndarray:
    """How far the beacon points from the labelled far point: the distance from ``far_x`` to the
    centre of the predicted action, in strip widths (a frame 2 strips off by label may miss by 1.5)."""
    space = get_space(n_actions)
    centre = np.array([space.action_center_x(int(a)) for a in pred])
    return np.abs(np.asarray(far_x, float) - centre) * N_BINS


def wrong_at_coverage(score: np.ndarray, pred: np.ndarray, labels: np.ndarray,
                      coverages=COVERAGES) -> list[dict]:
    """Beacon on for the frames with a crossing whose score is among the lowest ``coverage`` of them
    (:func:`beacon_on`): per coverage, the beacon-on and confidently-wrong rates over the frames with
    a crossing and the silence over those without."""
    pos = labels != 0
    out = []
    for c in coverages:
        on = beacon_on(score, pred, labels, c)
        wrong = confidently_wrong(on, pred, labels)
        out.append({"coverage": c, "beacon_on": float(on[pos].mean()), "confidently_wrong": float(wrong.sum() / pos.sum()),
                    "silence_no_crossing": float(1 - on[~pos].mean()) if (~pos).any() else None})
    return out


def fold_outputs(fold: Path, source: str, ptl, neg, used, frames: int, seed: int, mirror: bool) -> dict:
    """The fold bundle's outputs on its held-out photos and no-crossing views (cached in the fold)."""
    from crossing_assist.runtime.engine import Engine

    done = fold / f"gate_scores{draw_tag(mirror, frames, seed)}.json"
    if done.is_file():
        return json.loads(done.read_text())
    engine = Engine(fold_bundle(fold, source, ptl, mirror), threads=1)
    pos, negs = held_out_rows(ptl, neg, source, used, frames, seed)
    out = {"labels": [], "probs": [], "mutual_info": []}
    for ds, rows in ((ptl, pos), (neg, negs)):
        for r in rows:
            p = engine.predict(load_frame(ds.image_path(r), r.flags))
            out["labels"].append(int(r.label))
            out["probs"].append(p.probs.tolist() if p.ok else None)
            out["mutual_info"].append(p.mutual_info if p.ok else float("inf"))
    done.write_text(json.dumps(out))
    return out


def saved_outputs(fold: Path, view: str, frames: int, seed: int, mirror: bool, portrait: int) -> dict | None:
    """The first frame's outputs of each clip ``scripts/choose_gate.py`` listened to in ``view``
    (its ``listened…npz``; None when missing): the no-crossing clips and those whose goal is in
    view (all of them for landscape). No mutual information (not saved)."""
    path = fold / f"listened{view_tag(mirror, frames, seed, view, portrait)}.npz"
    if not path.is_file():
        return None
    with np.load(path) as z:
        labels, probs, ok = z["labels"], z["probs"][:, 0], z["ok"][:, 0]
        keep = np.ones(len(labels), bool)
        if "in_view" in z.files:
            keep = labels == 0
            keep[z["in_view"]] = True
    return {"labels": labels[keep].tolist(), "probs": [p.tolist() if o else None for p, o in zip(probs[keep], ok[keep])],
            "mutual_info": None}


def table(name: str, rows: list[dict]) -> str:
    return f"| {name} | " + " | ".join(f"{100 * r['confidently_wrong']:.2f} %" for r in rows) + " |"


def wrong_sheet(probs: np.ndarray, labels: np.ndarray, rows: list, path: Path, coverage: float = 0.9) -> dict:
    """Draw the frames confidently wrong at ``coverage`` beacon on (ranked by entropy) on one sheet and
    say how far each misses the labelled far point (:func:`miss_strips`)."""
    from crossing_assist.models.plots import plot_examples

    pred = probs.argmax(1)
    on = beacon_on(scores(probs)["entropy"], pred, labels, coverage)
    idx = np.flatnonzero(confidently_wrong(on, pred, labels))
    onpos = np.flatnonzero(on & (labels != 0))
    miss = miss_strips([rows[i][1].far_x for i in onpos], pred[onpos], probs.shape[1])
    wrong_miss = miss[np.isin(onpos, idx)]
    out = {"coverage": coverage, "frames": len(idx), "images": [rows[i][1].image for i in idx],
           "miss_strips_median": float(np.median(wrong_miss)) if len(idx) else None,
           "miss_strips_max": float(wrong_miss.max()) if len(idx) else None,
           "beacon_on_missing_by_more_than": {str(k): int((miss > k).sum()) for k in (1.5, 2.0, 2.5, 3.0)}}
    print(f"\nconfidently wrong at {coverage:.0%} beacon on (entropy): {len(idx)} frames; the beacon misses the far point "
          f"by a median {out['miss_strips_median'] or 0:.2f} strip widths, at most {out['miss_strips_max'] or 0:.2f}; of the {len(onpos)} "
          f"frames with the beacon on, missing by more than 1.5 / 2 / 2.5 / 3 strips: "
          + " / ".join(str(v) for v in out["beacon_on_missing_by_more_than"].values()))
    if len(idx):
        images = [load_frame(rows[i][0].image_path(rows[i][1]), rows[i][1].flags) for i in idx]
        plot_examples(images, probs[idx], labels[idx], probs.shape[1], [None] * len(idx), path, cols=6)
        print(f"wrote {path}")
    return out


def main(argv=None) -> int:
    ap = held_out_parser(__doc__.split("\n\n")[0], frames=200)
    ap.add_argument("--with", dest="others", type=Path, action="append", default=[],
                    help="another --cv source run of the same photographers: ensemble members")
    ap.add_argument("--sheet", action="store_true",
                    help="also write CV/gate_scores_wrong[_mirror].png: the first run's frames confidently wrong at "
                         "90 %% beacon on (ranked by entropy, the gate's measure) and how far each misses the far point")
    ap.add_argument("--view", choices=("landscape", "portrait", "portrait_window"),
                    help="score the clips scripts/choose_gate.py saved for this view (the same --frames, --seed, "
                         "--mirror and --portrait as it ran with; goal in view) instead of playing a draw here")
    ap.add_argument("--portrait", type=int, default=3, help="with --view: portrait views a photo, as listened to")
    ap.add_argument("--coverages", type=float, nargs="+", default=list(COVERAGES), metavar="C",
                    help="beacon-on rates to read the confidently-wrong rate at (0 < C < 1)")
    ap.add_argument("--disagreement", type=float, nargs="+", default=[0.1, 0.3], metavar="W",
                    help="with --with: the ensemble is also ranked by its far mass plus W times the members' "
                         "disagreement (mutual information between the members, nats), for each W (default 0.1 0.3)")
    a = ap.parse_args(argv)
    if not all(0 < c < 1 for c in a.coverages):
        print(f"error: --coverages {a.coverages}: each must lie in (0, 1)", file=sys.stderr)
        return 2
    if a.view and a.sheet:
        print("error: --sheet draws a played draw's photos; it does not go with --view", file=sys.stderr)
        return 2
    ptl, neg = read_manifest(a.ptl), read_manifest(a.neg)
    used = {r.image for r in read_manifest(a.used_neg).rows}
    runs = [a.cv, *a.others]
    members: list[list[dict]] = [[] for _ in runs]
    held = []   # (dataset, row) of every frame, in the order of the fold outputs
    for fold, source in finished_folds(a.cv):
        print(f"fold {source}", file=sys.stderr, flush=True)
        if not a.view:
            pos, negs = held_out_rows(ptl, neg, source, used, a.frames, a.seed)
            held += [(ptl, r) for r in pos] + [(neg, r) for r in negs]
        for i, cv in enumerate(runs):
            other = cv / fold.name
            if not (other / "weights").is_dir():
                print(f"error: {other} has no weights: every run needs the same folds", file=sys.stderr)
                return 2
            if a.view:
                out = saved_outputs(other, a.view, a.frames, a.seed, a.mirror, a.portrait)
                if out is None:
                    print(f"error: {other} has no saved {a.view} clips for this draw: run scripts/choose_gate.py first",
                          file=sys.stderr)
                    return 2
                members[i].append(out)
            else:
                members[i].append(fold_outputs(other, source, ptl, neg, used, a.frames, a.seed, a.mirror))
    if not members[0]:
        print(f"error: no finished fold in {a.cv}", file=sys.stderr)
        return 2
    labels = np.concatenate([f["labels"] for f in members[0]])
    ok = np.ones(len(labels), bool)
    entries = []   # (name, probs, mutual information, members' disagreement): each run, then their ensemble
    for cv, run in zip(runs, members):
        probs = [p for f in run for p in f["probs"]]   # None where inference failed
        width = next((len(p) for p in probs if p is not None), None)
        if width is None:
            print(f"error: every inference failed in {cv}", file=sys.stderr)
            return 2
        ok &= np.asarray([p is not None for p in probs])
        entries.append((str(cv), np.asarray([p or [np.nan] * width for p in probs], float),
                        None if a.view else np.concatenate([f["mutual_info"] for f in run]), None))
    if len(entries) > 1:
        each = [p for _, p, _, _ in entries]
        entries.append(("ensemble (mean probabilities)", np.mean(each, 0), None, member_disagreement(each)))
    labels = labels[ok]
    pos = labels != 0
    head = "| score | " + " | ".join(f"on {c:.0%}" for c in a.coverages) + " |\n|---|" + "---:|" * len(a.coverages)
    result = {"runs": [str(r) for r in runs], "frames": int(pos.sum()), "no_crossing_frames": int((~pos).sum()),
              "failed": int((~ok).sum()), "runs_scored": {}}
    print(f"{pos.sum()} held-out frames with a crossing, {(~pos).sum()} without; confidently wrong (of frames with a "
          f"crossing) at each beacon-on rate, frame level")
    for name, probs, mi, dis in entries:
        probs = probs[ok]
        pred = probs.argmax(1)
        acc = float((pred[pos] == labels[pos]).mean())
        ranked = scores(probs, None if mi is None else mi[ok], None if dis is None else dis[ok], tuple(a.disagreement))
        rows = {k: wrong_at_coverage(s, pred, labels, a.coverages) for k, s in ranked.items()}
        result["runs_scored"][name] = {"accuracy": acc, "bin_mae": float(np.abs(pred[pos] - labels[pos]).mean()),
                                       "scores": rows}
        print(f"\n{name}: argmax accuracy {acc:.3f}\n{head}")
        for k, r in rows.items():
            print(table(k, r))
    if a.sheet:
        probs = entries[0][1][ok]
        kept = [h for h, k in zip(held, ok) if k]
        result["wrong_sheet"] = wrong_sheet(probs, labels, kept, a.cv / f"gate_scores_wrong{tag(a.mirror)}.png")
    (a.cv / f"gate_scores{tag(a.mirror)}{'_' + a.view if a.view else ''}.json").write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

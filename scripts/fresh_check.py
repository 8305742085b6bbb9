"""How far a gate threshold chosen on held-out photos carries to held-out photos the choice never saw.

``scripts/choose_gate.py CV --frames 100000`` plays every unseen photo and no-crossing view of
each fold's held-out photographer (landscape) and saves the plays (``listened…_100000.npz``).
This script replays them, no model run: per photographer it takes the draw ``choose_gate.py
--frames N`` (``--choose-frames``) would have played (:func:`choose_gate.draw_indices`), chooses
the threshold by choose_gate's rule on those plays pooled over the photographers (most beacon
with confidently wrong <= 0.5 % and silence >= 98 %), and measures that threshold on every other
photo and no-crossing view: the rates a user meets when the threshold meets photos it was not
chosen on. With ``--also``, the runs' plays are averaged frame by frame (their ensemble, as
``choose_gate.py --ensemble``). Prints both and writes ``CV/fresh{…}.json``.

    python scripts/fresh_check.py runs/res256/cv --also runs/res256_s1/cv --frames 100000 \\
        --choose-frames 400 --grid 16 --measure far_mass
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import choose_gate as cg  # noqa: E402

from crossing_assist.fileio import atomic_write_text  # noqa: E402
from crossing_assist.runtime.listen import Listener, summarise  # noqa: E402


def photographer_plays(folds: list[Path], mirror: bool, frames: int, seed: int, measure: str | None):
    """The saved plays of one photographer's folds (one a run; averaged when several), and the
    clip indices of its photos and no-crossing views in the draw order. ValueError when a draw is
    missing or is not every unseen photo and view (then the clip order is not the rows' order)."""
    from crossing_assist.runtime.engine import Engine

    paths = [f / f"listened{cg.draw_tag(mirror, frames, seed)}.npz" for f in folds]
    for p in paths:
        if not p.is_file():
            raise ValueError(f"{p} not found: run scripts/choose_gate.py {p.parent.parent} --frames {frames}"
                             + (" --mirror" if mirror else "") + " first")
    engine = Engine(folds[0] / f"bundle{cg.tag(mirror)}", threads=1)
    lis, extra = (Listener.average(engine, paths, measure) if len(paths) > 1 else Listener.load(engine, paths[0], measure))
    labels = [int(x) for x in lis.labels]
    n_pos = sum(x != 0 for x in labels)
    if any(x == 0 for x in labels[:n_pos]) or n_pos >= frames or len(labels) - n_pos >= frames // 2:
        raise ValueError(f"{paths[0]}: not every unseen photo and view of the photographer (photos first); "
                         "choose_gate.py --frames must exceed their number")
    return lis, engine, n_pos, len(labels) - n_pos, set(extra["in_view"].tolist())


def fresh_check(run_folds: list[list[tuple[Path, str]]], *, mirror: bool, frames: int, choose_frames: int,
                seed: int, grid: int, measure: str | None, upper: bool = False) -> dict:
    """``run_folds``: per photographer, ``(fold folder, source)`` of each run. The threshold chosen
    on the ``choose_frames`` draw (its pooled curve point; ``upper``: by :func:`choose_gate.choose`'s
    upper-bound rule) and the pooled rates on the other clips."""
    drawn, rest = [], []
    for folds in run_folds:
        source = folds[0][1]
        lis, engine, n_pos, n_neg, in_view = photographer_plays([f for f, _ in folds], mirror, frames, seed, measure)
        pos, neg = cg.draw_indices(n_pos, n_neg, choose_frames, seed)
        sub = pos + [n_pos + j for j in neg]
        t0 = cg.reference_threshold(engine, measure)
        seen = set(sub)
        drawn.append({"source": source, "frames": len(pos), "no_crossing_frames": len(neg),
                      "goal_in_view_frames": sum(i in in_view for i in sub),
                      "curve": [{"scale": m, **cg.sweep_point(lis.heard(m * t0, sub),
                                                               [k for k, i in enumerate(sub) if i in in_view])}
                                for m in cg.gate_scales(grid)]})
        rest.append((source, lis, [i for i in range(len(lis.labels)) if i not in seen], t0))
    best, met = cg.choose(cg.pool(drawn), upper=upper)
    heard, per_source = [], {}
    for source, lis, idx, t0 in rest:
        h = lis.heard(best["scale"] * t0, idx)
        per_source[source] = summarise(h)
        heard += h
    fresh = summarise(heard)
    wrong = round((fresh["confidently_wrong"] or 0) * fresh["frames_with_crossing"])
    return {"chosen_on": {"frames_per_photographer": choose_frames, "rule": "upper 95 % bound" if upper else "rate",
                          "scale": best["scale"], "targets_met": met,
                          "threshold": best["scale"] * cg.FAR_MASS_REFERENCE if measure == "far_mass" else None,
                          "point": best},
            "fresh": {"frames": fresh["frames_with_crossing"], "no_crossing_frames": fresh["frames_without_crossing"],
                      "beacon_on": fresh["beacon_on"], "confidently_wrong": fresh["confidently_wrong"],
                      "confidently_wrong_frames": wrong,
                      "confidently_wrong_95": cg.wilson(wrong, fresh["frames_with_crossing"]),
                      "silence_no_crossing": fresh["silence_no_crossing"], "per_photographer": per_source}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cv", type=Path, help="the --cv source run folder (fold-* inside), listened to by choose_gate.py")
    cg.add_also(ap)
    ap.add_argument("--frames", type=int, default=100000,
                    help="the saved draw to replay: choose_gate.py's --frames that played every unseen photo")
    ap.add_argument("--choose-frames", type=int, default=400, help="photos a photographer the threshold is chosen on")
    ap.add_argument("--seed", type=int, default=0, help="choose_gate.py's --seed (the draws)")
    ap.add_argument("--mirror", action="store_true", help="the folds' bundles with mirror test-time augmentation")
    ap.add_argument("--grid", type=int, default=cg.GRID, metavar="STEPS", help="gate scales a doubling")
    ap.add_argument("--measure", choices=("far_mass",), help="replay the gate with this measure (as choose_gate.py)")
    ap.add_argument("--upper", action="store_true",
                    help="choose as choose_gate.py --upper: the confidently-wrong rate's upper 95 %% bound within the limit")
    a = ap.parse_args(argv)
    if not 0 < a.choose_frames < a.frames:
        ap.error(f"--choose-frames {a.choose_frames}: between 1 and --frames ({a.frames})")
    by_source: dict[str, list] = {}
    runs = [a.cv, *a.also]
    for cv in runs:
        for fold, source in cg.finished_folds(cv):
            by_source.setdefault(source, []).append((fold, source))
    run_folds = [f for f in by_source.values() if len(f) == len(runs)]
    if not run_folds:
        print(f"error: no photographer held out by every run's finished folds in {', '.join(map(str, runs))}",
              file=sys.stderr)
        return 2
    try:
        out = fresh_check(run_folds, mirror=a.mirror, frames=a.frames, choose_frames=a.choose_frames, seed=a.seed,
                          grid=a.grid, measure=a.measure, upper=a.upper)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    c, f = out["chosen_on"], out["fresh"]
    what = f"the ensemble of {len(runs)} runs" if len(runs) > 1 else str(a.cv)
    print(f"{what}: chosen on {a.choose_frames} photos a photographer{' (upper bound)' if a.upper else ''}: scale {c['scale']:g}"
          + (f" (far mass {c['threshold']:.4g})" if a.measure else "")
          + f"{'' if c['targets_met'] else ' (targets not met)'}: beacon on {100 * c['point']['beacon_on']:.1f} %, "
          f"confidently wrong {100 * c['point']['confidently_wrong']:.2f} % ({c['point']['confidently_wrong_frames']} "
          f"of {c['point']['frames']})")
    lo, hi = f["confidently_wrong_95"]
    silence = "n/a" if f["silence_no_crossing"] is None else f"{100 * f['silence_no_crossing']:.1f} %"
    print(f"on the other {f['frames']} photos and {f['no_crossing_frames']} no-crossing views: beacon on "
          f"{100 * (f['beacon_on'] or 0):.1f} %, confidently wrong {100 * (f['confidently_wrong'] or 0):.2f} % "
          f"({f['confidently_wrong_frames']}; 95 % interval {100 * lo:.2f}-{100 * hi:.2f} %), silence {silence}")
    name = (f"fresh{cg.tag(a.mirror)}_{a.choose_frames}of{a.frames}" + (f"_seed{a.seed}" if a.seed else "")
            + cg.measure_tag(a.measure) + cg.upper_tag(a.upper) + (f"_ensemble{len(runs)}" if len(runs) > 1 else "") + ".json")
    atomic_write_text(a.cv / name, json.dumps({"runs": [str(r) for r in runs], **out}, indent=1))
    print(f"-> {a.cv / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python
"""What each augmentation of the default recipe is worth on unseen photographers (issue 13, item 2).

Each variant is the default recipe (``scripts/build_default_model.sh``) with one thing left out:
a field-view step (``crossing-train --field-without``: roll, phone aspect, corruptions, or one
corruption by name), all field views, or the negatives. Each is cross-validated leave-one-
photographer-out (``CV=1``, 2 epochs a fold, as the default's own CV); the table compares it fold by
fold with the full recipe's CV, so a difference is paired on the same held-out photos.

    python scripts/augment_ablation.py --run --jobs 2     # train what is missing (hours here), then tabulate
    python scripts/augment_ablation.py                    # tabulate the variants already trained

Writes OUT/ablation.md (the table), OUT/ablation.json and OUT/ablation.png (paired differences
per fold). A variant is trained into OUT/NAME/cv; a killed run resumes its unfinished fold.

Clean held-out photos cannot show what an augmentation is for (a night photo is rare in PTL).
Where both the baseline and a variant hold the field-conditions table of their folds
(``python scripts/robustness_table.py OUT/NAME/cv --mirror --frames 60``, ``robustness_mirror.json``),
a second table sets each condition's held-out accuracy with and without the augmentation side by side.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from crossing_assist.data_tools.corrupt import CORRUPTIONS  # noqa: E402

#: name -> (what is left out, environment of scripts/build_default_model.sh)
VARIANTS: dict[str, tuple[str, dict[str, str]]] = {
    "no_corruption": ("every corruption (night, glare, rain, blur, JPEG, noise, occluder)",
                      {"FIELD_WITHOUT": "corruption"}),
    "no_roll": ("camera roll (up to 15 deg)", {"FIELD_WITHOUT": "roll"}),
    "no_aspect": ("phone aspects (3:4, 9:16, 1:1, 16:9 windows, letterboxed)", {"FIELD_WITHOUT": "aspect"}),
    "no_field_views": ("all field views (no augmentation of the photos)", {"FIELD": "0"}),
    "no_negatives": ("negatives (synthetic corners, views above the far kerb)", {"NEGATIVES": "0"}),
    **{f"no_{c}": (f"the {c} corruption only", {"FIELD_WITHOUT": c}) for c in CORRUPTIONS},
}
#: trained by ``--run`` unless ``--variants`` names others
DEFAULT_VARIANTS = ("no_corruption", "no_roll", "no_aspect", "no_negatives", "no_field_views")
METRICS = (("accuracy", "accuracy", 1), ("bin_mae", "bin MAE", -1), ("far_x_error", "far-x error", -1))
ROBUSTNESS = "robustness_mirror.json"   # scripts/robustness_table.py CV --mirror


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="runs/ablation", help="folder of the variants' runs and the table")
    p.add_argument("--baseline", default="runs/default/cv",
                   help="the full recipe's CV folder (CV=1 scripts/build_default_model.sh); trained into OUT/full/cv with --run if absent")
    p.add_argument("--variants", default=",".join(DEFAULT_VARIANTS),
                   help=f"comma-separated; valid: {', '.join(VARIANTS)}")
    p.add_argument("--run", action="store_true", help="train the variants (and baseline) that have no cv.json yet")
    p.add_argument("--jobs", type=int, default=1, help="variants trained at once (one CPU thread each)")
    p.add_argument("--epochs", type=int, default=2, help="epochs a fold (the default's CV uses 2)")
    a = p.parse_args(argv)
    a.variants = [v.strip() for v in a.variants.split(",") if v.strip()]
    bad = [v for v in a.variants if v not in VARIANTS]
    if bad:
        p.error(f"unknown variant {', '.join(bad)}; valid: {', '.join(VARIANTS)}")
    if a.jobs < 1:
        p.error(f"--jobs {a.jobs}: valid >= 1")
    return a


def train(out: Path, env: dict[str, str], epochs: int) -> int:
    """One leave-one-photographer-out CV of the default recipe with ``env``; log in OUT.log."""
    out.parent.mkdir(parents=True, exist_ok=True)
    full_env = {**os.environ, "CV": "1", "EPOCHS": str(epochs), "OUT": str(out), **env}   # finished folds are kept
    print(f"training {out} ({' '.join(f'{k}={v}' for k, v in env.items()) or 'full recipe'}) ...", flush=True)
    with open(f"{out}.log", "a") as log:
        rc = subprocess.call(["scripts/build_default_model.sh"], cwd=ROOT, env=full_env, stdout=log, stderr=log)
    print(f"{out}: {'done' if rc == 0 else f'failed (rc {rc}, see {out}.log)'}", flush=True)
    return rc


def read_cv(folder: Path) -> dict | None:
    path = folder / "cv.json"
    return json.loads(path.read_text()) if path.is_file() else None


def compare(base: dict, cv: dict) -> dict:
    """Mean +- sd over folds of each metric, and of its paired difference from ``base``."""
    by_src = {f["source"]: f for f in base["folds"]}
    folds = [f for f in cv["folds"] if f["source"] in by_src]
    row = {"folds": len(folds)}
    for key, _, sign in METRICS:
        vals = np.array([f[key] for f in folds])
        diffs = vals - np.array([by_src[f["source"]][key] for f in folds])
        row[key] = [float(vals.mean()), float(vals.std(ddof=1)) if len(vals) > 1 else 0.0]
        row[f"delta_{key}"] = [float(diffs.mean()), float(diffs.std(ddof=1)) if len(diffs) > 1 else 0.0]
        row[f"per_fold_delta_{key}"] = {f["source"]: float(d) for f, d in zip(folds, diffs)}
        row[f"folds_better_{key}"] = int((sign * diffs > 0).sum())
    return row


def table(base: dict, rows: dict[str, dict]) -> str:
    acc, mae, fx = (base[k] for k in ("accuracy", "bin_mae", "far_x_error"))
    lines = ["| left out | accuracy | Δ accuracy (paired) | folds better without | bin MAE | Δ | far-x error | Δ |",
             "|---|---:|---:|---:|---:|---:|---:|---:|",
             f"| nothing (the default recipe) | {acc['mean']:.3f} ± {acc['sd']:.3f} | | | {mae['mean']:.3f} | | "
             f"{fx['mean']:.4f} | |"]
    for name, r in rows.items():
        (a, sa), (da, sda) = r["accuracy"], r["delta_accuracy"]
        lines.append(f"| {VARIANTS[name][0]} | {a:.3f} ± {sa:.3f} | {da:+.3f} ± {sda:.3f} | "
                     f"{r['folds_better_accuracy']}/{r['folds']} | {r['bin_mae'][0]:.3f} | {r['delta_bin_mae'][0]:+.3f} | "
                     f"{r['far_x_error'][0]:.4f} | {r['delta_far_x_error'][0]:+.4f} |")
    return "\n".join(lines)


def conditions_table(base: dict, var: dict, name: str) -> str:
    """Held-out accuracy, confidently-wrong rate and silence on no-crossing views under each field
    condition, the full recipe beside the variant (both from :mod:`robustness_table`, the same photos)."""
    lines = [f"| condition | accuracy: full recipe | without {name[3:].replace('_', ' ')} | Δ | "
             "confidently wrong: full | without | silence, no crossing: full | without |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for cond, b in base["conditions"].items():
        v = var["conditions"].get(cond)
        if v is not None:
            lines.append(f"| {cond} | {b['accuracy']:.3f} | {v['accuracy']:.3f} | {100 * (v['accuracy'] - b['accuracy']):+.1f} | "
                         f"{100 * b['confidently_wrong']:.2f} % | {100 * v['confidently_wrong']:.2f} % | "
                         f"{100 * b['silence_no_crossing']:.1f} % | {100 * v['silence_no_crossing']:.1f} % |")
    frames = {base.get("frames_per_fold"), var.get("frames_per_fold")}
    note = "" if len(frames) == 1 else " (warning: different photos per fold)"
    return "\n".join(lines) + f"\n\n{base.get('frames_per_fold')} photos per fold, folds pooled{note}."


def plot(rows: dict[str, dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(rows)
    fig, ax = plt.subplots(figsize=(8, 0.6 * len(names) + 1.8))
    for i, n in enumerate(names):
        d = rows[n]["per_fold_delta_accuracy"]
        ax.barh(i, rows[n]["delta_accuracy"][0], color="tab:red" if rows[n]["delta_accuracy"][0] < 0 else "tab:green",
                alpha=0.5)
        ax.scatter(list(d.values()), [i] * len(d), color="k", s=12, zorder=3)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(range(len(names)), [f"without {n[3:].replace('_', ' ')}" for n in names])
    ax.set_xlabel("accuracy without minus with (dots: held-out photographers; bars: mean)\nleft of 0: the augmentation helps")
    ax.set_title("Leave-one-photographer-out: what each augmentation is worth")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    a = parse_args(argv)
    out = Path(a.out)
    base_dir = Path(a.baseline)
    if read_cv(base_dir) is None:   # the full recipe trained here (by --run) instead
        base_dir = out / "full" / "cv"
    if a.run:
        jobs = [(out / name, VARIANTS[name][1]) for name in a.variants if read_cv(out / name / "cv") is None]
        if read_cv(base_dir) is None:
            jobs.insert(0, (base_dir.parent, {}))
        with ThreadPoolExecutor(a.jobs) as pool:
            failed = [str(o) for (o, _), rc in zip(jobs, pool.map(lambda j: train(*j, a.epochs), jobs)) if rc]
        if failed:
            print(f"error: training failed for {', '.join(failed)}", file=sys.stderr)
            return 1
    base = read_cv(base_dir)
    if base is None:
        print(f"error: no baseline CV in {a.baseline} or {base_dir}; run CV=1 EPOCHS={a.epochs} scripts/build_default_model.sh "
              "or pass --run", file=sys.stderr)
        return 2
    cvs = {n: cv for n in a.variants if (cv := read_cv(out / n / "cv")) is not None}
    missing = [n for n in a.variants if n not in cvs]
    if not cvs:
        print(f"error: no variant trained yet in {out} ({', '.join(missing)}); pass --run", file=sys.stderr)
        return 2
    odd = [n for n, cv in cvs.items() if cv["config"]["epochs"] != base["config"]["epochs"]]
    if odd:
        print(f"warning: {', '.join(odd)} trained for other epochs than the baseline", file=sys.stderr)
    rows = {n: compare(base, cv) for n, cv in cvs.items()}
    text = table(base, rows)
    base_rob = json.loads((base_dir / ROBUSTNESS).read_text()) if (base_dir / ROBUSTNESS).is_file() else None
    for n in rows:
        if base_rob is not None and (out / n / "cv" / ROBUSTNESS).is_file():
            var_rob = json.loads((out / n / "cv" / ROBUSTNESS).read_text())
            text += f"\n\nField conditions, without {VARIANTS[n][0]}:\n\n" + conditions_table(base_rob, var_rob, n)
    out.mkdir(parents=True, exist_ok=True)
    (out / "ablation.md").write_text(text + "\n")
    (out / "ablation.json").write_text(json.dumps({"baseline": str(base_dir), "variants": rows}, indent=1))
    plot(rows, out / "ablation.png")
    print(text)
    if missing:
        print(f"not trained yet: {', '.join(missing)} (pass --run)")
    print(f"wrote {out / 'ablation.md'}, {out / 'ablation.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

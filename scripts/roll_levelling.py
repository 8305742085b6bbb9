"""What a rolled phone hears, with and without levelling its frames from the orientation sensor.

Draws photos from one split of a crossing-data manifest (default: PTL val in ``runs/data/ptl``,
which ``scripts/prepare_default_data.sh`` writes; the default bundle never trained on those
photos, though it did on their photographers) and plays each as a 1 s still clip at 10 fps
through the runtime (``runtime/listen.py``: engine + filter + gate, the bundle's thresholds;
``--source ptl:X --split train`` with a leave-one-photographer-out fold's bundle measures it on
the photographer that fold never saw):

- ``level``: the photo as taken (a level phone);
- per roll range ``LO:HI`` (degrees, either way at random; :func:`~crossing_assist.data_tools.augment.roll`,
  the scene beyond the photo's edges reflected in): ``rolled``, the rolled camera's frame as it
  is (no sensor); ``levelled``, the same frame with the sensor's roll given to the engine
  (``Engine.predict(…, roll_deg=…)``, :func:`~crossing_assist.geometry.level`, what the phone app
  does); ``levelled±E``, the sensor off by up to ``E`` degrees (``--sensor-error``).

Every play is judged against the strip where the goal lies for a *level* camera, the bearing
the user has to walk (``rolled`` also against the rolled frame's own strip: ``rolled, own strip``).
Prints a markdown table (beacon on, confidently wrong, right strip while on) with, per range,
how many photos the beacon starts or stops playing for when levelled; ``--out`` writes the
figures as JSON and ``--plot`` a bar chart.

    .venv/bin/python scripts/roll_levelling.py [--photos 864] [--rolls 5:10,10:20,20:35] \\
        [--out /tmp/roll.json] [--plot docs/img/roll_levelling.png] [--gate crossing_assist/assets/default_bundle]

``--pool A.json B.json …`` pools earlier ``--out`` files instead (each rate weighted by its
photos; e.g. the four folds of a leave-one-photographer-out run, each on its unseen photographer)
and prints, writes and plots the pooled figures the same way.

A missing manifest, an empty split, an unusable bundle or an unreadable ``--pool`` file is one
line and exit 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from prepared_data import draw, open_manifest  # noqa: E402  (a sibling script: the probes' photos)
from robustness_table import gated  # noqa: E402  (a sibling script: one way to decide at another bundle's gate)

from crossing_assist.bundle import BundleError, read_bundle
from crossing_assist.data_tools.augment import roll
from crossing_assist.data_tools.images import flag_value, load_frame
from crossing_assist.fileio import atomic_write_text
from crossing_assist.runtime.demo import DEFAULT_BUNDLE
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.listen import Listener, summarise


def parse_rolls(text: str) -> list[tuple[float, float]]:
    """``"5:10,10:20"`` -> [(5, 10), (10, 20)]; one line (SystemExit) for anything else."""
    out = []
    for part in text.split(","):
        try:
            lo, hi = (float(v) for v in part.split(":"))
        except ValueError:
            raise SystemExit(f"error: --rolls: {part!r} is not LO:HI (degrees)") from None
        if not 0 <= lo <= hi <= 90:
            raise SystemExit(f"error: --rolls: {part!r}: need 0 <= LO <= HI <= 90")
        out.append((lo, hi))
    return out


def rates(heard: list) -> dict:
    s = summarise(heard)
    return {k: s[k] for k in ("beacon_on", "confidently_wrong", "accuracy_heard", "frames_with_crossing")}


def flips(a: list, b: list) -> tuple[int, int]:
    """Photos the beacon plays for in ``b`` (heard) but not in ``a``, and the other way."""
    return sum(y.on and not x.on for x, y in zip(a, b)), sum(x.on and not y.on for x, y in zip(a, b))


def measure(engine: Engine, rows, images, rolls, sensor_error: float, seed: int) -> dict:
    level = Listener(engine)
    for r, img in zip(rows, images):
        level.add(img, r.label)
    out = {"level": rates(level.heard()), "ranges": {}}
    print(f"level: {out['level']}", file=sys.stderr, flush=True)
    for k, (lo, hi) in enumerate(rolls):
        rng = np.random.default_rng([seed, k])
        plays = {name: Listener(engine) for name in ("rolled", "rolled_own", "levelled", "levelled_noisy")}
        for r, img in zip(rows, images):
            deg = float(rng.choice([-1, 1]) * rng.uniform(lo, hi))
            far_y = flag_value(r.flags, "far_y")
            view, _, own = roll(img, r.far_x, 0.5 if far_y is None else float(far_y), r.label, deg, fill="reflect")
            plays["rolled"].add(view, r.label)
            plays["rolled_own"].clips.append(plays["rolled"].clips[-1])   # the same play, its own strip
            plays["rolled_own"].labels.append(own)
            plays["levelled"].add(view, r.label, roll_deg=deg)
            plays["levelled_noisy"].add(view, r.label, roll_deg=deg + float(rng.uniform(-sensor_error, sensor_error)))
        heard = {name: lis.heard() for name, lis in plays.items()}
        on, off = flips(heard["rolled"], heard["levelled"])
        row = {name: rates(h) for name, h in heard.items()}
        row["levelled_vs_rolled"] = {"beacon_starts": on, "beacon_stops": off}
        out["ranges"][f"{lo:g}:{hi:g}"] = row
        print(f"roll {lo:g}..{hi:g}: {row}", file=sys.stderr, flush=True)
    return out


def pool(results: list[dict]) -> dict:
    """Several runs' figures as one: each rate weighted by its run's photos, flips summed."""
    n = sum(r["photos"] for r in results)

    def mean(rows: list[dict]) -> dict:
        out = {k: sum(r[k] * res["photos"] for r, res in zip(rows, results)) / n
               for k in ("beacon_on", "confidently_wrong", "accuracy_heard")}
        return {**out, "frames_with_crossing": sum(r["frames_with_crossing"] for r in rows)}

    ranges = {}
    for key in results[0]["ranges"]:
        rows = [r["ranges"][key] for r in results]
        ranges[key] = {name: mean([row[name] for row in rows]) for name in rows[0] if name != "levelled_vs_rolled"}
        ranges[key]["levelled_vs_rolled"] = {k: sum(row["levelled_vs_rolled"][k] for row in rows)
                                             for k in ("beacon_starts", "beacon_stops")}
    first = results[0]
    return {"bundle": "pooled: " + ", ".join(r["bundle"] for r in results), "gate": first.get("gate"), "data": first["data"],
            "split": ", ".join(sorted({f"{r['split']} {r.get('source') or ''}".strip() for r in results})),
            "source": None, "photos": n, "sensor_error_deg": first["sensor_error_deg"], "seed": first["seed"],
            "level": mean([r["level"] for r in results]), "ranges": ranges}


def markdown(res: dict, sensor_error: float) -> str:
    names = {"rolled": "rolled, no sensor", "rolled_own": "rolled, own strip", "levelled": "levelled",
             "levelled_noisy": f"levelled, sensor ±{sensor_error:g}°"}
    lines = ["| roll | frames | beacon on | confidently wrong | right strip |", "|---|---|---|---|---|"]

    def line(label, r):
        lines.append(f"| {label} | {r['frames_with_crossing']} | {100 * r['beacon_on']:.1f} % | "
                     f"{100 * r['confidently_wrong']:.2f} % | {100 * r['accuracy_heard']:.1f} % |")

    line("0° (level phone)", res["level"])
    for rng_, row in res["ranges"].items():
        lo, hi = rng_.split(":")
        for name, label in names.items():
            line(f"{lo}–{hi}°, {label}", row[name])
    flips_ = "; ".join(f"{k}°: +{v['levelled_vs_rolled']['beacon_starts']} / -{v['levelled_vs_rolled']['beacon_stops']}"
                       for k, v in res["ranges"].items())
    return "\n".join(lines) + f"\n\nlevelled against rolled, photos the beacon starts / stops playing for: {flips_}"


def plot(res: dict, path: Path, sensor_error: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ranges = list(res["ranges"])
    names = [("rolled", "rolled, no sensor"), ("levelled", "levelled"), ("levelled_noisy", f"levelled, sensor ±{sensor_error:g}°")]
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    x = np.arange(len(ranges))
    for ax, key, title in ((axes[0], "beacon_on", "beacon on (%)"), (axes[1], "accuracy_heard", "on and the right strip (%)"),
                           (axes[2], "confidently_wrong", "confidently wrong (%)")):
        for j, (name, label) in enumerate(names):
            ax.bar(x + (j - 1) * 0.27, [100 * res["ranges"][r][name][key] for r in ranges], 0.27, label=label)
        ax.axhline(100 * res["level"][key], color="k", ls="--", lw=1, label="level phone")
        ax.set_xticks(x, [f"roll {r.replace(':', '–')}°" for r in ranges])
        ax.set_title(title)
    axes[0].legend(fontsize=8, loc="lower left")
    name = res["bundle"] if res["bundle"].startswith("pooled") else Path(res["bundle"]).name
    fig.suptitle(f"{res['photos']} photos ({res['split']}), {name[:80]}; judged against a level camera's strip")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE, help="bundle folder (default: the embedded one)")
    ap.add_argument("--data", type=Path, default=Path("runs/data/ptl"), help="crossing-data manifest folder")
    ap.add_argument("--split", default="val", help="which split's photos (default val)")
    ap.add_argument("--source", help="only this photographer's photos (e.g. ptl:heon, with --split train: a "
                    "leave-one-photographer-out fold's bundle on the photographer it never saw)")
    ap.add_argument("--photos", type=int, default=864, help="photos drawn from the split (default 864, all of PTL val)")
    ap.add_argument("--rolls", default="5:10,10:20,20:35", help="roll ranges LO:HI in degrees, comma-separated")
    ap.add_argument("--sensor-error", type=float, default=3.0, help="the noisy sensor's error bound, degrees (default 3)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, help="write the figures as JSON here")
    ap.add_argument("--plot", type=Path, help="write a bar chart (PNG) here")
    ap.add_argument("--gate", type=Path, metavar="BUNDLE", help="decide with this bundle's gate (measure and thresholds, "
                    "e.g. the shipped default's) instead of --bundle's own; for a fold's bundle judged at the shipped rule")
    ap.add_argument("--pool", type=Path, nargs="+", metavar="JSON", help="pool earlier --out files instead of playing")
    a = ap.parse_args(argv)
    if a.pool:
        try:
            results = [json.loads(p.read_text()) for p in a.pool]
            res = pool(results)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"error: --pool: {exc}", file=sys.stderr)
            return 1
        return report(res, a.out, a.plot)
    rolls = parse_rolls(a.rolls)
    ds = open_manifest(a.data)
    if ds is None:
        return 1
    rows = [r for r in ds.rows if r.split == a.split and r.far_x is not None and a.source in (None, r.source)]
    if not rows:
        print(f"error: no photo with a crossing in split {a.split!r}{'' if a.source is None else f' from {a.source}'} "
              f"of {a.data}", file=sys.stderr)
        return 1
    try:
        engine = Engine(a.bundle, threads=1)
        if a.gate is not None:
            engine = gated(engine, read_bundle(a.gate).calibration.uncertainty)
    except BundleError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    rng = np.random.default_rng(a.seed)
    rows = draw(rows, a.photos, rng)
    images = [load_frame(ds.image_path(r), r.flags) for r in rows]
    res = {"bundle": str(a.bundle), "gate": None if a.gate is None else str(a.gate),
           "data": str(a.data), "split": a.split, "source": a.source, "photos": len(rows),
           "sensor_error_deg": a.sensor_error, "seed": a.seed,
           **measure(engine, rows, images, rolls, a.sensor_error, a.seed)}
    return report(res, a.out, a.plot)


def report(res: dict, out: Path | None, plot_path: Path | None) -> int:
    print(markdown(res, res["sensor_error_deg"]))
    if out:
        atomic_write_text(out, json.dumps(res, indent=1))
    if plot_path:
        plot(res, plot_path, res["sensor_error_deg"])
    return 0


if __name__ == "__main__":
    sys.exit(main())

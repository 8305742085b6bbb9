"""The gate checked on held-out scans: photographers the folds never saw, sweeping the phone.

``scripts/choose_gate.py`` chooses each view's far-mass threshold on still clips. A user looking
for the crossing sweeps the phone left and right; then the decision logic's filter and heading
hold carry headings across frames while the view moves, and a narrow camera's strips are only
3.4 deg wide, so a threshold safe on still clips can be riskier scanned (the default's 3:4-window
threshold, PTL val scanned: 0.88 % confidently wrong where 0.04 gave 0.43 %).

For each finished fold of the CV runs (``CV`` and each ``--also``), play its held-out
photographer's unseen photos (choose_gate's draw of ``--frames``) as ``scripts/pan_probe.py``
plays them: 1 s still, then turned right, left and back (``--amplitude``, ``--rate``; ``--sway``:
swung either side by a walker's sway instead, ``runtime.listen.sway_yaw``), every
frame re-rendered as the turned camera sees it; ``--window``: the narrow camera's middle 3:4
window; ``--phone``: a phone held in portrait (3:4 at the bundle's portrait FOV, choose_gate's
``portrait`` view of each turned frame). The model's outputs are saved in the fold
(``scanned[_window|_phone]_N_seed.npz``), so a second
call replays without the model. The runs' plays of one photographer are averaged frame by frame
(the ensemble the default ships; one run: that model). Then the far-mass thresholds choose_gate
sweeps (``--grid``, ``--max-scale``; from ``--min-scale``) are replayed through the runtime's
decision logic (``runtime.listen.judge_scans``): every frame after the still second whose goal is
in view, with the turn from a gyroscope and the turn read from the frames, the worse of the two
counted (``--heard-after S``: judged when heard, the beacon turned by the gyroscope until then, as
the app plays it; each point also keeps the same decisions heard late as two other players play
them, in :data:`LATE_PLAYS`: not turned, ``…_unturned``; a stop once half a strip stale, the app
while its gyroscope is not followed, ``…_stale``; a stop once the turn rate read at its frame makes
it half a strip stale by the end of its play, a player without a gyroscope, ``…_read_stale``). Per
photographer a curve in choose_gate's format, pooled and chosen with its rule (confidently wrong
<= 0.5 % of goal-in-view frames, the most beacon-on), and each photographer measured at the
threshold chosen on the others. Each point also counts the photos its wrong frames come from
(``confidently_wrong_photos``): a misread photo stays wrong over many frames, so a choice can
rest on a handful of photos. Writes ``CV/scan_gate[_window|_phone]….json``.

``--cap GATE_JSON`` (choose_gate's result, in CV): also write ``GATE_JSON`` with the view's
threshold lowered to the scans' choice where that is lower (``…_scan.json``; a file already named
so is updated in place, so the cameras' and the sweeps' caps stack, each check listed in the
view's ``scans``), its still figures read at the capped threshold, for
``scripts/stamp_bundle.py --rescale-gate --gate-json …_scan.json``. ``--saved``: cap from the
result an earlier call with the same options and runs wrote, without replaying the scans.

    .venv/bin/python scripts/scan_gate.py runs/ship_s0/cv --also runs/ship_s1/cv --also runs/ship_s2/cv \\
        --frames 100 --window --grid 16 --max-scale 16 --cap gate_far_mass_top16_ensemble3.json

A missing CV run or an unusable option is one line and a non-zero exit.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import (  # noqa: E402  (sibling scripts: the folds, their draw, the rule; the scans)
    FAR_MASS_REFERENCE, add_also, choose, ensemble_members, finished_folds, fold_bundle, held_out_parser,
    held_out_rows, leave_one_photographer_out, pool,
)
from pan_probe import camera, camera_suffix, play  # noqa: E402

from crossing_assist.data_tools.images import load_frame  # noqa: E402
from crossing_assist.data_tools.manifest import read_manifest  # noqa: E402
from crossing_assist.fileio import atomic_write_text  # noqa: E402
from crossing_assist.models.evaluate import GATE_TOP, gate_scales  # noqa: E402
from crossing_assist.runtime.listen import Listener, judge_scans, scan_yaw, sway_yaw  # noqa: E402

#: Heard late, the plays kept beside the app's turned one, each the worse of its readings
#: (``runtime.listen.judge_scans``): as decided (a player without a gyroscope before 2026-12-07),
#: a stop once half a strip stale (the app while its gyroscope reports but is not yet followed),
#: and a stop once the rate read at its frame makes it so (a player without a gyroscope)
LATE_PLAYS = {"unturned": ("gyro", "camera"), "stale": ("camera_stale",), "read_stale": ("camera_read_stale",)}

#: choose_gate's view each scanning camera checks: landscape, the narrow camera's (3:4 windows) or
#: the phone held in portrait's threshold
VIEWS = {"landscape": "landscape", "window": "portrait_window", "phone": "portrait"}


def scan_suffix(amplitude: float, rate: float, sway: bool = False) -> str:
    """The file-name part a scan other than the default (±20° at 30°/s) adds."""
    if sway:
        return f"_sway_a{amplitude:g}_r{rate:g}"
    return "" if (amplitude, rate) == (20.0, 30.0) else f"_a{amplitude:g}_r{rate:g}"


def scan_cache(fold: Path, cam: str, n: int, seed: int, amplitude: float, rate: float, sway: bool = False) -> Path:
    return fold / f"scanned{camera_suffix(cam)}_{n}_{seed}{scan_suffix(amplitude, rate, sway)}.npz"


def scan_fold(fold: Path, source: str, ptl, neg, used: set[str], a) -> tuple[Path, Path]:
    """The fold's held-out photos scanned with its bundle (once; cached in the fold): the saved
    play and the bundle."""
    from crossing_assist.runtime.engine import Engine

    path = scan_cache(fold, camera(a), a.frames, a.seed, a.amplitude, a.rate, a.sway)
    bundle = fold_bundle(fold, source, ptl)
    if path.is_file():
        return path, bundle
    rows = [r for r in held_out_rows(ptl, neg, source, used, a.frames, a.seed)[0] if r.far_x is not None]
    if not rows:
        raise ValueError(f"{fold}: {source} has no unseen photo with a crossing")
    engine = Engine(bundle, threads=1)
    lis, labels, rates = play(engine, (load_frame(ptl.image_path(r), r.flags) for r in rows), rows, a.psi, camera(a))
    lis.save(path, scan_labels=labels, psi=a.psi, camera_rates=rates)
    return path, bundle


def scan_curve(plays: list[Path], bundle: Path, source: str, view: str, scales: list[float],
               heard_after: float) -> dict:
    """One photographer's scans (the runs' ``plays`` averaged; decided with ``bundle``'s decision
    settings, one of the runs' fold bundles, at the swept gate) judged at far mass
    :data:`FAR_MASS_REFERENCE` x each scale, for every frame alike: a record in choose_gate's format
    over the goal-in-view frames, each point keeping each yaw reading's counts."""
    from crossing_assist.runtime.engine import Engine

    engine = Engine(bundle, threads=1)
    lis, extra = Listener.average(engine, plays, "far_mass")
    readings = ("gyro_turned", "camera_turned") if heard_after else ("gyro", "camera")
    curve, frames = [], 0
    for m in scales:
        judged = judge_scans(engine, lis.clips, extra["scan_labels"], extra["psi"], extra["camera_rates"],
                             heard_after_s=heard_after, measure="far_mass", threshold=m * FAR_MASS_REFERENCE)
        got = {k: judged[k] for k in readings}
        frames = got[readings[0]]["in_view"]
        on = min(g["on"] for g in got.values()) / frames
        late = LATE_PLAYS if heard_after else {}
        counts = {}
        for kind, keys in late.items():
            counts[f"confidently_wrong_{kind}_frames"] = max(judged[k]["wrong"] for k in keys)
            counts[f"beacon_on_{kind}_frames"] = min(judged[k]["on"] for k in keys)
        shown = {k: judged[k] for k in (*readings, *(k for keys in late.values() for k in keys))}
        curve.append({"scale": m, "beacon_on": on, "beacon_on_goal_in_view": on,
                      "confidently_wrong": max(g["wrong"] for g in got.values()) / frames,
                      "confidently_wrong_photos": max(g["wrong_photos"] for g in got.values()),
                      "silence_no_crossing": None, **counts,
                      "readings": {k: {c: g[c] for c in ("on", "wrong", "wrong_hold", "wrong_photos")}
                                   for k, g in shown.items()}})
    return {"source": source, "view": f"{view} scanned", "measure": "far_mass", "threshold": FAR_MASS_REFERENCE,
            "photos": len(lis.clips), "frames": frames, "no_crossing_frames": 0, "goal_in_view_frames": frames,
            "curve": curve}


def cap(gate_path: Path, view: str, scanned: dict) -> tuple[Path, float]:
    """``gate_path`` (choose_gate's result) with ``view``'s threshold lowered to the scans' choice
    where that is lower, written as ``…_scan.json``; its still figures read at the capped scale.
    The file written and the view's threshold now."""
    g = json.loads(gate_path.read_text())
    rec = g if view == "landscape" else g.get(view)
    if rec is None:
        raise ValueError(f"{gate_path} has no {view} choice (choose_gate.py --portrait)")
    scan_rec = {k: scanned[k] for k in ("scanned", "heard_after_s", "scale", "threshold", "targets_met", "at_scale")
                if k in scanned}
    if scanned["scale"] < rec["scale"]:
        still = next((c for c in rec["curve"] if np.isclose(c["scale"], scanned["scale"])), None)
        if still is None:
            raise ValueError(f"{gate_path}: {view} was not swept at scale {scanned['scale']:g}; use its --grid")
        scan_rec["capped_from"] = {"scale": rec["scale"], "threshold": rec["threshold"]}
        rec.update(scale=still["scale"], threshold=still["scale"] * FAR_MASS_REFERENCE, at_scale=still)
    # every check the view passed, one per sweep and hearing (a file stamped before the list: its one check)
    checks = rec.pop("scans", None) or ([rec.pop("scan")] if "scan" in rec else [])
    same = (scan_rec.get("scanned"), scan_rec["heard_after_s"])
    rec["scans"] = [s for s in checks if (s.get("scanned"), s["heard_after_s"]) != same] + [scan_rec]
    out = gate_path if gate_path.stem.endswith("_scan") else gate_path.with_name(f"{gate_path.stem}_scan.json")
    atomic_write_text(out, json.dumps(g, indent=1))
    return out, rec["threshold"]


def main(argv=None) -> int:
    ap = held_out_parser(__doc__.split("\n\n")[0], frames=100)
    add_also(ap)
    ap.add_argument("--window", action="store_true",
                    help="the narrow camera (the middle 3:4 window, ~41 deg): checks choose_gate's portrait_window")
    ap.add_argument("--phone", action="store_true",
                    help="a phone held in portrait (3:4 at the bundle's portrait FOV): checks choose_gate's portrait")
    ap.add_argument("--amplitude", type=float, default=None,
                    help="degrees either side of straight ahead (default 20; with --sway 2.5)")
    ap.add_argument("--rate", type=float, default=None,
                    help="turn rate, degrees per second (default 30; with --sway the fastest, 14)")
    ap.add_argument("--sway", action="store_true",
                    help="a walker's sway instead of a sweep: 3 periods of a sine (runtime.listen.sway_yaw)")
    ap.add_argument("--heard-after", type=float, default=0.0, metavar="S",
                    help="judge each decision S seconds after its capture, turned by the gyroscope meanwhile")
    ap.add_argument("--grid", type=int, default=16, metavar="STEPS", help="scales a doubling (default 16)")
    ap.add_argument("--min-scale", type=float, default=1.0, metavar="M",
                    help="the smallest scale swept (default 1: far mass 0.01)")
    ap.add_argument("--max-scale", type=float, default=GATE_TOP, metavar="M",
                    help=f"the largest scale swept (a power of two; default {GATE_TOP:g})")
    ap.add_argument("--cap", metavar="GATE_JSON", help="choose_gate's result in CV whose threshold the scans cap")
    ap.add_argument("--saved", action="store_true",
                    help="with --cap: cap from the result an earlier call with these options wrote (no replay)")
    a = ap.parse_args(argv)
    a.amplitude = a.amplitude if a.amplitude is not None else (2.5 if a.sway else 20.0)
    a.rate = a.rate if a.rate is not None else (14.0 if a.sway else 30.0)
    if a.mirror:
        ap.error("--mirror: scans are played with the folds' plain bundles")
    if a.window and a.phone:
        ap.error("--window and --phone: one camera scans at a time")
    try:
        a.psi = (sway_yaw if a.sway else scan_yaw)(a.amplitude, a.rate)   # the camera's yaw at each frame
    except ValueError as exc:
        ap.error(f"--amplitude {a.amplitude:g} / --rate {a.rate:g}: {exc}")
    if not 0 <= a.heard_after <= 1:
        ap.error(f"--heard-after {a.heard_after:g}: valid 0..1 s")
    try:
        scales = [m for m in gate_scales(a.grid, a.max_scale) if m >= a.min_scale - 1e-12]
    except ValueError as exc:
        ap.error(f"--grid/--max-scale: {exc}")
    if not scales:
        ap.error(f"--min-scale {a.min_scale:g}: above --max-scale {a.max_scale:g}")
    runs = [a.cv, *a.also]
    if missing := [str(cv) for cv in runs if not cv.is_dir()]:
        print(f"error: no CV run folder {', '.join(missing)}", file=sys.stderr)
        return 2
    gate_path = a.cv / a.cap if a.cap else None
    if gate_path and not gate_path.is_file():
        print(f"error: --cap {gate_path} not found (scripts/choose_gate.py writes it)", file=sys.stderr)
        return 2
    view = VIEWS[camera(a)]
    name = (f"scan_gate{camera_suffix(camera(a))}{scan_suffix(a.amplitude, a.rate, a.sway)}"
            f"{f'_heard{a.heard_after:g}' if a.heard_after else ''}.json")
    if a.saved:
        return cap_saved(gate_path, view, a.cv / name, [str(cv) for cv in runs])
    ptl, neg = read_manifest(a.ptl), read_manifest(a.neg)
    used = {r.image for r in read_manifest(a.used_neg).rows}
    by_source: dict[str, list[tuple[Path, str]]] = {}
    for cv in runs:
        for fold, source in finished_folds(cv):
            by_source.setdefault(source, []).append((fold, source))
    members = ensemble_members(by_source, len(runs))   # the photographers every run held out
    if not members:
        return 2
    folds = []
    for held in sorted(members, key=lambda m: m[0][1]):
        played = []
        for fold, source in held:
            print(f"{fold} ({source}): scan", file=sys.stderr, flush=True)
            played.append(scan_fold(fold, source, ptl, neg, used, a))
        folds.append(scan_curve([p for p, _ in played], played[0][1], held[0][1], view, scales, a.heard_after))
    curve = pool(folds)
    for i, c in enumerate(curve):   # the photos the wrong frames come from: what the choice rests on
        c["confidently_wrong_photos"] = sum(f["curve"][i]["confidently_wrong_photos"] for f in folds)
        for kind in LATE_PLAYS if a.heard_after else ():
            for rate in (f"confidently_wrong_{kind}", f"beacon_on_{kind}"):
                n = c[f"{rate}_frames"] = sum(f["curve"][i][f"{rate}_frames"] for f in folds)
                c[rate] = n / c["frames"]
    photos = sum(f["photos"] for f in folds)
    best, met = choose(curve)
    lopo = leave_one_photographer_out(folds)
    result = {"view": view, "scanned": {"amplitude_deg": a.amplitude, "rate_dps": a.rate, **({"sway": True} if a.sway else {})},
              "heard_after_s": a.heard_after, "runs": [str(cv) for cv in runs], "measure": "far_mass",
              "scale": best["scale"], "threshold": best["scale"] * FAR_MASS_REFERENCE, "targets_met": met,
              "at_scale": {k: v for k, v in best.items() if k != "per_fold"},
              **({"leave_one_photographer_out": lopo} if lopo else {}), "curve": curve, "folds": folds}
    atomic_write_text(a.cv / name, json.dumps(result, indent=1))
    print(f"{view} scanned, {len(folds)} photographers x {len(runs)} run(s), "
          f"{folds[0]['photos']}+ photos each, {best['frames']} goal-in-view frames:")
    late = (" not turned: wrong | a gyroscope not followed: on / wrong | no gyroscope: on / wrong |"
            if a.heard_after else "")
    print(f"| far mass | beacon on | confidently wrong (frames) | photos with a wrong frame, of {photos} |{late}\n"
          f"|---|---:|---:|---:|{'---:|---:|---:|' if late else ''}")
    for c in curve:
        print(f"| {c['scale'] * FAR_MASS_REFERENCE:.5f} | {100 * c['beacon_on']:.1f} % | "
              f"{100 * c['confidently_wrong']:.2f} % ({c['confidently_wrong_frames']}) | {c['confidently_wrong_photos']} |"
              + (f" {100 * c['confidently_wrong_unturned']:.2f} % | {100 * c['beacon_on_stale']:.1f} % / "
                 f"{100 * c['confidently_wrong_stale']:.2f} % | {100 * c['beacon_on_read_stale']:.1f} % / "
                 f"{100 * c['confidently_wrong_read_stale']:.2f} % |" if late else ""))
    print(f"chosen: far mass {result['threshold']:.5f} ({'targets met' if met else 'targets NOT met; nearest point'}): "
          f"beacon on {100 * best['beacon_on']:.1f} %, confidently wrong {100 * best['confidently_wrong']:.2f} % "
          f"({best['confidently_wrong_frames']} frames from {best['confidently_wrong_photos']} of {photos} photos)"
          + (f"; not turned {100 * best['confidently_wrong_unturned']:.2f} %; "
             f"a stop once half a strip stale (a gyroscope not followed) {100 * best['beacon_on_stale']:.1f} % on, "
             f"{100 * best['confidently_wrong_stale']:.2f} % wrong; a stop once the rate read makes it so "
             f"(no gyroscope) {100 * best['beacon_on_read_stale']:.1f} % on, "
             f"{100 * best['confidently_wrong_read_stale']:.2f} % wrong" if a.heard_after else ""))
    if lopo:
        print(f"chosen on the other photographers, measured on each: beacon on {100 * lopo['beacon_on']:.1f} %, "
              f"confidently wrong {100 * lopo['confidently_wrong']:.2f} % (per photographer "
              + " / ".join(f"{100 * r['confidently_wrong']:.2f} % at {r['scale'] * FAR_MASS_REFERENCE:.4f}"
                           for r in lopo["per_photographer"]) + ")")
    print(f"written: {a.cv / name}")
    return capped(gate_path, view, result) if gate_path else 0


def capped(gate_path: Path, view: str, result: dict) -> int:
    """:func:`cap` with its line: the file written and the view's threshold, or the error."""
    try:
        out, threshold = cap(gate_path, view, result)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"capped: {out} ({view} at far mass {threshold:.5f})")
    return 0


def cap_saved(gate_path: Path | None, view: str, saved: Path, runs: list[str]) -> int:
    """``--saved``: cap ``gate_path`` from the sweep's result an earlier call wrote, if it pooled ``runs``."""
    if gate_path is None:
        print("error: --saved caps from a saved sweep: give --cap GATE_JSON", file=sys.stderr)
        return 2
    if not saved.is_file():
        print(f"error: --saved: no {saved} (run this sweep once without --saved)", file=sys.stderr)
        return 2
    result = json.loads(saved.read_text())
    if result.get("runs") != runs:
        print(f"error: --saved: {saved} pooled {', '.join(result.get('runs', []))}, not {', '.join(runs)}",
              file=sys.stderr)
        return 2
    return capped(gate_path, view, result)


if __name__ == "__main__":
    sys.exit(main())

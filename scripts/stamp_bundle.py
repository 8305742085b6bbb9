"""Stamp a bundle's held-out figures (and, on request, held-out gate scales and the current
geometry schema) into its bundle.json and the graph's embedded copy, writing a new bundle
atomically. The graph itself is left as it is, unless ``--share-alike``.

    .venv/bin/python scripts/stamp_bundle.py SRC OUT --cv runs/default/cv --gate-json gate_mirror.json
        [--rescale-gate [--narrow-fov 42]] [--wide-fov 60] [--view-crop] [--sensor-aspect 4:3]
    .venv/bin/python scripts/stamp_bundle.py SRC OUT --gate-from crossing_assist/assets/default_bundle

* ``--cv CV``: ``metrics.leave_one_photographer_out`` from ``CV/cv.json`` (the folds' checkpoints),
  ``metrics.leave_one_photographer_out_bundle`` from ``CV/cv_bundles_mirror.json`` (the folds'
  bundles, scripts/cv_bundles.py; ``cv_bundles.json`` for a bundle without mirror TTA) and
  ``metrics.gate_held_out`` from ``CV/GATE_JSON`` (scripts/choose_gate.py), where present.
* ``--rescale-gate``: the gate thresholds become the bundle's fitted threshold times the scales in
  ``GATE_JSON`` (landscape, and portrait where chosen); a ``GATE_JSON`` of ``choose_gate.py
  --measure far_mass`` (``gate_mirror_far_mass.json``) sets that measure and its held-out
  thresholds instead (absolute: no fitted threshold to scale). The fitted threshold is the bundle's
  ``calibration.uncertainty.fitted_threshold`` (bundles exported before it was recorded: their
  landscape threshold over their recorded held-out scale), so a shipped bundle takes new held-out
  scales without a re-export. With ``--narrow-fov DEG`` the threshold chosen on the 3:4 windows
  (``portrait_window``: a ~41 deg camera, what 9:16 portrait video gives) becomes
  ``narrow_threshold``, for portrait frames at most DEG across (``narrow_fov_deg``); without it a
  rescaled bundle has none.
* ``--wide-fov DEG``: ``calibration.uncertainty.wide_fov_deg`` = DEG: the camera's width picks each
  frame's threshold, whatever its orientation: at least DEG across the landscape one, narrower the
  portrait one (at most the narrow FOV the narrow one). A square frame of the 4:3 sensor sees ~53 deg,
  as the phone held in portrait whose threshold that is; by orientation it took the landscape one.
  60 is midway between the cameras the two thresholds were chosen on (67 and 53 deg).
* ``--gate-from REF``: the gate of bundle REF (its ``calibration.uncertainty``: measure and
  thresholds) replaces SRC's, so two models are judged at one gate, e.g. a candidate at the
  default's thresholds (docs/models.md, "Look-alikes in training"). Not with ``--rescale-gate``;
  REF must share SRC's canvas and geometry.
* ``--view-crop``: upgrade a letterbox bundle to the current schema with ``geometry.view_crop``
  (consumers crop rows beyond the training camera's view, crossing_assist/geometry.py): right for
  models trained on windows of the training photos at their own scale, as the default is.
* ``--sensor-aspect X``: ``geometry.sensor_aspect`` = X (long side / short side of the sensor
  ``camera_fov_deg`` describes, 1..3; a number or a ratio, ``4:3`` = 1.3333333333333333): frames narrower than it (9:16
  video) get their crop's default FOV (crossing_assist/geometry.py ``default_fov``). Schema 2 or 3
  bundles; the schema is kept.
* ``--share-alike``: the graph runs once what it computes more than once: an ensemble merged before
  ``crossing-export ensemble`` shared its members' frame fitting and frozen blocks
  (crossing_assist/export/ensemble.py ``share_alike``); the outputs are unchanged bit for bit.
Each stamp is appended to ``provenance.stamped`` (a list, oldest first; a single earlier record
becomes its first entry), so a bundle stamped twice keeps both records.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import onnx

from crossing_assist.bundle import BundleError, read_bundle, write_bundle
from crossing_assist.export.ensemble import share_alike
from crossing_assist.export.graph import model_bytes, set_metadata
from crossing_assist.geometry import FOV_RANGE_DEG, GeometryError, check_sensor_aspect, parse_ratio

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import tag  # noqa: E402  (a sibling script: the file-name suffix of mirror-TTA measurements)


def summary(g: dict) -> dict:
    """One view of choose_gate.py's result, without its curves (``pooled_runs``: the CV runs it pooled;
    ``scans``: scripts/scan_gate.py's checks on held-out scans, one per sweep, and the thresholds they
    capped; ``scan``: the one check of a file written before the list)."""
    return {k: g[k] for k in ("measure", "scale", "threshold", "targets_met", "folds", "accuracy", "bin_mae",
                              "accuracy_goal_in_view", "pooled_runs", "scan", "scans") if k in g} | {
        "at_scale": {k: v for k, v in g["at_scale"].items() if k != "per_fold"},
        "at_fitted_threshold": {k: v for k, v in g["at_fitted_threshold"].items() if k != "per_fold"}}


def narrow(fov_deg: float | None, threshold: float | None) -> dict:
    """The narrow camera's threshold fields of ``calibration.uncertainty`` (none without ``fov_deg``)."""
    return {} if fov_deg is None else {"narrow_threshold": threshold, "narrow_fov_deg": fov_deg}


def _number_or_ratio(text: str) -> float | str:
    """``4:3`` as the number 4 / 3; anything else as typed (checked by the caller)."""
    try:
        return parse_ratio(text) if ":" in text else text
    except ValueError:
        return text


def stamp_held_out(a: argparse.Namespace, b, meta: dict) -> list[str] | None:
    """Stamp the held-out figures in ``a.cv`` into ``meta`` (and, with ``--rescale-gate``, its gate):
    what was stamped, or None after an error line."""
    old_gate = meta["metrics"].get("gate_held_out")
    shipped, gate_path = a.cv / f"cv_bundles{tag(b.mc.mirror)}.json", a.cv / a.gate_json
    read = [p.name for p in (a.cv / "cv.json", shipped, gate_path) if p.is_file()]
    if (a.cv / "cv.json").is_file():
        c = json.loads((a.cv / "cv.json").read_text())
        meta["metrics"]["leave_one_photographer_out"] = {
            "epochs": c["config"]["epochs"], "folds": c["folds"],
            **{k: c[k] for k in ("accuracy", "bin_mae", "far_x_error", "majority_accuracy")}}
    # scripts/cv_bundles.py's figures for folds exported with this bundle's test-time augmentation
    if shipped.is_file():
        meta["metrics"]["leave_one_photographer_out_bundle"] = json.loads(shipped.read_text())
    stamped = [f"held-out figures from {a.cv} ({', '.join(read)})"] if read else []
    if gate_path.is_file():
        g = json.loads(gate_path.read_text())
        meta["metrics"]["gate_held_out"] = summary(g) | {k: summary(g[k]) for k in ("portrait", "portrait_window") if k in g}
        window = g.get("portrait_window")
        if a.narrow_fov is not None and not (window and window.get("targets_met")):
            print(f"error: --narrow-fov: {gate_path} has no 3:4-window choice that meets the targets "
                  "(run scripts/choose_gate.py with --portrait)", file=sys.stderr)
            return None
        if a.rescale_gate and "threshold" in g:   # choose_gate.py --measure: absolute thresholds of that measure
            views = {"landscape": g, **{k: g[k] for k in ("portrait",) if k in g},
                     **({f"portrait frames at most {a.narrow_fov:g} deg": window} if a.narrow_fov is not None else {})}
            meta["calibration"]["uncertainty"] = {"measure": g["measure"], "threshold": g["threshold"],
                                                  **({"portrait_threshold": g["portrait"]["threshold"]} if "portrait" in g else {}),
                                                  **narrow(a.narrow_fov, window and window["threshold"])}
            stamped.append(f"gate measure {g['measure']}, held-out thresholds "
                           + ", ".join(f"{v['threshold']:.4g} ({k})" for k, v in views.items()))
        elif a.rescale_gate:
            unc = meta["calibration"]["uncertainty"]
            if (chosen := g.get("measure", "entropy")) != unc["measure"]:
                print(f"error: {gate_path} chose scales of {chosen}, {a.src} gates with {unc['measure']}",
                      file=sys.stderr)
                return None
            fitted = unc.get("fitted_threshold")
            if fitted is None:   # exported before bundles recorded it: undo the recorded scale
                if not old_gate:
                    print(f"error: {a.src} records neither its fitted gate threshold nor a held-out gate scale; "
                          "re-export it instead", file=sys.stderr)
                    return None
                fitted = unc["threshold"] / old_gate["scale"]
            unc["fitted_threshold"] = fitted
            unc["threshold"] = fitted * g["scale"]
            if "portrait" in g:
                unc["portrait_threshold"] = fitted * g["portrait"]["scale"]
            for k in ("narrow_threshold", "narrow_fov_deg", "wide_fov_deg"):   # a rescaled gate keeps no stale rule
                unc.pop(k, None)
            unc.update(narrow(a.narrow_fov, window and fitted * window["scale"]))
            stamped.append(f"gate thresholds = fitted {fitted:.4f} x held-out scales {g['scale']:.4f} (landscape), "
                           f"{g.get('portrait', {}).get('scale', 'unchanged')} (portrait)"
                           + (f", {window['scale']:.4f} (portrait frames at most {a.narrow_fov:g} deg)"
                              if a.narrow_fov is not None else ""))
    elif a.rescale_gate:
        print(f"error: {gate_path} not found (run scripts/choose_gate.py {a.cv})", file=sys.stderr)
        return None
    return stamped


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--cv", type=Path, help="the --cv source run folder (its held-out figures are stamped)")
    ap.add_argument("--gate-json", default="gate.json", help="choose_gate.py's result in CV")
    ap.add_argument("--rescale-gate", action="store_true", help="thresholds = fitted x the held-out scales")
    ap.add_argument("--narrow-fov", type=float, metavar="DEG",
                    help="with --rescale-gate: portrait frames at most DEG across take the threshold chosen on the "
                         "3:4 windows (calibration.uncertainty.narrow_threshold, narrow_fov_deg)")
    ap.add_argument("--wide-fov", type=float, metavar="DEG",
                    help="calibration.uncertainty.wide_fov_deg: frames under DEG across take the portrait threshold, "
                         "at least DEG the landscape one, whatever their orientation")
    ap.add_argument("--gate-from", type=Path, metavar="REF",
                    help="the gate (calibration.uncertainty) of bundle REF instead of SRC's: two models at one gate")
    ap.add_argument("--view-crop", action="store_true", help="current schema, geometry.view_crop true")
    ap.add_argument("--sensor-aspect", metavar="X", help="geometry.sensor_aspect = X (long / short side of the "
                    "sensor camera_fov_deg describes, 1..3; a number or a ratio such as 4:3)")
    ap.add_argument("--share-alike", action="store_true",
                    help="run once what the graph computes more than once (an ensemble's shared frozen blocks); "
                         "the outputs are unchanged")
    a = ap.parse_args(argv)
    if a.narrow_fov is not None and not a.rescale_gate:
        ap.error("--narrow-fov needs --rescale-gate")
    if a.rescale_gate and a.cv is None:
        ap.error("--rescale-gate needs --cv")
    if a.rescale_gate and a.gate_from is not None:
        ap.error("--gate-from and --rescale-gate: one gate at a time")
    if (a.cv is None and a.gate_from is None and not a.view_crop and a.sensor_aspect is None and a.wide_fov is None
            and not a.share_alike):
        ap.error("nothing to stamp: give --cv, --gate-from, --wide-fov, --view-crop, --sensor-aspect or --share-alike")
    for flag, fov in (("--narrow-fov", a.narrow_fov), ("--wide-fov", a.wide_fov)):
        if fov is not None and not FOV_RANGE_DEG[0] <= fov <= FOV_RANGE_DEG[1]:
            ap.error(f"{flag} {fov:g}: valid {FOV_RANGE_DEG[0]:g}..{FOV_RANGE_DEG[1]:g} degrees")
    try:
        aspect = None if a.sensor_aspect is None else check_sensor_aspect(_number_or_ratio(a.sensor_aspect))
    except GeometryError as exc:
        print(f"error: --sensor-aspect: {exc}", file=sys.stderr)
        return 2
    try:
        b = read_bundle(a.src)
        ref = None if a.gate_from is None else read_bundle(a.gate_from)
    except BundleError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if ref is not None and (ref.input.size, ref.geometry) != (b.input.size, b.geometry):
        print(f"error: --gate-from {a.gate_from}: its canvas or geometry differs from {a.src}'s; "
              "a gate carries only between bundles that fit frames alike", file=sys.stderr)
        return 2
    meta = json.loads((a.src / "bundle.json").read_text())
    stamped = stamp_held_out(a, b, meta) if a.cv is not None else []
    if stamped is None:
        return 2
    if ref is not None:
        gate = json.loads((a.gate_from / "bundle.json").read_text())["calibration"]["uncertainty"]
        meta["calibration"]["uncertainty"] = gate
        stamped.append(f"gate of {a.gate_from} ({gate['measure']}, threshold {gate['threshold']:.4g})")
    if a.wide_fov is not None:
        unc = meta["calibration"]["uncertainty"]
        if unc.get("narrow_fov_deg") is not None and not a.wide_fov > unc["narrow_fov_deg"]:
            print(f"error: --wide-fov {a.wide_fov:g}: must exceed the bundle's narrow_fov_deg {unc['narrow_fov_deg']:g}",
                  file=sys.stderr)
            return 2
        unc["wide_fov_deg"] = a.wide_fov
        stamped.append(f"gate threshold by the camera's width: frames under {a.wide_fov:g} deg take the portrait one")
    if a.view_crop:
        if b.geometry.fit != "letterbox":
            print(f"error: {a.src} is not letterboxed (geometry.fit = {b.geometry.fit}); no view crop", file=sys.stderr)
            return 2
        meta["schema_version"] = max(3, b.schema_version)
        meta["geometry"]["view_crop"] = True
        stamped.append(f"schema {meta['schema_version']}, geometry.view_crop")
    if aspect is not None:
        if b.schema_version < 2:
            print(f"error: {a.src} is schema {b.schema_version} (no geometry block); re-export it", file=sys.stderr)
            return 2
        meta["geometry"]["sensor_aspect"] = aspect
        stamped.append(f"geometry.sensor_aspect {aspect:g}")
    model = onnx.load_model_from_string(b.model_path.read_bytes())
    if a.share_alike:
        before = len(model.graph.node)
        dropped = share_alike(model)
        stamped.append(f"graph: {dropped} of {before} nodes computed alike run once")
    if stamped:
        earlier = meta["provenance"].get("stamped", [])
        record = {"what": stamped, "by": "scripts/stamp_bundle.py " + " ".join(sys.argv[1:] if argv is None else argv),
                  "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        meta["provenance"]["stamped"] = [*(earlier if isinstance(earlier, list) else [earlier]), record]
    set_metadata(model, meta)
    write_bundle(a.out, model_bytes(model), meta)
    b = read_bundle(a.out)
    full, cross = b.metrics.get("full_split"), b.metrics.get("cross_fit")
    measured = (f", val accuracy {full['accuracy']:.3f}, held-out coverage {cross['coverage']:.3f} at target "
                f"{b.calibration.conformal.coverage}") if full and cross else ""
    print(f"bundle written: {a.out} ({b.model_size / 1e6:.1f} MB, {b.precision}, schema {b.schema_version}{measured}"
          + "".join(f"; {s}" for s in stamped) + ")")
    return 0


if __name__ == "__main__":
    sys.exit(main())

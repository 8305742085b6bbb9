"""``crossing-export --run RUN_DIR --out BUNDLE_DIR [--samples 16] [--p 0.5] [--calib-data DIR] [--int8]``;
``crossing-export ensemble BUNDLE BUNDLE [...] --out BUNDLE_DIR --calib-data DIR``: several bundles'
graphs as one (:mod:`crossing_assist.export.ensemble`).

The export parser is generated from :class:`~crossing_assist.export.exporter.ExportConfig`'s
defaults; user errors print one ``error: ...`` line to stderr and exit 2. Both refuse a
``--calib-data`` with fewer than ``--min-calib`` (default 50) frames with a crossing, and print a
``warning: ...`` line for a calibration fit that ended on a clip.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from typing import Sequence

HELP = {
    "run": "run folder (uses weights/best.pt) or a .pt checkpoint",
    "out": "bundle folder to write (an existing bundle is replaced atomically; anything else is refused)",
    "samples": "MC dropout samples T folded into the batch",
    "mirror": "mirror test-time augmentation in the graph: each frame also runs flipped left-right (actions mapped back) and both sets of samples are summarised together; twice the backbone's cost",
    "p": "drop probability of the sampled layers (default: the checkpoint's, 0.5 in the thesis)",
    "calib_data": "dataset folder (manifest.csv) with labelled frames to calibrate on",
    "calib_split": "split of --calib-data to calibrate on (all of it; held-out coverage by folds of sources)",
    "calib_folds": "folds (whole sources) for the held-out coverage: each measured with a calibration fitted on the others",
    "min_calib": "fewest --calib-data frames with a crossing to calibrate on; fewer are refused, as they fit the "
                 "calibration to noise (lower it only for toy runs and tests)",
    "coverage": "target coverage of the conformal action sets",
    "measure": "the gate's uncertainty measure: entropy | mutual_info | far_mass (the probability beyond one strip of the argmax)",
    "gate_scale": "multiply the fitted gate threshold by this (pick it on held-out sources' risk-coverage curve: scripts/choose_gate.py)",
    "gate_scale_portrait": "the same for portrait frames, written as calibration.uncertainty.portrait_threshold (default: portrait uses --gate-scale's)",
    "view_zoom": "show frames from a camera narrower than the training one (a phone in portrait) magnified by up to this instead of at the training scale (bundle schema 4); for models trained with crossing-train --field-zoom; 1 = the training scale",
    "int8": "quantise the convolutions to int8 (static QDQ, calibrated on real frames)",
    "int8_mode": "static: int8 weights and activations in the backbone's convolutions; weights: int8 weights only (float activations)",
    "int8_frames": "calibration frames for the int8 ranges",
    "parity_frames": "frames for the T=1, p=0 onnxruntime vs PyTorch parity check",
    "parity_tol": "largest allowed |probs| difference in the parity check",
    "batch": "frames per batch",
    "threads": "CPU threads for PyTorch",
    "seed": "seed of the dropout masks (PyTorch's and onnxruntime's) drawn while calibrating and measuring",
    "progress": "progress bars",
    "force": "replace --out even if it is not a bundle (deletes what is there)",
}


def build_parser() -> argparse.ArgumentParser:
    from crossing_assist.export.exporter import ExportConfig  # noqa: F401  (torch loaded lazily below)

    p = argparse.ArgumentParser(prog="crossing-export",
                                description="Export a trained run to a calibrated one-pass MC-dropout ONNX bundle.")
    for f in _fields():
        flag = "--" + f.name.replace("_", "-")
        if f.name in ("run", "out"):
            p.add_argument(flag, required=True, help=HELP[f.name])
        elif f.name == "progress":
            p.add_argument("--quiet", dest="progress", action="store_false", help="no progress bars")
        elif f.type in (bool, "bool"):
            p.add_argument(flag, action="store_true", help=HELP[f.name])
        else:
            kind = {"int": int, "float": float, "float | None": float}.get(str(f.type), str)
            p.add_argument(flag, type=kind, default=f.default, help=f"{HELP[f.name]} (default: {f.default})")
    p.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    return p


def _fields():
    from crossing_assist.export.exporter import ExportConfig

    return fields(ExportConfig)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``crossing-export`` (exit 2 user error, 130 Ctrl-C; ``--debug`` for tracebacks)."""
    from crossing_assist.errors import run_cli

    return run_cli(_main, argv)


def ensemble_parser() -> argparse.ArgumentParser:
    from crossing_assist.export.ensemble import EnsembleConfig

    d = {f.name: f.default for f in fields(EnsembleConfig)}
    p = argparse.ArgumentParser(prog="crossing-export ensemble",
                                description="Merge bundles exported alike (e.g. one recipe, several seeds) into one "
                                            "ensemble bundle: their graphs side by side (what they compute alike run "
                                            "once), their MC samples pooled, the thresholds fitted again on labelled "
                                            "frames through the merged graph. An ensemble bundle among them counts as "
                                            "its members.")
    p.add_argument("members", nargs="+", help="the member bundles' folders (at least 2; an ensemble counts as its members)")
    p.add_argument("--out", required=True, help=HELP["out"])
    p.add_argument("--calib-data", required=True, help=HELP["calib_data"])
    for name in ("calib_split", "min_calib", "coverage", "measure", "gate_scale", "gate_scale_portrait", "batch", "seed"):
        kind = {"calib_split": str, "measure": str, "min_calib": int, "batch": int, "seed": int}.get(name, float)
        p.add_argument("--" + name.replace("_", "-"), type=kind, default=d[name], help=f"{HELP[name]} (default: {d[name]})")
    p.add_argument("--quiet", dest="progress", action="store_false", help="no progress bars")
    p.add_argument("--force", action="store_true", help=HELP["force"])
    p.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    return p


def _ensemble(argv: list[str]) -> int:
    from crossing_assist.export.ensemble import EnsembleConfig, ensemble_bundle
    from crossing_assist.bundle import read_bundle

    args = vars(ensemble_parser().parse_args(argv))
    args.pop("debug")
    cfg = EnsembleConfig(**{**args, "members": tuple(args["members"])})
    out = read_bundle(ensemble_bundle(cfg, log=lambda m: print(m, file=sys.stderr)))
    u, full = out.calibration.uncertainty, out.metrics["full_split"]
    print(f"ensemble bundle written: {out.dir} ({out.mc.members} members, {out.model_size / 1e6:.1f} MB); "
          f"{cfg.calib_split} accuracy {full['accuracy']:.3f} on {full['n']} frames, {u.measure} threshold {u.threshold:.4g}")
    return 0


def _main(argv: list[str]) -> int:
    if argv[:1] == ["ensemble"]:
        return _ensemble(argv[1:])
    args = build_parser().parse_args(argv)
    from crossing_assist.export.exporter import ExportConfig, export_bundle

    cfg = ExportConfig(**{f.name: getattr(args, f.name) for f in _fields()})
    res = export_bundle(cfg, log=lambda m: print(m, file=sys.stderr))
    for note in res.notes:
        print(f"note: {note}", file=sys.stderr)
    full, cross = res.metrics.get("full_split"), res.metrics.get("cross_fit")
    if full and cross:
        c = res.calibration
        print(f"{full['n']} labelled frames: accuracy {full['accuracy']:.3f} (majority {full['majority_accuracy']:.3f}); "
              f"held-out conformal coverage {cross['coverage']:.3f} (target {c.coverage:.2f}), mean set size "
              f"{cross['mean_set_size']:.2f}; temperature {c.temperature:.3f}, {c.measure} threshold "
              f"{c.uncertainty_threshold:.3f}", file=sys.stderr)
    q = res.metrics.get("int8_vs_fp32")
    if q:
        print(f"int8 vs fp32: size {q['size_int8'] / 1e6:.1f} / {q['size_fp32'] / 1e6:.1f} MB "
              f"({q['size_ratio']:.2f}x), {q['ms_int8']:.1f} / {q['ms_fp32']:.1f} ms a frame, accuracy "
              f"{q['accuracy_int8']:.3f} / {q['accuracy_fp32']:.3f}", file=sys.stderr)
    print(f"bundle written: {res.path} ({res.size / 1e6:.1f} MB, {res.calibration.n_frames} calibration frames, "
          f"parity {res.parity_max_abs:.1e})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

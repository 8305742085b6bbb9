"""``crossing-train`` and ``crossing-eval``: parse, build a frozen config, call the library."""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import fields
from typing import Callable, Sequence

from ..geometry import parse_size
from .config import ConfigError, TrainConfig

_DEFAULTS = {f.name: f.default for f in fields(TrainConfig) if f.name not in ("data", "out")}


def _run(func: Callable[[], int], argv: Sequence[str] | None = None, interrupted: Callable[[], str] = str) -> int:
    """Run ``func`` through the shared wrapper (exit 2 user error, 130 Ctrl-C, ``--debug``)."""
    from ..errors import run_cli

    return run_cli(lambda _args: func(), argv, interrupted=interrupted)


def _args(argv: Sequence[str] | None) -> list[str]:
    from ..errors import split_debug

    return split_debug(argv)[0]


def _given(parser: argparse.ArgumentParser, args: list[str]) -> set[str]:
    """Names of the options given on the command line (not left at their defaults)."""
    for action in parser._actions:
        action.default = argparse.SUPPRESS
    return set(vars(parser.parse_args(args)))


def _resume_hint(out: str) -> Callable[[], str]:
    from pathlib import Path

    def hint() -> str:
        if (Path(out) / "weights" / "last.pt").is_file():
            return "run the same command with --resume to continue from the last finished epoch"
        return "no epoch finished yet, so there is nothing to resume; run the same command again"
    return hint


def _canvas_size(text: str) -> tuple[int, int]:
    """``--input-size``: ``224`` -> (224, 224); ``224x298`` -> (H=224, W=298)."""
    return parse_size(text, "HxW")


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid list {text!r}; expected numbers like 8,16") from None


def _names(text: str) -> tuple[str, ...]:
    """``a, b,`` -> ("a", "b")."""
    return tuple(t.strip() for t in text.split(",") if t.strip())


def train_parser() -> argparse.ArgumentParser:
    d = _DEFAULTS
    p = argparse.ArgumentParser(prog="crossing-train", description="Train a crossing policy (frozen backbone, cached features).")
    p.add_argument("--data", required=True, help="dataset folder (manifest.csv)")
    p.add_argument("--out", required=True, help="run folder, e.g. runs/lite0_spatial")
    p.add_argument("--extra-data", action="append", default=[], help="another dataset folder whose train rows are added (repeatable)")
    p.add_argument("--backbone", default=d["backbone"])
    p.add_argument("--weights", default=d["weights"], help="imagenet | none | PATH to a state dict")
    p.add_argument("--head", default=d["head"], help="spatial | spatial_fine | spatial_strips | spatial_mlp | thesis | thesis_fc")
    p.add_argument("--feature-stride", type=int, default=d["feature_stride"],
                   help="16: the head also reads the backbone's last stride-16 block (efficientnet_lite0); default: its own 32")
    p.add_argument("--actions", type=int, default=d["actions"], help="4 | 8 | 13")
    p.add_argument("--epochs", type=int, default=d["epochs"])
    p.add_argument("--batch-size", type=int, default=d["batch_size"])
    p.add_argument("--optimizer", default=d["optimizer"], help="rmsprop | adamw")
    p.add_argument("--lr", type=float, default=d["lr"])
    p.add_argument("--weight-decay", type=float, default=d["weight_decay"])
    p.add_argument("--lr-schedule", default=d["lr_schedule"],
                   help="constant | cosine: the learning rate falls from --lr to 0 over the run, step by step")
    p.add_argument("--p", "--dropout", dest="p", type=float, default=d["p"],
                   help="MC dropout probability of the head (--dropout under torchrun, whose --print-completion takes --p)")
    p.add_argument("--no-mirror", dest="mirror", action="store_false", help="do not add mirrored frames")
    p.add_argument("--yaw", type=_floats, default=d["yaw"], help="fixed yaw angles in degrees, e.g. 8,16 (each +-)")
    p.add_argument("--field", type=int, default=d["field"],
                   help="random field views per frame: roll, phone aspect (letterboxed), corruption")
    p.add_argument("--field-without", type=_names, default=d["field_without"],
                   help="field-view steps left out, comma-separated, for an ablation: mirror, roll, aspect, "
                        "corruption, or one corruption (night, rain, ...)")
    p.add_argument("--field-zoom", type=float, default=d["field_zoom"],
                   help="> 1: half the field views magnified by 1..this, as a narrower camera shown filling "
                        "the canvas sees the scene (1 = none)")
    p.add_argument("--fov", dest="fov_deg", type=float, default=d["fov_deg"],
                   help="horizontal field of view of the training photos (deg)")
    p.add_argument("--input-size", type=_canvas_size, default=d["input_size"], help="canvas H or HxW, e.g. 168x224 (4:3)")
    p.add_argument("--fit", default=d["fit"], help="letterbox (default) | stretch: how frames meet the canvas")
    p.add_argument("--four-three", action="store_true", help="shortcut for --input-size 224x298")
    p.add_argument("--unfreeze", type=int, default=d["unfreeze"], help="train the last N backbone blocks")
    p.add_argument("--balance", default=d["balance"], help="none | weights (inverse-frequency class weights in the loss) | sqrt (their square root, milder) | sampler")
    p.add_argument("--smoothing", type=float, default=d["smoothing"], help="label mass given to neighbouring bins")
    p.add_argument("--aux-x", type=float, default=d["aux_x"], help="weight of the far_x regression auxiliary loss")
    p.add_argument("--soft-x", type=float, default=d["soft_x"],
                   help="targets from a Gaussian around the goal's x, sd in strip widths (0: --smoothing only)")
    p.add_argument("--select-on", default=d["select_on"], help="val | holdout | last: which set picks best.pt")
    p.add_argument("--holdout", type=_names, default=d["holdout"], help="comma-separated train sources held out for selection")
    p.add_argument("--seed", type=int, default=d["seed"])
    p.add_argument("--threads", type=int, default=d["threads"])
    p.add_argument("--cache-dir", default=d["cache_dir"])
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from weights/last.pt "
                   "(options must match the run's args.yaml; a larger --epochs extends it)")
    p.add_argument("--cv", choices=("source",), help="leave-one-source-out cross-validation: one run per "
                   "train source in OUT/fold-SOURCE, mean +- sd in OUT/cv.json (finished folds are kept)")
    p.add_argument("--cv-jobs", type=int, default=1, metavar="N",
                   help="with --cv: train N folds side by side, each in its own process with --threads threads "
                   "(the feature cache is built once; the others wait for it)")
    p.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    return p


def train_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``crossing-train``."""
    a = train_parser().parse_args(_args(argv))

    def go() -> int:
        from . import distributed
        from .train import resume_config, train, trained_epochs

        cfg = TrainConfig(
            data=a.data, out=a.out, extra_data=tuple(a.extra_data), backbone=a.backbone, weights=a.weights, head=a.head,
            feature_stride=a.feature_stride, actions=a.actions,
            epochs=a.epochs, batch_size=a.batch_size, optimizer=a.optimizer, lr=a.lr, lr_schedule=a.lr_schedule,
            weight_decay=a.weight_decay, p=a.p, mirror=a.mirror, yaw=tuple(a.yaw), field=a.field,
            field_without=tuple(a.field_without), field_zoom=a.field_zoom, fov_deg=a.fov_deg,
            input_size=(224, 298) if a.four_three else a.input_size, fit=a.fit, unfreeze=a.unfreeze, balance=a.balance,
            smoothing=a.smoothing, aux_x=a.aux_x, soft_x=a.soft_x, select_on=a.select_on,
            holdout=tuple(a.holdout), seed=a.seed,
            threads=a.threads, cache_dir=a.cache_dir, progress=not a.quiet)
        if a.cv:
            from .crossval import cross_validate, format_cv

            if distributed.requested():
                raise ConfigError("Invalid --cv under torchrun: folds run one after another; run --cv in one process")

            summary = cross_validate(cfg, resume=a.resume, jobs=a.cv_jobs)
            print(format_cv(summary))
            return 0
        if a.cv_jobs != 1:
            raise ConfigError(f"Invalid --cv-jobs {a.cv_jobs} without --cv: it trains the folds of a --cv run side by side")
        if a.resume:
            cfg = resume_config(cfg, _given(train_parser(), _args(argv)))
        try:
            out = train(cfg, resume=a.resume)
        finally:
            distributed.teardown()
        best = out / "weights" / "best.pt"
        if os.environ.get("RANK", "0") == "0":  # one line per run, not per torchrun rank
            print(f"trained {trained_epochs(out)} epochs -> {best} ({best.stat().st_size / 1e6:.1f} MB)")
        if distributed.requested():
            distributed.leave(0)
        return 0

    return _run(go, argv, interrupted=_resume_hint(a.out))


def eval_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="crossing-eval", description="Evaluate a run (or a bundle) on a dataset split.")
    p.add_argument("--run", help="run folder (uses weights/best.pt) or a .pt checkpoint")
    p.add_argument("--bundle", help="bundle folder (model.onnx + bundle.json) instead of --run")
    p.add_argument("--data", required=True, help="dataset folder (manifest.csv)")
    p.add_argument("--split", default="val", choices=("val", "test", "train"), help="val | test | train")
    p.add_argument("--out", help="output folder (default RUN/eval_SPLIT or BUNDLE/eval_SPLIT; for the embedded "
                                 "bundle runs/default_bundle/eval_SPLIT: the package is never written into)")
    p.add_argument("--samples", type=int, default=1, help="MC dropout samples for checkpoints (1 = deterministic)")
    p.add_argument("--examples", type=int, default=12, help="frames on the example sheet")
    p.add_argument("--tta-mirror", action="store_true", help="average each frame with its mirror image (checkpoints)")
    p.add_argument("--actions", type=int, help="score a 13-action model as 4 or 8 actions (probabilities summed per action)")
    p.add_argument("--no-listen", dest="listen", action="store_false",
                   help="bundles: skip playing frames through the runtime (beacon-on, confidently wrong, silence)")
    p.add_argument("--portrait", type=int, default=3,
                   help="bundles: portrait views per photo (0 = none): a phone held in portrait at the bundle's "
                        "portrait FOV, and 3:4 windows of the photo (a narrower camera)")
    p.add_argument("--negatives", help="bundles: dataset of no-crossing frames (its SPLIT rows), for the silence rate")
    p.add_argument("--clip-seconds", type=float, default=1.0, help="bundles: each photo plays as a still clip this long")
    p.add_argument("--fov", type=float, metavar="DEG",
                   help="bundles: the frames' camera, horizontal FOV in degrees, as crossing-demo --fov (a row's "
                        "fov=DEG flag, from crossing-data frames --fov, wins; default: the bundle's for each "
                        "frame's orientation); such frames are cut into portrait views only when that is the "
                        "training camera's FOV (within 1 deg)")
    p.add_argument("--scan", type=float, default=0.0, metavar="DEG_PER_S",
                   help="bundles: also play each photo as a user scanning for the crossing, the camera turned "
                        "0 -> +20 -> -20 -> 0 deg at this rate (e.g. 30), the turn told to the decision logic by a "
                        "gyroscope, read from the frames (the default without one) and not at all; judged per frame; "
                        "with --portrait also by a narrow camera (the middle 3:4 window), with --negatives those "
                        "frames scanned too")
    p.add_argument("--heard-after", type=float, default=0.0, metavar="S",
                   help="with --scan: judge each decision S seconds after its frame's capture, when the user hears "
                        "it (the app: 0.28-0.51 after capture in its e2e run; whole frames), and add the readings with the beacon turned by a "
                        "gyroscope's turn since the capture (decision step 10); default 0, at the capture")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the MC-dropout masks (onnxruntime for bundles, torch for --samples > 1): "
                        "the same seed gives the same figures")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--cache-dir", default=_DEFAULTS["cache_dir"])
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    return p


def eval_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``crossing-eval``."""
    a = eval_parser().parse_args(_args(argv))

    def go() -> int:
        from .config import ConfigError
        from .evaluate import EvalConfig, evaluate

        if bool(a.run) == bool(a.bundle):
            raise ConfigError("Invalid arguments: give exactly one of --run DIR and --bundle DIR")
        cfg = EvalConfig(run=a.run, bundle=a.bundle, data=a.data, split=a.split, out=a.out, samples=a.samples,
                         examples=a.examples, tta_mirror=a.tta_mirror, actions=a.actions, listen=a.listen,
                         portrait=a.portrait, negatives=a.negatives, clip_seconds=a.clip_seconds,
                         fov_deg=a.fov, scan_dps=a.scan, scan_heard_s=a.heard_after, seed=a.seed, threads=a.threads, cache_dir=a.cache_dir,
                         progress=not a.quiet)
        out, m = evaluate(cfg)
        print(f"{cfg.split}: accuracy {m['accuracy']:.3f} (majority {m['majority_accuracy']:.3f}), "
              f"bin MAE {m['bin_mae']:.3f} -> {out / 'metrics.json'}")
        f = lambda x, p=".3f": "n/a" if x is None else format(x, p)  # noqa: E731  (a figure, or n/a)
        for name in ("landscape", "portrait", "portrait_window"):
            v = m.get("listen", {}).get(name)
            if v:
                kinds = v.get("orientations") or {}
                label = name if name != "landscape" or set(kinds) <= {"landscape"} else \
                    "as taken (" + ", ".join(f"{n} {o}" for o, n in sorted(kinds.items())) + ")"
                fovs = ", ".join(f"{k} deg ({n})" for k, n in (v.get("camera_fov_deg") or {}).items())
                print(f"{label:>15} ({v['frames_with_crossing']} + {v['frames_without_crossing']} no-crossing "
                      f"frames, each a still clip through the runtime; camera FOV {fovs or 'n/a'})")
                print(f"{'':>15} model, first frame: accuracy {f(v['accuracy'])}, bin MAE {f(v['bin_mae'])}, "
                      f"far-x error {f(v['far_x_error'], '.4f')} (of the view's width)")
                print(f"{'':>15} heard, last decision: beacon on {f(v['beacon_on'])} (goal in view "
                      f"{f(v['beacon_on_goal_in_view'])}), on the right strip {f(v['accuracy_heard'])}, "
                      f"confidently wrong {f(v['confidently_wrong'], '.4f')} (of frames with a crossing), "
                      f"silence off-crossing {f(v['silence_no_crossing'])}")
                e = v.get("heading_error_deg") or {}
                if e.get("n"):
                    print(f"{'':>15} heading played vs the goal, beacon on and goal in view ({e['n']} frames): median "
                          f"{e['median']:.1f} deg, mean {e['mean']:.1f} deg, p90 {e['p90']:.1f} deg")
        scan = m.get("listen", {}).get("scan")
        if scan:
            from ..runtime.listen import LATE_READINGS, SCAN_YAW_INPUTS

            names = {**SCAN_YAW_INPUTS, **{k: name for k, (_, name) in LATE_READINGS.items()}}
            heard = scan.get("heard_after_s") or 0
            print(f"{'scan':>15} ({scan['photos']} photos, each turned 0 -> +{scan['amplitude_deg']:g} -> "
                  f"-{scan['amplitude_deg']:g} -> 0 deg at {scan['rate_dps']:g} deg/s; every frame after the first second, "
                  + (f"each decision judged {heard:g} s after its frame's capture)" if heard else "judged at its capture)"))

            def judged(s: dict) -> None:
                for k, name in names.items():
                    if k not in s:
                        continue
                    g = s[k]
                    print(f"{'':>15} {name}: beacon on {f(g['beacon_on'])}, confidently wrong "
                          f"{f(g['confidently_wrong'], '.4f')} of {g['in_view']} frames with the goal in view "
                          f"({f(g['wrong_by_hold'])} of them from the hold); goal out of view: beacon on "
                          f"{f(g['out_of_view_on'])}")

            judged(scan)
            if "portrait_window" in scan:
                w = scan["portrait_window"]
                print(f"{'':>15} the same scans by a narrow camera, a 3:4 window in the middle of each view "
                      f"({w['photos']} photos, {' / '.join(w['camera_fov_deg'])} deg across; a goal beside the "
                      "window is its edge strip):")
                judged(scan["portrait_window"])
            if "no_crossing" in scan:
                n = scan["no_crossing"]
                print(f"{'':>15} {n['photos']} no-crossing frames scanned the same way, beacon off: "
                      + ", ".join(f"{name} {f(n[k]['silence'])}" for k, name in names.items() if k in n))
        if "conformal" in m:
            c = m["conformal"]
            print(f"conformal sets: coverage {c['coverage']:.3f} (target {c['target_coverage']:.2f}), "
                  f"mean size {c['mean_size']:.2f} actions, empty {c['empty']:.3f}")
        return 0

    return _run(go, argv)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m crossing_assist.models.cli train|eval ...`` (same as the console scripts)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] not in ("train", "eval"):
        print("error: usage: python -m crossing_assist.models.cli train|eval [options]", file=sys.stderr)
        return 2
    return train_main(args[1:]) if args[0] == "train" else eval_main(args[1:])


if __name__ == "__main__":
    sys.exit(main())

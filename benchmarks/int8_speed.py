"""int8 vs fp32 for a bundle: speed side by side, onnxruntime's profile by op type, accuracy.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/int8_speed.py [--bundle DIR] [--data DIR]
        [--mode static|weights] [--calib-frames 128] [--frame 640x480] [--rounds 15] [--block 3]
        [--repeats 2] [--lopo] [--save-int8 FILE]

Takes the bundle's fp32 ``model.onnx`` (default: the embedded default bundle), quantises it
the way ``crossing-export --int8 --int8-mode MODE`` does (``crossing_assist.export.quantize``),
calibrated on ``--calib-frames`` frames of ``--data``'s val split picked as the exporter picks
them (without ``--data``: smooth synthetic frames, timing only), then

1. speed: both graphs on one uint8 frame of ``--frame`` size (the graph resizes it to the
   bundle's canvas and runs the MC head), 1 onnxruntime thread, thread CPU time, rounds
   interleaved; prints the median ms of each and the median per-round ratio fp32/int8;
2. onnxruntime's profiler (``SessionOptions.enable_profiling``): kernel time by op type for
   both, side by side (the profiler's overhead inflates absolute figures: read the shares);
3. with ``--data``: accuracy of both on the val frames the int8 ranges never saw (mean over
   ``--repeats`` MC runs), argmax agreement, accuracy by photographer, conformal coverage
   with the bundle's threshold and leave-one-photographer-out (threshold fitted on the other
   photographers' frames of the same graph); with ``--lopo`` also int8 ranges calibrated
   without each photographer, accuracy measured on that photographer.

Absolute milliseconds depend on the machine's load; quote the ratios.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import onnx  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speedlib import (Frames, int8_split, interleaved, load_split, parse_size, predict, print_profiles,  # noqa: E402
                      profile_by_op, ratio, session, synthetic_frames)

from crossing_assist.bundle import BundleError, read_bundle  # noqa: E402
from crossing_assist.export.calibrate import conformal_threshold  # noqa: E402
from crossing_assist.export.graph import model_bytes  # noqa: E402
from crossing_assist.export.quantize import INT8_MODES, quantize_convs  # noqa: E402

DEFAULT_BUNDLE = Path(__file__).resolve().parents[1] / "crossing_assist" / "assets" / "default_bundle"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bundle", default=str(DEFAULT_BUNDLE), help="fp32 bundle folder (default: the embedded one)")
    p.add_argument("--data", help="dataset folder (manifest.csv) for calibration frames and accuracy")
    p.add_argument("--split", default="val")
    p.add_argument("--mode", default="static", choices=INT8_MODES)
    p.add_argument("--calib-frames", type=int, default=128)
    p.add_argument("--frame", type=parse_size, default=(640, 480), help="timed frame WIDTHxHEIGHT (640x480)")
    p.add_argument("--rounds", type=int, default=15)
    p.add_argument("--block", type=int, default=3)
    p.add_argument("--profile-runs", type=int, default=20)
    p.add_argument("--repeats", type=int, default=2, help="MC runs averaged for accuracy")
    p.add_argument("--lopo", action="store_true", help="also: int8 calibrated without each photographer")
    p.add_argument("--save-int8", help="write the int8 model here (.onnx)")
    return p


def accuracy_block(fp32: bytes, int8: bytes, data: Frames, idx: np.ndarray, repeats: int, target: float,
                   threshold: float) -> None:
    labels, sources = data.labels[idx], data.sources[idx]
    images = [data.images[i] for i in idx]
    res = {}
    for name, model in (("fp32", fp32), ("int8", int8)):
        sess = session(model)
        runs = [predict(sess, images)["probs"] for _ in range(repeats)]
        res[name] = (float(np.mean([(p.argmax(1) == labels).mean() for p in runs])), np.mean(runs, 0))
    (a32, p32), (a8, p8) = res["fp32"], res["int8"]
    print(f"\naccuracy on the {len(idx)} {len(set(sources))}-photographer frames the int8 ranges never saw "
          f"(mean of {repeats} MC runs): fp32 {a32:.4f}, int8 {a8:.4f} ({100 * (a8 - a32):+.1f} points); "
          f"argmax agreement {100 * (p32.argmax(1) == p8.argmax(1)).mean():.1f} %")
    print(f"{'source':<12}{'n':>5}{'fp32':>8}{'int8':>8}{'cov fp32':>10}{'cov int8':>10}   "
          f"(coverage: threshold fitted on the other sources, target {target:.2f})")
    covered = {"fp32": 0, "int8": 0}
    for s in sorted(set(sources)):
        m = sources == s
        cells = []
        for name, (_, p) in res.items():
            t = conformal_threshold(p[~m], labels[~m], target)
            hit = p[m][np.arange(m.sum()), labels[m]] >= t
            covered[name] += int(hit.sum())
            cells.append(hit.mean())
        print(f"{s:<12}{int(m.sum()):>5}{(p32[m].argmax(1) == labels[m]).mean():>8.3f}"
              f"{(p8[m].argmax(1) == labels[m]).mean():>8.3f}{cells[0]:>10.3f}{cells[1]:>10.3f}")
    print(f"{'pooled':<12}{len(idx):>5}{'':>16}{covered['fp32'] / len(idx):>10.3f}{covered['int8'] / len(idx):>10.3f}")
    for name, (_, p) in res.items():
        hit = p[np.arange(len(idx)), labels] >= threshold
        sizes = (p >= threshold).sum(1)
        print(f"{name}: coverage with the bundle's threshold {threshold:.3f}: {hit.mean():.3f}, "
              f"mean set {sizes.mean():.2f}")


def lopo_block(model: onnx.ModelProto, fp32: bytes, data: Frames, args: argparse.Namespace) -> None:
    print("\nint8 ranges calibrated WITHOUT the photographer, accuracy on that photographer's frames "
          f"(mean of {args.repeats} MC runs):")
    s32 = session(fp32)
    tot = {"fp32": 0.0, "int8": 0.0}
    n_all = 0
    for s in sorted(set(data.sources)):
        test = np.flatnonzero(data.sources == s)
        others = np.flatnonzero(data.sources != s)
        calib = others[np.random.default_rng(0).permutation(len(others))[:args.calib_frames]]
        q = quantize_convs(model, [data.images[i] for i in np.sort(calib)], mode=args.mode)
        s8 = session(model_bytes(q))
        images, labels = [data.images[i] for i in test], data.labels[test]
        acc = {name: float(np.mean([(predict(sess, images)["probs"].argmax(1) == labels).mean()
                                    for _ in range(args.repeats)])) for name, sess in (("fp32", s32), ("int8", s8))}
        for k in tot:
            tot[k] += acc[k] * len(test)
        n_all += len(test)
        print(f"  {s:<12} n={len(test):<4} fp32 {acc['fp32']:.3f}  int8 {acc['int8']:.3f}  "
              f"({100 * (acc['int8'] - acc['fp32']):+.1f} points)")
    print(f"  pooled       n={n_all:<4} fp32 {tot['fp32'] / n_all:.3f}  int8 {tot['int8'] / n_all:.3f}  "
          f"({100 * (tot['int8'] - tot['fp32']) / n_all:+.1f} points)")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        bundle = read_bundle(args.bundle)
    except (BundleError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if bundle.precision != "fp32":
        print(f"error: {args.bundle}: precision {bundle.precision}; give an fp32 bundle (it is quantised here)",
              file=sys.stderr)
        return 2
    model = onnx.load_model(str(bundle.model_path))
    fp32 = model_bytes(model)
    data = load_split(args.data, args.split, bundle.actions.n) if args.data else None
    if data is not None:
        calib_idx, unseen = int8_split(len(data.images), args.calib_frames)
        calib = [data.images[i] for i in calib_idx]
    else:
        calib, unseen = synthetic_frames(max(args.calib_frames, 8), 240, 320), None
    t0 = time.time()
    q = quantize_convs(model, calib, mode=args.mode)
    int8 = model_bytes(q)
    if args.save_int8:
        Path(args.save_int8).write_bytes(int8)
    h, w = bundle.input.size
    print(f"bundle {args.bundle}: canvas {h}x{w} (HxW), T={bundle.mc.samples}; int8 {args.mode}, "
          f"{len(calib)} {'val' if data else 'synthetic'} calibration frames, quantised in {time.time() - t0:.0f} s")
    print(f"size: fp32 {len(fp32) / 1e6:.1f} MB, int8 {len(int8) / 1e6:.1f} MB ({len(int8) / len(fp32):.2f}x)")

    fw, fh = args.frame
    frame = synthetic_frames(1, fh, fw, seed=1)[0][None]
    feed = {"frames": frame}
    timed = interleaved({"fp32": (session(fp32), feed), "int8": (session(int8), feed)},
                        rounds=args.rounds, block=args.block)
    print(f"\none {fw}x{fh} uint8 frame a call, 1 thread, thread CPU time, {args.rounds} interleaved rounds "
          f"of {args.block} calls:")
    for t in timed.values():
        print(f"  {t.name}: median {np.median(t.ms):.2f} ms")
    print(f"  int8 is {ratio(timed['fp32'], timed['int8']):.2f}x faster than fp32 (median of per-round ratios)")

    print(f"\nonnxruntime profiler, kernel time by op type (mean of {args.profile_runs} calls):")
    print_profiles({"fp32": profile_by_op(fp32, feed, args.profile_runs),
                    "int8": profile_by_op(int8, feed, args.profile_runs)})

    if data is not None:
        conf = bundle.calibration.conformal
        accuracy_block(fp32, int8, data, unseen, args.repeats, conf.coverage, conf.threshold)
        if args.lopo:
            lopo_block(model, fp32, data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``crossing-data``: the data tools' command line. Each sub-command parses its arguments,
builds a frozen config and calls the library; user errors print one ``error: ...`` line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Sequence

from crossing_assist.data_tools.images import ImageError
from crossing_assist.data_tools.manifest import ManifestError

USER_ERRORS: tuple[type[BaseException], ...] = (ManifestError, ImageError, OSError)


def _user_errors() -> tuple[type[BaseException], ...]:
    from crossing_assist.data_tools.ptl import PTLError
    from crossing_assist.data_tools.frames import VideoError
    from crossing_assist.data_tools.synth import SynthError
    return USER_ERRORS + (PTLError, SynthError, VideoError)


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r} invalid; expected WxH, e.g. 320x240") from None
    return w, h


# ---------------------------------------------------------------- sub-commands


def _cmd_import_ptl(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.ptl import PTLImportConfig, import_ptl
    cfg = PTLImportConfig(Path(args.ptl_dir), Path(args.out), args.images, not args.quiet)
    path = import_ptl(cfg)
    from crossing_assist.data_tools.manifest import read_manifest
    ds = read_manifest(path.parent)
    counts = ", ".join(f"{s} {len(ds.split(s))}" for s in ("train", "val", "test") if len(ds.split(s)))
    print(f"wrote {path} ({len(ds)} rows: {counts}; images {args.images})")
    return 0


def _cmd_stats(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.manifest import read_manifest
    from crossing_assist.data_tools.stats import compute_stats, format_stats, plot_histogram
    ds = read_manifest(args.dataset)
    st = compute_stats(ds)
    print(format_stats(st))
    if not args.no_plot:
        out = Path(args.plot) if args.plot else Path(args.dataset) / "stats_histogram.png"
        try:
            print(f"histogram: {plot_histogram(st, out)}")
        except ImportError:
            print("histogram skipped: matplotlib is not installed (pip install matplotlib)", file=sys.stderr)
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools import synth
    if args.video:
        w, h = args.size or (320, 240)
        command = "crossing-data " + " ".join(sys.argv[1:]) if args.record_command is None else args.record_command
        cfg = synth.ClipConfig(Path(args.out), args.seed, args.seconds, args.fps, w, h, args.fov,
                               args.supersample, command, not args.quiet)
        video, side = synth.synth_clip(cfg)
        print(f"wrote {video} ({video.stat().st_size / 1e6:.2f} MB, {int(round(args.seconds * args.fps))} frames) "
              f"and {side}")
        return 0
    w, h = args.size or (224, 168)
    cfg = synth.SynthConfig(Path(args.out), args.frames, args.seed, w, h, args.fov, args.unknown_fraction,
                            args.val_fraction, args.supersample, not args.quiet)
    path = synth.synth_dataset(cfg)
    print(f"wrote {path} ({args.frames} synthetic frames, seed {args.seed})")
    return 0


def _cmd_frames(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.frames import FramesConfig, extract_frames
    cfg = FramesConfig(tuple(Path(v) for v in args.videos), Path(args.out), args.fps, progress=not args.quiet)
    results, listing = extract_frames(cfg)
    for r in results:
        if r.error:
            print(f"error: {r.error}", file=sys.stderr)
        elif r.warning:
            print(f"warning: {r.warning}", file=sys.stderr)
        if r.frames:
            print(f"{r.video}: {len(r.frames)} frames -> {Path(args.out) / r.name}")
    failed = sum(1 for r in results if r.error)
    total = sum(len(r.frames) for r in results)
    print(f"{total} frames from {len(results) - failed} of {len(results)} videos"
          + (f"; listed in {listing}" if listing else ""))
    return 1 if failed else 0


# ---------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="crossing-data", description=__doc__.split(".")[0] + ".")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("import-ptl", help="turn a folder in the PTL layout into a dataset")
    p.add_argument("ptl_dir", help="folder with labels.csv and the images")
    p.add_argument("--out", required=True, help="dataset folder to write")
    p.add_argument("--images", choices=("copy", "reference"), default="copy",
                   help="copy (hard link where possible) the images into OUT/images, or reference "
                        "them in place by relative path (checked on every read)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_import_ptl)

    p = sub.add_parser("stats", help="counts per bin / action space / split, majority baseline, histogram")
    p.add_argument("dataset", help="dataset folder (with manifest.csv)")
    p.add_argument("--plot", help="histogram PNG path (default DATASET/stats_histogram.png)")
    p.add_argument("--no-plot", action="store_true", help="skip the histogram")
    p.set_defaults(func=_cmd_stats)

    p = sub.add_parser("frames", help="frames from videos at a fixed rate, named by video and timestamp")
    p.add_argument("videos", nargs="+", metavar="VIDEO")
    p.add_argument("--out", required=True, help="folder for the frames and frames.csv")
    p.add_argument("--fps", type=float, default=2.0, help="frames per second to keep (default 2)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_frames)

    d_frames, d_clip = synth_defaults()
    p = sub.add_parser("synth", help="render synthetic street corners (a dataset, or with --video a clip)")
    p.add_argument("--out", required=True, help="dataset folder; with --video the .mp4 file to write")
    p.add_argument("--frames", type=int, default=d_frames.frames, help="frames to render (dataset)")
    p.add_argument("--seed", type=int, default=d_frames.seed)
    p.add_argument("--size", type=_size, help="WxH (default 224x168 frames, 320x240 video)")
    p.add_argument("--fov", type=float, default=d_frames.fov_deg, help="horizontal field of view, degrees")
    p.add_argument("--unknown-fraction", type=float, default=d_frames.unknown_fraction,
                   help="share of frames with no crossing in view (labelled unknown)")
    p.add_argument("--val-fraction", type=float, default=d_frames.val_fraction,
                   help="share of scenes put in the val split")
    p.add_argument("--supersample", type=int, choices=(1, 2, 3), default=d_frames.supersample,
                   help="anti-aliasing factor (render cost grows with its square)")
    p.add_argument("--video", action="store_true", help="render a first-person clip (+ JSON ground truth)")
    p.add_argument("--seconds", type=float, default=d_clip.seconds, help="clip length (--video)")
    p.add_argument("--fps", type=float, default=d_clip.fps, help="clip frame rate (--video)")
    p.add_argument("--record-command", help=argparse.SUPPRESS)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_synth)
    return parser


def synth_defaults():
    """Default configs of ``synth`` (the CLI's defaults are read from them)."""
    from crossing_assist.data_tools.synth import ClipConfig, SynthConfig
    return SynthConfig(Path(".")), ClipConfig(Path("clip.mp4"))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``crossing-data``; returns the exit status."""
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except _user_errors() as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

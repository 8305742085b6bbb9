"""``crossing-data``: the data tools' command line. Each sub-command parses its arguments,
builds a frozen config and calls the library through :func:`crossing_assist.errors.run_cli`:
user errors print one ``error: ...`` line and exit 2 (``--debug`` shows the traceback)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Sequence

from crossing_assist.actions import DEFAULT_FOV_DEG
from crossing_assist.geometry import parse_size


def _frame_size(text: str) -> tuple[int, int]:
    """``--size WxH`` (width first, as frames and videos are named) -> (H, W)."""
    return parse_size(text, "WxH")


# ---------------------------------------------------------------- sub-commands


def _cmd_import_ptl(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.ptl import PTLImportConfig, import_ptl
    cfg = PTLImportConfig(Path(args.ptl_dir), Path(args.out), args.images, not args.quiet, args.square,
                          not args.no_exif_fov)
    path = import_ptl(cfg)
    from crossing_assist.data_tools.images import flag_value
    from crossing_assist.data_tools.manifest import read_manifest
    ds = read_manifest(path.parent)
    counts = ", ".join(f"{s} {len(ds.split(s))}" for s in ("train", "val", "test") if len(ds.split(s)))
    fovs = sum(flag_value(r.flags, "fov") is not None for r in ds.rows)
    print(f"wrote {path} ({len(ds)} rows: {counts}; images {args.images}"
          + (f"; {fovs} with their camera's FOV from EXIF" if fovs else "") + ")")
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


def _cmd_negatives(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.negatives import NegativesConfig, make_negatives

    path = make_negatives(NegativesConfig(Path(args.dataset), Path(args.out), args.seed, not args.quiet))
    print(f"wrote {path}")
    return 0


def _cmd_photo_clip(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.manifest import ManifestError
    from crossing_assist.data_tools.photo_clip import PhotoClipConfig, make_photo_clip

    from crossing_assist.geometry import parse_ratio

    try:
        aspect = parse_ratio(args.aspect)
    except ValueError:
        raise ManifestError(f"--aspect {args.aspect!r} invalid; expected W:H, e.g. 3:4") from None
    clip, side, fov = make_photo_clip(PhotoClipConfig(Path(args.dataset), Path(args.out), args.split, args.count,
                                                      args.seconds_each, args.fps, aspect, args.height, args.photo_fov))
    print(f"wrote {clip} and {side}; the frames see {fov:.1f} deg across: crossing-demo {clip} --fov {fov:.1f}")
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools import synth
    if args.video:
        h, w = args.size or (240, 320)
        command = "crossing-data " + " ".join(sys.argv[1:]) if args.record_command is None else args.record_command
        cfg = synth.ClipConfig(Path(args.out), args.seed, args.seconds, args.fps, w, h, args.fov,
                               args.supersample, command, not args.quiet)
        video, side = synth.synth_clip(cfg)
        print(f"wrote {video} ({video.stat().st_size / 1e6:.2f} MB, {int(round(args.seconds * args.fps))} frames) "
              f", {side} (ground truth) and {synth.imu_path(video)} (the camera's motion: crossing-demo {video} "
              f"--imu {synth.imu_path(video)})")
        return 0
    h, w = args.size or (168, 224)
    cfg = synth.SynthConfig(Path(args.out), args.frames, args.seed, w, h, args.fov, args.unknown_fraction,
                            args.val_fraction, args.supersample, not args.quiet, args.lookalike_fraction)
    path = synth.synth_dataset(cfg)
    print(f"wrote {path} ({args.frames} synthetic frames, seed {args.seed})")
    return 0


def _cmd_frames(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.frames import FramesConfig, extract_frames
    cfg = FramesConfig(tuple(Path(v) for v in args.videos), Path(args.out), args.fps, progress=not args.quiet,
                       fov_deg=args.fov)
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


def _cmd_votes(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.labels import VotesConfig, build_voted_dataset
    from crossing_assist.data_tools.splits import SplitConfig
    cfg = VotesConfig(Path(args.frames_dir), tuple(Path(v) for v in args.votes), args.tie, args.min_votes,
                      SplitConfig(args.val, args.test, args.seed))
    print(build_voted_dataset(cfg).format())
    return 0


def _cmd_split(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.manifest import read_manifest, write_manifest
    from crossing_assist.data_tools.splits import SplitConfig, assign_splits
    ds = read_manifest(args.dataset)
    rows = assign_splits(ds.rows, SplitConfig(args.val, args.test, args.seed))
    path = write_manifest(args.dataset, rows)
    counts = {s: sum(r.split == s for r in rows) for s in ("train", "val", "test")}
    n_src = {s: len({r.source for r in rows if r.split == s}) for s in counts}
    print(f"wrote {path}: " + ", ".join(f"{s} {counts[s]} frames / {n_src[s]} sources" for s in counts if counts[s]))
    return 0


def _cmd_augment(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.augment_dataset import AugmentConfig, augment_dataset
    cfg = AugmentConfig(Path(args.dataset), Path(args.out), not args.no_mirror, tuple(args.yaw), args.fov,
                        args.out_of_frame, tuple(args.splits), args.drop_unknown, not args.quiet)
    path = augment_dataset(cfg)
    from crossing_assist.data_tools.manifest import read_manifest
    print(f"wrote {path} ({len(read_manifest(path.parent))} rows)")
    return 0


def _cmd_label_config(args: argparse.Namespace) -> int:
    from crossing_assist.data_tools.votes import LABEL_STUDIO_CONFIG
    sys.stdout.write(LABEL_STUDIO_CONFIG)
    return 0


# ---------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="crossing-data", description="Data tools: frames, votes, datasets, augmentation, synthetic corners.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("import-ptl", help="turn a folder in the PTL layout into a dataset")
    p.add_argument("ptl_dir", help="folder with labels.csv and the images")
    p.add_argument("--out", required=True, help="dataset folder to write")
    p.add_argument("--images", choices=("copy", "reference"), default="copy",
                   help="copy (hard link where possible) the images into OUT/images, or reference "
                        "them in place by relative path (checked on every read)")
    p.add_argument("--square", choices=("squashed", "square"), default="squashed",
                   help="what a square image is: a 4:3 photo squashed, as PTL's 224x224 copies (default: "
                        "read back at 4:3), or a photo taken square; other images keep their own aspect")
    p.add_argument("--no-exif-fov", action="store_true",
                   help="ignore the photos' EXIF focal lengths (by default a photo that gives its camera's "
                        "35 mm-equivalent focal length gets flag fov=DEG, its horizontal FOV, which crossing-eval "
                        "plays it at; others get the bundle's default for their orientation)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_import_ptl)

    p = sub.add_parser("negatives", help="unknown views cut above the far kerb of labelled photos (needs far_y)")
    p.add_argument("dataset", help="dataset folder (manifest.csv) whose rows carry far_y flags, e.g. imported PTL")
    p.add_argument("--out", required=True, help="dataset folder to write")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_negatives)

    p = sub.add_parser("photo-clip", help="a clip panning a phone-shaped window across labelled photos, with ground truth")
    p.add_argument("dataset", help="dataset folder (manifest.csv) with far_x, e.g. imported PTL")
    p.add_argument("--out", required=True, help="clip path (.mp4); the ground truth goes beside it (.json)")
    p.add_argument("--split", default="val")
    p.add_argument("--count", type=int, default=6, help="photos in the clip")
    p.add_argument("--seconds-each", type=float, default=3.0)
    p.add_argument("--fps", type=float, default=10.0)
    p.add_argument("--aspect", default="3:4", help="the phone frame's W:H, e.g. 3:4 (portrait) or 4:3 (landscape)")
    p.add_argument("--height", type=int, default=320, help="frame height in pixels")
    p.add_argument("--photo-fov", type=float, default=None, metavar="DEG",
                   help="horizontal FOV of the camera that took the photos (default: each row's fov=DEG flag, "
                        "e.g. from its EXIF at import-ptl, else a phone's for the photo's orientation and aspect: "
                        "67 deg for 4:3 landscape, 53 for 3:4 portrait)")
    p.set_defaults(func=_cmd_photo_clip)

    p = sub.add_parser("stats", help="counts per bin / action space / split, majority baseline, histogram")
    p.add_argument("dataset", help="dataset folder (with manifest.csv)")
    p.add_argument("--plot", help="histogram PNG path (default DATASET/stats_histogram.png)")
    p.add_argument("--no-plot", action="store_true", help="skip the histogram")
    p.set_defaults(func=_cmd_stats)

    p = sub.add_parser("frames", help="frames from videos at a fixed rate, named by video and timestamp")
    p.add_argument("videos", nargs="+", metavar="VIDEO")
    p.add_argument("--out", required=True, help="folder for the frames and frames.csv")
    p.add_argument("--fps", type=float, default=2.0, help="frames per second to keep (default 2)")
    p.add_argument("--fov", type=float, metavar="DEG",
                   help="the videos' camera: horizontal field of view of the frames as saved, degrees; kept in "
                        "frames.csv and the manifest (flag fov=DEG), so crossing-eval plays them at it "
                        "(default: unknown, the bundle's for the frame's orientation)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_frames)

    p = sub.add_parser("votes", help="majority-vote people's labels into FRAMES_DIR/manifest.csv")
    p.add_argument("frames_dir", help="folder written by 'crossing-data frames' (with frames.csv)")
    p.add_argument("votes", nargs="+", help="votes: CSV (frame,annotator,label) and/or Label Studio JSON exports")
    p.add_argument("--tie", choices=("unknown", "drop"), default="unknown",
                   help="a tied vote becomes unknown (flag 'tie'), or the frame is dropped")
    p.add_argument("--min-votes", type=int, default=1, help="leave out frames with fewer votes")
    p.add_argument("--val", type=float, default=0.0, help="share of frames for val, by source")
    p.add_argument("--test", type=float, default=0.0, help="share of frames for test, by source")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_votes)

    p = sub.add_parser("split", help="reassign splits by source (no frame of a video/place on two sides)")
    p.add_argument("dataset")
    p.add_argument("--val", type=float, default=0.2)
    p.add_argument("--test", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_split)

    p = sub.add_parser("augment", help="write a dataset with mirrored / yawed copies (exact labels)")
    p.add_argument("dataset")
    p.add_argument("--out", required=True)
    p.add_argument("--no-mirror", action="store_true", help="no mirrored copies")
    p.add_argument("--yaw", type=float, nargs="*", default=[], help="yaw angles in degrees (+ = user turned right)")
    p.add_argument("--fov", type=float, default=DEFAULT_FOV_DEG, help="assumed horizontal field of view, degrees")
    p.add_argument("--out-of-frame", choices=("unknown", "edge"), default="unknown",
                   help="label of a goal the yaw pushes out of the frame")
    p.add_argument("--drop-unknown", action="store_true", help="skip yawed copies whose goal left the frame")
    p.add_argument("--splits", nargs="+", default=["train"], help="splits to augment (others are copied as is)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_augment)

    p = sub.add_parser("label-config", help="print the Label Studio labelling config (12 strips + unknown)")
    p.set_defaults(func=_cmd_label_config)

    d_frames, d_clip = synth_defaults()
    p = sub.add_parser("synth", help="render synthetic street corners (a dataset, or with --video a clip)")
    p.add_argument("--out", required=True, help="dataset folder; with --video the .mp4 file to write")
    p.add_argument("--frames", type=int, default=d_frames.frames, help="frames to render (dataset)")
    p.add_argument("--seed", type=int, default=d_frames.seed)
    p.add_argument("--size", type=_frame_size, help="WxH (default 224x168 frames, 320x240 video)")
    p.add_argument("--fov", type=float, default=d_frames.fov_deg, help="horizontal field of view, degrees")
    p.add_argument("--unknown-fraction", type=float, default=d_frames.unknown_fraction,
                   help="share of frames with no crossing in view (labelled unknown)")
    p.add_argument("--lookalike-fraction", type=float, default=d_frames.lookalike_fraction,
                   help="share of the no-crossing frames showing a zebra look-alike (stairs up or down, a "
                        "crossing's picture on a poster, screen or billboard); the other frames are unchanged")
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
    """Entry point of ``crossing-data``; returns the exit status (2 user error, 130 Ctrl-C)."""
    from crossing_assist.errors import run_cli

    def body(args: list[str]) -> int:
        ns = build_parser().parse_args(args)
        func: Callable[[argparse.Namespace], int] = ns.func
        return func(ns)

    return run_cli(body, argv)


if __name__ == "__main__":
    sys.exit(main())

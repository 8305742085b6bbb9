"""``crossing-demo``: run a bundle on a video (or camera) and hear/see what the beacon does.

    crossing-demo                              # embedded bundle + embedded sample clip
    crossing-demo street.mp4 --bundle runs/x/bundle --out demo_out
    crossing-demo --camera 0 --live            # live: camera -> headphones (Ctrl-C to stop)
    crossing-demo street.mp4 --live            # play a video's beacon in real time
    crossing-demo walk.mp4 --imu walk.imu.csv  # with the phone's gyroscope and tilt logged beside it
    crossing-demo walk.mp4 --imu log.csv --imu-offset auto   # ... a log started apart from the video
    crossing-demo walk.mp4 --labels walk_labelled  # judged on its labelled frames (crossing-data frames + votes)

Offline it writes ``beacon.wav`` (on the video's timeline), ``annotated.mp4``, ``trace.jsonl``
(one decision a line) and, with ffmpeg, ``annotated_with_audio.mp4``; then prints a summary.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from crossing_assist.errors import UserError
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S

ASSETS = Path(__file__).resolve().parents[1] / "assets"
DEFAULT_BUNDLE = ASSETS / "default_bundle"
DEFAULT_CLIP = ASSETS / "sample_clip.mp4"
DEFAULT_OUT = Path("crossing_demo_out")
MAX_WATCHDOG_S = 2.0   # the stale-frame stop must fire: a longer silence is not a safety switch
MAX_CAMERA = 63
MAX_THREADS = 64


class DemoError(UserError, RuntimeError):
    """A user-facing problem; printed as one ``error:`` line."""


@dataclass(frozen=True)
class DemoConfig:
    """Resolved command line."""

    video: Path | None
    camera: int | None
    bundle: Path
    out_dir: Path
    live: bool
    annotate: bool
    progress: bool
    audio_device: str | None
    max_seconds: float | None
    watchdog_s: float
    fov_deg: float | None = None
    visual_yaw: bool = True
    threads: int = 1
    imu: Path | None = None
    imu_offset: float | None = 0.0     # None: found from the video (--imu-offset auto)
    follow_gyro: bool = False
    labels: Path | None = None
    plot: bool = True


def offset_arg(text: str) -> float | None:
    """``--imu-offset``: seconds, or ``auto`` (None)."""
    if text.strip().lower() == "auto":
        return None
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is neither seconds nor auto")
    return v


def parse_args(argv: list[str] | None) -> DemoConfig:
    """Parse the command line into a :class:`DemoConfig` (defaults: embedded assets)."""
    ap = argparse.ArgumentParser(prog="crossing-demo", description=__doc__.split("\n\n")[0])
    ap.add_argument("video", nargs="?", type=Path, help="video file (default: the embedded sample clip)")
    ap.add_argument("--camera", type=int, metavar="N", help="use camera N instead of a video")
    ap.add_argument("--bundle", type=Path, default=None, help="bundle folder (default: the embedded bundle)")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default: ./{DEFAULT_OUT})")
    ap.add_argument("--live", action="store_true", help="play the beacon on the audio device in real time")
    ap.add_argument("--no-video", action="store_true", help="skip annotated.mp4 (faster)")
    ap.add_argument("--no-plot", action="store_true", help="skip timeline.png (made where matplotlib is installed)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    ap.add_argument("--audio-device", default=None, help="sounddevice output device (index or name)")
    ap.add_argument("--max-seconds", type=float, default=None, help="stop a live run after this long")
    ap.add_argument("--fov", type=float, default=None, metavar="DEG",
                    help="the camera's horizontal field of view in its present orientation, 20..170 "
                         "(default: the bundle's, per orientation: typical phone 67 landscape, 53 portrait)")
    ap.add_argument("--watchdog", type=float, default=DEFAULT_WATCHDOG_S, help="seconds without a fresh decision "
                    f"before the beacon stops (default {DEFAULT_WATCHDOG_S}; 0 < w <= {MAX_WATCHDOG_S})")
    ap.add_argument("--no-visual-yaw", action="store_true",
                    help="do not follow the camera's turns read from the frames (without a gyroscope, the "
                         "direction then stays where it was while the phone turns)")
    ap.add_argument("--imu", type=Path, default=None, metavar="CSV",
                    help="a motion-sensor log recorded with the video: columns t (s), yaw_dps (+ right) and "
                         "optionally roll_deg; its gyroscope's turn is followed once the picture confirms it, "
                         "its roll levels the frames (docs/runtime.md, 'A recorded motion-sensor log')")
    ap.add_argument("--imu-offset", type=offset_arg, default=0.0, metavar="S|auto",
                    help="the log's time t at the video's first frame (default 0); auto: found by lining the "
                         "log's turns up with the turns read from the video's frames")
    ap.add_argument("--follow-gyro", action="store_true",
                    help="follow the log's gyroscope from the start, before the picture has confirmed its sign")
    ap.add_argument("--labels", type=Path, default=None, metavar="DIR",
                    help="a dataset of this video's frames, labelled (crossing-data frames VIDEO, then votes): the "
                         "summary judges what the user heard on them (beacon on, confidently wrong, silence)")
    ap.add_argument("--threads", type=int, default=1, metavar="N",
                    help=f"onnxruntime threads for the model, 0..{MAX_THREADS} (default 1, as a phone's app runs it; "
                         "0 = onnxruntime's default, all cores)")
    ap.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    a = ap.parse_args(argv)
    if a.video is not None and a.camera is not None:
        raise DemoError("give a VIDEO or --camera N, not both")
    if a.camera is not None and not a.live:
        raise DemoError("--camera needs --live (the camera has no end for an offline run)")
    if a.fov is not None:
        from crossing_assist.geometry import GeometryError, check_fov

        try:
            check_fov(a.fov)
        except GeometryError as exc:
            raise DemoError(f"--fov: {exc}") from None
    if a.imu is not None and a.camera is not None:
        raise DemoError("--imu replays a log recorded with a video; give the VIDEO, not --camera")
    if a.imu is None and (a.follow_gyro or a.imu_offset != 0.0):   # auto (None) too
        raise DemoError("--follow-gyro and --imu-offset need --imu CSV (a motion-sensor log recorded with the video)")
    if a.labels is not None and a.live:
        raise DemoError("--labels judges the offline run; leave out --live")
    if a.camera is not None and not 0 <= a.camera <= MAX_CAMERA:
        raise DemoError(f"--camera {a.camera} invalid; valid: a camera index 0..{MAX_CAMERA} (0 = the first camera)")
    if not 0 < a.watchdog <= MAX_WATCHDOG_S:
        raise DemoError(f"--watchdog {a.watchdog} invalid; valid: 0 < seconds <= {MAX_WATCHDOG_S} "
                        "(the beacon must stop soon after the frames stop)")
    if not 0 <= a.threads <= MAX_THREADS:
        raise DemoError(f"--threads {a.threads} invalid; valid: 0..{MAX_THREADS} (0 = onnxruntime's default)")
    if a.max_seconds is not None and not 0 < a.max_seconds < 1e7:
        raise DemoError(f"--max-seconds {a.max_seconds} invalid; valid: > 0 seconds")
    video, bundle = a.video, a.bundle
    missing = []
    if video is None and a.camera is None:
        video = DEFAULT_CLIP
        if not DEFAULT_CLIP.is_file():
            missing.append(f"the embedded sample clip {DEFAULT_CLIP} (pass a VIDEO)")
    if bundle is None:
        bundle = DEFAULT_BUNDLE
        if not (DEFAULT_BUNDLE / "bundle.json").is_file():
            missing.append(f"the embedded default bundle {DEFAULT_BUNDLE} (pass --bundle DIR from crossing-export)")
    if missing:
        raise DemoError(" and ".join(missing) + (" is" if len(missing) == 1 else " are") + " missing")
    if video is not None and not video.is_file():
        raise DemoError(f"video {video} does not exist")
    dev = a.audio_device
    return DemoConfig(video=video, camera=a.camera, bundle=bundle, out_dir=a.out, live=a.live,
                      annotate=not a.no_video, progress=not a.quiet,
                      audio_device=int(dev) if dev is not None and dev.isdigit() else dev,
                      max_seconds=a.max_seconds, watchdog_s=a.watchdog, fov_deg=a.fov,
                      visual_yaw=not a.no_visual_yaw, threads=a.threads, imu=a.imu, imu_offset=a.imu_offset,
                      follow_gyro=a.follow_gyro, labels=a.labels, plot=not a.no_plot)


def run_live_demo(cfg: DemoConfig) -> None:
    """Live: frames -> decisions -> headphones; trace.jsonl in the output folder."""
    from crossing_assist.runtime.audio import LiveAudio
    from crossing_assist.runtime.beacon import CuePlayer
    from crossing_assist.runtime.gyro import YawIntegrator
    from crossing_assist.runtime.imu import ImuLog, line_up
    from crossing_assist.runtime.live import LiveConfig, run_live
    from crossing_assist.runtime.pipeline import open_pipeline, trace_record
    from crossing_assist.runtime.sources import CameraSource, VideoSource

    log = ImuLog.load(cfg.imu, cfg.imu_offset or 0.0) if cfg.imu is not None else None   # refused before the model
    pipeline = open_pipeline(cfg.bundle, fov_deg=cfg.fov_deg, watchdog_s=cfg.watchdog_s, visual_yaw=cfg.visual_yaw,
                             threads=cfg.threads)
    imu, alignment = (line_up(log, cfg.imu_offset, cfg.video, pipeline.engine.frame_fov) if log is not None
                      else (None, None))
    if alignment is not None:
        print(f"gyroscope ({imu.path.name}): {alignment.describe()}", file=sys.stderr)
    player = CuePlayer(pipeline.beacon_cfg)
    source = CameraSource(cfg.camera) if cfg.camera is not None else VideoSource(cfg.video)
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    trace_path = cfg.out_dir / "trace.jsonl"
    with LiveAudio(player, device=cfg.audio_device), open(trace_path, "w", encoding="utf-8") as trace:
        print("live: playing the beacon; Ctrl-C to stop", file=sys.stderr)
        decided = told = 0

        def on_step(i: int, step) -> None:
            nonlocal decided, told
            decided += 1
            told += step.yaw_source == "gyro"
            trace.write(json.dumps(trace_record(i, step)) + "\n")

        gyro = YawIntegrator() if imu is not None else None
        start = time.monotonic()
        replay = imu.replay(gyro, start) if imu is not None else contextlib.nullcontext()
        try:
            with replay:
                n = run_live(source, pipeline, player,
                             LiveConfig(watchdog_s=cfg.watchdog_s, pace=cfg.camera is None,
                                        frozen_check=cfg.camera is not None, max_seconds=cfg.max_seconds),
                             on_step=on_step, video_time=cfg.camera is None, gyro=gyro,
                             follow_gyro=cfg.follow_gyro, roll_at=imu.roll_at if imu is not None else None,
                             start=start)
        except KeyboardInterrupt:
            n = -1
    dropped = n - decided if cfg.camera is None and n > decided else 0
    print(f"live run {'stopped' if n < 0 else 'ended'} after {decided} frames decided"
          + (f" of the video's first {n}; the other {dropped} came while the model ran and were dropped, "
             f"as a camera's are" if dropped else "") + f"; trace: {trace_path}")
    if imu is not None:
        print(f"gyroscope ({imu.path.name}): its turn told on {told} of {decided} decisions"
              + ("" if told or cfg.follow_gyro else " (the picture's turn never confirmed it; --follow-gyro "
                 "follows it unchecked)"))


def run(cfg: DemoConfig) -> None:
    """Run the demo described by ``cfg``."""
    if cfg.live:
        run_live_demo(cfg)
        return
    from crossing_assist.runtime.offline import OfflineConfig, run_offline

    summary = run_offline(OfflineConfig(video=cfg.video, bundle=cfg.bundle, out_dir=cfg.out_dir,
                                        annotate=cfg.annotate, progress=cfg.progress, fov_deg=cfg.fov_deg,
                                        watchdog_s=cfg.watchdog_s, visual_yaw=cfg.visual_yaw,
                                        threads=cfg.threads, imu=cfg.imu, imu_offset=cfg.imu_offset,
                                        follow_gyro=cfg.follow_gyro, labels=cfg.labels, plot=cfg.plot))
    for warning in summary.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"crossing-demo: {cfg.video} with bundle {cfg.bundle}")
    for line in summary.lines():
        print("  " + line)
    print(f"outputs are in {cfg.out_dir.resolve()}")


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 user error, 130 Ctrl-C)."""
    from crossing_assist.errors import run_cli

    return run_cli(lambda args: run(parse_args(args)) or 0, argv)


if __name__ == "__main__":
    sys.exit(main())

"""Runtime throughput: decisions per second end to end vs the video's real time, one thread.

    .venv/bin/python benchmarks/demo_throughput.py [--bundle DIR] [--video CLIP] [--repeat 3] [--threads 1 2]

Each frame goes through everything the live runtime does: decode (OpenCV), preprocess (BGR ->
RGB, downsize to 640 px wide at most), inference (onnxruntime, 1 thread, T MC samples in the
graph), the turn read from the frames (``runtime.visual_yaw``: the Python pipeline's default
without a gyroscope; timed on its own), the Bayes filter and the gate, and audio synthesis (cue
rendering + the player filling the frame's share of a 48 kHz stereo stream). Annotated video and file writing are not counted.

Defaults: the embedded bundle, and a 30 fps clip made by re-timing the embedded sample clip's
frames at 30 fps (same pictures; the real-time budget per frame is then 33.3 ms). The report
names the bundle and the clip used. Target: >= 3x real time. ``--threads 1 2`` also runs the model
on two onnxruntime threads (``crossing-demo --threads 2``), the passes alternating, and gives the
ratio; the rest of the loop stays on one thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one thread: set before numpy/onnxruntime load

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from crossing_assist.bundle import BundleError  # noqa: E402
from crossing_assist.runtime.beacon import BeaconConfig, CuePlayer, cue_for  # noqa: E402
from crossing_assist.runtime.demo import DEFAULT_BUNDLE, DEFAULT_CLIP, MAX_THREADS  # noqa: E402
from crossing_assist.runtime.engine import Engine  # noqa: E402
from crossing_assist.runtime.pipeline import Pipeline, cached_loop  # noqa: E402
from crossing_assist.runtime.sources import SourceError, VideoSource  # noqa: E402


def retime_clip(src: Path, dst: Path, fps: float = 30.0) -> Path:
    """Write ``src``'s frames to ``dst`` (mp4v) declared at ``fps``."""
    cap = cv2.VideoCapture(str(src))
    writer = None
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        if writer is None:
            writer = cv2.VideoWriter(str(dst), cv2.VideoWriter_fourcc(*"mp4v"), fps, (frame.shape[1], frame.shape[0]))
        writer.write(frame)
    cap.release()
    if writer is None:
        raise SourceError(f"video {src} has no readable frames")
    writer.release()
    return dst


def run_once(engine: Engine, clip: Path, beacon: BeaconConfig) -> dict:
    """One pass over the clip; returns counts and per-stage seconds."""
    pipeline = Pipeline(engine, beacon_cfg=beacon)
    player = CuePlayer(beacon)
    source = VideoSource(clip, max_width=640)
    stages = {"decode": 0.0, "infer": 0.0, "visual_yaw": 0.0, "decide_audio": 0.0}
    n, rendered = 0, 0
    it = iter(source)
    t_start = time.perf_counter()
    while True:
        t0 = time.perf_counter()
        try:
            t, frame = next(it)
        except StopIteration:
            break
        t1 = time.perf_counter()
        pred = engine.predict(frame)
        t2 = time.perf_counter()
        yaw = pipeline.visual_yaw.update(frame, t, pred.fov_deg)
        t2y = time.perf_counter()
        decision = pipeline.decider.step(t, pred.observation(), yaw)
        player.set_loop(cached_loop(cue_for(decision), beacon))
        upto = round((t + 1.0 / source.fps) * beacon.sample_rate)
        player.render(upto - rendered)
        rendered = upto
        t3 = time.perf_counter()
        stages["decode"] += t1 - t0
        stages["infer"] += t2 - t1
        stages["visual_yaw"] += t2y - t2
        stages["decide_audio"] += t3 - t2y
        n += 1
    wall = time.perf_counter() - t_start
    return {"frames": n, "video_s": n / source.fps, "wall_s": wall, "fps": source.fps, **stages}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", type=Path, default=None, help="bundle folder (default: the embedded bundle)")
    ap.add_argument("--video", type=Path, default=None, help="clip (default: the sample clip re-timed to 30 fps)")
    ap.add_argument("--repeat", type=int, default=3, help="passes; the best is reported (default 3)")
    ap.add_argument("--threads", type=int, nargs="+", default=[1], metavar="N",
                    help="onnxruntime threads for the model, each measured (default 1); the first is the baseline")
    ap.add_argument("--json", action="store_true", help="also print one JSON line (the first thread count)")
    a = ap.parse_args(argv)
    if any(not 1 <= n <= MAX_THREADS for n in a.threads):
        print(f"error: --threads {a.threads} invalid; valid: 1..{MAX_THREADS} each", file=sys.stderr)
        return 2
    cv2.setNumThreads(1)
    bundle = a.bundle or DEFAULT_BUNDLE
    if a.bundle is None and not (DEFAULT_BUNDLE / "bundle.json").is_file():
        print(f"error: the embedded bundle {DEFAULT_BUNDLE} is missing; pass --bundle DIR", file=sys.stderr)
        return 2
    try:
        engines = {n: Engine(bundle, threads=n) for n in dict.fromkeys(a.threads)}
        with tempfile.TemporaryDirectory() as tmp:
            if a.video is None:
                if not DEFAULT_CLIP.is_file():
                    print(f"error: the sample clip {DEFAULT_CLIP} is missing; pass --video CLIP", file=sys.stderr)
                    return 2
                clip, clip_name = retime_clip(DEFAULT_CLIP, Path(tmp) / "clip30.mp4"), f"{DEFAULT_CLIP.name} re-timed to 30 fps"
            else:
                clip, clip_name = a.video, str(a.video)
            for engine in engines.values():
                engine.predict(np.zeros((240, 320, 3), np.uint8))  # warm-up
            runs = {n: [] for n in engines}
            for _ in range(max(1, a.repeat)):   # alternating, so a busy spell on the machine hits both
                for n, engine in engines.items():
                    runs[n].append(run_once(engine, clip, BeaconConfig()))
    except (BundleError, SourceError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    bests = {n: min(r, key=lambda x: x["wall_s"]) for n, r in runs.items()}
    first = next(iter(bests))
    best = bests[first]
    dps = best["frames"] / best["wall_s"]
    b = engines[first].bundle
    print(f"bundle: {bundle} ({b.training.get('backbone', '?')}, {b.precision}, input {b.input.size[1]}x{b.input.size[0]}, "
          f"T={b.mc.samples}){' [embedded default]' if a.bundle is None else ''}")
    print(f"clip: {clip_name}, {best['frames']} frames at {best['fps']:.0f} fps ({best['video_s']:.1f} s)")
    print(f"model on {first} thread{'s' if first > 1 else ''}, best of {len(runs[first])}: {dps:.1f} decisions/s = "
          f"{dps / best['fps']:.2f}x real time (target >= 3x)")
    per = {k: 1000 * best[k] / best["frames"] for k in ("decode", "infer", "visual_yaw", "decide_audio")}
    print("per frame: " + ", ".join(f"{k} {v:.2f} ms" for k, v in per.items()))
    print(f"the turn read from the frames: {100 * best['visual_yaw'] / best['wall_s']:.1f} % of the wall time "
          f"(x {best['wall_s'] / (best['wall_s'] - best['visual_yaw']):.3f} the time without it)")
    for n, other in list(bests.items())[1:]:
        o = other["frames"] / other["wall_s"]
        print(f"model on {n} threads: {o:.1f} decisions/s = {o / other['fps']:.2f}x real time, x {o / dps:.2f} the "
              f"{first}-thread rate (inference {1000 * other['infer'] / other['frames']:.2f} ms a frame, x "
              f"{best['infer'] / best['frames'] / (other['infer'] / other['frames']):.2f} faster)")
    if a.json:
        print(json.dumps({"bundle": str(bundle), "clip": clip_name, "decisions_per_s": dps,
                          "x_real_time": dps / best["fps"], "per_frame_ms": per}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Offline demo: a video in, ``beacon.wav`` + ``annotated.mp4`` + ``trace.jsonl`` out.

The WAV follows the video's timeline exactly: the cue of the decision made on frame ``i``
(at ``t_i = i / fps``) plays from sample ``round(t_i sr)`` to ``round(t_{i+1} sr)``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import cv2
import numpy as np

from crossing_assist.runtime.annotate import annotate
from crossing_assist.runtime.audio import write_wav
from crossing_assist.runtime.beacon import BeaconConfig, CuePlayer
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.pipeline import Pipeline, Step
from crossing_assist.runtime.truth import compare, load_truth, truth_line


@dataclass(frozen=True)
class OfflineConfig:
    """One offline run. ``annotate=False`` skips the video (faster); ``max_width`` downsizes
    frames before everything (None = as decoded)."""

    video: Path
    bundle: Path
    out_dir: Path
    annotate: bool = True
    mux: bool = True
    progress: bool = True
    max_width: int | None = 640
    beacon: BeaconConfig = field(default_factory=BeaconConfig)


@dataclass(frozen=True)
class Summary:
    """What a run did: counts per gate state and stop reason, timings, output paths."""

    frames: int
    video_s: float
    wall_s: float
    gates: dict
    reasons: dict
    failed: int
    outputs: dict
    truth: dict | None = None

    def lines(self) -> list[str]:
        """Human-readable summary lines."""
        n = max(self.frames, 1)
        pct = lambda c: ", ".join(f"{k} {100 * v / n:.0f}%" for k, v in sorted(c.items()))  # noqa: E731
        speed = self.video_s / self.wall_s if self.wall_s > 0 else math.inf
        out = [f"{self.frames} frames, {self.video_s:.1f} s of video in {self.wall_s:.1f} s "
               f"({speed:.1f}x real time)",
               f"gate: {pct(self.gates)}", f"stop reasons: {pct(self.reasons)}"]
        if self.failed:
            out.append(f"failed inferences: {self.failed}")
        if self.truth:
            out.append(truth_line(self.truth))
        out += [f"{k}: {v}" for k, v in self.outputs.items()]
        return out


def trace_record(i: int, step: Step) -> dict:
    """One trace.jsonl line: frame index, model outputs and the decision."""
    p, d = step.prediction, step.decision
    rec = {"frame": i, "ok": p.ok, "error": p.error or None, "action": p.action if p.ok else None,
           "probs": None if p.probs is None else [round(float(v), 5) for v in p.probs],
           "entropy": p.entropy if p.ok else None, "mutual_info": p.mutual_info if p.ok else None,
           "uncertainty": p.uncertainty if p.ok else None, "conformal_set": list(p.conformal_set),
           "cue": step.cue.kind}
    rec.update(d.to_json())
    rec["belief"] = [round(v, 5) for v in rec["belief"]]
    return rec


def run_frames(frames: Iterable[tuple[float, np.ndarray]], pipeline: Pipeline, *, sink) -> int:
    """Drive ``pipeline`` over ``(t, frame)`` pairs, calling ``sink(i, t, frame, step)``; returns
    the number of frames."""
    n = 0
    for i, (t, frame) in enumerate(frames):
        sink(i, t, frame, pipeline.step(frame, t))
        n = i + 1
    return n


def _mux(video: Path, wav: Path, out: Path) -> Path | None:
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        return None
    tmp = out.with_name(f".{out.stem}.tmp{out.suffix}")
    cmd = [ffmpeg, "-loglevel", "error", "-y", "-i", str(video), "-i", str(wav), "-c:v", "copy",
           "-c:a", "aac", "-shortest", str(tmp)]
    if subprocess.run(cmd, capture_output=True).returncode != 0:
        tmp.unlink(missing_ok=True)
        return None
    os.replace(tmp, out)
    return out


def run_offline(cfg: OfflineConfig, engine: Engine | None = None) -> Summary:
    """Run the whole demo on ``cfg.video``; writes the outputs into ``cfg.out_dir``."""
    from tqdm import tqdm

    from crossing_assist.runtime.sources import VideoSource

    engine = engine or Engine(cfg.bundle)
    source = VideoSource(cfg.video, max_width=cfg.max_width)
    pipeline = Pipeline(engine, beacon_cfg=cfg.beacon)
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sr = cfg.beacon.sample_rate
    player = CuePlayer(cfg.beacon)
    chunks: list[np.ndarray] = []
    gates: Counter = Counter()
    reasons: Counter = Counter()
    state = {"writer": None, "failed": 0, "pos": 0}
    headings: list[float | None] = []
    tmp_video = out / ".annotated.tmp.mp4"
    trace_tmp = tempfile.NamedTemporaryFile("w", dir=out, prefix=".trace.", suffix=".jsonl", delete=False)

    def flush_audio(t_end: float) -> None:  # play the current cue up to t_end (seconds)
        n = round(t_end * sr) - state["pos"]
        if n > 0:
            chunks.append(player.render(n))
            state["pos"] += n

    def sink(i: int, t: float, frame: np.ndarray, step: Step) -> None:
        flush_audio(t)
        player.set_loop(step.loop)
        headings.append(step.decision.heading_deg)
        gates[step.decision.gate] += 1
        reasons[step.decision.reason] += 1
        state["failed"] += not step.prediction.ok
        trace_tmp.write(json.dumps(trace_record(i, step)) + "\n")
        if cfg.annotate:
            img = annotate(frame, step.prediction, step.decision, engine.space, engine.bundle.fov_deg)
            if state["writer"] is None:
                h, w = img.shape[:2]
                state["writer"] = cv2.VideoWriter(str(tmp_video), cv2.VideoWriter_fourcc(*"mp4v"),
                                                  source.fps, (w, h))
            state["writer"].write(img)
        bar.update(1)

    t0 = time.perf_counter()
    total = source.frame_count or None
    with tqdm(total=total, unit="frame", disable=not cfg.progress, leave=False, desc="crossing-demo") as bar:
        try:
            n = run_frames(source, pipeline, sink=sink)
        finally:
            trace_tmp.close()
            if state["writer"] is not None:
                state["writer"].release()
    if n == 0:
        Path(trace_tmp.name).unlink(missing_ok=True)
        from crossing_assist.runtime.sources import SourceError
        raise SourceError(f"video {cfg.video} has no readable frames")
    video_s = n / source.fps
    flush_audio(video_s)
    wall = time.perf_counter() - t0
    outputs = {"beacon": write_wav(out / "beacon.wav", np.concatenate(chunks), sr)}
    os.chmod(trace_tmp.name, 0o644)
    os.replace(trace_tmp.name, out / "trace.jsonl")
    outputs["trace"] = out / "trace.jsonl"
    if cfg.annotate:
        os.replace(tmp_video, out / "annotated.mp4")
        outputs["annotated"] = out / "annotated.mp4"
        if cfg.mux:
            muxed = _mux(out / "annotated.mp4", outputs["beacon"], out / "annotated_with_audio.mp4")
            outputs["with_audio"] = muxed if muxed else "skipped (ffmpeg not found; play annotated.mp4 with beacon.wav)"
    truth = load_truth(cfg.video)
    return Summary(frames=n, video_s=video_s, wall_s=wall, gates=dict(gates), reasons=dict(reasons),
                   failed=state["failed"], outputs={k: str(v) for k, v in outputs.items()},
                   truth=compare(truth, headings) if truth else None)

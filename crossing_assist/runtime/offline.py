"""Offline demo: a video in, ``beacon.wav`` + ``annotated.mp4`` + ``trace.jsonl`` (+ ``timeline.png``,
with matplotlib) out.

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

from crossing_assist.actions import UNKNOWN, bin_center_x, x_to_heading
from crossing_assist.fileio import sweep_orphans, tmp_tag
from crossing_assist.geometry import GeometryError, orientation
from crossing_assist.runtime.annotate import annotate
from crossing_assist.runtime.audio import write_wav
from crossing_assist.runtime.beacon import BeaconConfig, CuePlayer
from crossing_assist.runtime.decide import REASON_UNCERTAIN
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.gyro import GyroFollow
from crossing_assist.runtime.imu import Alignment, ImuLog, line_up
from crossing_assist.runtime.pipeline import Pipeline, Seen, Step, open_pipeline, trace_record
from crossing_assist.runtime.timeline import plot_timeline
from crossing_assist.runtime.truth import (LabelledFrame, compare, judge_labels, labels_line, load_labels, load_truth,
                                          truth_line)
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S


STOP_TAIL_S = 1.0  # seconds of stop cue that end the WAV of a video that died mid-way
SIDEWAYS_UNSURE = 0.5  # a portrait video unsure on at least this share of frames: the summary advises sideways


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
    fov_deg: float | None = None     # the camera's horizontal FOV; None = the bundle's per orientation
    watchdog_s: float = DEFAULT_WATCHDOG_S   # seconds without a fresh frame before the stop (a video that dies)
    visual_yaw: bool = True          # follow the camera's turns read from the frames (runtime.visual_yaw)
    threads: int = 1                 # onnxruntime threads for the model (0: its default, all cores)
    imu: Path | None = None          # a motion-sensor log recorded with the video (runtime.imu)
    imu_offset: float | None = 0.0   # the log's time at the video's first frame; None: found (imu.align)
    follow_gyro: bool = False        # tell the decision logic the log's turn from the start, unconfirmed
    labels: Path | None = None       # a dataset of this video's labelled frames (truth.load_labels)
    plot: bool = True                # timeline.png (runtime.timeline), where matplotlib is installed


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
    frame_size: tuple[int, int] | None = None      # (W, H) of the decoded frames
    fov_deg: tuple[float, ...] = ()                # the horizontal FOVs the headings assumed
    view_rows: tuple[int, int] | None = None       # (top, rows) the graph saw (Bundle.rows_seen)
    thresholds: tuple[str, ...] = ()               # the gate thresholds the frames took, in words
    warnings: tuple[str, ...] = ()
    unsure_seeing: int = 0                         # unsure frames whose model's most probable action is a strip
    gyro: str | None = None                        # what the IMU log did, in words (None: no log)
    labels: dict | None = None                     # the decisions judged on labelled frames (truth.judge_labels)

    def lines(self) -> list[str]:
        """Human-readable summary lines."""
        n = max(self.frames, 1)
        pct = lambda c: ", ".join(f"{k} {100 * v / n:.0f}%" for k, v in sorted(c.items()))  # noqa: E731
        speed = self.video_s / self.wall_s if self.wall_s > 0 else math.inf
        out = [f"{self.frames} frames, {self.video_s:.1f} s of video in {self.wall_s:.1f} s "
               f"({speed:.1f}x real time)",
               f"gate: {pct(self.gates)}", f"stop reasons: {pct(self.reasons)}"]
        if self.frame_size:
            w, h = self.frame_size
            fovs = ", ".join(f"{f:g}" for f in self.fov_deg) or "none (no frame was understood)"
            seen = ""
            if self.view_rows and self.view_rows[1] < h:
                top, rows = self.view_rows
                seen = f"; the model sees rows {top}-{top + rows} of {h} (view crop: the training camera's view)"
            elif self.view_rows and self.view_rows[1] > h:
                seen = (f"; the model sees the frame padded to {self.view_rows[1]} rows (narrower than its default "
                        "camera: shown at the training scale, not magnified)")
            portrait = h > w
            out.insert(1, f"frames {w}x{h} ({'portrait' if portrait else 'landscape'}); headings assume a "
                          f"horizontal field of view of {fovs} deg{seen}")
            if self.thresholds:
                out.insert(2, f"gate threshold: {', '.join(self.thresholds)}")
            # the phone app's SidewaysHint, for a whole video: unsure frames on which the model places a
            # crossing somewhere (a video with no crossing in view is unsure too, and held sideways it stays so)
            unsure = self.unsure_seeing / n
            if portrait and unsure >= SIDEWAYS_UNSURE:
                out.insert(2, f"advice: the model was unsure where the crossing is on {100 * unsure:.0f}% of these "
                              "portrait frames; a phone held sideways (landscape) hears the beacon more often "
                              "(README, 'What the user hears')")
        if self.gyro:
            out.append(self.gyro)
        if self.failed:
            out.append(f"failed inferences: {self.failed}")
        if self.truth:
            out.append(truth_line(self.truth))
        if self.labels:
            out.append(labels_line(self.labels))
        out += [f"{k}: {v}" for k, v in self.outputs.items()]
        return out


def read_with_imu(pipeline: Pipeline, frame: np.ndarray, t: float, before: float | None, imu: ImuLog,
                  follow: GyroFollow) -> Seen:
    """:meth:`Pipeline.read` of a frame taken at ``t`` with a recorded log: levelled by its roll,
    and told the log's turn since the frame before (at ``before``) where it reports and ``follow``
    follows it (the live loop's rule: once the picture's turn has confirmed its sign)."""
    seen = pipeline.read(frame, t, roll_deg=imu.roll_at(t))
    return follow.tell(seen, imu, before, t) if imu.reporting(t) else seen


def run_frames(frames: Iterable[tuple[float, np.ndarray]], pipeline: Pipeline, *, sink, on_watchdog=None,
               imu: ImuLog | None = None, follow: GyroFollow | None = None) -> int:
    """Drive ``pipeline`` over ``(t, frame)`` pairs, calling ``sink(i, t, frame, step)``; returns
    the number of frames. With ``on_watchdog``: where the frames stop for longer than the
    watchdog (a gap in a variable-frame-rate video), the pipeline is stepped without a frame at
    the watchdog's moment, as the live loop's watchdog does, and ``on_watchdog(step)`` (a stop)
    is called, so the stop cue plays through the rest of the gap. With ``imu``: each frame is read
    with the recorded log (:func:`read_with_imu`; ``follow``: its rule, default confirmed first)."""
    n, prev = 0, None
    follow = follow or GyroFollow()
    for i, (t, frame) in enumerate(frames):
        if on_watchdog is not None and prev is not None:
            at = prev + pipeline.decider.cfg.watchdog_s * (1 + 1e-6)
            if t > at:
                on_watchdog(pipeline.step(None, at))
        seen = pipeline.read(frame, t) if imu is None else read_with_imu(pipeline, frame, t, prev, imu, follow)
        sink(i, t, frame, pipeline.decide(seen))
        n, prev = i + 1, t
    return n


RATE_SCALE_OFF = 3.0   # the picture's turn this many times the log's (or a third of it): the log's unit is wrong


def gyro_line(imu: ImuLog, follow: GyroFollow, times: list[float], told: int, alignment: Alignment | None = None) -> str:
    """The summary's line on a recorded log: where it reported, and whether its turn was followed."""
    n = max(len(times), 1)
    head = (f"gyroscope ({imu.path.name}): {alignment.describe() + '; ' if alignment else ''}"
            f"reported on {100 * imu.coverage(times):.0f}% of frames; its turn told on {100 * told / n:.0f}%")
    scale = follow.scale()
    if scale is not None and not 1 / RATE_SCALE_OFF <= abs(scale) <= RATE_SCALE_OFF:
        head += (f"; the picture turns {abs(scale):.3g} times as fast as the log says"
                 + (" (a log in rad/s reads 57 times too slow: give yaw_dps in degrees)" if 30 <= abs(scale) <= 100
                    else " (is yaw_dps in deg/s?)"))
    if follow.check.verdict == "wrong":
        return (head + "; the picture's turn found it the wrong way round, so it was not followed from then on "
                "(check the sign of yaw_dps, and --imu-offset)")
    if follow.follow:
        return head + " (--follow-gyro: followed from the start, unchecked)"
    if follow.confirmed_at is not None:
        by = "the walker's sway" if follow.confirmed_by == "sway" else "clear turns"
        return head + f", from {follow.confirmed_at:.1f} s, once the picture's turn had confirmed it by {by}"
    c = follow.check.cfg
    return (head + f"; the picture's turn never confirmed it (that takes clear turns, {c.turn_dps:g} deg/s, in both, "
            f"or {c.sway_window} frames of a walker's sway read alike by both), so the turn read from the frames "
            "was used (--follow-gyro follows it unchecked)")


def _mux(video: Path, wav: Path, out: Path) -> Path | None:
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        return None
    tmp = out.with_name(f".{out.stem}.{tmp_tag()}{out.suffix}")
    base = [ffmpeg, "-loglevel", "error", "-y", "-i", str(video), "-i", str(wav)]
    for vcodec in (["-c:v", "libx264", "-pix_fmt", "yuv420p"], ["-c:v", "copy"]):  # H.264 plays everywhere
        cmd = base + vcodec + ["-c:a", "aac", "-shortest", str(tmp)]
        try:
            done = subprocess.run(cmd, capture_output=True, timeout=600).returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            done = False
        if done:
            os.replace(tmp, out)
            return out
    tmp.unlink(missing_ok=True)
    return None


class _Recorder:
    """Collects one run's outputs: WAV samples on the video's timeline, trace lines, video."""

    def __init__(self, cfg: OfflineConfig, engine: Engine, fps: float) -> None:
        self.cfg, self.engine, self.fps = cfg, engine, fps
        self.out = Path(cfg.out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.player = CuePlayer(cfg.beacon)
        self.chunks: list[np.ndarray] = []
        self.pos = 0  # samples rendered so far
        self.gates: Counter = Counter()
        self.reasons: Counter = Counter()
        self.failed = 0
        self.unsure_seeing = 0
        self.headings: list[float | None] = []
        self.times: list[float] = []
        self.frame_fovs: list[float | None] = []   # the FOV each frame's heading was read with
        self.sources: Counter = Counter()   # where each frame's turn came from (Step.yaw_source)
        self.fovs: set[float] = set()
        self.frame_size: tuple[int, int] | None = None
        self.writer = None
        sweep_orphans(self.out)  # what a killed run left (SIGKILL runs no clean-up)
        self.tmp_video = self.out / f".annotated.{tmp_tag()}.mp4"
        self.trace = tempfile.NamedTemporaryFile("w", dir=self.out, prefix=f".trace.{tmp_tag()}-", suffix=".jsonl",
                                                 delete=False)

    def audio_until(self, t_end: float) -> None:
        """Play the current cue up to ``t_end`` seconds."""
        n = round(t_end * self.cfg.beacon.sample_rate) - self.pos
        if n > 0:
            self.chunks.append(self.player.render(n))
            self.pos += n

    def add(self, i: int, t: float, frame: np.ndarray, step: Step) -> None:
        """Record frame ``i`` (taken at ``t`` s): its cue plays from ``t`` to the next frame."""
        self.audio_until(t)
        self.player.set_loop(step.loop)
        d = step.decision
        self.headings.append(d.heading_deg)
        self.times.append(t)
        self.frame_fovs.append(step.prediction.fov_deg)
        self.sources[step.yaw_source] += 1
        self.gates[d.gate] += 1
        self.reasons[d.reason] += 1
        self.failed += not step.prediction.ok
        self.unsure_seeing += d.reason == REASON_UNCERTAIN and step.prediction.ok and step.prediction.action != 0
        self.frame_size = self.frame_size or (frame.shape[1], frame.shape[0])
        if step.prediction.fov_deg is not None:
            self.fovs.add(step.prediction.fov_deg)
        self.trace.write(json.dumps(trace_record(i, step)) + "\n")
        if self.cfg.annotate:
            fov = step.prediction.fov_deg
            if fov is None:
                try:
                    fov = self.engine.camera_fov(frame.shape[1], frame.shape[0])
                except GeometryError:   # refused (e.g. a crop too narrow): frames of this size get no heading
                    fov = None
            img = annotate(frame, step.prediction, d, self.engine.space, fov)
            if self.writer is None:
                h, w = img.shape[:2]
                self.writer = cv2.VideoWriter(str(self.tmp_video), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (w, h))
            self.writer.write(img)

    def close(self) -> None:
        self.trace.close()
        if self.writer is not None:
            self.writer.release()

    def abort(self) -> None:
        """Remove the temporary files of an unfinished run."""
        self.close()
        Path(self.trace.name).unlink(missing_ok=True)
        self.tmp_video.unlink(missing_ok=True)

    def watchdog(self, step: Step) -> None:
        """The watchdog's stop in a gap between frames: the last cue plays until ``step.decision.t``,
        then ``step``'s (the stop cue) until the next frame. Not a frame: no trace line, not counted."""
        self.audio_until(step.decision.t)
        self.player.set_loop(step.loop)

    def stop_tail(self, i: int, step: Step, tail_s: float = STOP_TAIL_S) -> float:
        """End on a stop: the last cue plays until ``step.decision.t`` (the watchdog's moment),
        then ``step`` (a stop) is recorded as trace line ``i`` and its cue plays for ``tail_s``.
        Returns the end of the audio (s)."""
        self.watchdog(step)
        self.gates[step.decision.gate] += 1
        self.reasons[step.decision.reason] += 1
        self.trace.write(json.dumps(trace_record(i, step)) + "\n")
        return step.decision.t + tail_s

    def finish(self, n: int, end_s: float | None = None) -> dict:
        """Write the final files atomically; returns name -> path (or a note). The audio runs to
        ``end_s`` (default: the end of frame ``n - 1``)."""
        self.close()
        self.audio_until(n / self.fps if end_s is None else end_s)
        out = self.out
        outputs: dict = {"beacon": write_wav(out / "beacon.wav", np.concatenate(self.chunks),
                                             self.cfg.beacon.sample_rate)}
        os.chmod(self.trace.name, 0o644)
        os.replace(self.trace.name, out / "trace.jsonl")
        outputs["trace"] = out / "trace.jsonl"
        if self.cfg.annotate:
            os.replace(self.tmp_video, out / "annotated.mp4")
            outputs["annotated"] = out / "annotated.mp4"
            if self.cfg.mux:
                muxed = _mux(out / "annotated.mp4", outputs["beacon"], out / "annotated_with_audio.mp4")
                outputs["with_audio"] = muxed or "skipped (no working ffmpeg; play annotated.mp4 with beacon.wav)"
        return outputs


def _timeline(rec: _Recorder, trace: Path, truth: dict | None, labelled: list[LabelledFrame] | None,
              video: Path) -> Path | None:
    """``timeline.png`` beside the trace, with the goal's heading where it is known: the labelled
    frames' (their far point, else their strip's centre, at the FOV of the frame at their time),
    else the synthetic clip's ground truth."""
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    goal: list[tuple[float, float | None]] = []
    if labelled:
        ts = np.asarray(rec.times)
        for f in labelled:
            fov = rec.frame_fovs[int(np.argmin(np.abs(ts - f.t)))] if len(ts) else None
            if f.label == UNKNOWN:
                goal.append((f.t, None))
            elif fov is not None:
                goal.append((f.t, x_to_heading(f.far_x if f.far_x is not None else bin_center_x(f.label), fov)))
    elif truth:
        visible = truth.get("far_x") or truth["label"]
        goal = [(t, a if v is not None and str(v) != "unknown" else None)
                for t, a, v in zip(rec.times, truth["goal_azimuth_deg"], visible)]
    return plot_timeline(records, trace.with_name("timeline.png"), truth=goal,
                         truth_label="goal (labelled)" if labelled else "goal (truth)", title=f"crossing-demo: {video.name}")


def run_offline(cfg: OfflineConfig, engine: Engine | None = None) -> Summary:
    """Run the whole demo on ``cfg.video``; writes the outputs into ``cfg.out_dir``."""
    from tqdm import tqdm

    from crossing_assist.runtime.sources import SourceError, VideoSource

    log = ImuLog.load(cfg.imu, cfg.imu_offset or 0.0) if cfg.imu is not None else None   # refused before the model
    labelled = load_labels(cfg.labels, cfg.video) if cfg.labels is not None else None
    pipeline = open_pipeline(cfg.bundle, fov_deg=cfg.fov_deg, watchdog_s=cfg.watchdog_s, beacon=cfg.beacon,
                             engine=engine, visual_yaw=cfg.visual_yaw, threads=cfg.threads)
    engine = pipeline.engine
    imu, alignment = line_up(log, cfg.imu_offset, cfg.video, engine.frame_fov) if log is not None else (None, None)
    follow = GyroFollow(cfg.follow_gyro)
    source = VideoSource(cfg.video, max_width=cfg.max_width)
    rec = _Recorder(cfg, engine, source.fps)
    t0 = time.perf_counter()
    with tqdm(total=source.frame_count or None, unit="frame", disable=not cfg.progress, leave=False,
              desc="crossing-demo") as bar:
        def sink(i: int, t: float, frame: np.ndarray, step: Step) -> None:
            rec.add(i, t, frame, step)
            bar.update(1)

        try:
            n = run_frames(source, pipeline, sink=sink, on_watchdog=rec.watchdog, imu=imu, follow=follow)
        except BaseException:
            rec.abort()
            raise
    if n == 0:
        rec.abort()
        raise SourceError(f"video {cfg.video} has no readable frames")
    warnings: list[str] = []
    end_s = None
    if source.frame_count > 0 and n < source.frame_count:
        # The video died mid-way (truncated or corrupt): the frames stopped coming, so the
        # watchdog stops the beacon; the trace and the WAV end on that stop, never on a direction.
        watchdog_s = pipeline.decider.cfg.watchdog_s
        t_stop = max(n / source.fps, (n - 1) / source.fps + watchdog_s * (1 + 1e-6))
        end_s = rec.stop_tail(n, pipeline.step(None, t_stop))
        warnings.append(f"video {cfg.video} ended after {n} of {source.frame_count} frames (truncated or corrupt); "
                        "the trace and beacon.wav end with a stop")
    outputs = rec.finish(n, end_s)
    truth = load_truth(cfg.video)
    if cfg.plot:
        outputs["timeline"] = _timeline(rec, outputs["trace"], truth, labelled, cfg.video) or \
            "skipped (matplotlib is not installed: pip install matplotlib)"
    view, thresholds = None, ()
    if rec.frame_size and len(rec.fovs) == 1:
        view = pipeline.engine.bundle.rows_seen(rec.frame_size[1], rec.frame_size[0], next(iter(rec.fovs)))
    if rec.frame_size:
        unc, o = pipeline.engine.bundle.calibration.uncertainty, orientation(*rec.frame_size)
        thresholds = tuple(dict.fromkeys(unc.describe(o, f) for f in sorted(rec.fovs)))
    return Summary(frames=n, video_s=n / source.fps, wall_s=time.perf_counter() - t0, gates=dict(rec.gates),
                   reasons=dict(rec.reasons), failed=rec.failed, outputs={k: str(v) for k, v in outputs.items()},
                   truth=compare(truth, rec.headings) if truth else None, frame_size=rec.frame_size,
                   fov_deg=tuple(sorted(rec.fovs)), view_rows=view, thresholds=thresholds, warnings=tuple(warnings),
                   unsure_seeing=rec.unsure_seeing,
                   labels=judge_labels(labelled, rec.times, rec.headings, rec.frame_fovs) if labelled else None,
                   gyro=gyro_line(imu, follow, rec.times, rec.sources["gyro"], alignment) if imu is not None else None)

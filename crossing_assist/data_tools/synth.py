"""``crossing-data synth``: synthetic labelled frames and a synthetic first-person crossing clip.

Frames: each frame is its own random street corner (:mod:`synth_scene`), seen by a phone at
chest height roughly facing the crossing; a fraction ``unknown_fraction`` shows no crossing
(a blank wall, or the user facing along the road), labelled ``unknown``. Frame ``i`` of seed
``s`` depends only on ``(s, i)``: the same command gives the same bytes, and more frames extend
the same sequence. Every row is flagged ``synthetic`` (plus ``marking=…``, ``lighting=…``,
``blocked`` when an occluder hides the goal); its source is its own scene, so splits made
from it are leakage-free.

Clip: one corner; the user starts facing along the road (no crossing in view), turns
towards the crossing (the goal sweeps across the frame from the right and overshoots),
aligns, waits while a car passes, and walks across with a slow veer and step sway. A JSON
sidecar records the command and the per-frame ground truth.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from crossing_assist.actions import DEFAULT_FOV_DEG, format_label
from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import Row, atomic_write_text, write_manifest
from crossing_assist.data_tools.synth_scene import (Camera, Occluder, Poster, Scene, Stairs, goal_label, project, render,
                                                   sample_scene)
from crossing_assist.errors import UserError


class SynthError(UserError):
    """Bad synthesis settings or an output that cannot be written."""


@dataclass(frozen=True)
class SynthConfig:
    out_dir: Path
    frames: int = 100
    seed: int = 0
    width: int = 224
    height: int = 168
    fov_deg: float = DEFAULT_FOV_DEG
    unknown_fraction: float = 0.15
    val_fraction: float = 0.2
    supersample: int = 2
    progress: bool = True
    lookalike_fraction: float = 0.0   # share of the no-crossing frames showing stairs or a crossing's picture


@dataclass(frozen=True)
class ClipConfig:
    out_path: Path
    seed: int = 0
    seconds: float = 16.0
    fps: float = 15.0
    width: int = 320
    height: int = 240
    fov_deg: float = DEFAULT_FOV_DEG
    supersample: int = 2
    command: str = ""
    progress: bool = True


def _check_size(width: int, height: int, fov: float) -> None:
    if not (16 <= width <= 4096 and 16 <= height <= 4096):
        raise SynthError(f"size {width}x{height} invalid; valid: 16..4096 pixels a side")
    if not 10 <= fov <= 150:
        raise SynthError(f"fov {fov} invalid; valid: 10..150 degrees")


# ---------------------------------------------------------------- labelled frames


def sample_view(scene: Scene, rng: np.random.Generator, fov_deg: float, away: bool) -> Camera:
    """A phone pose at the near kerb: facing the goal (its bearing in view: 60% near the centre,
    N(0, 10°), 40% anywhere across the field of view) or, with ``away``, facing along the road
    so the goal is out of view."""
    goal = scene.goal()
    bearing = math.degrees(math.atan2(goal[0], goal[2])) if goal is not None else scene.theta
    if away:
        side = 1.0 if rng.random() < 0.5 else -1.0
        yaw = bearing + side * float(rng.uniform(fov_deg / 2 + 25, fov_deg / 2 + 70))
    elif rng.random() < 0.6:
        yaw = bearing - float(np.clip(rng.normal(0, 10), -30, 30))
    else:
        yaw = bearing - float(rng.uniform(-0.98, 0.98)) * fov_deg / 2
    return Camera(yaw=yaw, pitch=float(rng.uniform(3, 20)), roll=float(rng.normal(0, 2.5)),
                  height=float(rng.uniform(1.2, 1.6)), fov_deg=fov_deg)


LOOKALIKES = ("stairs_up", "stairs_down", "poster")


def sample_lookalike(rng: np.random.Generator, fov_deg: float) -> tuple[Scene, Camera, str]:
    """A scene with no crossing but something striped like one, the phone facing it: a flight
    of stairs up or down, or a picture of a zebra crossing on a poster, screen or billboard.
    Returns (scene, camera, kind); the label is unknown."""
    kind = str(rng.choice(LOOKALIKES))
    base = replace(sample_scene(rng), has_road=False, occluders=())
    # A common pose; each kind then sets its own pitch (and stairs their yaw). The draws stay in
    # this order: runs/data/synth_look, measured in docs/models.md, was made with it.
    yaw = base.theta + float(np.clip(rng.normal(0, 12), -30, 30))
    cam = Camera(yaw=yaw, pitch=float(rng.uniform(3, 22)), roll=float(rng.normal(0, 2.5)),
                 height=float(rng.uniform(1.2, 1.6)), fov_deg=fov_deg)
    if kind == "poster":
        wall = float(rng.uniform(2.5, 8.0))
        inner = replace(sample_scene(rng), has_road=True, marking="zebra",
                        lighting=str(rng.choice(["day", "overcast", "sunny", "dusk"])))
        if rng.random() < 0.3:        # a billboard: wide, high
            w, y0 = float(rng.uniform(3.0, 6.0)), float(rng.uniform(1.8, 3.5))
            h = w * float(rng.uniform(0.4, 0.6))
        elif rng.random() < 0.5:      # a shop or station screen: landscape
            w, y0 = float(rng.uniform(0.8, 2.2)), float(rng.uniform(0.6, 1.8))
            h = w * float(rng.uniform(0.5, 0.75))
        else:                         # a shelter or street ad: portrait
            w, y0 = float(rng.uniform(0.9, 1.4)), float(rng.uniform(0.2, 0.7))
            h = w * float(rng.uniform(1.3, 1.6))
        stand = bool(rng.random() < 0.5)
        a = float(rng.uniform(1.0, wall - 0.3)) if stand else wall - 0.02
        centre = a * math.tan(math.radians(yaw - base.theta)) + float(rng.normal(0, w / 3))
        frame = (0.05, 0.05, 0.06) if rng.random() < 0.5 else tuple(rng.uniform(0.3, 0.9, 3))
        shot = replace(sample_view(inner, rng, 60.0, False), pitch=float(rng.uniform(8, 28)))   # the zebra fills it
        poster = Poster(a, centre - w / 2, centre + w / 2, y0, y0 + h, inner, shot,
                        float(rng.uniform(0.02, 0.12)), frame, stand)
        scene = replace(base, near=wall - 1.5, poster=poster)
        return scene, replace(cam, pitch=float(rng.uniform(-8, 12))), kind
    down = kind == "stairs_down"
    steps = int(rng.integers(4, 15))
    start = float(rng.uniform(0.6, 3.0) if down else rng.uniform(1.0, 6.0))
    grey = float(rng.uniform(0.35, 0.8))
    color = tuple(np.clip(grey * np.array([1.0, 0.98, 0.94]) + rng.normal(0, 0.04, 3), 0, 1))
    nosing = (tuple(np.clip(np.array(color) * rng.uniform(0.5, 1.3), 0, 1)) if rng.random() < 0.4
              else tuple(rng.choice([(0.95, 0.85, 0.1), (0.92, 0.92, 0.9), (0.1, 0.1, 0.1), (0.6, 0.55, 0.3)])))
    centre = float(rng.uniform(-2.0, 2.0))
    stairs = Stairs(start, centre, float(rng.uniform(1.2, 8.0)), steps,
                    float(rng.uniform(0.12, 0.19)), float(rng.uniform(0.25, 0.42)), float(rng.uniform(1.0, 5.0)),
                    down, color, nosing, float(rng.uniform(0.03, 0.12)))
    yaw = base.theta + math.degrees(math.atan2(centre, start + 2.0)) + float(np.clip(rng.normal(0, 10), -25, 25))
    pitch = float(rng.uniform(15, 45) if down else rng.uniform(-5, 18))
    return replace(base, near=stairs.end - 1.5, stairs=stairs), replace(cam, yaw=yaw, pitch=pitch), kind


def synth_frame(seed: int, index: int, cfg: SynthConfig) -> tuple[np.ndarray, Row]:
    """Frame ``index`` of ``seed``: (H×W×3 uint8 RGB, its manifest row with image ``images/…``)."""
    rng = np.random.default_rng([seed, index])
    no_crossing = rng.random() < cfg.unknown_fraction
    wall = no_crossing and rng.random() < 0.4
    scene = sample_scene(rng)
    if wall:
        scene = replace(scene, has_road=False)
    cam = sample_view(scene, rng, cfg.fov_deg, away=no_crossing and not wall)
    lookalike = None
    if no_crossing and cfg.lookalike_fraction > 0:   # its own draws: frames that stay are unchanged
        look_rng = np.random.default_rng([seed, index, 1])
        if look_rng.random() < cfg.lookalike_fraction:
            scene, cam, lookalike = sample_lookalike(look_rng, cfg.fov_deg)
    image = render(scene, cam, cfg.width, cfg.height, rng=rng, supersample=cfg.supersample)
    far_x, label, blocked = goal_label(scene, cam, cfg.width, cfg.height)
    flags = ["synthetic", f"marking={scene.marking if scene.has_road else 'none'}", f"lighting={scene.lighting}"]
    if far_x is not None:   # the goal's height too, as PTL rows carry it: a rolled training view turns it exactly
        flags.append(f"far_y={project(cam, scene.goal(), cfg.width, cfg.height)[1]:.4f}")
    if lookalike:
        flags.append(f"view={lookalike}")
    elif wall:
        flags.append("view=wall")
    elif no_crossing:
        flags.append("view=away")
    if blocked:
        flags.append("blocked")
    split = "val" if rng.random() < cfg.val_fraction else "train"
    name = f"images/synth_s{seed}_{index:06d}.jpg"
    return image, Row(name, label, far_x, f"synth:s{seed}:{index}", split, {}, tuple(flags))


def synth_dataset(cfg: SynthConfig) -> Path:
    """Render ``cfg.frames`` frames into the dataset folder ``cfg.out_dir``; returns the manifest."""
    _check_size(cfg.width, cfg.height, cfg.fov_deg)
    if cfg.frames < 1:
        raise SynthError(f"frames={cfg.frames} invalid; expected >= 1")
    for name, v in (("unknown_fraction", cfg.unknown_fraction), ("val_fraction", cfg.val_fraction),
                    ("lookalike_fraction", cfg.lookalike_fraction)):
        if not 0 <= v <= 1:
            raise SynthError(f"{name}={v} invalid; valid: 0..1")
    out = Path(cfg.out_dir)
    rows = []
    for i in tqdm(range(cfg.frames), desc="synth", unit="frame", disable=not cfg.progress):
        image, row = synth_frame(cfg.seed, i, cfg)
        save_rgb(out / row.image, image, quality=90)
        rows.append(row)
    return write_manifest(out, rows)


# ---------------------------------------------------------------- the clip


def _ease(t: float) -> float:
    t = min(1.0, max(0.0, t))
    return t * t * (3 - 2 * t)


def clip_scene(seed: int) -> Scene:
    """The corner of the clip: a zebra crossing of a 7-10 m road, nothing blocking it."""
    rng = np.random.default_rng([seed, 1_000_003])
    scene = sample_scene(rng)
    return replace(scene, has_road=True, marking="zebra", road_width=float(rng.uniform(7, 10)),
                   near=float(rng.uniform(0.6, 1.2)), offset=float(rng.uniform(-0.8, 0.8)),
                   theta=float(rng.uniform(-10, 10)), occluders=(),
                   lighting=str(rng.choice(["day", "overcast", "sunny"])))


def clip_pose(scene: Scene, t: float, seconds: float, fov_deg: float) -> tuple[Camera, str]:
    """Camera at time ``t`` s of the clip, and the phase name (away/turn/align/walk)."""
    f = t / seconds
    start, overshoot = scene.theta - 125.0, scene.theta + 14.0
    sway = 1.5 * math.sin(2 * math.pi * 0.4 * t)
    along = 0.0
    lateral = 0.0
    if f < 0.16:
        phase, yaw = "away", start + sway
    elif f < 0.42:
        phase, yaw = "turn", start + (overshoot - start) * _ease((f - 0.16) / 0.26) + 0.5 * sway
    elif f < 0.56:
        phase, yaw = "align", overshoot + (scene.theta - 1.5 - overshoot) * _ease((f - 0.42) / 0.08) + 0.3 * sway
    else:
        phase = "walk"
        w = (f - 0.56) / 0.44
        veer = 9.0 * math.sin(math.pi * min(1.0, w * 1.6)) - 4.0 * _ease((w - 0.6) / 0.4)
        step = 2.5 * math.sin(2 * math.pi * 0.9 * t)
        yaw = scene.theta + veer + step
        along = (scene.near + scene.road_width - 1.8) * w
        lateral = 0.35 * math.sin(math.pi * w) * (1 if veer >= 0 else -1)
    base = along * scene.n + (scene.offset * 0.0 + lateral) * scene.u
    bob = 0.03 * math.sin(2 * math.pi * 1.8 * t) if phase == "walk" else 0.0
    cam = Camera(x=float(base[0]), z=float(base[2]), yaw=yaw, pitch=9.0 + 1.5 * math.sin(0.7 * t),
                 roll=1.2 * math.sin(1.1 * t), height=1.4 + bob, fov_deg=fov_deg)
    return cam, phase


def _passing_car(scene: Scene, t: float, seconds: float) -> tuple[Occluder, ...]:
    """A car crossing the view on the far lane during the align phase."""
    t0, t1 = 0.40 * seconds, 0.56 * seconds
    if not t0 <= t <= t1:
        return ()
    b0 = scene.offset + 14.0 - 28.0 * (t - t0) / (t1 - t0)
    return (Occluder(scene.near + scene.road_width * 0.72, b0, b0 + 4.3, 1.5, (0.7, 0.1, 0.1)),)


IMU_HZ = 100.0   # the clip's motion-sensor log: samples a second, as a phone's gyroscope reports


def imu_path(video: str | Path) -> Path:
    """Where a clip's motion-sensor log lies: ``<clip>.imu.csv`` beside it."""
    return Path(video).with_suffix(".imu.csv")


def clip_imu_csv(seed: int, seconds: float, fov_deg: float, hz: float = IMU_HZ) -> str:
    """The clip's camera motion as the motion-sensor log ``crossing-demo --imu`` replays
    (crossing_assist.runtime.imu): ``t``, ``yaw_dps`` (+ right; the camera's yaw differentiated
    over the sample interval) and ``roll_deg`` (+ clockwise, as ``geometry.level`` takes it)."""
    scene = clip_scene(seed)
    t = [k / hz for k in range(int(round(seconds * hz)) + 1)]
    cams = [clip_pose(scene, ti, seconds, fov_deg)[0] for ti in t]
    # each sample's rate covers the interval since the one before (the first's: the next's)
    rates = [(b.yaw - a.yaw) * hz for a, b in zip(cams, cams[1:])]
    rates = rates[:1] + rates
    lines = ["t,yaw_dps,roll_deg"] + [f"{ti:.4f},{r:.4f},{c.roll:.4f}" for ti, r, c in zip(t, rates, cams)]
    return "\n".join(lines) + "\n"


def synth_clip(cfg: ClipConfig) -> tuple[Path, Path]:
    """Render the clip to ``cfg.out_path`` (mp4v, atomic), its JSON ground truth beside it and its
    camera's motion-sensor log (:func:`imu_path`, :func:`clip_imu_csv`)."""
    _check_size(cfg.width, cfg.height, cfg.fov_deg)
    out = Path(cfg.out_path)
    if out.suffix.lower() != ".mp4":
        raise SynthError(f"--out {out} invalid for --video; expected a file name ending in .mp4")
    if not (2 <= cfg.seconds <= 600 and 1 <= cfg.fps <= 60):
        raise SynthError(f"seconds={cfg.seconds} fps={cfg.fps} invalid; valid: 2..600 s at 1..60 fps")
    out.parent.mkdir(parents=True, exist_ok=True)
    scene = clip_scene(cfg.seed)
    n = int(round(cfg.seconds * cfg.fps))
    tmp = out.with_name(f".{out.stem}.tmp.mp4")
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), cfg.fps, (cfg.width, cfg.height))
    if not writer.isOpened():
        raise SynthError(f"OpenCV cannot write mp4v video to {tmp}")
    truth: dict[str, list] = {"t": [], "far_x": [], "label": [], "phase": [], "blocked": [], "goal_azimuth_deg": []}
    try:
        for i in tqdm(range(n), desc="synth clip", unit="frame", disable=not cfg.progress):
            t = i / cfg.fps
            cam, phase = clip_pose(scene, t, cfg.seconds, cfg.fov_deg)
            sc = replace(scene, occluders=_passing_car(scene, t, cfg.seconds))
            rng = np.random.default_rng([cfg.seed, 2_000_003, i])
            frame = render(sc, cam, cfg.width, cfg.height, rng=rng, supersample=cfg.supersample, noise=0.3)
            writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
            far_x, label, blocked = goal_label(sc, cam, cfg.width, cfg.height)
            c = cam.rotation().T @ (scene.goal() - cam.position())
            truth["t"].append(round(t, 4))
            truth["far_x"].append(None if far_x is None else round(far_x, 6))
            truth["label"].append(format_label(label))
            truth["phase"].append(phase)
            truth["blocked"].append(blocked)
            truth["goal_azimuth_deg"].append(round(math.degrees(math.atan2(c[0], c[2])), 3))
    finally:
        writer.release()
    if not tmp.is_file() or tmp.stat().st_size == 0:
        raise SynthError(f"OpenCV wrote no video to {tmp}")
    os.replace(tmp, out)
    meta = {
        "synthetic": True,
        "description": "procedural street corner (crossing_assist.data_tools.synth), not real footage",
        "command": cfg.command or f"crossing-data synth --video --out {out.name} --seed {cfg.seed}",
        "seed": cfg.seed, "fps": cfg.fps, "size": [cfg.width, cfg.height], "fov_deg": cfg.fov_deg,
        "n_frames": n, "codec": "mp4v",
        "fields": {"far_x": "goal position, fraction of width, null when not in view",
                   "label": "bin 1..12 or unknown", "phase": "away | turn | align | walk",
                   "blocked": "a car hides the goal", "goal_azimuth_deg": "goal bearing from the optical axis, + right"},
        **truth,
    }
    side = out.with_suffix(".json")
    atomic_write_text(side, json.dumps(meta, indent=1) + "\n")
    atomic_write_text(imu_path(out), clip_imu_csv(cfg.seed, cfg.seconds, cfg.fov_deg))
    return out, side

"""Synthetic street corners: exact goal, determinism, unknown frames, the clip and its asset."""

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from crossing_assist.actions import parse_label, x_to_bin
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.data_tools.synth import ClipConfig, SynthConfig, sample_lookalike, synth_clip, synth_frame
from crossing_assist.data_tools.synth_scene import (Camera, Occluder, Poster, Stairs, goal_label, project, render,
                                                   sample_scene)

ASSETS = Path(__file__).resolve().parents[1] / "crossing_assist" / "assets"
SMALL = SynthConfig(Path("."), width=48, height=36, supersample=1)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", *map(str, args)],
                          capture_output=True, text=True)


def test_rendered_goal_is_where_the_label_says():
    """A red pole stands on the goal; its column in the frame must match far_x."""
    rng = np.random.default_rng(4)
    scene = sample_scene(rng)
    g = scene.goal()
    pole = Occluder(scene.far, scene.offset - 0.15, scene.offset + 0.15, 3.0, (1.0, 0.0, 0.0))
    scene = replace(scene, occluders=(pole,), lighting="day", marking="none")
    w, h = 160, 120
    for cam in (Camera(yaw=scene.theta + 10, pitch=8, roll=0), Camera(yaw=scene.theta - 15, pitch=14, roll=0)):
        far_x, label, blocked = goal_label(scene, cam, w, h)
        assert far_x is not None and label == x_to_bin(far_x)
        img = render(scene, cam, w, h, rng=np.random.default_rng(0), supersample=1, noise=0).astype(int)
        red = (img[..., 0] > 120) & (img[..., 1] < 60) & (img[..., 2] < 60)
        cols = np.nonzero(red.any(axis=0))[0]
        assert cols.size > 0
        assert abs((cols.min() + cols.max() + 1) / 2 / w - far_x) < 2.0 / w
        rows = np.nonzero(red.any(axis=1))[0]   # the pole's foot stands on the goal: its height is far_y
        assert abs((rows.max() + 1) / h - project(cam, g, w, h)[1]) < 2.0 / h
        assert g is not None


def test_frames_with_a_goal_carry_its_height_for_rolled_training_views():
    """far_y lets a rolled field view turn the goal exactly (without it, half height was assumed:
    about one strip off near a side edge at 15 degrees)."""
    from crossing_assist.data_tools.images import flag_value

    rows = [synth_frame(1, i, replace(SMALL, unknown_fraction=0.5))[1] for i in range(30)]
    known = [r for r in rows if r.label != 0]
    assert known and len(known) < len(rows)
    for r in known:
        assert 0.0 <= float(flag_value(r.flags, "far_y")) <= 1.0
    assert len({flag_value(r.flags, "far_y") for r in known}) > len(known) // 2
    assert all(flag_value(r.flags, "far_y") is None for r in rows if r.label == 0)


def test_frames_are_deterministic_per_seed_and_index():
    a_img, a_row = synth_frame(7, 3, SMALL)
    b_img, b_row = synth_frame(7, 3, SMALL)
    c_img, _ = synth_frame(7, 4, SMALL)
    d_img, _ = synth_frame(8, 3, SMALL)
    np.testing.assert_array_equal(a_img, b_img)
    assert a_row == b_row and a_img.shape == (36, 48, 3)
    assert not np.array_equal(a_img, c_img) and not np.array_equal(a_img, d_img)


def test_labels_are_consistent_and_unknown_fraction_is_honoured():
    rows = [synth_frame(1, i, replace(SMALL, unknown_fraction=0.0))[1] for i in range(40)]
    assert sum(r.label != 0 for r in rows) >= 36
    for r in rows:
        assert "synthetic" in r.flags
        if r.label:
            assert r.label == x_to_bin(r.far_x)
    assert len({r.source for r in rows}) == 40
    assert len({f for r in rows for f in r.flags if f.startswith("marking=")}) >= 3
    unknown = [synth_frame(1, i, replace(SMALL, unknown_fraction=1.0))[1] for i in range(10)]
    assert all(r.label == 0 and r.far_x is None for r in unknown)
    assert {f for r in unknown for f in r.flags} >= {"view=away", "view=wall"}


def test_lookalikes_replace_only_frames_without_a_crossing():
    """Frames with a crossing stay byte for byte; every frame without one becomes stairs or a
    crossing's picture, labelled unknown, each kind drawn."""
    cfg = replace(SMALL, unknown_fraction=0.5)
    plain = [synth_frame(3, i, cfg) for i in range(24)]
    look = [synth_frame(3, i, replace(cfg, lookalike_fraction=1.0)) for i in range(24)]
    kinds = set()
    for (a_img, a_row), (b_img, b_row) in zip(plain, look):
        views = [f for f in a_row.flags if f.startswith("view=")]
        if not views:   # a crossing in view (or out of the frame at its edge): unchanged
            assert a_row == b_row
            np.testing.assert_array_equal(a_img, b_img)
            continue
        view = next(f for f in b_row.flags if f.startswith("view="))[5:]
        assert view in ("stairs_up", "stairs_down", "poster") and b_row.label == 0 and b_row.far_x is None
        kinds.add(view)
    assert kinds == {"stairs_up", "stairs_down", "poster"}


def _bands(profile: np.ndarray) -> int:
    """Bright bands along a luminance profile (runs above its midrange); none in a profile of
    less than 40 grey levels (texture and shading, not bars)."""
    if np.ptp(profile) < 40:
        return 0
    bright = profile > (profile.min() + profile.max()) / 2
    return int(np.sum(bright[1:] & ~bright[:-1]))


@pytest.mark.parametrize("down", [False, True])
def test_stairs_are_seen_as_bars_across_the_view(down):
    scene = replace(sample_scene(np.random.default_rng(2)), has_road=False, occluders=(), theta=0.0, lighting="day")
    stairs = Stairs(start=1.0 if down else 2.0, centre=0.0, width=4.0, steps=8, rise=0.16, tread=0.32, landing=2.0,
                    down=down, color=(0.3, 0.3, 0.3), nosing=(0.95, 0.95, 0.95), nosing_depth=0.04)
    scene = replace(scene, near=stairs.end - 1.5, stairs=stairs)
    cam = Camera(yaw=0.0, pitch=30.0 if down else 5.0, roll=0.0, fov_deg=60.0)
    img, plain = (render(s, cam, 160, 240, rng=np.random.default_rng(0), supersample=2, noise=0).astype(float)
                  for s in (scene, replace(scene, stairs=None)))
    column, column_plain = img[:, 78:82].mean(axis=(1, 2)), plain[:, 78:82].mean(axis=(1, 2))
    flight = np.abs(column - column_plain) > 10          # the rows the flight covers
    assert flight.sum() > 30 and _bands(column[flight]) >= 6   # a bright edge a step


def test_a_poster_shows_a_picture_of_a_crossing():
    base = replace(sample_scene(np.random.default_rng(5)), has_road=False, occluders=(), theta=0.0, lighting="day")
    inner = replace(sample_scene(np.random.default_rng(6)), has_road=True, marking="zebra", lighting="day", occluders=())
    shot = Camera(yaw=inner.theta, pitch=15.0, fov_deg=60.0)
    poster = Poster(a=4.0, b0=-1.2, b1=1.2, y0=0.5, y1=2.3, scene=inner, camera=shot, bezel=0.05,
                    frame_color=(0.05, 0.05, 0.05), stand=False)
    scene = replace(base, near=4.02 - 1.5, poster=poster)
    cam = Camera(yaw=0.0, pitch=0.0, roll=0.0, height=1.4, fov_deg=60.0)
    w, h = 240, 180
    img = render(scene, cam, w, h, rng=np.random.default_rng(0), supersample=2, noise=0).astype(float)
    (x0, y0), (x1, y1) = (project(cam, np.array(c), w, h) for c in ((-1.2, 2.3, 4.0), (1.2, 0.5, 4.0)))
    crop = img[int(y0 * h) + 3:int(y1 * h) - 3, int(x0 * w) + 3:int(x1 * w) - 3].mean(axis=2)
    picture = render(inner, shot, 160, 120, rng=np.random.default_rng(inner.texture_seed), supersample=1,
                     noise=0.5).astype(float).mean(axis=2)
    picture = cv2.resize(picture, (crop.shape[1], crop.shape[0]), interpolation=cv2.INTER_AREA)
    def corr(p):
        return np.corrcoef(crop.ravel(), p.ravel())[0, 1]
    assert corr(picture) > 0.7                                        # the picture, upright and unmirrored
    assert max(corr(picture[::-1]), corr(picture[:, ::-1])) < 0.3


def test_sampled_lookalikes_face_the_user():
    """Each sampled look-alike fills a fair part of the frame (the phone points at it)."""
    for i in range(9):
        rng = np.random.default_rng([11, i])
        scene, cam, kind = sample_lookalike(rng, 60.0)
        assert scene.goal() is None
        plain = replace(scene, stairs=None, poster=None)
        a = render(scene, cam, 64, 48, rng=np.random.default_rng(0), supersample=1, noise=0).astype(int)
        b = render(plain, cam, 64, 48, rng=np.random.default_rng(0), supersample=1, noise=0).astype(int)
        assert (np.abs(a - b).max(axis=2) > 8).mean() > 0.03, (i, kind)


def test_synth_cli_writes_a_valid_dataset_and_extends_with_more_frames(tmp_path):
    proc = _cli("synth", "--out", tmp_path / "a", "--frames", 4, "--seed", 2, "--size", "40x30",
                "--supersample", 1, "--quiet")
    assert proc.returncode == 0, proc.stderr
    proc = _cli("synth", "--out", tmp_path / "b", "--frames", 6, "--seed", 2, "--size", "40x30",
                "--supersample", 1, "--quiet")
    a, b = read_manifest(tmp_path / "a"), read_manifest(tmp_path / "b")
    assert len(a) == 4 and b.rows[:4] == a.rows
    assert (tmp_path / "a" / a.rows[0].image).read_bytes() == (tmp_path / "b" / b.rows[0].image).read_bytes()


@pytest.mark.parametrize("args, message", [
    (["--video", "--out", "clip.avi"], "expected a file name ending in .mp4"),
    (["--out", "d", "--size", "4x4"], "size 4x4 invalid"),
    (["--out", "d", "--frames", "0"], "frames=0 invalid"),
    (["--out", "d", "--lookalike-fraction", "1.5"], "lookalike_fraction=1.5 invalid"),
])
def test_synth_cli_rejects_bad_settings(tmp_path, args, message):
    proc = _cli("synth", *[tmp_path / a if a in ("clip.avi", "d") else a for a in args])
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr


def _read_video(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    cap.release()
    return frames


def _check_truth(meta, frames):
    assert meta["synthetic"] is True and meta["n_frames"] == len(frames) == len(meta["far_x"])
    for x, label in zip(meta["far_x"], meta["label"]):
        assert (x is None) == (label == "unknown")
        if x is not None:
            assert parse_label(label) == x_to_bin(x)
    phases = meta["phase"]
    assert phases[0] == "away" and phases[-1] == "walk" and {"turn", "align"} <= set(phases)
    assert all(x is None for x, p in zip(meta["far_x"], phases) if p == "away")
    walk = [x for x, p in zip(meta["far_x"], phases) if p == "walk" and x is not None]
    assert walk and np.ptp(walk) > 0.01            # veer moves the goal while walking
    turn = [x for x, p in zip(meta["far_x"], phases) if p == "turn" and x is not None]
    assert turn and max(turn) - min(turn) > 0.3     # the goal sweeps across the frame


def test_clip_is_readable_with_ground_truth(tmp_path):
    video, side = synth_clip(ClipConfig(tmp_path / "c.mp4", seed=1, seconds=6, fps=8, width=64, height=48,
                                        supersample=1, progress=False))
    frames = _read_video(video)
    assert frames[0].shape == (48, 64, 3)
    _check_truth(json.loads(side.read_text()), frames)


def test_embedded_sample_clip_matches_its_ground_truth():
    video, side = ASSETS / "sample_clip.mp4", ASSETS / "sample_clip.json"
    assert video.stat().st_size < 2_000_000
    meta = json.loads(side.read_text())
    frames = _read_video(video)
    assert frames[0].shape == (240, 320, 3) and meta["size"] == [320, 240]
    assert 10 <= len(frames) / meta["fps"] <= 20
    assert meta["command"].startswith("crossing-data synth --video")
    _check_truth(meta, frames)


def test_embedded_clip_ground_truth_is_reproduced_by_the_current_code():
    """The sidecar's far_x per frame follows from the recorded seed with today's geometry."""
    from crossing_assist.data_tools.synth import _passing_car, clip_pose, clip_scene
    meta = json.loads((ASSETS / "sample_clip.json").read_text())
    scene = clip_scene(meta["seed"])
    seconds = meta["n_frames"] / meta["fps"]
    w, h = meta["size"]
    for i in range(0, meta["n_frames"], 5):
        t = i / meta["fps"]
        cam, phase = clip_pose(scene, t, seconds, meta["fov_deg"])
        far_x, _, _ = goal_label(replace(scene, occluders=_passing_car(scene, t, seconds)), cam, w, h)
        assert phase == meta["phase"][i]
        assert (far_x is None and meta["far_x"][i] is None) or abs(far_x - meta["far_x"][i]) < 1e-5

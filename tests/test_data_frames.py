"""crossing-data frames: real (OpenCV-written) videos, truncated and empty ones."""

import csv
import subprocess
import sys

import cv2
import numpy as np
import pytest

from crossing_assist.data_tools.frames import FramesConfig, VideoError, extract_frames
from crossing_assist.data_tools.images import load_rgb


def _video(path, n=30, fps=10, fourcc="mp4v"):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (32, 24))
    assert writer.isOpened()
    for i in range(n):
        writer.write(np.full((24, 32, 3), 8 * i, np.uint8))   # brightness encodes the frame index
    writer.release()
    return path


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def test_frames_at_the_requested_rate_named_by_time(tmp_path):
    results, listing = extract_frames(FramesConfig((_video(tmp_path / "corner 03.mp4"),), tmp_path / "out",
                                                   fps=2, progress=False))
    (r,) = results
    assert r.error is None and r.name == "corner_03"
    assert [t for _, t in r.frames] == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]
    assert r.frames[1][0] == "corner_03/corner_03_t00000.500.jpg"
    # frame at 0.5 s is the 6th frame of a 10 fps video: brightness 8 * 5
    assert abs(int(load_rgb(tmp_path / "out" / r.frames[1][0]).mean()) - 40) <= 3
    with open(listing, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and rows[0]["source"] == "vid:corner_03" and rows[3]["t_s"] == "1.500"


def test_broken_videos_are_reported_and_do_not_stop_the_others(tmp_path):
    good = _video(tmp_path / "good.mp4")
    trunc = _truncate(_video(tmp_path / "trunc.mp4"))
    partial = _truncate(_video(tmp_path / "partial.avi", fourcc="MJPG"))
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    videos = (trunc, empty, tmp_path / "missing.mp4", partial, good)
    results, listing = extract_frames(FramesConfig(videos, tmp_path / "out", fps=2, progress=False))
    by = {r.video.name: r for r in results}
    assert "cannot open" in by["trunc.mp4"].error and "cannot open" in by["empty.mp4"].error
    assert "no such file" in by["missing.mp4"].error
    assert by["good.mp4"].error is None and len(by["good.mp4"].frames) == 6
    p = by["partial.avi"]
    assert p.error is None and 0 < len(p.frames) < 6 and "truncated" in p.warning
    with open(listing, newline="") as fh:
        assert {r["source"] for r in csv.DictReader(fh)} == {"vid:good", "vid:partial"}


def test_same_stem_in_two_folders_gets_two_names(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    vids = (_video(tmp_path / "a" / "clip.mp4", n=5), _video(tmp_path / "b" / "clip.mp4", n=5))
    results, _ = extract_frames(FramesConfig(vids, tmp_path / "out", fps=2, progress=False))
    assert [r.name for r in results] == ["clip", "clip_2"]


def test_cli_exit_status_and_messages(tmp_path):
    good = _video(tmp_path / "good.mp4")
    bad = _truncate(_video(tmp_path / "bad.mp4"))
    cmd = [sys.executable, "-m", "crossing_assist.data_tools.cli", "frames", str(bad), str(good),
           "--fps", "2", "--out", str(tmp_path / "out"), "--quiet"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 1 and "error: " in proc.stderr and "bad.mp4" in proc.stderr
    assert "6 frames from 1 of 2 videos" in proc.stdout and "Traceback" not in proc.stderr
    proc = subprocess.run(cmd[:4] + [str(good), "--fps", "0", "--out", str(tmp_path / "o2")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "fps=0.0 invalid" in proc.stderr
    with pytest.raises(VideoError):
        extract_frames(FramesConfig((), tmp_path))


def test_clip_to_frames_to_votes_to_dataset(tmp_path):
    """The whole path a user takes: video -> frames at 2 fps -> three people's votes -> dataset."""
    import json

    from crossing_assist.data_tools.labels import VotesConfig, build_voted_dataset
    from crossing_assist.data_tools.manifest import read_manifest
    from crossing_assist.data_tools.synth import ClipConfig, synth_clip

    video, side = synth_clip(ClipConfig(tmp_path / "walk.mp4", seed=2, seconds=6, fps=8, width=64, height=48,
                                        supersample=1, progress=False))
    truth = json.loads(side.read_text())
    results, _ = extract_frames(FramesConfig((video,), tmp_path / "frames", fps=2, progress=False))
    frames = results[0].frames
    assert len(frames) == 12
    lines = []
    for k, (rel, t) in enumerate(frames):
        label = truth["label"][round(t * truth["fps"])]
        lines += [f"{rel},ann,{label}", f"{rel},bob,{label}", f"{rel},cat,{'unknown' if k % 3 == 0 else label}"]
    (tmp_path / "votes.csv").write_text("frame,annotator,label\n" + "\n".join(lines) + "\n")
    summary = build_voted_dataset(VotesConfig(tmp_path / "frames", (tmp_path / "votes.csv",)))
    ds = read_manifest(tmp_path / "frames")
    assert len(ds) == 12 and summary.ties == 0 and 0 < summary.kappa < 1
    expected = [truth["label"][round(t * truth["fps"])] for _, t in frames]
    assert [("unknown" if b == 0 else str(b)) for b in ds.labels()] == expected


def test_label_studio_tasks_round_trip_to_votes(tmp_path):
    """Tasks written by frames, annotated as Label Studio would export them, read back as votes."""
    import json

    from crossing_assist.data_tools.votes import FrameIndex, read_label_studio, tally

    results, listing = extract_frames(FramesConfig((_video(tmp_path / "v.mp4", n=10),), tmp_path / "out",
                                                   fps=2, progress=False))
    tasks = json.loads((tmp_path / "out" / "label_studio_tasks.json").read_text())
    assert len(tasks) == len(results[0].frames) == 2
    for k, task in enumerate(tasks):
        task["id"] = k
        task["annotations"] = [{"completed_by": 1, "result": [
            {"type": "choices", "from_name": "strip", "to_name": "image", "value": {"choices": [str(k + 5)]}}]}]
    (tmp_path / "export.json").write_text(json.dumps(tasks))
    votes = tally(read_label_studio(tmp_path / "export.json", FrameIndex([f for f, _ in results[0].frames])))
    assert [v.counts for v in votes.values()] == [{5: 1}, {6: 1}]


VIDEOS = __import__("pathlib").Path(__file__).parent / "data" / "videos"


def _upright(rgb):
    """The phone test videos' picture: red bar along the top and green bar down the left."""
    h, w = rgb.shape[:2]
    red = (rgb[..., 0] > 180) & (rgb[..., 1] < 90) & (rgb[..., 2] < 90)
    green = (rgb[..., 1] > 180) & (rgb[..., 0] < 90) & (rgb[..., 2] < 90)
    return h > w and red[: h // 16].mean() > 0.3 and green[:, : w // 16].mean() > 0.3


def test_phone_videos_are_extracted_upright_at_their_own_frame_times(tmp_path):
    """A portrait phone video (landscape frames + rotation matrix) comes out upright; a variable
    frame rate video is sampled at its frames' real times (index / average fps put frame 30,
    shown at 1.33 s, at 2.25 s and skipped the real 1.0-1.33 s gap's sampling)."""
    results, _ = extract_frames(FramesConfig((VIDEOS / "rot90_hevc.mov", VIDEOS / "rot90_vfr_h264.mp4"),
                                             tmp_path / "out", fps=2, progress=False))
    hevc, vfr = results
    assert hevc.error is None and vfr.error is None
    for rel, _ in hevc.frames + vfr.frames:
        assert _upright(load_rgb(tmp_path / "out" / rel)), rel
    assert [t for _, t in hevc.frames] == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]
    # 30 fps to 0.967 s, then a frame every 0.2 s from 1.333 s: the first frame at or after each 0.5 s
    assert [t for _, t in vfr.frames] == [0.0, 0.5, 1.333, 1.533, 2.133, 2.533, 3.133]


def test_the_cameras_fov_goes_from_frames_to_the_manifest(tmp_path):
    """``crossing-data frames --fov 40.8`` lists the FOV in frames.csv, and ``votes`` writes it as
    each row's ``fov=40.8`` flag (what crossing-eval plays the frames at); without it, no flag."""
    from crossing_assist.data_tools.images import frame_fov
    from crossing_assist.data_tools.manifest import read_manifest

    video = _video(tmp_path / "walk.mp4", n=20)
    for fov, out in ((["--fov", "40.8"], tmp_path / "narrow"), ([], tmp_path / "plain")):
        r = subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", "frames", str(video), "--out", str(out),
                            "--fps", "2", "--quiet", *fov], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        with open(out / "frames.csv", newline="") as fh:
            frames = list(csv.DictReader(fh))
        (out / "votes.csv").write_text("frame,annotator,label\n" +
                                       "".join(f"{f['image']},ann,6\n" for f in frames))
        r = subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", "votes", str(out),
                            str(out / "votes.csv")], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        rows = read_manifest(out).rows
        assert len(rows) == len(frames) == 4
        assert {frame_fov(r.flags) for r in rows} == ({40.8} if fov else {None})
    r = subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", "frames", str(video), "--out",
                        str(tmp_path / "bad"), "--fov", "400"], capture_output=True, text=True)
    assert r.returncode != 0 and r.stderr.strip().count("\n") == 0 and "--fov" in r.stderr, r.stderr


def test_a_photo_among_the_videos_is_refused_and_the_videos_still_read(tmp_path):
    """A still given as a video was opened by OpenCV as one frame, sideways (its EXIF orientation
    ignored): it is refused naming import-ptl; the video beside it still gives its frames."""
    from crossing_assist.data_tools.images import save_rgb

    photo = tmp_path / "IMG_0001.JPG"
    save_rgb(photo, np.zeros((24, 32, 3), np.uint8))
    results, listing = extract_frames(FramesConfig((photo, _video(tmp_path / "v.mp4")), tmp_path / "out",
                                                   fps=2, progress=False))
    bad, good = results
    assert bad.error and "a photo, not a video" in bad.error and "import-ptl" in bad.error and not bad.frames
    assert good.error is None and len(good.frames) == 6 and listing is not None

"""scripts/judge_walks.py: recorded walks judged on their labelled frames, each with the log beside
it, pooled over every video's frames."""

import csv
import json
import shutil
import sys
from pathlib import Path

import pytest

from crossing_assist.actions import UNKNOWN, parse_label
from crossing_assist.data_tools.frames import FramesConfig, extract_frames
from crossing_assist.data_tools.manifest import Row, write_manifest
from crossing_assist.data_tools.synth import imu_path
from crossing_assist.runtime.demo import DEFAULT_CLIP

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import judge_walks as jw  # noqa: E402


def _walks(tmp_path):
    """Two copies of the sample clip (the first with its motion log beside it, the second without),
    and a third video with no labels; the first two's frames at 2 fps labelled from the clip's
    ground truth, as one dataset."""
    walks = tmp_path / "walks"
    walks.mkdir()
    videos = [walks / name for name in ("a.mp4", "b.mp4", "c.mp4")]
    for v in videos:
        shutil.copy(DEFAULT_CLIP, v)
    shutil.copy(imu_path(DEFAULT_CLIP), walks / "a.imu.csv")
    truth = json.loads(DEFAULT_CLIP.with_suffix(".json").read_text())
    results, _ = extract_frames(FramesConfig(tuple(videos[:2]), tmp_path / "labels", fps=2.0, progress=False))
    rows = []
    for res in results:
        for image, t in res.frames:
            k = int(round(t * truth["fps"]))
            label = parse_label(truth["label"][k])
            rows.append(Row(image, label, truth["far_x"][k] if label != UNKNOWN else None, f"vid:{res.name}", "test"))
    write_manifest(tmp_path / "labels", rows)
    return videos


def test_walks_are_judged_each_with_its_log_and_pooled(tmp_path, capsys):
    videos = _walks(tmp_path)
    assert jw.main([*map(str, videos), "--labels", str(tmp_path / "labels"), "--out", str(tmp_path / "out")]) == 0
    out, err = capsys.readouterr()
    assert "c.mp4: no labelled frame" in err and "(with its log)" in out
    with open(tmp_path / "out" / "walks.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["video"] for r in rows] == ["a.mp4", "b.mp4", "all"] and rows[0]["imu"] == "a.imu.csv" and not rows[1]["imu"]
    a, b, total = rows
    assert int(total["frames_with_crossing"]) == int(a["frames_with_crossing"]) + int(b["frames_with_crossing"]) == 44
    assert int(total["frames_without_crossing"]) == 20
    # the same frames heard: the same rate whether the log was followed or not, pooled alike
    assert float(a["beacon_on"]) == float(b["beacon_on"]) == pytest.approx(float(total["beacon_on"]))
    assert float(total["confidently_wrong"]) == 0 and float(total["silence_no_crossing"]) == 1.0
    assert float(a["heading_error_p90"]) < float(b["heading_error_p90"])   # the log's turns: 1.2 against 2.1 deg
    assert (tmp_path / "out" / "a" / "trace.jsonl").is_file()


def test_no_video_with_labels_is_one_line_and_exit_2(tmp_path, capsys):
    videos = _walks(tmp_path)
    assert jw.main([str(videos[2]), "--labels", str(tmp_path / "labels"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error: none of the 1 videos has a labelled frame")
    assert not (tmp_path / "out" / "walks.csv").exists()

"""Votes from CSV and Label Studio, majority with the tie rule, agreement, leakage-free splits."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.data_tools.labels import VotesConfig, build_voted_dataset
from crossing_assist.data_tools.manifest import Row, read_manifest
from crossing_assist.data_tools.splits import SplitConfig, SplitError, assign_splits, shared_sources
from crossing_assist.data_tools.votes import (
    LABEL_STUDIO_CONFIG, FrameIndex, VotesError, fleiss_kappa, majority, read_label_studio, tally,
)

FRAMES = ["v1/v1_t00000.000.jpg", "v1/v1_t00000.500.jpg", "v2/v2_t00000.000.jpg", "v2/v2_t00000.500.jpg"]


def _votes_csv(path, lines):
    path.write_text("frame,annotator,label\n" + "\n".join(lines) + "\n")
    return path


def test_majority_and_tie_rule():
    assert majority({7: 3, 6: 1}).label == 7 and majority({7: 3, 6: 1}).agreement == 0.75
    tie = majority({6: 2, 7: 2, 0: 1})
    assert tie.tie and tie.label == 0
    assert majority({0: 2, 5: 1}).label == 0 and not majority({0: 2, 5: 1}).tie


def test_fleiss_kappa_textbook_example():
    # Fleiss (1971) as tabulated on Wikipedia: 10 items, 14 raters, 5 categories, kappa 0.210
    table = np.array([[0, 0, 0, 0, 14], [0, 2, 6, 4, 2], [0, 0, 3, 5, 6], [0, 3, 9, 2, 0], [2, 2, 8, 1, 1],
                      [7, 7, 0, 0, 0], [3, 2, 6, 3, 0], [2, 5, 3, 2, 2], [6, 5, 2, 1, 0], [0, 2, 2, 3, 7]])
    assert fleiss_kappa(table) == pytest.approx(0.2099, abs=5e-4)
    assert fleiss_kappa(np.array([[3, 0], [0, 3]])) == pytest.approx(1.0)
    assert np.isnan(fleiss_kappa(np.array([[3, 0], [3, 0]])))        # one category only
    assert np.isnan(fleiss_kappa(np.array([[1, 0]])))                # nobody rated twice


def test_csv_votes_build_a_dataset_with_ties_and_agreement(tmp_path, make_frames_dir):
    d = make_frames_dir(FRAMES)
    votes = _votes_csv(tmp_path / "votes.csv", [
        "v1/v1_t00000.000.jpg,ann,7", "v1_t00000.000.jpg,bob,7", "v1/v1_t00000.000.jpg,cat,6",
        "v1_t00000.500.jpg,ann,5", "v1_t00000.500.jpg,bob,6",             # a tie
        "v2_t00000.000.jpg,ann,unknown", "v2_t00000.000.jpg,bob,unknown",
    ])
    s = build_voted_dataset(VotesConfig(d, (votes,)))
    ds = read_manifest(d)
    assert [(r.image, r.label, r.flags) for r in ds.rows] == [
        (FRAMES[0], 7, ()), (FRAMES[1], 0, ("tie",)), (FRAMES[2], 0, ())]
    assert ds.rows[0].votes == {7: 2, 6: 1} and ds.rows[0].source == "vid:v1"
    assert s.ties == 1 and s.frames_voted == 3 and s.frames_listed == 4 and s.votes == 7
    assert s.mean_agreement == pytest.approx((2 / 3 + 0.5 + 1) / 3)
    assert "v1/v1_t00000.500.jpg,2,unknown,0.500,1" in (d / "agreement.csv").read_text()
    build_voted_dataset(VotesConfig(d, (votes,), tie="drop"))
    assert [r.image for r in read_manifest(d).rows] == [FRAMES[0], FRAMES[2]]


@pytest.mark.parametrize("line, message", [
    ("v1_t00000.000.jpg,ann,13", "line 3: label '13' invalid"),
    ("v1_t00000.000.jpg,ann,6", "line 3: annotator 'ann' already voted"),
    ("nothere.jpg,bob,6", "line 3: frame 'nothere.jpg' is not in frames.csv"),
])
def test_bad_votes_name_the_line(tmp_path, line, message, make_frames_dir):
    d = make_frames_dir(FRAMES)
    votes = _votes_csv(tmp_path / "votes.csv", ["v1_t00000.000.jpg,ann,7", line])
    with pytest.raises(VotesError, match=message):
        build_voted_dataset(VotesConfig(d, (votes,)))
    proc = subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", "votes", str(d), str(votes)],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr


def _ls_task(tid, url, *anns):
    return {"id": tid, "data": {"image": url}, "annotations": [
        {"id": 10 * tid + k, "completed_by": who, "was_cancelled": cancelled,
         "result": [{"from_name": "strip", "to_name": "image", "type": "choices", "value": {"choices": [choice]}}]}
        for k, (who, choice, cancelled) in enumerate(anns)]}


def test_label_studio_export(tmp_path, make_frames_dir):
    make_frames_dir(FRAMES)
    export = [
        _ls_task(1, "/data/local-files/?d=frames/v1/v1_t00000.000.jpg", (1, "7", False), ({"id": 2, "email": "b@x"}, "8", False),
                 (3, "7", False)),
        _ls_task(2, "/data/upload/4/8f3a2b1c-v2_t00000.500.jpg", (1, "unknown", False), (2, "3", True)),
    ]
    path = tmp_path / "export.json"
    path.write_text(json.dumps(export))
    votes = read_label_studio(path, FrameIndex(FRAMES))
    frames = tally(votes)
    assert frames[FRAMES[0]].counts == {7: 2, 8: 1}
    assert frames[FRAMES[3]].counts == {0: 1}                     # the cancelled one is skipped
    assert "ls:b@x" in frames[FRAMES[0]].annotators
    export[0]["annotations"][0]["result"][0]["value"]["choices"] = ["13"]
    path.write_text(json.dumps(export))
    with pytest.raises(VotesError, match=r"task 0 \(id 1\): choice '13' invalid"):
        read_label_studio(path, FrameIndex(FRAMES))
    path.write_text("{not json")
    with pytest.raises(VotesError, match="not valid JSON"):
        read_label_studio(path, FrameIndex(FRAMES))


def test_shipped_label_studio_config_has_12_strips_and_unknown():
    import xml.etree.ElementTree as ET
    shipped = Path(__file__).resolve().parents[1] / "crossing_assist" / "data_tools" / "label_studio_config.xml"
    assert shipped.read_text() == LABEL_STUDIO_CONFIG
    choices = [c.get("value") for c in ET.fromstring(LABEL_STUDIO_CONFIG).iter("Choice")]
    assert choices == [str(b) for b in range(1, 13)] + ["unknown"]


def test_splits_keep_sources_whole_and_hit_the_fractions():
    rows = [Row(f"{s}_{i}.jpg", 1, None, f"vid:{s}", "train") for s in range(20) for i in range(10)]
    out = assign_splits(rows, SplitConfig(val=0.2, test=0.1, seed=3))
    assert shared_sources(out) == {}
    counts = {k: sum(r.split == k for r in out) for k in ("train", "val", "test")}
    assert counts == {"train": 140, "val": 40, "test": 20}
    assert assign_splits(rows, SplitConfig(0.2, 0.1, 3)) == out            # deterministic
    assert assign_splits(rows, SplitConfig(0.2, 0.1, 4)) != out
    with pytest.raises(SplitError, match="cannot fill"):
        assign_splits(rows[:10], SplitConfig(val=0.2))
    leaky = [Row("a.jpg", 1, None, "vid:a", "train"), Row("b.jpg", 1, None, "vid:a", "val")]
    assert shared_sources(leaky) == {"vid:a": ("train", "val")}

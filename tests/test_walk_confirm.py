"""scripts/walk_confirm.py: a synthetic walk played live from its walk phase, the gyroscope confirmed
by the walker's sway and never when its log is reversed; bad input in one line."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

from crossing_assist.runtime.demo import DEFAULT_CLIP

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "walk_confirm.py"


def _run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=600)


def test_the_sample_clip_s_walk_is_followed_once_its_sway_confirms_it_and_never_reversed():
    r = _run(DEFAULT_CLIP, "--rules", "sway,reversed", "--extra", "0")
    assert r.returncode == 0, r.stderr
    sway, rev = (line for line in r.stdout.splitlines() if line.startswith("sample_clip.mp4"))
    assert " sway " in sway and "gyroscope followed from -" not in sway and ">= 2 strips off 0" in sway, sway
    assert " reversed " in rev and rev.endswith("gyroscope followed from -"), rev


def test_bad_input_is_one_line(tmp_path):
    r = _run("--rules", "sway,fast")
    assert r.returncode == 2 and r.stderr.strip() == "error: unknown rule(s) fast; valid: none, clear, sway, follow, reversed"
    r = _run(tmp_path / "missing.mp4")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "does not exist" in r.stderr
    # a video with a truth and a log but no walk phase (not a synthetic clip's)
    clip = tmp_path / "clip.mp4"
    shutil.copy(DEFAULT_CLIP, clip)
    shutil.copy(DEFAULT_CLIP.with_suffix(".imu.csv"), clip.with_suffix(".imu.csv"))
    truth = json.loads(DEFAULT_CLIP.with_suffix(".json").read_text())
    truth["phase"] = ["away"] * len(truth["phase"])
    clip.with_suffix(".json").write_text(json.dumps(truth))
    r = _run(clip, "--rules", "sway")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "walk phase" in r.stderr, r.stderr


"""scripts/fov_flag_check.py: the same narrow-camera windows, with and without their fov= flag."""

import sys
from pathlib import Path

from runtime_toy import bar_dataset

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import fov_flag_check as ffc  # noqa: E402

from crossing_assist.data_tools.images import frame_fov, load_frame  # noqa: E402
from crossing_assist.data_tools.manifest import read_manifest  # noqa: E402


def test_two_manifests_over_the_same_3x4_windows_one_flagged(tmp_path, capsys):
    data = bar_dataset(tmp_path / "data", n=6)
    assert ffc.main(["--data", str(data), "--photos", "4", "--out", str(tmp_path / "out")]) == 0
    plain, flag = read_manifest(tmp_path / "out" / "plain"), read_manifest(tmp_path / "out" / "flag")
    assert [r.image for r in plain.rows] == [r.image for r in flag.rows] and len(plain.rows) == 4
    assert {frame_fov(r.flags) for r in plain.rows} == {None} and {frame_fov(r.flags) for r in flag.rows} == {40.8}
    img = load_frame(flag.image_path(flag.rows[0]))
    assert abs(img.shape[1] / img.shape[0] - 3 / 4) < 0.05
    assert [r.label for r in plain.rows] == [r.label for r in flag.rows]
    assert ffc.main(["--data", str(tmp_path / "none")]) == 1 and capsys.readouterr().err.count("\n") == 1

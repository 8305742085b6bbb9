"""scripts/pitch_tolerance.py: the share of far kerbs a bundle's view crop keeps as the phone pitches."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from runtime_toy import make_toy_bundle

from crossing_assist.geometry import Geometry

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import pitch_tolerance as pt  # noqa: E402

SCRIPT = Path(pt.__file__)


def test_far_points_sit_at_their_angle_and_leave_a_band_as_the_phone_pitches():
    ang = pt.far_angles(np.array([0.0, 0.5, 1.0]), 67.0)
    top = math.degrees(math.atan(math.tan(math.radians(33.5)) * 0.75))   # a 4:3 photo's top edge
    assert ang == pytest.approx([top, 0.0, -top])
    # a band of ±20 deg: level, all three of ±26.4 deg fall outside but the centre; pitched 25 deg
    # down the top point is at 51 deg, the centre at 25 (out), the bottom at -1.4 (in)
    assert pt.in_view(ang, 20.0, [0, 25, -25]) == pytest.approx([1 / 3, 1 / 3, 1 / 3])
    assert pt.in_view(ang, 30.0, [0, 10]) == pytest.approx([1.0, 2 / 3])


def test_a_magnified_view_keeps_a_narrower_band_of_a_portrait_frame(tmp_path):
    g = Geometry(fit="letterbox", view_crop=True)
    at_scale = pt.band_half_angle(g, (168, 224), (480, 640), 53.0)
    zoomed = pt.band_half_angle(Geometry(fit="letterbox", view_crop=True, view_zoom=1.3), (168, 224), (480, 640), 53.0)
    # at the training scale the band is the training photo's own height: ±atan(0.75 tan 33.5)
    assert at_scale == pytest.approx(math.degrees(math.atan(0.75 * math.tan(math.radians(33.5)))), abs=0.2)
    assert zoomed < at_scale - 4
    whole = pt.band_half_angle(Geometry(fit="letterbox"), (168, 224), (480, 640), 53.0)   # no crop: every row
    assert whole == pytest.approx(math.degrees(math.atan(320 / (240 / math.tan(math.radians(26.5))))))


def test_cli_compares_view_zooms_and_fails_in_one_line(tmp_path):
    bundle = make_toy_bundle(tmp_path / "b", geometry=Geometry(fit="letterbox", view_crop=True))
    labels = tmp_path / "labels.csv"
    labels.write_text("image,far_y\na.jpg,0.3\nb.jpg,0.45\nc.jpg,\n")   # 11.2 and 2.8 deg above the axis
    r = subprocess.run([sys.executable, str(SCRIPT), str(bundle), "--labels", str(labels), "--view-zoom", "1", "1.3",
                        "--pitch", "0,5"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("2 far kerbs") and lines[2].startswith("view_zoom 1 ") and lines[3].startswith("view_zoom 1.3")
    # the toy's 2:1 canvas keeps ±18.3 deg of a 53 deg portrait frame at the training scale, ±14.3 magnified
    # 1.3x: pitched 5 deg down, the far kerb at 0.3 (then 16.2 deg up) stays in one and leaves the other
    assert lines[2].split()[-2:] == ["100.0%", "100.0%"] and lines[3].split()[-2:] == ["100.0%", "50.0%"]
    r = subprocess.run([sys.executable, str(SCRIPT), str(bundle), "--labels", str(tmp_path / "nope.csv")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.startswith("error:") and r.stderr.count("\n") == 1
    for bad in ([str(tmp_path), "--labels", str(labels)],                    # not a bundle
                [str(bundle), "--labels", str(labels), "--fov", "200"],      # a FOV no camera has
                [str(bundle), "--labels", str(SCRIPT)]):                     # no far_y column
        r = subprocess.run([sys.executable, str(SCRIPT), *bad], capture_output=True, text=True)
        assert r.returncode == 2 and r.stderr.startswith("error:") and "Traceback" not in r.stderr, bad

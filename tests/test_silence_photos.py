"""scripts/silence_photos.py: real no-crossing photos played through the runtime, both ways."""

import sys
from pathlib import Path

import pytest
from runtime_toy import bar_frame, toy_bundle  # noqa: F401  (fixture)

from crossing_assist.actions import bin_center_x
from crossing_assist.data_tools.images import save_rgb

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import silence_photos as sp  # noqa: E402


def test_reports_the_play_that_speaks_and_the_ones_that_stay_silent(tmp_path, toy_bundle, capsys):  # noqa: F811
    """The toy speaks on a vertical bright bar (strip 4) and not on the same bar turned 90 degrees
    (a horizontal bar lights every strip) nor on a flat frame: 3 of 4 plays silent."""
    save_rgb(tmp_path / "photos" / "bar.png", bar_frame(bin_center_x(4)))
    save_rgb(tmp_path / "photos" / "sub" / "flat.jpg", bar_frame(None))
    assert sp.main([str(tmp_path / "photos"), "--bundle", str(toy_bundle)]) == 0
    out = capsys.readouterr().out
    assert "| bar.png (as taken, landscape) | ON, strip 4 |" in out
    assert "| bar.png (turned, portrait) | off |" in out and "| flat.jpg (as taken, landscape) | off |" in out
    assert "silent on 75.0% of 4 plays (2 images, each both ways); beacon on for 1" in out


def test_bad_folders_and_bundles_are_one_line(tmp_path, toy_bundle):  # noqa: F811
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("no photos")
    save_rgb(tmp_path / "photos" / "bar.png", bar_frame(bin_center_x(4)))
    for args, match in (([str(tmp_path / "empty")], "error: no .png/.jpg image under"),
                        ([str(tmp_path / "nowhere")], "is not a folder"),
                        ([str(tmp_path / "photos"), "--bundle", str(tmp_path / "empty")], "^error: ")):
        with pytest.raises(SystemExit, match=match):
            sp.main([*args, *([] if "--bundle" in args else ["--bundle", str(toy_bundle)])])


def test_fov_plays_the_photos_as_a_narrow_camera_sees_them(tmp_path, capsys):
    """``--fov 41``: a portrait photo takes the bundle's narrow camera threshold (here the only
    one loose enough to speak on a bright bar) where at the bundle's own FOV it takes the
    portrait one and stays silent."""
    from runtime_toy import make_toy_bundle

    bundle = make_toy_bundle(tmp_path / "b", portrait_threshold=1e-6, narrow_threshold=1.0, narrow_fov_deg=42.0)
    save_rgb(tmp_path / "photos" / "tall.png", bar_frame(bin_center_x(4), h=128, w=96))
    assert sp.main([str(tmp_path / "photos"), "--bundle", str(bundle)]) == 0
    assert "| tall.png (as taken, portrait) | off |" in capsys.readouterr().out
    assert sp.main([str(tmp_path / "photos"), "--bundle", str(bundle), "--fov", "41"]) == 0
    assert "| tall.png (as taken, portrait) | ON, strip 4 |" in capsys.readouterr().out


def test_a_photo_is_played_at_the_fov_its_exif_gives(tmp_path, capsys):
    """A portrait photo from a 2.5x lens (65 mm: 22 deg across, EXIF) takes the narrow camera's
    threshold and speaks, as with ``--fov``; the same pixels without the EXIF take the portrait
    one and stay silent."""
    Image = pytest.importorskip("PIL.Image")
    from runtime_toy import make_toy_bundle

    bundle = make_toy_bundle(tmp_path / "b", portrait_threshold=1e-6, narrow_threshold=1.0, narrow_fov_deg=42.0)
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA405] = 65
    (tmp_path / "tele").mkdir()
    (tmp_path / "plain").mkdir()
    pixels = Image.fromarray(bar_frame(bin_center_x(4), h=128, w=96))
    pixels.save(tmp_path / "tele" / "tall.jpg", quality=95, exif=exif.tobytes())
    pixels.save(tmp_path / "plain" / "tall.jpg", quality=95)
    assert sp.main([str(tmp_path / "tele"), "--bundle", str(bundle)]) == 0
    assert "| tall.jpg (as taken, portrait) | ON, strip 4 |" in capsys.readouterr().out
    assert sp.main([str(tmp_path / "plain"), "--bundle", str(bundle)]) == 0
    assert "| tall.jpg (as taken, portrait) | off |" in capsys.readouterr().out

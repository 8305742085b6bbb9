"""A photo's camera FOV from its EXIF 35 mm-equivalent focal length, and import-ptl's fov flags."""

import math

import numpy as np
import pytest

from crossing_assist.data_tools.exif import equivalent_fov, exif_tags, photo_fov
from crossing_assist.data_tools.images import flag_value, frame_fov, inspect_image_file, load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.data_tools.ptl import PTLImportConfig, import_ptl

Image = pytest.importorskip("PIL.Image")   # writes the EXIF the tests read (the reader needs no Pillow)


def _photo(path, hw, focal=None, orientation=None, big_endian=False, recorded=None):
    """A JPEG of stored size ``hw`` with the EXIF given (Pillow writes it little- or big-endian);
    ``recorded``: the (width, height) the camera wrote as its image's size."""
    exif = Image.Exif()
    if orientation is not None:
        exif[0x0112] = orientation
    if focal is not None:
        exif.get_ifd(0x8769)[0xA405] = focal
    if recorded is not None:
        exif.get_ifd(0x8769).update({0xA002: recorded[0], 0xA003: recorded[1]})
    img = Image.fromarray(np.full((*hw, 3), 90, np.uint8))
    raw = exif.tobytes()
    if big_endian:   # the same tags, Motorola order (Canon, some Samsungs)
        raw = _swap_to_big_endian(exif)
    img.save(path, exif=raw)
    return path


def _swap_to_big_endian(exif):
    import struct
    ifd0 = [(t, v) for t, v in exif.items() if t != 0x8769]
    focal = exif.get_ifd(0x8769).get(0xA405)
    n0 = len(ifd0) + (focal is not None)
    body = struct.pack(">2sHI", b"MM", 42, 8) + struct.pack(">H", n0)
    sub_at = 8 + 2 + 12 * n0 + 4
    for t, v in ifd0:
        body += struct.pack(">HHIH2x", t, 3, 1, v)
    if focal is not None:
        body += struct.pack(">HHII", 0x8769, 4, 1, sub_at)
    body += struct.pack(">I", 0)
    if focal is not None:
        body += struct.pack(">H", 1) + struct.pack(">HHIH2x", 0xA405, 3, 1, focal) + struct.pack(">I", 0)
    return b"Exif\0\0" + body


def test_equivalent_fov_matches_the_bundles_defaults_at_a_phones_26mm():
    assert equivalent_fov(26, 4 / 3) == pytest.approx(67.3, abs=0.1)    # the default landscape 67 deg
    assert equivalent_fov(26, 3 / 4) == pytest.approx(53.1, abs=0.1)    # the default portrait 53 deg
    assert equivalent_fov(52, 4 / 3) < 37 and equivalent_fov(13, 4 / 3) > 105   # 2x tele, ultra-wide
    # the diagonal is matched: a 3:2 frame at f sees the full frame's 36 mm across
    assert equivalent_fov(50, 1.5) == pytest.approx(math.degrees(2 * math.atan(18 / 50)))
    with pytest.raises(ValueError):
        equivalent_fov(0, 4 / 3)


@pytest.mark.parametrize("big_endian", [False, True])
def test_photo_fov_reads_the_focal_length_and_turns_with_the_orientation(tmp_path, big_endian):
    land = _photo(tmp_path / "l.jpg", (300, 400), focal=26, big_endian=big_endian)
    assert photo_fov(land, inspect_image_file(land)[1]) == pytest.approx(67.3, abs=0.1)
    # stored landscape, displayed portrait (orientation 6, as phones save a portrait photo)
    turned = _photo(tmp_path / "p.jpg", (300, 400), focal=26, orientation=6, big_endian=big_endian)
    assert load_frame(turned).shape[:2] == (400, 300)
    assert photo_fov(turned, inspect_image_file(turned)[1]) == pytest.approx(53.1, abs=0.1)
    tele = _photo(tmp_path / "t.jpg", (300, 400), focal=77, big_endian=big_endian)
    assert photo_fov(tele, (300, 400)) == pytest.approx(equivalent_fov(77, 4 / 3))
    # an aspect the pixels do not say (a squashed copy's flag) wins
    assert photo_fov(land, (224, 224), 4 / 3) == pytest.approx(67.3, abs=0.1)


def test_photos_without_a_usable_focal_length_give_none(tmp_path):
    assert photo_fov(_photo(tmp_path / "none.jpg", (30, 40)), (30, 40)) is None               # no EXIF
    assert photo_fov(_photo(tmp_path / "o.jpg", (30, 40), orientation=6), (30, 40)) is None   # EXIF, no focal
    assert photo_fov(_photo(tmp_path / "z.jpg", (30, 40), focal=0), (30, 40)) is None         # "unknown"
    assert photo_fov(_photo(tmp_path / "w.jpg", (30, 40), focal=1), (30, 40)) is None         # 173 deg: over 170
    png = tmp_path / "x.png"
    Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(png)
    assert photo_fov(png, (30, 40)) is None
    assert photo_fov(tmp_path / "missing.jpg", (30, 40)) is None
    # malformed EXIF blocks: nothing read, nothing raised
    good = _photo(tmp_path / "g.jpg", (30, 40), focal=26).read_bytes()
    at = good.index(b"Exif\0\0") + 6
    for cut in (b"", b"II", b"XX*\0\x08\0\0\0", good[at:at + 12], good[at:at + 30]):
        assert exif_tags(cut) == {}
    bad_offset = bytearray(good[at:at + 60])
    bad_offset[4:8] = (10_000).to_bytes(4, "little")   # IFD0 beyond the block
    assert exif_tags(bytes(bad_offset)) == {}


def test_import_ptl_flags_each_photo_with_its_cameras_fov_and_evaluation_reads_it(tmp_path):
    root = tmp_path / "mine"
    root.mkdir()
    _photo(root / "main.jpg", (300, 400), focal=26)
    _photo(root / "tele.jpg", (300, 400), focal=52)
    _photo(root / "portrait.jpg", (300, 400), focal=26, orientation=6)
    _photo(root / "plain.jpg", (300, 400))
    (root / "labels.csv").write_text("image,split,photographer,far_x,bin12\n" + "".join(
        f"{n}.jpg,test,ann,0.5,7\n" for n in ("main", "tele", "portrait", "plain")))
    import_ptl(PTLImportConfig(root, tmp_path / "ds", progress=False))
    ds = read_manifest(tmp_path / "ds")
    fovs = {r.image: frame_fov(r.flags) for r in ds.rows}
    assert fovs == {"images/main.jpg": pytest.approx(67.3, abs=0.05), "images/tele.jpg": pytest.approx(36.8, abs=0.05),
                    "images/portrait.jpg": pytest.approx(53.1, abs=0.05), "images/plain.jpg": None}
    import_ptl(PTLImportConfig(root, tmp_path / "ds2", progress=False, exif_fov=False))
    assert all(flag_value(r.flags, "fov") is None for r in read_manifest(tmp_path / "ds2").rows)


def test_the_import_ptl_command_says_how_many_photos_gave_their_fov(tmp_path, capsys):
    from crossing_assist.data_tools.cli import main

    root = tmp_path / "mine"
    root.mkdir()
    _photo(root / "a.jpg", (300, 400), focal=52)
    _photo(root / "b.jpg", (300, 400))
    (root / "labels.csv").write_text("image,split,photographer,far_x,bin12\na.jpg,test,ann,0.5,7\nb.jpg,test,ann,0.5,7\n")
    assert main(["import-ptl", str(root), "--out", str(tmp_path / "ds"), "--quiet"]) == 0
    assert "1 with their camera's FOV from EXIF" in capsys.readouterr().out
    assert main(["import-ptl", str(root), "--out", str(tmp_path / "ds2"), "--quiet", "--no-exif-fov"]) == 0
    assert "FOV" not in capsys.readouterr().out
    assert [flag_value(r.flags, "fov") for r in read_manifest(tmp_path / "ds").rows] == ["36.8", None]
    assert [flag_value(r.flags, "fov") for r in read_manifest(tmp_path / "ds2").rows] == [None, None]


def test_a_photo_cropped_after_capture_is_read_as_a_crop_of_the_recorded_image(tmp_path):
    """The focal length describes the image the camera recorded (its size in the EXIF): a square or
    16:9 cut of a 26 mm 4:3 photo is its largest centred crop (53.1 / 67.3 deg, as the bundles'
    default takes a frame narrower than the sensor), not a 26 mm photo of that aspect (60.9 / 71.9)."""
    def fov(hw, recorded, **kw):
        return photo_fov(_photo(tmp_path / f"{hw}{recorded}{kw}.jpg", hw, focal=26, recorded=recorded, **kw), hw)

    assert fov((300, 300), (4032, 3024)) == pytest.approx(53.1, abs=0.1)     # a square, full height
    assert fov((300, 300), None) == pytest.approx(60.9, abs=0.1)             # no recorded size: its own diagonal
    assert fov((225, 400), (4032, 3024)) == pytest.approx(67.3, abs=0.1)     # 16:9, full width
    assert fov((225, 400), None) == pytest.approx(71.9, abs=0.1)
    assert fov((300, 400), (4032, 3024)) == pytest.approx(67.3, abs=0.1)     # a smaller copy: the whole photo
    assert fov((300, 400), (4032, 3024), orientation=6) == pytest.approx(53.1, abs=0.1)   # turned upright
    assert fov((400, 300), (4032, 3024)) == pytest.approx(53.1, abs=0.1)     # stored portrait, either way up
    assert fov((400, 225), (3024, 4032)) == pytest.approx(41.1, abs=0.1)     # a 9:16 cut of a portrait photo
    # the recorded size is read from the EXIF block
    raw = Image.open(_photo(tmp_path / "r.jpg", (30, 40), focal=26, recorded=(4032, 3024))).info["exif"]
    assert exif_tags(raw[6:]) == {0xA405: 26, 0xA002: 4032, 0xA003: 3024}


def test_heic_photos_give_their_fov_upright(tmp_path):
    """pillow-heif stores an EXIF turn as the container's rotation, which decoding applies: the FOV
    is read at the photo's upright aspect, not turned a second time."""
    pillow_heif = pytest.importorskip("pillow_heif")
    pillow_heif.register_heif_opener()
    exif = Image.Exif()
    exif[0x0112] = 6
    exif.get_ifd(0x8769)[0xA405] = 26
    path = tmp_path / "p.heic"
    Image.fromarray(np.full((300, 400, 3), 90, np.uint8)).save(path, quality=90, exif=exif.tobytes())
    size = inspect_image_file(path)[1]
    assert size == load_frame(path).shape[:2] == (400, 300)
    assert photo_fov(path, size) == pytest.approx(53.1, abs=0.1)

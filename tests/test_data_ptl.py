"""import-ptl and stats on a tiny PTL-layout folder, a broken one, and the shared PTL data."""

import shutil
import subprocess
import sys

import numpy as np
import pytest

from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import ManifestError, read_manifest
from crossing_assist.data_tools.ptl import PTLError, PTLImportConfig, import_ptl
from crossing_assist.data_tools.stats import compute_stats, format_stats

HEADER = "image,split,photographer,far_x,far_y,near_x,near_y,bin12,light,blocked"
LINES = [
    "images/a.jpg,train,john,0.45685,0.39,0.0,0.7,6,1,0",
    "images/b.jpg,train,sam,0.58333,0.5,1.0,1.0,8,0,1",      # boundary: file's bin wins
    "images/c.jpg,train,sam,0.52,0.4,0.5,1.0,7,3,0",
    "images/d.jpg,val,heon,0.10,0.4,0.5,1.0,2,4,0",
]


def _ptl(root, lines=LINES, images=("a", "b", "c", "d")):
    (root / "images").mkdir(parents=True)
    for name in images:
        save_rgb(root / "images" / f"{name}.jpg", np.full((8, 8, 3), 90, np.uint8))
    (root / "labels.csv").write_text("\n".join([HEADER, *lines]) + "\n")
    return root


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", *map(str, args)],
                          capture_output=True, text=True)


def test_import_copies_keeps_split_labels_and_moves_safely(tmp_path):
    ptl = _ptl(tmp_path / "ptl")
    import_ptl(PTLImportConfig(ptl, tmp_path / "ds", progress=False))
    ds = read_manifest(tmp_path / "ds")
    assert [r.label for r in ds.rows] == [6, 8, 7, 2]
    assert [r.split for r in ds.rows] == ["train", "train", "train", "val"]
    assert [r.source for r in ds.rows] == ["ptl:john", "ptl:sam", "ptl:sam", "ptl:heon"]
    assert ds.rows[1].flags[0] == "aspect=4:3" and ds.rows[1].flags[-2:] == ("blocked", "light=red")
    assert ds.rows[0].far_x == 0.45685
    shutil.move(tmp_path / "ds", tmp_path / "moved")
    shutil.rmtree(ptl)
    assert len(read_manifest(tmp_path / "moved")) == 4   # self-contained


def test_reference_mode_fails_clearly_when_moved(tmp_path):
    ptl = _ptl(tmp_path / "ptl")
    import_ptl(PTLImportConfig(ptl, tmp_path / "ds", images="reference", progress=False))
    assert read_manifest(tmp_path / "ds").rows[0].image == "../ptl/images/a.jpg"
    assert not (tmp_path / "ds" / "images").exists()
    shutil.move(tmp_path / "ds", tmp_path / "sub_ds")
    (tmp_path / "deeper").mkdir()
    shutil.move(tmp_path / "sub_ds", tmp_path / "deeper" / "ds")
    with pytest.raises(ManifestError, match=r"line 2: image '../ptl/images/a.jpg' not found"):
        read_manifest(tmp_path / "deeper" / "ds")


@pytest.mark.parametrize("bad, message", [
    ("images/d.jpg,val,heon,0.10,0.4,0.5,1.0,13,4,0", "line 5: bin12 '13' invalid"),
    ("images/d.jpg,val,heon,0.10,0.4,0.5,1.0,9,4,0", "line 5: label 9 disagrees with far_x 0.1"),
    ("images/a.jpg,val,heon,0.45,0.4,0.5,1.0,6,4,0", "line 5: duplicate image 'images/a.jpg'"),
    ("images/e.jpg,val,heon,0.10,0.4,0.5,1.0,2,4,0", "line 5: image 'images/e.jpg' not found"),
    ("images/d.jpg,holdout,heon,0.10,0.4,0.5,1.0,2,4,0", "line 5: split 'holdout' invalid"),
])
def test_broken_ptl_folders_name_the_line_and_write_nothing(tmp_path, bad, message):
    ptl = _ptl(tmp_path / "ptl", LINES[:3] + [bad])
    with pytest.raises(PTLError, match=message):
        import_ptl(PTLImportConfig(ptl, tmp_path / "ds", progress=False))
    assert not (tmp_path / "ds" / "manifest.csv").exists()
    proc = _cli("import-ptl", ptl, "--out", tmp_path / "ds", "--quiet")
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and "Traceback" not in proc.stderr
    assert message in proc.stderr


def test_stats_counts_baseline_and_leakage(tmp_path):
    ptl = _ptl(tmp_path / "ptl")
    import_ptl(PTLImportConfig(ptl, tmp_path / "ds", progress=False))
    st = compute_stats(read_manifest(tmp_path / "ds"))
    assert st.bins["train"].tolist() == [0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0]
    assert st.actions[4]["train"].tolist() == [0, 0, 3, 0] and st.actions[4]["val"].tolist() == [0, 1, 0, 0]
    assert st.baseline[4] == ("straight", 0.0, "val")     # val's only frame is 'left'
    assert st.shared_sources == ()
    assert "no leakage" in format_stats(st)
    proc = _cli("stats", tmp_path / "ds", "--plot", tmp_path / "h.png")
    assert proc.returncode == 0, proc.stderr
    assert "majority-class baseline" in proc.stdout and (tmp_path / "h.png").stat().st_size > 1000


def test_stats_cli_on_a_missing_dataset(tmp_path):
    proc = _cli("stats", tmp_path / "nothing")
    assert proc.returncode == 2 and "error:" in proc.stderr and "no manifest" in proc.stderr


def test_shared_ptl_imports_with_its_split_and_bins(ptl_dir, tmp_path):
    import csv
    import_ptl(PTLImportConfig(ptl_dir, tmp_path / "ds", images="reference", progress=False))
    ds = read_manifest(tmp_path / "ds")
    assert len(ds.split("train")) == 3456 and len(ds.split("val")) == 864
    with open(ptl_dir / "labels.csv", newline="") as fh:
        expected = [int(r["bin12"]) for r in csv.DictReader(fh)]
    assert ds.labels().tolist() == expected
    st = compute_stats(ds)
    assert st.bins["all"][0] == 0 and set(st.shared_sources) == {r.source for r in ds.rows}
    assert 0.5 < st.baseline[4][1] < 1.0


def test_minimal_ptl_layout_with_images_elsewhere(tmp_path):
    """Only the required columns, images outside an images/ folder: still imports."""
    root = tmp_path / "other"
    save_rgb(root / "pics" / "x.jpg", np.zeros((6, 8, 3), np.uint8))
    save_rgb(root / "y.jpg", np.zeros((6, 8, 3), np.uint8))
    (root / "labels.csv").write_text("photographer,image,bin12,far_x,split\n"
                                     "ann,pics/x.jpg,12,0.99,train\n,y.jpg,1,0.0,test\n")
    import_ptl(PTLImportConfig(root, tmp_path / "ds", progress=False))
    ds = read_manifest(tmp_path / "ds")
    assert [r.image for r in ds.rows] == ["images/pics/x.jpg", "images/y.jpg"]
    assert [r.source for r in ds.rows] == ["ptl:ann", "ptl:unnamed"] and ds.rows[1].split == "test"
    assert all(r.flags == () for r in ds.rows)   # 8x6 photos as taken: no squash to undo; no far_y column
    (root / "labels.csv").write_text("image,split,far_x\nx.jpg,train,0.5\n")
    with pytest.raises(PTLError, match="line 1: header lacks column.*photographer, bin12"):
        import_ptl(PTLImportConfig(root, tmp_path / "ds2", progress=False))


def test_photos_as_taken_keep_their_aspect_and_only_square_copies_are_unsquashed(tmp_path):
    """A researcher's own photos in the PTL layout: a portrait phone photo stays portrait (it was
    stretched to 4:3 landscape when every row got PTL's squash flag), a landscape one stays as it
    is, and a square 224x224 copy (PTL's squash) is read back at 4:3."""
    from crossing_assist.data_tools.images import load_frame

    root = tmp_path / "mine"
    save_rgb(root / "portrait.jpg", np.full((400, 300, 3), 90, np.uint8))
    save_rgb(root / "landscape.jpg", np.full((300, 400, 3), 90, np.uint8))
    save_rgb(root / "ptl_copy.jpg", np.full((224, 224, 3), 90, np.uint8))
    (root / "labels.csv").write_text("image,split,photographer,far_x,bin12\nportrait.jpg,test,ann,0.5,7\n"
                                     "landscape.jpg,test,ann,0.5,7\nptl_copy.jpg,test,ann,0.5,7\n")
    import_ptl(PTLImportConfig(root, tmp_path / "ds", progress=False))
    ds = read_manifest(tmp_path / "ds")
    shapes = {r.image: load_frame(ds.image_path(r), r.flags).shape[:2] for r in ds.rows}
    assert shapes == {"images/portrait.jpg": (400, 300), "images/landscape.jpg": (300, 400),
                      "images/ptl_copy.jpg": (224, 299)}
    assert [r.flags for r in ds.rows] == [(), (), ("aspect=4:3",)]


def test_phone_photos_with_data_after_the_image_import_and_cut_ones_do_not(tmp_path):
    """Pixel and Samsung motion photos append an MP4 after the JPEG's end marker (and PNGs can carry
    trailing bytes): whole images, imported. The same JPEG cut inside its scan, or its end marker
    missing, is refused with its line; a tiny PNG is one clear line, not an internal error."""
    from crossing_assist.data_tools.images import check_image_file

    root = tmp_path / "mine"
    img = np.random.default_rng(0).integers(0, 255, (240, 320, 3), dtype=np.uint8)
    save_rgb(root / "plain.jpg", img)
    jpeg = (root / "plain.jpg").read_bytes()
    video = b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 200 + b"\xff\xd8\xff\xe0"   # an MP4 after the image
    (root / "motion.MP.jpg").write_bytes(jpeg + video)
    save_rgb(root / "plain.png", img)
    (root / "trailer.png").write_bytes((root / "plain.png").read_bytes() + b"extra bytes")
    assert [check_image_file(root / n) for n in ("motion.MP.jpg", "trailer.png")] == [None, None]
    cut = jpeg[: len(jpeg) * 2 // 3]
    (root / "cut.jpg").write_bytes(cut + video)          # the image cut, something after it
    (root / "cut2.jpg").write_bytes(cut)
    (root / "cut.png").write_bytes((root / "plain.png").read_bytes()[:-20])
    for name in ("cut.jpg", "cut2.jpg", "cut.png"):
        assert "is truncated" in check_image_file(root / name), name
    (root / "labels.csv").write_text("image,split,photographer,far_x,bin12\nmotion.MP.jpg,test,ann,0.5,7\n"
                                     "trailer.png,test,ann,0.5,7\n")
    import_ptl(PTLImportConfig(root, tmp_path / "ds", progress=False))
    assert len(read_manifest(tmp_path / "ds")) == 2
    save_rgb(root / "tiny.png", np.zeros((1, 2, 3), np.uint8))
    (root / "labels.csv").write_text("image,split,photographer,far_x,bin12\ntiny.png,test,ann,0.5,7\n"
                                     "cut.jpg,test,ann,0.5,7\n")
    proc = _cli("import-ptl", root, "--out", tmp_path / "ds2", "--quiet")
    assert proc.returncode == 2 and "line 3: image 'cut.jpg' is truncated (no JPEG end marker)" in proc.stderr


def test_square_photos_taken_square_keep_their_aspect_with_square_square(tmp_path):
    from crossing_assist.data_tools.images import load_frame

    root = tmp_path / "mine"
    save_rgb(root / "sq.jpg", np.full((300, 300, 3), 90, np.uint8))
    (root / "labels.csv").write_text("image,split,photographer,far_x,bin12\nsq.jpg,test,ann,0.5,7\n")
    proc = _cli("import-ptl", root, "--out", tmp_path / "ds", "--square", "square", "--quiet")
    assert proc.returncode == 0, proc.stderr
    (row,) = read_manifest(tmp_path / "ds").rows
    assert row.flags == () and load_frame(tmp_path / "ds" / row.image, row.flags).shape[:2] == (300, 300)
    with pytest.raises(PTLError, match="Unknown square mode"):
        import_ptl(PTLImportConfig(root, tmp_path / "ds2", progress=False, square="round"))

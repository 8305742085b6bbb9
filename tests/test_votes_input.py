"""Votes CSVs as people really hand them in: spreadsheet encodings, separators and a stray 0.

A label ``0`` in a votes file is refused (in the manifest 0 means unknown, but a person who
types 0 meant a typo or numbered the strips 0..11); files saved by Excel (UTF-8 with a BOM,
CRLF, semicolon-separated) are read like plain ones.
"""

import json
import re

import pytest

from crossing_assist.data_tools.cli import main as data_main
from crossing_assist.data_tools.labels import VotesConfig, build_voted_dataset
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.data_tools.votes import (
    FrameIndex,
    VotesError,
    read_label_studio,
    read_votes_csv,
)

FRAMES = ["v1/a.jpg", "v1/b.jpg", "v2/c.jpg"]
INDEX = FrameIndex(FRAMES)
VOTES = [("a.jpg", "ann", "7"), ("a.jpg", "bob", "7"), ("b.jpg", "ann", "unknown"), ("c.jpg", "ann", "12")]
WANT = [("v1/a.jpg", "ann", 7), ("v1/a.jpg", "bob", 7), ("v1/b.jpg", "ann", 0), ("v2/c.jpg", "ann", 12)]


def _write(path, rows, *, sep=",", eol="\n", bom=False, head=("frame", "annotator", "label")):
    text = eol.join(sep.join(r) for r in [head, *rows]) + eol
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
    return path


def _cli_error(make_frames_dir, votes, capsys):
    """Run ``crossing-data votes`` and return its stderr, checking exit 2 and one error line."""
    assert data_main(["votes", str(make_frames_dir(FRAMES)), str(votes)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


def _plain(votes):
    return [v[:3] for v in votes]


# ----------------------------------------------------------------------------- Excel files

@pytest.mark.parametrize("bom, eol, sep", [
    (True, "\n", ","), (True, "\r\n", ","), (False, "\r\n", ","), (False, "\r", ","),
    (True, "\r\n", ";"), (False, "\n", ";"), (True, "\r\n", "\t"),
], ids=["bom", "bom-crlf", "crlf", "cr", "bom-crlf-semicolon", "semicolon", "bom-crlf-tab"])
def test_spreadsheet_saved_votes_read_like_plain_ones(tmp_path, bom, eol, sep):
    plain = read_votes_csv(_write(tmp_path / "plain.csv", VOTES), INDEX)
    assert _plain(plain) == WANT
    got = read_votes_csv(_write(tmp_path / "excel.csv", VOTES, sep=sep, eol=eol, bom=bom), INDEX)
    assert _plain(got) == _plain(plain)
    assert [v[3] for v in got] == [f"{tmp_path / 'excel.csv'} line {n}" for n in (2, 3, 4, 5)]


def test_bom_crlf_votes_give_the_same_dataset_through_the_cli(tmp_path, capsys, make_frames_dir):
    d = make_frames_dir(FRAMES)
    assert data_main(["votes", str(d), str(_write(tmp_path / "plain.csv", VOTES))]) == 0
    plain = [(r.image, r.label, r.votes) for r in read_manifest(d).rows]
    (d / "manifest.csv").unlink()
    excel = _write(tmp_path / "excel.csv", VOTES, sep=";", eol="\r\n", bom=True)
    assert data_main(["votes", str(d), str(excel)]) == 0, capsys.readouterr().err
    assert [(r.image, r.label, r.votes) for r in read_manifest(d).rows] == plain
    assert plain == [("v1/a.jpg", 7, {7: 2}), ("v1/b.jpg", 0, {0: 1}), ("v2/c.jpg", 12, {12: 1})]


def test_bom_with_bin_column_and_quoted_header(tmp_path):
    path = tmp_path / "v.csv"
    path.write_bytes(b'\xef\xbb\xbf"frame","annotator","bin"\r\n"a.jpg","ann","7"\r\n')
    assert _plain(read_votes_csv(path, INDEX)) == [("v1/a.jpg", "ann", 7)]


def test_a_semicolon_file_with_a_broken_header_is_still_named(tmp_path, capsys, make_frames_dir):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", "7")], sep=";", bom=True,
                   head=("frame", "annotator", "strip"))
    err = _cli_error(make_frames_dir, votes, capsys)
    assert "line 1: header must have frame,annotator,label (got 'frame;annotator;strip')" in err
    assert "\\ufeff" not in err                       # the BOM is not shown as part of the header


def test_a_mixed_separator_row_is_a_field_count_error(tmp_path, capsys, make_frames_dir):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", "7"), ("b.jpg,ann", "7")], sep=";")
    assert "line 3: wrong number of fields" in _cli_error(make_frames_dir, votes, capsys)


def test_utf16_votes_are_refused_with_the_fix(tmp_path, capsys, make_frames_dir):
    path = tmp_path / "v.csv"
    path.write_bytes("frame\tannotator\tlabel\r\na.jpg\tann\t7\r\n".encode("utf-16"))
    err = _cli_error(make_frames_dir, path, capsys)
    assert "saved as UTF-16" in err and "save it as 'CSV UTF-8'" in err


# ----------------------------------------------------------------------------- label 0

ZERO_FIX = "refused: write unknown (or leave the frame out) for no crossing; strips are 1..12"
ZERO_RE = re.escape(ZERO_FIX)


@pytest.mark.parametrize("zero", ["0", "00"])
def test_label_zero_is_refused_naming_file_and_line(tmp_path, capsys, zero, make_frames_dir):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", "7"), ("b.jpg", "ann", zero), ("c.jpg", "ann", "12")])
    with pytest.raises(VotesError, match=rf"v\.csv line 3: label '{zero}' {ZERO_RE}$"):
        read_votes_csv(votes, INDEX)
    err = _cli_error(make_frames_dir, votes, capsys)
    assert f"v.csv line 3: label '{zero}' {ZERO_FIX}" in err and "0..11" not in err   # 12 is there


def test_zero_and_no_twelve_suggests_0_to_11_numbering(tmp_path, capsys, make_frames_dir):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", "6"), ("b.jpg", "ann", "0"), ("c.jpg", "ann", "0"),
                                         ("a.jpg", "bob", "11")])
    err = _cli_error(make_frames_dir, votes, capsys)
    assert (f"v.csv line 3: label '0' {ZERO_FIX} (this file has 2 labels 0 and none 12: "
            "if its strips are numbered 0..11, add 1 to every label)") in err
    assert not (tmp_path / "frames" / "manifest.csv").exists()


def test_zero_refused_in_a_bom_semicolon_file_too(tmp_path, make_frames_dir):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", "0")], sep=";", eol="\r\n", bom=True)
    with pytest.raises(VotesError, match=r"line 2: label '0' refused.*1 label 0 and none 12"):
        build_voted_dataset(VotesConfig(make_frames_dir(FRAMES), (votes,)))


def test_unknown_is_still_accepted(tmp_path):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", "unknown"), ("b.jpg", "ann", "UNKNOWN")])
    assert _plain(read_votes_csv(votes, INDEX)) == [("v1/a.jpg", "ann", 0), ("v1/b.jpg", "ann", 0)]


@pytest.mark.parametrize("choice", ["0", 0])
def test_label_studio_choice_zero_is_refused(tmp_path, choice):
    export = [{"id": 1, "data": {"image": "/data/local-files/?d=frames/v1/a.jpg"}, "annotations": [
        {"id": 1, "completed_by": 1, "result": [{"type": "choices", "value": {"choices": [choice]}}]}]}]
    path = tmp_path / "export.json"
    path.write_text(json.dumps(export))
    with pytest.raises(VotesError, match=rf"task 0 \(id 1\): choice '0' {ZERO_RE}$"):
        read_label_studio(path, INDEX)


@pytest.mark.parametrize("zero, shown", [(" 0 ", "'0'"), ("0" * 5000, "'" + "0" * 36 + "...")])
def test_padded_or_huge_zero_is_refused_in_a_short_line(tmp_path, capsys, zero, shown, make_frames_dir):
    votes = _write(tmp_path / "v.csv", [("a.jpg", "ann", zero), ("b.jpg", "ann", "12")])
    err = _cli_error(make_frames_dir, votes, capsys)
    assert f"v.csv line 2: label {shown} {ZERO_FIX}" in err and len(err) < 300

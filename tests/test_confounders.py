"""scripts/confounders.py: zebra look-alikes and true-zebra controls played through the runtime."""

import json
import sys
from pathlib import Path

import cv2
import pytest
from runtime_toy import make_toy_bundle, toy_bundle  # noqa: F401  (fixture)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import confounders as cf  # noqa: E402

SMALL = ["--per-type", "1", "--scale", "0.1"]   # 64x48 / 48x64 frames


def rows(summary: str, name: str) -> list[list[str]]:
    """The cells of the summary's table rows whose first cell is ``name``."""
    return [[c.strip() for c in line.strip("|").split("|")] for line in summary.splitlines()
            if line.startswith(f"| {name} |")]


@pytest.fixture(scope="module")
def loose(tmp_path_factory) -> Path:
    """A toy bundle whose gate never closes: it speaks whenever its argmax is a strip."""
    return make_toy_bundle(tmp_path_factory.mktemp("loose") / "bundle", threshold=100.0)


@pytest.fixture(scope="module")
def run(tmp_path_factory, loose):
    out = tmp_path_factory.mktemp("probe") / "out"
    assert cf.main([str(loose), "--out", str(out), *SMALL]) == 0
    return out, [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]


def test_every_type_is_rendered_played_and_summarised(run):
    out, recs = run
    kinds = [r["type"] for r in recs]
    assert kinds == [cf.CONTROL, cf.CONTROL, *[t for t in cf.TYPES if t != cf.CONTROL]]   # controls: 2N
    assert [(r["orientation"], r["width"], r["height"], r["fov_deg"]) for r in recs[:2]] == \
        [("landscape", 64, 48, 67.0), ("portrait", 48, 64, 53.0)]
    assert all(r["frames"] == 10 and (r["strip"] > 0) == r["on"] for r in recs)
    assert all(r["label"] == 0 for r in recs if r["type"] != cf.CONTROL)
    assert all(1 <= r["label"] <= 12 and 0 <= r["goal_x"] <= 1 for r in recs if r["type"] == cf.CONTROL)
    text = (out / "summary.md").read_text()
    table, rest = text.split("Controls (")
    variants = rest.split("by variant")[1]
    speaking = [r for r in recs if r["on"] and r["type"] != cf.CONTROL]
    for t in cf.TYPES:
        if t == cf.CONTROL:
            continue
        mine = [r for r in recs if r["type"] == t]
        on = sum(r["on"] for r in mine)
        (cells,) = rows(table, t)
        assert (int(cells[1].split()[0]), int(cells[2])) == (len(mine), on), t
        by_variant = rows(variants, t)
        assert (sum(int(c[2]) for c in by_variant), sum(int(c[3]) for c in by_variant)) == (len(mine), on), t
    (total,) = rows(table, "**all look-alikes**")
    assert (int(total[1]), int(total[2])) == (len(recs) - 2, len(speaking))
    controls = [r for r in recs if r["type"] == cf.CONTROL]
    (ctl,) = rows(rest, cf.CONTROL)
    assert int(ctl[3]) == sum(r["on"] for r in controls)
    assert int(ctl[5].split()[0]) == sum(r["on"] and r["strip"] == r["label"] for r in controls)
    # the loose gate speaks on some look-alikes: they, and only they, are on the contact sheet
    assert speaking
    sheet = cv2.imread(str(out / "speaking.png"))
    assert sheet.shape[0] == (240 + 28) * -(-len(speaking) // 6)


def test_a_frame_depends_only_on_its_type_index_and_seed(run, tmp_path, loose):
    """``--types`` replays the same frames with the same answers; another ``--seed`` renders others."""
    _, recs = run
    out = tmp_path / "some"
    assert cf.main([str(loose), "--out", str(out), *SMALL, "--types", "poster,stairs_up"]) == 0
    again = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    assert [r["type"] for r in again] == ["stairs_up", "poster"]   # in TYPES order
    assert again == [r for r in recs if r["type"] in ("stairs_up", "poster")]
    img, facts = cf.render("stairs_up", 0, scale=0.1)
    assert (img == cf.render("stairs_up", 0, scale=0.1)[0]).all()
    assert not (img == cf.render("stairs_up", 0, seed=1, scale=0.1)[0]).all()


def test_prints_the_summary_and_says_when_nothing_spoke(tmp_path, toy_bundle, capsys):  # noqa: F811
    """The default toy gate (1 nat) stays shut on these frames: no contact sheet, and it says so."""
    out = tmp_path / "out"
    assert cf.main([str(toy_bundle), "--out", str(out), *SMALL, "--types", "fence"]) == 0
    printed = capsys.readouterr().out
    assert printed == (out / "summary.md").read_text()
    assert "Look-alike frames that spoke: none." in printed and not (out / "speaking.png").exists()


def test_bad_input_is_one_line(tmp_path, toy_bundle):  # noqa: F811
    for args, match in (([str(tmp_path / "nowhere")], "^error: "),
                        ([str(toy_bundle), "--per-type", "0"], "^error: --per-type must be at least 1, got 0$"),
                        ([str(toy_bundle), "--types", "stairs,zebra"], "^error: unknown type\\(s\\) stairs; valid: zebra, "),
                        ([str(toy_bundle), "--types", ","], "^error: no type given"),
                        ([str(toy_bundle), "--scale", "0.01"], "^error: --scale 0.01 makes frames under 32 px")):
        with pytest.raises(SystemExit, match=match) as exc:
            cf.main([*args, "--out", str(tmp_path / "out")])
        assert "\n" not in str(exc.value)
    assert not (tmp_path / "out").exists()

"""scripts/roll_levelling.py: photos played as a rolled phone sees them, with and without levelling."""

import json
import sys
from pathlib import Path

import pytest
from runtime_toy import bar_dataset, toy_bundle  # noqa: F401  (fixture)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import roll_levelling as rl  # noqa: E402


def test_levelling_gives_back_what_a_level_phone_hears(tmp_path, toy_bundle, capsys):  # noqa: F811
    """The toy places vertical bars. Rolled 25-35 deg, a bar leans across strips and the toy
    places fewer of them; levelled by the sensor's roll it places them as on the level photo."""
    data = bar_dataset(tmp_path / "data", n=16)
    out = tmp_path / "roll.json"
    assert rl.main(["--bundle", str(toy_bundle), "--data", str(data), "--rolls", "25:35", "--source", "src:1",
                    "--out", str(out), "--plot", str(tmp_path / "roll.png")]) == 0
    res = json.loads(out.read_text())
    row = res["ranges"]["25:35"]
    level, rolled, levelled = res["level"], row["rolled"], row["levelled"]
    assert res["photos"] == 8 and res["source"] == "src:1" and level["accuracy_heard"] >= 0.75
    assert rolled["accuracy_heard"] < level["accuracy_heard"]
    assert levelled["accuracy_heard"] == level["accuracy_heard"]
    assert (tmp_path / "roll.png").stat().st_size > 1000
    table = capsys.readouterr().out
    assert "| 0° (level phone) | 8 |" in table and "| 25–35°, levelled, sensor ±3° | 8 |" in table
    # pooled with the other source's photos: rates weighted by photos, counts and flips summed
    other = tmp_path / "other.json"
    assert rl.main(["--bundle", str(toy_bundle), "--data", str(data), "--rolls", "25:35", "--source", "src:0",
                    "--split", "val", "--out", str(other)]) == 0
    pooled = tmp_path / "pooled.json"
    assert rl.main(["--pool", str(out), str(other), "--out", str(pooled), "--plot", str(tmp_path / "p.png")]) == 0
    p, o = json.loads(pooled.read_text()), json.loads(other.read_text())
    assert p["photos"] == 16 and p["level"]["frames_with_crossing"] == 16
    assert p["level"]["beacon_on"] == pytest.approx((level["beacon_on"] + o["level"]["beacon_on"]) / 2)
    assert p["ranges"]["25:35"]["levelled_vs_rolled"]["beacon_starts"] == \
        row["levelled_vs_rolled"]["beacon_starts"] + o["ranges"]["25:35"]["levelled_vs_rolled"]["beacon_starts"]
    assert "| 0° (level phone) | 16 |" in capsys.readouterr().out


def test_gate_decides_with_another_bundles_measure_and_thresholds(tmp_path, toy_bundle):  # noqa: F811
    """``--gate``: the plays are decided at the other bundle's gate; one that never opens keeps
    the beacon off on every play, where the bundle's own gate speaks."""
    import shutil

    shut = tmp_path / "shut"
    shutil.copytree(toy_bundle, shut)
    meta = json.loads((shut / "bundle.json").read_text())
    unc = meta["calibration"]["uncertainty"]
    for key in ("threshold", "portrait_threshold"):
        if key in unc:
            unc[key] = 1e-9
    (shut / "bundle.json").write_text(json.dumps(meta))
    data = bar_dataset(tmp_path / "data", n=4)
    own, gated = tmp_path / "own.json", tmp_path / "gated.json"
    args = ["--bundle", str(toy_bundle), "--data", str(data), "--rolls", "10:20"]
    assert rl.main([*args, "--out", str(own)]) == 0
    assert rl.main([*args, "--gate", str(shut), "--out", str(gated)]) == 0
    assert json.loads(own.read_text())["level"]["beacon_on"] > 0
    res = json.loads(gated.read_text())
    assert res["gate"] == str(shut) and res["level"]["beacon_on"] == 0
    assert all(r["beacon_on"] == 0 for name, r in res["ranges"]["10:20"].items() if name != "levelled_vs_rolled")


def test_bad_input_is_one_line(tmp_path, toy_bundle, capsys):  # noqa: F811
    assert rl.main(["--bundle", str(toy_bundle), "--data", str(tmp_path / "nowhere")]) == 1
    assert "error: no manifest at" in capsys.readouterr().err
    data = bar_dataset(tmp_path / "data", n=2, split="train")
    assert rl.main(["--bundle", str(toy_bundle), "--data", str(data)]) == 1
    assert "no photo with a crossing in split 'val'" in capsys.readouterr().err
    assert rl.main(["--bundle", str(toy_bundle), "--data", str(data), "--split", "train", "--source", "src:7"]) == 1
    assert "from src:7" in capsys.readouterr().err
    assert rl.main(["--bundle", str(tmp_path), "--data", str(bar_dataset(tmp_path / "d2", n=2))]) == 1
    assert capsys.readouterr().err.startswith("error: ")
    assert rl.main(["--bundle", str(toy_bundle), "--data", str(data), "--split", "train", "--gate", str(tmp_path)]) == 1
    assert capsys.readouterr().err.startswith("error: ")
    assert rl.main(["--pool", str(tmp_path / "missing.json")]) == 1
    assert capsys.readouterr().err.startswith("error: --pool: ")
    for bad in ("10-20", "20:10", "5:100"):
        with pytest.raises(SystemExit, match="error: --rolls"):
            rl.main(["--rolls", bad])

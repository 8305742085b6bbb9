"""Table 3 numbers from hand-made run folders: means per episode, sd over seeds, late queries."""

import json

import pytest

from crossing_assist.iil.report import ReportError, collect, table, write_report


def _fake_run(root, algo, seed, rewards, queries, oob, horizon=10):
    d = root / "toy" / algo / f"seed{seed}"
    d.mkdir(parents=True)
    (d / "config.json").write_text(json.dumps({"run": {"env": "toy", "algo": algo, "seed": seed, "horizon": horizon},
                                               "env": {"source": "toy"}}))
    lines = ["episode,reward,queries,penalties,out_of_bounds,expert_steps,term_speed"]
    for i, (r, q, o) in enumerate(zip(rewards, queries, oob), 1):
        lines.append(f"{i},{r},{q},1,{o},{q},{r / 2}")
    (d / "episodes.csv").write_text("\n".join(lines) + "\n")


def test_table_means_and_spread(tmp_path):
    _fake_run(tmp_path, "dagger", 1, [1, 2, 3, 4], [10, 10, 10, 10], [0, 1, 0, 0])
    _fake_run(tmp_path, "dagger", 2, [3, 4, 5, 6], [10, 10, 10, 10], [0, 0, 0, 2])
    _fake_run(tmp_path, "upms", 1, [0, 0, 0, 0], [10, 6, 2, 0], [0, 0, 0, 0])
    md, rows = table(collect([tmp_path]))
    dagger, upms = rows
    assert dagger["algorithm"] == "dagger" and dagger["seeds"] == 2 and dagger["episodes"] == 4
    assert dagger["reward / ep"] == "3.5 ± 1.4"           # seed means 2.5 and 4.5: sd = sqrt(2)
    assert dagger["out-of-bounds / run"] == "1.5 ± 0.7"   # totals 1 and 2
    assert dagger["queries % horizon (ep ≥ 3)"] == "100.0 ± 0.0"
    assert upms["queries % horizon (ep ≥ 3)"] == "10.0"   # episodes 3-4: (2 + 0) / 2 of 10 steps
    assert upms["reward, last ep"] == "0.0" and dagger["speed term / ep"] == "1.8 ± 0.7"
    assert md.count("\n") == 4


def test_write_report_files_and_errors(tmp_path):
    _fake_run(tmp_path / "runs", "upms", 1, [1, 2], [5, 5], [0, 0])
    paths = write_report([tmp_path / "runs"], tmp_path / "rep")
    assert [p.name for p in paths[:2]] == ["table3.md", "table3.csv"] and len(paths) == 6
    with pytest.raises(ReportError, match="no run folders"):
        collect([tmp_path / "rep"])

"""Table 3 from hand-made run folders: totals per run (mean ± sd over iterations), rates, the
thesis's numbers beside ours, the claims checked on both, and the reduced-scale warning."""

import json

import pytest

from crossing_assist.iil.report import THESIS_TABLE3, ReportError, claims, collect, table, write_report


def _fake_run(root, algo, seed, rewards, interventions, oob, horizon=10, config="thesis", penalties=1.0):
    d = root / "toy" / config / algo / f"seed{seed}"
    d.mkdir(parents=True)
    (d / "config.json").write_text(json.dumps({"run": {"env": "toy", "algo": algo, "seed": seed, "horizon": horizon,
                                                       "params": {"config": config}},
                                               "env": {"source": "toy"}}))
    lines = ["episode,reward,training_reward,penalties,out_of_bounds,interventions,expert_labels"]
    for i, (r, q, o) in enumerate(zip(rewards, interventions, oob), 1):
        lines.append(f"{i},{r - penalties},{r},{penalties},{o},{q},{horizon}")
    (d / "episodes.csv").write_text("\n".join(lines) + "\n")


def test_table_totals_rates_and_the_thesis_beside_ours(tmp_path):
    _fake_run(tmp_path, "dagger", 1, [1, 2, 3, 4], [10, 5, 5, 5], [0, 1, 0, 0])
    _fake_run(tmp_path, "dagger", 2, [3, 4, 5, 6], [10, 5, 5, 5], [0, 0, 0, 2])
    _fake_run(tmp_path, "upms", 1, [5, 5, 5, 5], [10, 6, 2, 0], [0, 0, 0, 0])
    _fake_run(tmp_path, "upms", 2, [5, 5, 5, 5], [10, 6, 2, 0], [0, 0, 0, 0])
    md, rows = table(collect([tmp_path]))
    dagger, upms = rows
    assert dagger["algorithm"] == "dagger" and dagger["iterations"] == 2 and dagger["steps / run"] == 40
    assert dagger["training reward: ours"] == "14.00 ± 5.66"    # run totals 10 and 18: sd = sqrt(32)
    assert dagger["penalties: ours"] == "4.00 ± 0.00"
    assert dagger["out of bounds (all iterations): ours"] == "3"
    assert dagger["interventions / run: ours"] == "25.0 ± 0.0" and dagger["expert labels / run: ours"] == "40.0 ± 0.0"
    assert dagger["interventions % horizon, ep ≥ 3: ours"] == "50.0 ± 0.0"
    assert upms["interventions % horizon, ep ≥ 3: ours"] == "10.0 ± 0.0"  # episodes 3-4: (2 + 0) / 2 of 10
    assert upms["interventions: thesis"] == "994" and upms["training reward: thesis"] == "3807.29 ± 10.83"
    assert "Reduced scale" in md and "## toy, configuration `thesis`" in md
    # the claims, ours and the thesis's: UPMS 18 < DAgger 25 interventions; 10 % < 20 %; 0 <= 3 out of bounds
    assert "| upms: fewer interventions than DAgger | **held** | 18.0 vs 25.0 | **held** | 994 vs 2924 |" in md
    assert "| upms: under 20 % of the horizon after two episodes | **held** | 10.0 %" in md
    assert "| upms: higher training reward than DAgger / AggreVaTe | **held** | 20.0 vs 14.0 | **held** |" in md


def test_claims_say_when_they_did_not_hold_and_check_the_thesis_itself():
    import numpy as np

    st = lambda i, late, oob, r: {"interventions": np.array([i]), "late": np.array([late]),  # noqa: E731
                                  "oob": np.array([oob]), "training_reward": np.array([r])}
    lines = "\n".join(claims({"dagger": st(100, 50, 1, 10), "aggrevate": st(200, 60, 2, 12),
                              "upms-sl": st(150, 30, 3, 11)}))
    assert "| upms-sl: fewer interventions than DAgger | **did not hold** | 150.0 vs 100.0 |" in lines
    assert "| upms-sl: under 20 % of the horizon after two episodes | **did not hold** |" in lines
    assert "| upms-sl: no more out-of-bounds than DAgger / AggreVaTe | **did not hold** | 3 vs 1 / 2 |" in lines
    # the thesis's own UPMS-SL (3517.04) is below DropoutDAgger but above DAgger (3175.94) and AggreVaTe
    assert "3517.0 vs 3175.9 / 3154.6 |" in lines
    assert THESIS_TABLE3["upms-ne-sl"][4] == 0


def test_write_report_files_and_errors(tmp_path):
    _fake_run(tmp_path / "runs", "upms", 1, [1, 2], [5, 5], [0, 0])
    _fake_run(tmp_path / "runs", "upms", 1, [1, 2], [5, 5], [0, 0], config="code")
    paths = write_report([tmp_path / "runs"], tmp_path / "rep")
    assert [p.name for p in paths[:2]] == ["table3.md", "table3.csv"] and len(paths) == 10  # 4 figures a config
    assert {p.name for p in paths[2:]} >= {"fig_toy_thesis_interventions.png", "fig_toy_code_training_reward.png"}
    with pytest.raises(ReportError, match="no run folders"):
        collect([tmp_path / "rep"])


def test_config_free_baselines_serve_both_configurations(tmp_path):
    _fake_run(tmp_path, "dagger", 1, [1, 2, 3], [10, 5, 5], [0, 0, 0], config="thesis")
    _fake_run(tmp_path, "upms", 1, [5, 5, 5], [10, 1, 1], [0, 0, 0], config="thesis")
    _fake_run(tmp_path, "upms", 1, [5, 5, 5], [10, 9, 9], [0, 0, 0], config="code")
    md, rows = table(collect([tmp_path]))
    code = md.split("configuration `code`")[1]
    assert "| dagger ¹ | 1 | 30 |" in code and "dagger: the runs of configuration `thesis`" in code
    assert "| upms: fewer interventions than DAgger | **did not hold** | 28.0 vs 20.0 |" in code
    assert [r["config"] for r in rows].count("code") == 2

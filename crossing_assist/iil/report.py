"""Reports over run folders: the thesis's Table 3 (markdown + CSV) with, per column, ours and
the thesis's, whether each of the thesis's claims held (in our runs and in its own numbers),
and Figures 4.4-4.7 (per episode: training reward, interventions, penalties, out-of-bounds;
mean over iterations with a +-1 sd band). One section and one set of figures per environment
and configuration (``thesis`` / ``code``).

Definitions (the thesis's Table 3): over a run (all its episodes; the thesis: 10 x 512 = 5120
steps), **training reward** = the sum of the positive step rewards, **penalties** = the sum of
the negative step rewards' magnitudes (both without the out-of-bounds steps, whose -1000 is
left out), **out of bounds** = events (all iterations together), **interventions** = steps the
expert acted (the thesis's "queries"); **expert labels** = steps whose expert action went into
``D`` (DAgger: every step). Ours: mean +- sd over iterations (seeds). Rates (per step, % of
steps) compare runs of different sizes; totals compare only at the thesis's scale.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import ALGORITHMS, THESIS_HORIZON
from .files import _atomic_write, _write_csv, read_episodes

METRICS = (("training_reward", "Figure 4.4: training reward per episode"),
           ("interventions", "Figure 4.5: expert interventions per episode"),
           ("penalties", "Figure 4.6: penalties per episode"),
           ("out_of_bounds", "Figure 4.7: out-of-bounds events per episode"))
ORDER = ALGORITHMS  # the table's row order
UPMS = ("upms", "upms-ne", "upms-sl", "upms-ne-sl")
# Algorithms that neither configuration changes (they ignore the expert's uncertainty and use
# no UPMS/DropoutDAgger setting): one set of runs serves both configurations' tables (tested:
# identical episodes under both).
CONFIG_FREE = ("supervised", "dagger", "aggrevate")

# The thesis's Table 3 (Duckietown udem1, 3 iterations x 10 episodes x 512 steps; mean +- sd
# over iterations): training reward, penalties, out of bounds, queries (= interventions).
THESIS_STEPS = 5120
THESIS_TABLE3 = {
    "supervised": (3434.85, 8.67, 9.06, 0.36, 2, 5120),
    "dagger": (3175.94, 14.63, 32.88, 4.47, 1, 2924),
    "aggrevate": (3154.63, 67.03, 252.63, 43.58, 13, 4440),
    "dropout-dagger": (3574.55, 10.75, 17.87, 0.51, 5, 2826),
    "upms": (3807.29, 10.83, 10.18, 0.78, 1, 994),
    "upms-ne": (3813.60, 11.20, 9.18, 0.54, 1, 931),
    "upms-sl": (3517.04, 22.41, 12.74, 0.62, 0, 1175),
    "upms-ne-sl": (3948.06, 25.58, 3.53, 0.34, 0, 1100),
}
FALLBACK = {"interventions": "expert_steps", "expert_labels": "queries", "training_reward": "reward"}


class ReportError(ValueError):
    """No runs found, or unreadable run folders."""


@dataclass(frozen=True)
class RunSeries:
    env: str
    algo: str
    seed: int
    horizon: int
    rows: list
    config: str = "code"


class _Shared:
    """A run shown in another configuration's table (see :data:`CONFIG_FREE`)."""

    def __init__(self, run: RunSeries, shared_from: str):
        self._run, self.shared_from = run, shared_from

    def __getattr__(self, name):
        return getattr(self._run, name)


def collect(dirs: list[Path]) -> list[RunSeries]:
    """Every run folder (with ``config.json`` and ``episodes.csv``) under ``dirs``."""
    found = []
    for d in dirs:
        if not Path(d).exists():
            raise ReportError(f"{d}: no such folder")
        for cfg_path in sorted(Path(d).rglob("config.json")):
            ep = cfg_path.parent / "episodes.csv"
            if not ep.exists():
                continue
            try:
                meta = json.loads(cfg_path.read_text())
                run = meta["run"]
                env = meta.get("env", {}).get("source", run["env"])
                env = run["env"] if env == run["env"] else f"{run['env']} ({env})"
                config = run.get("params", {}).get("config", "code")
                found.append(RunSeries(env, run["algo"], int(run["seed"]), int(run["horizon"]), read_episodes(ep),
                                       config))
            except (ValueError, KeyError, TypeError) as exc:
                raise ReportError(f"{cfg_path.parent}: unreadable run folder ({type(exc).__name__}: {exc})") from None
    if not found:
        raise ReportError(f"no run folders (config.json + episodes.csv) under {', '.join(map(str, dirs))}")
    return found


def _value(row: dict, metric: str) -> float:
    v = row.get(metric, row.get(FALLBACK.get(metric, ""), math.nan))
    return float(v) if v not in ("", None) else math.nan


def _groups(runs: list[RunSeries]) -> dict[tuple[str, str, str], list[RunSeries]]:
    """Runs by (env, config, algorithm); a configuration without its own runs of a
    :data:`CONFIG_FREE` algorithm borrows the other configuration's (marked ``shared_from``)."""
    groups: dict[tuple[str, str, str], list[RunSeries]] = {}
    for r in runs:
        groups.setdefault((r.env, r.config, r.algo), []).append(r)
    for env, config in {(k[0], k[1]) for k in groups}:
        for algo in CONFIG_FREE:
            if (env, config, algo) in groups:
                continue
            donor = next((k for k in sorted(groups) if k[0] == env and k[2] == algo and k[1] != config
                          and all(getattr(r, "shared_from", None) is None for r in groups[k])), None)
            if donor:
                groups[(env, config, algo)] = [_Shared(r, donor[1]) for r in groups[donor]]
    key = lambda k: (k[0], k[1] != "thesis", k[1], ORDER.index(k[2]) if k[2] in ORDER else 99, k[2])  # noqa: E731
    return {k: sorted(groups[k], key=lambda r: r.seed) for k in sorted(groups, key=key)}


def _n_episodes(series: list[RunSeries]) -> int:
    return min(len(s.rows) for s in series)


def _per_seed(series: list[RunSeries], metric: str, episodes: slice = slice(None), how: str = "mean") -> np.ndarray:
    """One number per seed over ``episodes`` of its first ``n`` (common) episodes."""
    n = _n_episodes(series)
    out = []
    for s in series:
        vals = [_value(r, metric) for r in s.rows[:n]][episodes]
        out.append((np.nansum(vals) if how == "sum" else np.nanmean(vals)) if vals else np.nan)
    return np.array(out, dtype=float)


def _fmt(vals: np.ndarray, digits: int = 1) -> str:
    vals = np.asarray(vals, dtype=float)
    vals = vals[np.isfinite(vals)]
    if not len(vals):
        return "-"
    sd = f" ± {np.std(vals, ddof=1):.{digits}f}" if len(vals) > 1 else ""
    return f"{np.mean(vals):.{digits}f}{sd}"


def _stats(series: list[RunSeries]) -> dict:
    """Per-seed totals and rates of one (env, config, algorithm) group."""
    n, h = _n_episodes(series), series[0].horizon
    steps = n * h
    tr = _per_seed(series, "training_reward", how="sum")
    pen = _per_seed(series, "penalties", how="sum")
    oob = _per_seed(series, "out_of_bounds", how="sum")
    inter = _per_seed(series, "interventions", how="sum")
    return {"n": n, "h": h, "steps": steps, "training_reward": tr, "penalties": pen, "oob": oob,
            "interventions": inter, "labels": _per_seed(series, "expert_labels", how="sum"),
            "late": 100 * _per_seed(series, "interventions", slice(2, n)) / h if n > 2 else np.array([np.nan])}


def _thesis_late(algo: str) -> float:
    """The thesis's interventions as % of the horizon in episodes 2-10, from its totals (episode
    1 is the expert's 512 steps): the closest its table comes to "after two episodes"."""
    q = THESIS_TABLE3[algo][5]
    return 100.0 * (q - THESIS_HORIZON) / (THESIS_STEPS - THESIS_HORIZON)


HEAD = ["algorithm", "iterations", "steps / run",
        "training reward: ours", "thesis", "penalties: ours", "thesis",
        "out of bounds (all iterations): ours", "thesis", "interventions / run: ours", "thesis (of 5120)",
        "interventions % of steps: ours", "thesis", "expert labels / run: ours",
        "reward / step: ours", "thesis", "interventions % horizon, ep ≥ 3: ours", "thesis, ep 2-10"]


def table(runs: list[RunSeries]) -> tuple[str, list[dict]]:
    """Table 3 per (environment, configuration): ours beside the thesis's, then the claims."""
    lines, rows = [], []
    sections: dict[tuple[str, str], dict[str, dict]] = {}
    shared: dict[tuple[str, str], dict[str, str]] = {}
    for (env, config, algo), series in _groups(runs).items():
        sections.setdefault((env, config), {})[algo] = (_stats(series), len(series))
        if getattr(series[0], "shared_from", None):
            shared.setdefault((env, config), {})[algo] = series[0].shared_from
    for (env, config), algos in sections.items():
        shapes = sorted({(k, st["n"], st["h"]) for st, k in algos.values()})
        full = shapes == [(3, THESIS_STEPS // THESIS_HORIZON, THESIS_HORIZON)]
        lines += [f"## {env}, configuration `{config}`", ""]
        scale = " / ".join(f"{k} iteration(s) x {n} episodes x {h} steps" for k, n, h in shapes)
        scale += " a run" if len(shapes) == 1 else " (differs by algorithm: unfinished runs; see each row)"
        lines.append(f"Scale: {scale}. The thesis: 3 iterations x 10 episodes x 512 steps = 5120 steps a run "
                     "(Duckietown udem1)." + ("" if full else " **Reduced scale: not the full protocol; compare the "
                                                            "rates (per step, %), not the totals.**"))
        lines += ["", "| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
        for algo, (st, n_seeds) in algos.items():
            th = THESIS_TABLE3.get(algo)
            per_step = (st["training_reward"] - st["penalties"]) / st["steps"]
            row = {"env": env, "config": config, "algorithm": algo, "iterations": n_seeds, "steps / run": st["steps"],
                   "training reward: ours": _fmt(st["training_reward"], 2),
                   "penalties: ours": _fmt(st["penalties"], 2),
                   "out of bounds (all iterations): ours": f"{np.nansum(st['oob']):.0f}",
                   "interventions / run: ours": _fmt(st["interventions"]),
                   "interventions % of steps: ours": _fmt(100 * st["interventions"] / st["steps"]),
                   "expert labels / run: ours": _fmt(st["labels"]),
                   "reward / step: ours": _fmt(per_step, 3),
                   "interventions % horizon, ep ≥ 3: ours": _fmt(st["late"])}
            if th:
                row.update({"training reward: thesis": f"{th[0]:.2f} ± {th[1]:.2f}",
                            "penalties: thesis": f"{th[2]:.2f} ± {th[3]:.2f}",
                            "out of bounds: thesis": f"{th[4]}", "interventions: thesis": f"{th[5]}",
                            "interventions %: thesis": f"{100 * th[5] / THESIS_STEPS:.1f}",
                            "reward / step: thesis": f"{(th[0] - th[2]) / THESIS_STEPS:.3f}",
                            "late: thesis": f"{_thesis_late(algo):.1f}"})
            mark = " ¹" if algo in shared.get((env, config), {}) else ""
            cells = [algo + mark, str(n_seeds), str(st["steps"]),
                     row["training reward: ours"], row.get("training reward: thesis", "-"),
                     row["penalties: ours"], row.get("penalties: thesis", "-"),
                     row["out of bounds (all iterations): ours"], row.get("out of bounds: thesis", "-"),
                     row["interventions / run: ours"], row.get("interventions: thesis", "-"),
                     row["interventions % of steps: ours"], row.get("interventions %: thesis", "-"),
                     row["expert labels / run: ours"],
                     row["reward / step: ours"], row.get("reward / step: thesis", "-"),
                     row["interventions % horizon, ep ≥ 3: ours"], row.get("late: thesis", "-")]
            lines.append("| " + " | ".join(cells) + " |")
            rows.append(row)
        if shared.get((env, config)):
            lines += ["", "¹ " + ", ".join(f"{a}: the runs of configuration `{c}`" for a, c in shared[(env, config)].items())
                      + " (neither configuration changes these algorithms: they ignore the expert's uncertainty)."]
        lines += ["", *claims({a: st for a, (st, _) in algos.items()}), ""]
    return "\n".join(lines) + "\n", rows


def _mean(v) -> float:
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else math.nan


def _verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else ("**held**" if ok else "**did not hold**")


def claims(stats: dict[str, dict]) -> list[str]:
    """The thesis's claims for the UPMS variants, checked on our means and on its own numbers."""
    out = ["| claim (UPMS variant) | ours | ours: values | thesis's own numbers | thesis: values |",
           "|---|---|---|---|---|"]
    th = THESIS_TABLE3

    def row(text, ours, ours_v, thesis, thesis_v):
        out.append(f"| {text} | {_verdict(ours)} | {ours_v} | {_verdict(thesis)} | {thesis_v} |")

    for v in UPMS:
        if v not in stats:
            continue
        s = stats[v]
        d = stats.get("dagger")
        i_v, i_d = _mean(s["interventions"]), _mean(d["interventions"]) if d else math.nan
        row(f"{v}: fewer interventions than DAgger", (i_v < i_d) if d else None,
            f"{i_v:.1f} vs {i_d:.1f}" if d else "no DAgger run", th[v][5] < th["dagger"][5],
            f"{th[v][5]} vs {th['dagger'][5]}")
        late = _mean(s["late"])
        row(f"{v}: under 20 % of the horizon after two episodes", (late < 20.0) if math.isfinite(late) else None,
            f"{late:.1f} % (episodes ≥ 3)", _thesis_late(v) < 20.0, f"{_thesis_late(v):.1f} % (episodes 2-10)")
        base = [(n, stats[n]) for n in ("dagger", "aggrevate") if n in stats]
        o_v = float(np.nansum(s["oob"]))
        o_b = {n: float(np.nansum(b["oob"])) for n, b in base}
        row(f"{v}: no more out-of-bounds than DAgger / AggreVaTe", all(o_v <= x for x in o_b.values()) if base else None,
            f"{o_v:.0f} vs " + " / ".join(f"{x:.0f}" for x in o_b.values()) if base else "no baseline run",
            th[v][4] <= min(th["dagger"][4], th["aggrevate"][4]),
            f"{th[v][4]} vs {th['dagger'][4]} / {th['aggrevate'][4]}")
        r_v = _mean(s["training_reward"])
        r_b = {n: _mean(b["training_reward"]) for n, b in base}
        row(f"{v}: higher training reward than DAgger / AggreVaTe", all(r_v > x for x in r_b.values()) if base else None,
            f"{r_v:.1f} vs " + " / ".join(f"{x:.1f}" for x in r_b.values()) if base else "no baseline run",
            th[v][0] > max(th["dagger"][0], th["aggrevate"][0]),
            f"{th[v][0]:.1f} vs {th['dagger'][0]:.1f} / {th['aggrevate'][0]:.1f}")
    return out if len(out) > 2 else []


def figures(runs: list[RunSeries], out: Path) -> list[Path]:
    """One PNG per metric, environment and configuration: mean over iterations per episode, ±1 sd band."""
    import matplotlib  # noqa: PLC0415
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    paths = []
    groups = _groups(runs)
    for env, config in dict.fromkeys((k[0], k[1]) for k in groups):
        mine = {k: v for k, v in groups.items() if k[:2] == (env, config)}
        for metric, title in METRICS:
            fig, ax = plt.subplots(figsize=(9, 4))
            for k, ((_, _, algo), series) in enumerate(mine.items()):
                color = plt.cm.tab20(k % 20)
                style = "-" if algo in ORDER[:10] else "--"
                n_ep = _n_episodes(series)
                vals = np.array([[_value(r, metric) for r in s.rows[:n_ep]] for s in series], dtype=float)
                x = np.arange(1, n_ep + 1)
                m = vals.mean(0)
                ax.plot(x, m, style, marker="o", ms=3, label=algo, color=color)
                if len(series) > 1:
                    sd = vals.std(0, ddof=1)
                    ax.fill_between(x, np.maximum(m - sd, 0.0), m + sd, alpha=0.10, color=color)  # all >= 0
            ax.set(xlabel="episode", ylabel=metric.replace("_", " "), title=f"{title} ({env}, {config})")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
            fig.tight_layout()
            slug = env.split(" ")[0]
            path = Path(out) / f"fig_{slug}_{config}_{metric}.png"
            tmp = path.with_name(path.stem + ".tmp.png")
            fig.savefig(tmp, dpi=110)
            plt.close(fig)
            tmp.replace(path)
            paths.append(path)
    return paths


def write_report(dirs: list[Path], out: Path) -> list[Path]:
    """Table 3 (``table3.md``, ``table3.csv``) and the figures into ``out``."""
    runs = collect(dirs)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md, rows = table(runs)
    intro = ("# Table 3 and the thesis's claims\n\n" + __doc__.split("\n\n", 1)[1].strip() + "\n\n")
    _atomic_write(out / "table3.md", intro + md)
    _write_csv(out / "table3.csv", rows)
    return [out / "table3.md", out / "table3.csv", *figures(runs, out)]

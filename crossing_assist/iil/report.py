"""Reports over run folders: the thesis's Table 3 (markdown + CSV) and Figures 4.4-4.7
(per-episode reward, queries, penalties, out-of-bounds; mean over seeds with a +-1 sd band).

Definitions (per episode of ``horizon`` steps): reward = sum of rewards without the
out-of-bounds steps (the simulator's -1000 is left out, as the thesis normalises it);
penalties = steps with negative reward (out-of-bounds steps not counted); out-of-bounds =
events (the episode continues after a reset); queries = steps whose expert action was used
(to act or as a label).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .files import _atomic_write, read_episodes

METRICS = (("reward", "Figure 4.4: reward per episode"), ("queries", "Figure 4.5: expert queries per episode"),
           ("penalties", "Figure 4.6: penalties per episode"), ("out_of_bounds", "Figure 4.7: out-of-bounds events per episode"))
ORDER = ("supervised", "forward", "smile", "dagger", "aggrevate", "dropout-dagger", "upms", "upms-ne", "upms-sl",
         "upms-ne-sl", "ensemble-dagger", "hg-dagger", "thrifty-dagger")


class ReportError(ValueError):
    """No runs found, or unreadable run folders."""


@dataclass(frozen=True)
class RunSeries:
    env: str
    algo: str
    seed: int
    horizon: int
    rows: list


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
            meta = json.loads(cfg_path.read_text())
            run = meta["run"]
            env = meta.get("env", {}).get("source", run["env"])
            env = run["env"] if env == run["env"] else f"{run['env']} ({env})"
            found.append(RunSeries(env, run["algo"], int(run["seed"]), int(run["horizon"]), read_episodes(ep)))
    if not found:
        raise ReportError(f"no run folders (config.json + episodes.csv) under {', '.join(map(str, dirs))}")
    return found


def _groups(runs: list[RunSeries]) -> dict[tuple[str, str], list[RunSeries]]:
    groups: dict[tuple[str, str], list[RunSeries]] = {}
    for r in runs:
        groups.setdefault((r.env, r.algo), []).append(r)
    key = lambda k: (k[0], ORDER.index(k[1]) if k[1] in ORDER else 99, k[1])  # noqa: E731
    return {k: groups[k] for k in sorted(groups, key=key)}


def _per_seed(series: list[RunSeries], metric: str, episodes: slice = slice(None)) -> np.ndarray:
    return np.array([np.nanmean([r[metric] for r in s.rows][episodes]) if s.rows[episodes] else np.nan
                     for s in series])


def _fmt(vals: np.ndarray, digits: int = 1) -> str:
    vals = vals[np.isfinite(vals)]
    if not len(vals):
        return "-"
    sd = f" ± {np.std(vals, ddof=1):.{digits}f}" if len(vals) > 1 else ""
    return f"{np.mean(vals):.{digits}f}{sd}"


def table(runs: list[RunSeries]) -> tuple[str, list[dict]]:
    """Table 3: per algorithm, means per episode over all episodes (± sd over seeds), plus the
    environment's reward terms (``term_*`` columns of the runs) per episode."""
    head = ["env", "algorithm", "seeds", "episodes", "reward / ep", "queries / ep", "queries % horizon (ep ≥ 3)",
            "penalties / ep", "out-of-bounds / run", "expert steps / ep", "reward, last ep"]
    terms = sorted({k for r in runs for row in r.rows for k in row if k.startswith("term_")})
    head += [f"{t[5:]} term / ep" for t in terms]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    rows = []
    for (env, algo), series in _groups(runs).items():
        n_ep = min(len(s.rows) for s in series)
        h = series[0].horizon
        oob = np.array([sum(r["out_of_bounds"] for r in s.rows[:n_ep]) for s in series], dtype=float)
        q_late = 100 * _per_seed(series, "queries", slice(2, n_ep)) / h
        row = {"env": env, "algorithm": algo, "seeds": len(series), "episodes": n_ep,
               "reward / ep": _fmt(_per_seed(series, "reward", slice(0, n_ep))),
               "queries / ep": _fmt(_per_seed(series, "queries", slice(0, n_ep))),
               "queries % horizon (ep ≥ 3)": _fmt(q_late),
               "penalties / ep": _fmt(_per_seed(series, "penalties", slice(0, n_ep))),
               "out-of-bounds / run": _fmt(oob),
               "expert steps / ep": _fmt(_per_seed(series, "expert_steps", slice(0, n_ep))),
               "reward, last ep": _fmt(_per_seed(series, "reward", slice(n_ep - 1, n_ep)))}
        for t in terms:
            has = all(t in s.rows[0] for s in series)
            row[f"{t[5:]} term / ep"] = _fmt(_per_seed(series, t, slice(0, n_ep))) if has else "-"
        rows.append(row)
        lines.append("| " + " | ".join(str(row[k]) for k in head) + " |")
    return "\n".join(lines) + "\n", rows


def figures(runs: list[RunSeries], out: Path) -> list[Path]:
    """One PNG per metric and environment: mean over seeds per episode, ±1 sd band."""
    import matplotlib  # noqa: PLC0415
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    paths = []
    envs = sorted({r.env for r in runs})
    for env in envs:
        groups = {k: v for k, v in _groups(runs).items() if k[0] == env}
        for metric, title in METRICS:
            fig, ax = plt.subplots(figsize=(9, 4))
            for k, ((_, algo), series) in enumerate(groups.items()):
                color = plt.cm.tab20(k % 20)
                style = "-" if algo in ORDER[:10] else "--"
                n_ep = min(len(s.rows) for s in series)
                vals = np.array([[r[metric] for r in s.rows[:n_ep]] for s in series], dtype=float)
                x = np.arange(1, n_ep + 1)
                m = vals.mean(0)
                ax.plot(x, m, style, marker="o", ms=3, label=algo, color=color)
                if len(series) > 1:
                    sd = vals.std(0, ddof=1)
                    lo = m - sd if metric == "reward" else np.maximum(m - sd, 0.0)  # counts are >= 0
                    ax.fill_between(x, lo, m + sd, alpha=0.10, color=color)
            ax.set(xlabel="episode", ylabel=metric.replace("_", " "), title=f"{title} ({env})")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
            fig.tight_layout()
            slug = env.split(" ")[0]
            path = Path(out) / f"fig_{slug}_{metric}.png"
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
    _atomic_write(out / "table3.md", md)
    import csv  # noqa: PLC0415
    import io  # noqa: PLC0415
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    _atomic_write(out / "table3.csv", buf.getvalue())
    return [out / "table3.md", out / "table3.csv", *figures(runs, out)]

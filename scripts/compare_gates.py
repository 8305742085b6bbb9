"""Two held-out gate choices side by side: risk-coverage curves per view in one figure, and each
choice's rates at its chosen thresholds.

Reads results of ``scripts/choose_gate.py`` over the same folds (e.g. ``gate_mirror.json``, the
bundles' own entropy gate, and ``gate_mirror_far_mass.json``, ``--measure far_mass``). A 3:4
window takes the portrait threshold, so its row is read at the portrait choice's scale; with
``--narrow`` at its own choice, as a bundle with a narrow camera's threshold gates it
(``scripts/stamp_bundle.py --narrow-fov``: a window is a ~41 deg camera).

    .venv/bin/python scripts/compare_gates.py runs/res256/gate_mirror.json runs/res256/gate_mirror_far_mass.json \
        --out docs/img/gate_measures.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

VIEWS = ("landscape", "portrait", "portrait_window")
#: The view whose chosen scale a view's row is read at (3:4 windows take the portrait threshold).
THRESHOLD_OF = {"landscape": "landscape", "portrait": "portrait", "portrait_window": "portrait"}


def view(g: dict, name: str) -> dict | None:
    """One view's result (landscape sits at the top level of choose_gate.py's file)."""
    return g if name == "landscape" else g.get(name)


def at_choice(g: dict, name: str, narrow: bool = False) -> dict | None:
    """The pooled curve point of view ``name`` at the scale chosen for its threshold's view
    (``narrow``: each view at its own choice)."""
    v, chooser = view(g, name), view(g, name if narrow else THRESHOLD_OF[name])
    if v is None or chooser is None:
        return None
    return min(v["curve"], key=lambda c: abs(c["scale"] - chooser["scale"]))


def label(path: Path, g: dict) -> str:
    return f"{g.get('measure', 'entropy')} ({path.name})"


def table(gates: list[tuple[Path, dict]], narrow: bool = False) -> list[str]:
    """Markdown rows: per view and gate file, beacon on (goal in view), confidently wrong, silence."""
    rows = ["| view | gate | beacon on (goal in view) | confidently wrong | silence off-crossing |", "|---|---|---:|---:|---:|"]
    for name in VIEWS:
        for path, g in gates:
            c = at_choice(g, name, narrow)
            if c is None:
                continue
            gv = c.get("beacon_on_goal_in_view")
            rows.append(f"| {name} | {label(path, g)} | {100 * c['beacon_on']:.1f} %"
                        + ("" if gv is None else f" ({100 * gv:.1f} %)")
                        + f" | {100 * c['confidently_wrong']:.2f} % ({c['confidently_wrong_frames']} of {c['frames']}) | "
                        + ("n/a" if c["silence_no_crossing"] is None else f"{100 * c['silence_no_crossing']:.2f} %") + " |")
    return rows


def plot(gates: list[tuple[Path, dict]], out: Path, narrow: bool = False) -> Path:
    from crossing_assist.models.plots import _plt, _save

    plt = _plt()
    names = [n for n in VIEWS if any(view(g, n) for _, g in gates)]
    fig, axes = plt.subplots(1, len(names), figsize=(4.5 * len(names), 4), squeeze=False)
    for ax, name in zip(axes[0], names):
        for i, (path, g) in enumerate(gates):
            v = view(g, name)
            if v is None:
                continue
            line, = ax.plot([100 * c["beacon_on"] for c in v["curve"]], [100 * c["confidently_wrong"] for c in v["curve"]],
                            "o-", ms=2, label=label(path, g))
            c = at_choice(g, name, narrow)
            ax.plot([100 * c["beacon_on"]], [100 * c["confidently_wrong"]], "*", ms=13, color=line.get_color())
        ax.axhline(0.5, color="grey", ls="--", lw=1)
        ax.set(xlabel="beacon on (% of frames with a crossing)", ylabel="confidently wrong (%)", title=name,
               ylim=(0, 1.5))
        ax.legend(fontsize=7)
    window = "its own, a narrow camera's" if narrow else "the portrait one"
    fig.suptitle(f"held out: each gate's sweep, star = its chosen threshold (3:4 window: {window})", fontsize=9)
    fig.tight_layout()
    return _save(fig, out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("gates", nargs="+", type=Path, help="choose_gate.py result files (gate*.json)")
    ap.add_argument("--out", type=Path, help="write the figure here (PNG)")
    ap.add_argument("--narrow", action="store_true",
                    help="3:4 windows at their own chosen threshold (a bundle's narrow_threshold), not the portrait one")
    a = ap.parse_args(argv)
    gates = []
    for p in a.gates:
        try:
            gates.append((p, json.loads(p.read_text())))
        except (OSError, ValueError) as exc:
            print(f"error: {p}: {exc}", file=sys.stderr)
            return 2
        if "curve" not in gates[-1][1]:
            print(f"error: {p} is not a scripts/choose_gate.py result (no curve)", file=sys.stderr)
            return 2
    print("\n".join(table(gates, a.narrow)))
    if a.out:
        print(f"figure: {plot(gates, a.out, a.narrow)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

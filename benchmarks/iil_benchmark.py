"""Reproduce docs/iil: the Duckietown benchmark (the thesis's eight, Table 3) in both
configurations, the crossing benchmarks, then the reports. Resumable: re-running continues
unfinished runs. Seed by seed, so that a partial result holds complete iterations.

    python benchmarks/iil_benchmark.py duckietown --config thesis             # the full protocol:
    python benchmarks/iil_benchmark.py duckietown --config code               #   3 x 10 x 512 steps each
    python benchmarks/iil_benchmark.py duckietown --config thesis --horizon 128   # as run for docs/iil (reduced)
    python benchmarks/iil_benchmark.py report --horizon 128                  # -> docs/iil/duckietown-h128
    python benchmarks/iil_benchmark.py duckietown-peers    # the five others (code configuration)
    python benchmarks/iil_benchmark.py crossing            # .venv, all 13 algorithms (code configuration)
    python benchmarks/iil_benchmark.py crossing-binary     # the thesis's 0/inf expert

Duckietown runs under .venv-duckietown (``scripts/setup_duckietown.sh``; see docs/iil.md).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MAIN_PY = REPO / ".venv" / "bin" / "python"
DT_PY = REPO / ".venv-duckietown" / "bin" / "python"
RUNS = REPO / "runs" / "iil"


def _cli(python: Path, *args: str) -> None:
    cmd = [str(python), "-m", "crossing_assist.iil.cli", *args]
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, cwd=REPO)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("what", choices=["crossing", "crossing-binary", "duckietown", "duckietown-peers", "report"])
    p.add_argument("--seeds", nargs="+", default=["1", "2", "3"])
    p.add_argument("--episodes", default="10")
    p.add_argument("--horizon", default=None, help="crossing: 128, duckietown: 512 (the thesis's)")
    p.add_argument("--config", default="thesis", choices=["thesis", "code"], help="duckietown: the configuration")
    a = p.parse_args()
    if a.what == "crossing":
        for s in a.seeds:  # seed by seed, so that a partial result holds complete seeds
            _cli(Path(sys.executable), "run", "--env", "crossing", "--algo", "all", "--config", "code", "--episodes", a.episodes,
                 "--horizon", a.horizon or "128", "--lr", "0.01", "--seeds", s, "--out", str(RUNS / "crossing"))
    elif a.what == "crossing-binary":  # the thesis's 0/inf expert, UPMS family against DAgger / HG-DAgger
        for s in a.seeds:
            _cli(Path(sys.executable), "run", "--env", "crossing", "--config", "code",
                 "--algo", "dagger,upms,upms-ne,upms-sl,upms-ne-sl,hg-dagger",
                 "--episodes", a.episodes, "--horizon", a.horizon or "128", "--lr", "0.01", "--binary-expert", "0.5",
                 "--seeds", s, "--out", str(RUNS / "crossing-binary"))
    elif a.what == "duckietown":
        if not DT_PY.exists():
            print("error: .venv-duckietown is missing; see docs/iil.md", file=sys.stderr)
            return 2
        h = a.horizon or "512"
        # supervised, dagger and aggrevate are the same under both configurations (the report
        # borrows the `thesis` runs for the `code` table): `code` runs the five others only
        algos = "thesis" if a.config == "thesis" else "dropout-dagger,upms,upms-ne,upms-sl,upms-ne-sl"
        for s in a.seeds:
            _cli(DT_PY, "run", "--env", "duckietown", "--algo", algos, "--config", a.config, "--episodes", a.episodes,
                 "--horizon", h, "--seeds", s, "--quiet", "--out", str(RUNS / f"duckietown-h{h}"))
    elif a.what == "duckietown-peers":  # Forward Training, SMILe and the three peers
        h = a.horizon or "512"
        for s in a.seeds:
            _cli(DT_PY, "run", "--env", "duckietown", "--algo", "forward,smile,ensemble-dagger,hg-dagger,thrifty-dagger",
                 "--config", "code", "--episodes", a.episodes, "--horizon", h, "--epochs", "2", "--seeds", s,
                 "--out", str(RUNS / f"duckietown-peers-h{h}"))
    else:
        h = a.horizon or "512"
        names = {"crossing": "crossing", "crossing-binary": "crossing-binary",
                 f"duckietown-h{h}": "duckietown" if h == "512" else f"duckietown-h{h}",
                 "duckietown-peers-h512": "duckietown-peers"}
        for run_name, doc_name in names.items():
            if (RUNS / run_name).exists():
                _cli(Path(sys.executable), "report", str(RUNS / run_name), "--out", str(REPO / "docs" / "iil" / doc_name))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Reproduce docs/iil: the crossing benchmark (all 13 algorithms) and the Duckietown benchmark
(the thesis's eight), then the reports. Resumable: re-running continues unfinished runs.

    python benchmarks/iil_benchmark.py crossing            # .venv, ~12 min a seed on 2 busy cores
    python benchmarks/iil_benchmark.py crossing-binary     # the thesis's 0/inf expert
    python benchmarks/iil_benchmark.py duckietown          # as run: 3 seeds x 10 x 512 steps, ~70 min
    python benchmarks/iil_benchmark.py duckietown-peers    # as run: the five others, 3 seeds x 10 x 512
    python benchmarks/iil_benchmark.py report

Duckietown runs under .venv-duckietown (see docs/iil.md).
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
    p.add_argument("--horizon", default=None, help="crossing: 128, duckietown: 512 (as run for docs/iil)")
    a = p.parse_args()
    if a.what == "crossing":
        for s in a.seeds:  # seed by seed, so that a partial result holds complete seeds
            _cli(Path(sys.executable), "run", "--env", "crossing", "--algo", "all", "--episodes", a.episodes,
                 "--horizon", a.horizon or "128", "--lr", "0.01", "--seeds", s, "--out", str(RUNS / "crossing"))
    elif a.what == "crossing-binary":  # the thesis's 0/inf expert, UPMS family against DAgger / HG-DAgger
        for s in a.seeds:
            _cli(Path(sys.executable), "run", "--env", "crossing", "--algo", "dagger,upms,upms-ne,upms-sl,upms-ne-sl,hg-dagger",
                 "--episodes", a.episodes, "--horizon", a.horizon or "128", "--lr", "0.01", "--binary-expert", "0.5",
                 "--seeds", s, "--out", str(RUNS / "crossing-binary"))
    elif a.what == "duckietown":
        if not DT_PY.exists():
            print("error: .venv-duckietown is missing; see docs/iil.md", file=sys.stderr)
            return 2
        h = a.horizon or "512"
        for s in a.seeds:
            _cli(DT_PY, "run", "--env", "duckietown", "--algo", "thesis", "--episodes", a.episodes, "--horizon", h,
                 "--epochs", "2", "--seeds", s, "--out", str(RUNS / f"duckietown-h{h}"))
    elif a.what == "duckietown-peers":  # Forward Training, SMILe and the three peers
        h = a.horizon or "512"
        for s in a.seeds:
            _cli(DT_PY, "run", "--env", "duckietown", "--algo", "forward,smile,ensemble-dagger,hg-dagger,thrifty-dagger",
                 "--episodes", a.episodes, "--horizon", h, "--epochs", "2", "--seeds", s,
                 "--out", str(RUNS / f"duckietown-peers-h{h}"))
    else:
        names = {"crossing": "crossing", "crossing-binary": "crossing-binary", "duckietown-h512": "duckietown",
                 "duckietown-peers-h512": "duckietown-peers"}
        for run_name, doc_name in names.items():
            if (RUNS / run_name).exists():
                _cli(Path(sys.executable), "report", str(RUNS / run_name), "--out", str(REPO / "docs" / "iil" / doc_name))
    return 0


if __name__ == "__main__":
    sys.exit(main())

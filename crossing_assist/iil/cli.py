"""``crossing-iil``: run interactive imitation learning benchmarks and report them.

    crossing-iil list
    crossing-iil run --env duckietown --algo thesis --config thesis --episodes 10 --horizon 512 --seeds 1 2 3 --out runs/iil
    crossing-iil run --env crossing-synthetic --algo upms --expert human --episodes 3 --horizon 64 --out runs/me
    crossing-iil report runs/iil --out docs/iil

``--algo`` takes names, ``thesis`` (the thesis's eight) or ``all``; ``--config`` is ``thesis``
(chapter 4 as written: Eq. 19-21, the 0/inf expert, x30, sigma^2 = 0.1) or ``code`` (this
project's earlier variant; see :mod:`crossing_assist.iil.algorithms`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Sequence

from ..errors import UserError
from .config import ALGORITHMS, CONFIGS, THESIS_ALGORITHMS, AlgoParams, LearnerConfig, RunConfig
from .envs import ENV_NAMES
from .files import RunError
from .report import ReportError, write_report


def _algos(names: list[str]) -> list[str]:
    from .algorithms import list_algorithms  # noqa: PLC0415 - torch, only when running

    out: list[str] = []
    for n in names:
        for part in n.split(","):
            if part == "thesis":
                out += list(THESIS_ALGORITHMS)
            elif part == "all":
                out += list_algorithms()
            elif part in list_algorithms():
                out.append(part)
            else:
                raise RunError(f"unknown algorithm {part!r}; valid: {', '.join(list_algorithms())}, thesis, all")
    return list(dict.fromkeys(out))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="crossing-iil", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="list environments and algorithms")
    r = sub.add_parser("run", help="run algorithms x seeds on an environment (resumable per episode)")
    r.add_argument("--env", required=True, choices=ENV_NAMES)
    r.add_argument("--algo", nargs="+", required=True, help="names, 'thesis' or 'all'")
    run_d, algo_d = RunConfig(env="", algo="", seed=0), AlgoParams()
    r.add_argument("--episodes", type=int, default=run_d.episodes)
    r.add_argument("--horizon", type=int, default=run_d.horizon, help=f"steps per episode (default {run_d.horizon})")
    r.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--config", choices=CONFIGS, default=algo_d.config,
                   help=f"thesis: chapter 4 as written; code: the earlier code variant (default: {algo_d.config})")
    r.add_argument("--expert", choices=["oracle", "human"], default=run_d.expert,
                   help="oracle: the environment's scripted expert; human: you, in a window (keys; crossing/toy)")
    r.add_argument("--fps", type=float, default=5.0, help="human expert: frames a second shown (the loop's pace)")
    r.add_argument("--frame-size", type=int, nargs=2, metavar=("W", "H"), default=None,
                   help="duckietown frame size (default: the thesis's 160 120)")
    d = LearnerConfig()
    r.add_argument("--lr", type=float, default=d.lr, help="AdaGrad learning rate")
    r.add_argument("--epochs", type=int, default=d.epochs, help="passes over D after each episode")
    r.add_argument("--mc-samples", type=int, default=d.mc_samples)
    r.add_argument("--ensemble", type=int, default=d.ensemble)
    r.add_argument("--max-samples", type=int, default=d.max_samples,
                   help="train on the most recent N samples of D only (default: all of D, as the thesis)")
    r.add_argument("--expert-threshold", type=float, default=None, help="U_T where alpha = 1/2")
    r.add_argument("--learner-threshold", type=float, default=None, help="U_L where alpha = 1/2")
    r.add_argument("--dagger-p", type=float, default=algo_d.dagger_p,
                   help=f"DAgger/AggreVaTe: the expert acts w.p. p^(i-1) in episode i (default {algo_d.dagger_p})")
    r.add_argument("--binary-expert", type=float, default=None, metavar="RISK",
                   help="the thesis's 0/inf expert: U = 0 above this risk, inf below (default: 0.5 with "
                        "--config thesis; the continuous confidence with --config code)")
    r.add_argument("--threads", type=int, default=1, help="torch CPU threads (1 is fastest for this small net)")
    r.add_argument("--quiet", action="store_true")
    rep = sub.add_parser("report", help="Table 3 (markdown/CSV) and Figures 4.4-4.7 from run folders")
    rep.add_argument("dirs", type=Path, nargs="+")
    rep.add_argument("--out", type=Path, default=None, help="default: DIRS[0]/report")
    for parser in (p, r, rep):
        parser.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    from .sweep import add_sweep_parser  # noqa: PLC0415 - `sweep`: run's options as Ray tasks

    add_sweep_parser(sub, r)
    return p


def _check_run_args(a: argparse.Namespace) -> None:
    """Refuse impossible numbers before any work (one line naming the option and the valid range)."""
    if a.episodes < 1 or a.horizon < 1:
        raise RunError(f"--episodes={a.episodes} and --horizon={a.horizon} must both be >= 1")
    for flag, value in (("--epochs", a.epochs), ("--mc-samples", a.mc_samples), ("--ensemble", a.ensemble),
                        ("--threads", a.threads)):
        if value < 1:
            raise RunError(f"Invalid {flag} {value}; valid: >= 1")
    if not (math.isfinite(a.lr) and a.lr > 0):
        raise RunError(f"Invalid --lr {a.lr}; valid: a finite number > 0")
    for flag, value in (("--expert-threshold", a.expert_threshold), ("--learner-threshold", a.learner_threshold)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise RunError(f"Invalid {flag} {value}; valid: a finite number > 0 (the uncertainty where alpha = 1/2)")
    if a.binary_expert is not None and not math.isfinite(a.binary_expert):
        raise RunError(f"Invalid --binary-expert {a.binary_expert}; valid: a finite risk")


def run_configs(a: argparse.Namespace) -> list[RunConfig]:
    """The :class:`RunConfig` of every (algorithm, seed) the ``run``/``sweep`` options ask for
    (options checked first; one line naming the option on a bad value)."""
    _check_run_args(a)
    if a.frame_size is not None and (a.env != "duckietown" or min(a.frame_size) < 16):
        raise RunError(f"--frame-size applies to duckietown only, each side >= 16 (got {a.env}, {a.frame_size})")
    if a.max_samples is not None and a.max_samples < 1:
        raise RunError(f"--max-samples={a.max_samples} must be >= 1")
    if not 0.0 <= a.dagger_p <= 1.0:
        raise RunError(f"--dagger-p={a.dagger_p} must be in [0, 1]")
    learner = LearnerConfig(lr=a.lr, epochs=a.epochs, mc_samples=a.mc_samples, ensemble=a.ensemble,
                            max_samples=a.max_samples)
    params = AlgoParams(config=a.config, expert_threshold=a.expert_threshold, learner_threshold=a.learner_threshold,
                        dagger_p=a.dagger_p)
    return [RunConfig(env=a.env, algo=al, seed=s, episodes=a.episodes, horizon=a.horizon,
                      learner=learner, params=params, expert_binary_risk=a.binary_expert,
                      frame_size=tuple(a.frame_size) if a.frame_size else None, expert=a.expert)
            for al in _algos(a.algo) for s in a.seeds]


def _cmd_run(a: argparse.Namespace) -> int:
    configs = run_configs(a)
    import torch  # noqa: PLC0415
    from tqdm import tqdm  # noqa: PLC0415

    from .runner import run  # noqa: PLC0415

    torch.set_num_threads(max(1, a.threads))
    expert = _human(a) if a.expert == "human" else None
    bar = tqdm(total=len(configs) * a.episodes * a.horizon, unit="step", disable=a.quiet, file=sys.stderr)
    for cfg in configs:
        bar.set_description(f"{cfg.algo} seed {cfg.seed}")

        def show(row, cfg=cfg):
            bar.set_postfix(ep=int(row["episode"]), reward=f"{row['reward']:.0f}", interventions=int(row["interventions"]),
                            oob=int(row["out_of_bounds"]))
        folder = run(cfg, a.out, progress=bar.update, on_episode=show, expert=expert)
    bar.close()
    print(f"done: {len(configs)} run(s) in {a.out} (last: {folder})")
    return 0


def _human(a: argparse.Namespace):
    """A :class:`HumanExpert` in a real window, with the environment's keys."""
    from .experts import HumanExpert, KeyMap, PygameWindow  # noqa: PLC0415

    keymaps = {"crossing": KeyMap.crossing, "crossing-synthetic": KeyMap.crossing, "toy": KeyMap.toy}
    if a.env not in keymaps:
        raise RunError(f"--expert human drives discrete actions by keys: crossing, crossing-synthetic or toy "
                       f"(not {a.env})")
    if a.fps <= 0:
        raise RunError(f"--fps={a.fps} must be > 0")
    if not a.quiet:
        keys = "1..9, 0, -, = steer to strips 1..12, space stops" if a.env != "toy" else "left/right steer, space stays"
        print(f"you are the expert: hold a key while you want to act ({keys}); release to let the "
              f"algorithm act; close the window to stop (the run resumes later)", file=sys.stderr)
    return HumanExpert(PygameWindow(fps=a.fps), keymaps[a.env]())


def _cmd_report(a: argparse.Namespace) -> int:
    out = a.out or (a.dirs[0] / "report")
    paths = write_report(a.dirs, out)
    print(f"report: {len(paths)} files in {out} ({paths[0].name}, {paths[1].name}, {len(paths) - 2} figures)")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``crossing-iil`` (exit 2 user error, 130 Ctrl-C; ``--debug`` for tracebacks)."""
    from crossing_assist.errors import run_cli

    return run_cli(_main, argv, interrupted="run the same command again to continue from the last finished episode")


def _main(argv: list[str]) -> int:
    a = build_parser().parse_args(argv)
    if a.cmd == "list":
        print("environments:", ", ".join(ENV_NAMES))
        print("algorithms:", ", ".join(ALGORITHMS))
        print("thesis:", ", ".join(THESIS_ALGORITHMS))
        return 0
    try:
        if a.cmd == "sweep":
            from .sweep import cmd_sweep  # noqa: PLC0415

            return cmd_sweep(a)
        return _cmd_run(a) if a.cmd == "run" else _cmd_report(a)
    except (RunError, ReportError, ImportError, RuntimeError) as exc:
        # bad options, a missing optional package or simulator: the user's to fix. (RunError and
        # ReportError live in iil/files.py and iil/report.py; until they derive from UserError
        # themselves, they are mapped here.)
        if isinstance(exc, UserError):
            raise
        raise UserError(str(exc)) from exc


if __name__ == "__main__":
    sys.exit(main())

"""``crossing-iil sweep``: every (environment, algorithm, seed) run of ``crossing-iil run`` as a Ray task.

    crossing-iil sweep --env crossing --algo all --seeds 1 2 3 --out runs/iil            # a local Ray
    crossing-iil sweep --env crossing --algo all --seeds 1 2 3 --out /shared/iil --address auto   # a cluster

Each run is :func:`crossing_assist.iil.runner.run` on one worker, one CPU a task, with the
same configuration and seed as the sequential runner, so it writes the same folder with the
same numbers. Runs whose folder already holds every episode with the same configuration are
skipped before any task starts; an unfinished one resumes at its next episode. On a cluster,
``--out`` must be a folder every node sees (shared file system). Ray is optional:
``pip install -e '.[scale]'``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .files import RunError, read_episodes


def add_sweep_parser(sub, run_parser: argparse.ArgumentParser) -> None:
    """``sweep``: the options of ``run`` plus where Ray runs."""
    s = sub.add_parser("sweep", parents=[run_parser], add_help=False,
                       help="run algorithms x seeds as Ray tasks (a local Ray, or a cluster with --address)")
    s.add_argument("--address", default=None,
                   help="Ray cluster to join ('auto': the one started on this node by `ray start`); "
                        "default: start a local Ray for this sweep")
    s.add_argument("--cpus", type=int, default=None, help="CPUs of the local Ray (default: all); ignored with --address")


def finished(cfg, out: Path) -> bool:
    """True when ``cfg``'s folder holds all its episodes with the same configuration."""
    from .runner import _config_json  # noqa: PLC0415 - torch, only when sweeping

    folder = cfg.folder(out)
    try:
        have = json.loads((folder / "config.json").read_text())["run"]
        rows = read_episodes(folder / "episodes.csv")
    except (OSError, ValueError, KeyError):
        return False
    want = _config_json(cfg)
    same = all(want[k] == have.get(k) for k in want if k != "episodes")
    return same and (folder / "state.pt").is_file() and len(rows) >= cfg.episodes


def _one(cfg, out: str, threads: int) -> str:
    """A Ray task: one run, as the sequential runner does it."""
    import torch  # noqa: PLC0415

    from .runner import run  # noqa: PLC0415

    torch.set_num_threads(max(1, threads))
    return str(run(cfg, Path(out)))


def sweep(configs: list, out: Path, *, address: str | None = None, cpus: int | None = None,
          threads: int = 1, log=print) -> dict[str, list]:
    """Run the unfinished ``configs`` as Ray tasks; ``{"ran": [...], "skipped": [...]}`` (folders).
    Joins the cluster at ``address`` or starts a local Ray (``cpus`` CPUs) that ends with the sweep."""
    try:
        import ray  # noqa: PLC0415
    except ImportError:
        raise RunError("crossing-iil sweep needs Ray: pip install -e '.[scale]' (or pip install ray)") from None
    todo = [c for c in configs if not finished(c, out)]
    skipped = [str(c.folder(out)) for c in configs if c not in todo]
    for f in skipped:
        log(f"skip (finished): {f}")
    if not todo:
        return {"ran": [], "skipped": skipped}
    started = not ray.is_initialized()
    if started:
        # "local": a new Ray for this sweep, even where another local cluster runs (or left its address file)
        kw = {"address": address} if address else {"address": "local", "num_cpus": cpus, "include_dashboard": False}
        ray.init(**kw, log_to_driver=False)
    try:
        task = ray.remote(num_cpus=1)(_one)
        pending = {task.remote(c, str(Path(out).resolve()), threads): c for c in todo}
        ran = []
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            cfg = pending.pop(done[0])
            try:
                ran.append(ray.get(done[0]))
            except ray.exceptions.RayTaskError as exc:
                cause = exc.cause if isinstance(getattr(exc, "cause", None), Exception) else exc
                raise RunError(f"{cfg.env}/{cfg.algo}/seed{cfg.seed} failed: {cause}") from None
            log(f"done: {ran[-1]}")
    finally:
        if started:
            ray.shutdown()
    return {"ran": ran, "skipped": skipped}


def cmd_sweep(a: argparse.Namespace) -> int:
    """``crossing-iil sweep``: the configurations of ``run``, as Ray tasks."""
    from .cli import run_configs  # noqa: PLC0415

    if a.cpus is not None and a.cpus < 1:
        raise RunError(f"Invalid --cpus {a.cpus}; valid: >= 1")
    if a.expert != "oracle":
        raise RunError(f"--expert {a.expert} cannot run as Ray tasks; use `crossing-iil run`")
    configs = run_configs(a)
    res = sweep(configs, a.out, address=a.address, cpus=a.cpus, threads=a.threads,
                log=(lambda *_: None) if a.quiet else print)
    print(f"done: {len(res['ran'])} run(s) as Ray tasks, {len(res['skipped'])} already finished, in {a.out}")
    return 0

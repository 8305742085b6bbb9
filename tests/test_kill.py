"""Kill tests (issue 16): SIGKILL ``crossing-train`` and ``crossing-export`` at random moments, then
resume / retry the same command: the outputs equal an uninterrupted run's and no temporary file
or folder is left anywhere. Slow (each case starts fresh processes): run with ``-m slow``.

The kill moments are drawn from a seeded generator over the uninterrupted run's duration, so a
failure can be replayed; ``KILL_SEED`` picks other moments.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from test_models_train import make_tiny_dataset

from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import Row, write_manifest
from crossing_assist.models.checkpoint import load_checkpoint

pytestmark = pytest.mark.slow

TRAIN = [sys.executable, "-m", "crossing_assist.models.cli", "train"]
EXPORT = [sys.executable, "-m", "crossing_assist.export"]
KILLS = 3
RNG = np.random.default_rng(int(os.environ.get("KILL_SEED", "16")))


SYS_TMP: Path | None = None  # the commands' temporary folder (TMPDIR), checked for leftovers too


def _env():
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return {**env, "TMPDIR": str(SYS_TMP)} if SYS_TMP else env


@pytest.fixture(autouse=True)
def _own_tmpdir(tmp_path):
    global SYS_TMP
    SYS_TMP = tmp_path / "systmp"
    SYS_TMP.mkdir()
    yield
    SYS_TMP = None


def _timed(args) -> float:
    t0 = time.monotonic()
    r = subprocess.run(args, capture_output=True, text=True, env=_env())
    assert r.returncode == 0, r.stderr
    return time.monotonic() - t0


def _kill_at(args, seconds: float) -> int | None:
    """Start ``args`` and SIGKILL it after ``seconds``; returns its exit status if it ended first."""
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=_env())
    try:
        return proc.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        return None


def _leftovers(*folders: Path) -> list[str]:
    """Temporary names anywhere under ``folders`` (what a killed writer could leave)."""
    out = []
    for folder in folders:
        if folder.exists():
            out += [str(p) for p in folder.rglob("*") if ".tmp" in p.name or ".old" in p.name]
    return out


def _ours(folder: Path) -> list[str]:
    """Our temporary folders in the system temp folder (others' files there are not our business)."""
    return [p.name for p in folder.iterdir() if p.name.startswith((".crossing-", "crossing-"))]


def _rows(run: Path) -> list[dict]:
    with open(run / "results.csv") as fh:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(fh)]


def _state(path: Path) -> dict:
    return load_checkpoint(path)["state_dict"]


def _same_state(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_sigkill_during_training_then_resume_matches_an_uninterrupted_run(tmp_path):
    data = make_tiny_dataset(tmp_path / "data", n_train=24, n_val=6)

    def args(out: Path, cache: Path):
        return [*TRAIN, "--data", str(data), "--out", str(out), "--backbone", "mobilenet_v3_small", "--weights",
                "none", "--input-size", "64", "--epochs", "4", "--batch-size", "4", "--unfreeze", "2",
                "--threads", "1", "--cache-dir", str(cache), "--quiet"]

    ref = tmp_path / "ref"
    duration = _timed(args(ref, tmp_path / "ref_cache"))
    for k, moment in enumerate(sorted(RNG.uniform(0.15, 0.95, KILLS) * duration)):
        run, cache = tmp_path / f"run{k}", tmp_path / f"cache{k}"
        status = _kill_at(args(run, cache), moment)
        for attempt in range(2):  # resume if an epoch finished, else start again (same command)
            resume = ["--resume"] if (run / "weights" / "last.pt").is_file() else []
            r = subprocess.run(args(run, cache) + resume, capture_output=True, text=True, env=_env())
            if r.returncode == 0:
                break
        assert r.returncode == 0, f"kill at {moment:.1f}s (status {status}): {r.stderr}"
        assert _rows(run) == _rows(ref), f"kill at {moment:.1f}s"
        for name in ("last.pt", "best.pt"):
            assert _same_state(_state(run / "weights" / name), _state(ref / "weights" / name)), (moment, name)
        assert _leftovers(run, cache) == [], f"kill at {moment:.1f}s"


@pytest.fixture(scope="module")
def export_work(tmp_path_factory):
    from crossing_assist.models.backbones import create_backbone
    from crossing_assist.models.checkpoint import save_checkpoint
    from crossing_assist.models.heads import create_head
    from crossing_assist.models.policy import Policy, policy_config

    root = tmp_path_factory.mktemp("killexport")
    rng = np.random.default_rng(0)
    rows = []
    for i in range(24):
        label = int(rng.integers(1, 13))
        img = rng.integers(0, 200, (40, 48, 3)).astype(np.uint8)
        img[:, int((label - 0.5) / 12 * 48)] = 255
        save_rgb(root / "data" / f"f{i}.png", img)
        rows.append(Row(f"f{i}.png", label, (label - 0.5) / 12, f"vid:{i % 3}", "val"))
    write_manifest(root / "data", rows)
    torch.manual_seed(0)
    backbone = create_backbone("squeezenet1_1", weights="none")
    head = create_head("spatial", backbone.num_features, 4, p=0.5)
    policy = Policy(backbone, head, policy_config(backbone, "spatial", 4, input_size=(32, 32), data="tiny"))
    save_checkpoint(root / "run" / "weights" / "best.pt", policy, {"metrics": {}})
    return root


def _export_args(root: Path, out: Path):
    return [*EXPORT, "--run", str(root / "run"), "--out", str(out), "--samples", "4", "--calib-data",
            str(root / "data"), "--min-calib", "2", "--batch", "8", "--parity-frames", "4", "--threads", "1", "--quiet"]


def _export_facts(folder: Path) -> tuple:
    """bundle.json without the creation time and the byte fields, and the graph itself (the
    model's metadata embeds that time, so the file's bytes differ from one export to the next)."""
    import onnx

    from crossing_assist.bundle import read_bundle

    read_bundle(folder)  # whole: size and SHA-256 match
    meta = json.loads((folder / "bundle.json").read_text())
    meta["provenance"].pop("created", None)
    for key in ("model_sha256", "model_size"):
        meta.pop(key)
    return meta, onnx.load(str(folder / "model.onnx")).graph.SerializeToString()


def test_sigkill_during_export_then_retry_gives_the_same_bundle(export_work, tmp_path):
    import shutil

    out = tmp_path / "b" / "bundle"  # one path: the graph embeds the bundle facts, provenance included
    duration = _timed(_export_args(export_work, out))
    ref = _export_facts(out)
    whole = lambda: _export_facts(out) == ref  # noqa: E731
    for moment in sorted(RNG.uniform(0.2, 1.0, KILLS) * duration):
        shutil.rmtree(out.parent)
        _kill_at(_export_args(export_work, out), moment)
        assert not out.exists() or whole(), f"kill at {moment:.1f}s: half a bundle is visible"
        r = subprocess.run(_export_args(export_work, out), capture_output=True, text=True, env=_env())
        assert r.returncode == 0, r.stderr
        assert whole(), f"kill at {moment:.1f}s"
        assert _leftovers(out.parent) == [] and _ours(SYS_TMP) == [], f"kill at {moment:.1f}s"
        _kill_at(_export_args(export_work, out), moment)  # over an existing bundle: it stays whole
        assert whole(), f"kill at {moment:.1f}s over an existing bundle"
    r = subprocess.run(_export_args(export_work, out), capture_output=True, text=True, env=_env())
    assert r.returncode == 0, r.stderr
    assert whole() and _leftovers(out.parent) == []  # the retry swept what the killed writers left
    assert _ours(SYS_TMP) == []

"""Issue 16, training side: --resume refuses changed options, results.csv survives a kill between
it and last.pt, the feature cache leaves nothing half-written behind."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import threading
import time

import pytest
from test_models_train import _cfg, make_tiny_dataset

from crossing_assist.models import cache as cache_mod
from crossing_assist.models import train as train_mod
from crossing_assist.models.checkpoint import load_checkpoint
from crossing_assist.models.cli import train_main
from crossing_assist.models.config import ConfigError


@pytest.fixture()
def tiny(tmp_path):
    return make_tiny_dataset(tmp_path / "data")


def _args(tiny, out, *extra):
    return ["--data", str(tiny), "--out", str(out), "--backbone", "mobilenet_v3_small", "--weights", "none",
            "--epochs", "1", "--batch-size", "4", "--input-size", "64", "--cache-dir", str(out.parent / "cache"),
            "--quiet", *extra]


def _epochs(out):
    with open(out / "results.csv") as fh:
        return [int(r["epoch"]) for r in csv.DictReader(fh)]


def test_resume_refuses_changed_options_and_extends_epochs(tiny, tmp_path, capsys):
    out = tmp_path / "run"
    assert train_main(_args(tiny, out)) == 0
    assert "trained 1 epochs" in capsys.readouterr().out
    other = make_tiny_dataset(tmp_path / "other", seed=3)
    # changed options: refused, naming every difference, nothing trained
    args = _args(tiny, out, "--resume", "--actions", "4", "--lr", "0.1")
    args[args.index(str(tiny))] = str(other)
    assert train_main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    assert "--actions 4 (run: 13)" in err and "--lr 0.1" in err and "--data" in err
    assert _epochs(out) == [1]
    # the same options (left out or repeated): resumes; an explicit larger --epochs extends the run
    args = _args(tiny, out, "--resume")
    args[args.index("--epochs") + 1] = "3"
    assert train_main(args) == 0
    assert "trained 3 epochs" in capsys.readouterr().out
    assert _epochs(out) == [1, 2, 3] and load_checkpoint(out / "weights" / "last.pt")["epoch"] == 3
    # fewer epochs than done: refused; resuming a finished run says how many epochs it has
    args[args.index("--epochs") + 1] = "2"
    assert train_main(args) == 2
    assert "already trained 3 epochs" in capsys.readouterr().err
    assert train_main(["--data", str(tiny), "--out", str(out), "--resume", "--quiet"]) == 0
    assert "trained 3 epochs" in capsys.readouterr().out


def test_kill_between_results_and_last_pt_keeps_them_consistent(tiny, tmp_path, monkeypatch):
    """The epoch-2 row must not be lost when the process dies right after writing it."""
    ref = train_mod.train(_cfg(tiny, tmp_path / "ref", epochs=3))
    real = train_mod.save_checkpoint

    def dying(path, policy, extra=None):
        if path.name == "last.pt" and extra["epoch"] == 2:
            raise KeyboardInterrupt  # stands in for SIGKILL at that moment
        return real(path, policy, extra)

    run = tmp_path / "run"
    monkeypatch.setattr(train_mod, "save_checkpoint", dying)
    with pytest.raises(KeyboardInterrupt):
        train_mod.train(_cfg(tiny, run, epochs=3))
    monkeypatch.setattr(train_mod, "save_checkpoint", real)
    assert load_checkpoint(run / "weights" / "last.pt")["epoch"] == 1
    train_mod.train(_cfg(tiny, run, epochs=3), resume=True)
    strip = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]  # noqa: E731
    read = lambda p: list(csv.DictReader(open(p / "results.csv")))  # noqa: E731
    assert strip(read(run)) == strip(read(ref))


def test_feature_cache_leaves_no_tmp_folder_after_an_error(tiny, tmp_path, monkeypatch):
    calls = {"n": 0}
    real = cache_mod.load_variants

    def failing(*a, **kw):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt  # Ctrl-C while caching
        return real(*a, **kw)

    monkeypatch.setattr(cache_mod, "load_variants", failing)
    with pytest.raises(KeyboardInterrupt):
        train_mod.train(_cfg(tiny, tmp_path / "run"))
    cache = tmp_path / "cache"
    assert not [p for p in cache.iterdir() if ".tmp" in p.name]


def test_feature_cache_sweeps_a_killed_runs_tmp_folder(tiny, tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    cache = tmp_path / "cache"
    orphan = cache / f"0123456789abcdef01234567.tmp{proc.pid}"
    orphan.mkdir(parents=True)
    (orphan / "feats.npy").write_bytes(b"\0" * 1000)
    mine = cache / f"0123456789abcdef01234567.tmp{os.getpid()}x"  # not a tag of ours: left alone
    mine.mkdir()
    train_mod.train(_cfg(tiny, tmp_path / "run", epochs=1))
    assert not orphan.exists() and mine.exists()


def test_library_resume_refuses_a_different_config(tiny, tmp_path):
    train_mod.train(_cfg(tiny, tmp_path / "run", epochs=1))
    with pytest.raises(ConfigError, match="--batch-size 8"):
        train_mod.train(_cfg(tiny, tmp_path / "run", epochs=2, batch_size=8), resume=True)


def test_a_process_needing_an_entry_another_is_computing_waits_and_reads_it(tiny, tmp_path, monkeypatch):
    """Runs side by side on one cache take turns on an entry: while another holder has the
    entry's lock, compute_features waits; once the entry is there it reads it, computing nothing."""
    from crossing_assist.data_tools.manifest import read_manifest
    from crossing_assist.models.backbones import create_backbone
    from crossing_assist.models.data import make_variants

    ds = read_manifest(tiny).split("train")
    bb = create_backbone("mobilenet_v3_small", weights="none").eval()
    args = (bb, 6, ds, (64, 64), make_variants(False), 90.0)
    built = cache_mod.compute_features(*args, tmp_path / "elsewhere", progress=False)   # the other run's work
    key = built.path.name

    def never(*a, **kw):
        raise AssertionError("computed an entry another process was computing")

    monkeypatch.setattr(cache_mod, "_compute", never)
    got = {}
    with cache_mod.entry_lock(tmp_path / "c", key):   # the other process, still computing
        waiter = threading.Thread(target=lambda: got.update(fs=cache_mod.compute_features(
            *args, tmp_path / "c", progress=False)))
        waiter.start()
        time.sleep(1.0)
        assert waiter.is_alive() and "fs" not in got    # waiting, not computing
        shutil.copytree(built.path, tmp_path / "c" / key)   # ... and done
    waiter.join(30)
    assert got["fs"].path == tmp_path / "c" / key and got["fs"].feats.shape == built.feats.shape


def test_a_run_builds_the_entries_no_one_else_is_building_before_it_waits(tiny, tmp_path):
    """Two runs side by side need the same entries: while another process builds the train
    entry, this run builds the others (here val) instead of idling, then waits and reads train;
    compute_features(wait=False) gives None at once for an entry another process holds."""
    train_mod.train(_cfg(tiny, tmp_path / "other", epochs=1, cache_dir=str(tmp_path / "elsewhere")))
    built = {p.name: p for p in (tmp_path / "elsewhere").iterdir() if (p / "meta.json").is_file()}
    cache = tmp_path / "c"
    cache.mkdir()
    done = {}
    assert len(built) == 2   # train (8 rows x 2 mirror variants) and val (4 rows)
    train_key = max(built, key=lambda k: json.loads((built[k] / "meta.json").read_text())["n"])
    with cache_mod.entry_lock(cache, train_key):   # the other process, building train
        run = threading.Thread(target=lambda: done.update(out=train_mod.train(
            _cfg(tiny, tmp_path / "run", epochs=1, cache_dir=str(cache)))))
        run.start()
        deadline = time.time() + 60
        while time.time() < deadline and not any((p / "meta.json").is_file() for p in cache.iterdir()):
            time.sleep(0.2)
        others = [p.name for p in cache.iterdir() if (p / "meta.json").is_file()]
        assert others and train_key not in others, others   # built the rest first ...
        assert run.is_alive() and "out" not in done         # ... and waits for train
        shutil.copytree(built[train_key], cache / train_key)   # the other process is done
    run.join(120)
    assert "out" in done and (tmp_path / "run" / "weights" / "last.pt").is_file()

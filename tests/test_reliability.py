"""Issue 16: every bad input gets one line, nothing is deleted or left half-written.

One test (or parametrised case) per case of the issue; each fails on the code before the fix.
Data-tool cases run in-process through ``crossing-data``'s ``main`` (the shared wrapper), so
they are fast; the rest call the library or the entry points directly.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import soundfile as sf
from runtime_toy import make_toy_bundle, toy_bundle, toy_meta, toy_model_bytes, bar_frame  # noqa: F401

from crossing_assist.bundle import BundleError, read_bundle, write_bundle
from crossing_assist.data_tools.cli import main as data_main
from crossing_assist.data_tools.images import save_rgb
from crossing_assist.errors import UserError, run_cli
from crossing_assist.fileio import sweep_orphans
from crossing_assist.runtime.watchdog import DEFAULT_WATCHDOG_S


def one_error_line(text: str) -> bool:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in text


# ----------------------------------------------------------------------------- the wrapper


def test_every_module_error_is_a_user_error():
    from crossing_assist.data_tools import frames, images, manifest, ptl, splits, synth, votes
    from crossing_assist.export.exporter import ExportError
    from crossing_assist.models.backbones import BackboneError
    from crossing_assist.models.checkpoint import CheckpointError
    from crossing_assist.models.config import ConfigError
    from crossing_assist.models.heads import HeadError
    from crossing_assist.runtime.audio import AudioDeviceError
    from crossing_assist.runtime.demo import DemoError
    from crossing_assist.runtime.sources import SourceError

    classes = [BundleError, ExportError, BackboneError, CheckpointError, ConfigError,
               HeadError, AudioDeviceError, DemoError, SourceError, frames.VideoError, images.ImageError,
               manifest.ManifestError, ptl.PTLError, splits.SplitError, synth.SynthError, votes.VotesError]
    assert all(issubclass(c, UserError) for c in classes)


def test_run_cli_exit_codes_and_one_line(capsys):
    def raiser(exc):
        def body(args):
            raise exc
        return body

    assert run_cli(raiser(UserError("bad thing\nsecond line")), []) == 2
    assert capsys.readouterr().err == "error: bad thing\n"
    assert run_cli(raiser(KeyboardInterrupt()), [], interrupted="run it again") == 130
    assert capsys.readouterr().err == "interrupted; run it again\n"
    assert run_cli(raiser(ZeroDivisionError("boom")), []) == 1
    err = capsys.readouterr().err
    assert one_error_line(err) and "ZeroDivisionError: boom" in err and "--debug" in err
    assert run_cli(raiser(OSError(36, "File name too long", "x" * 300)), []) == 2
    err = capsys.readouterr().err
    assert one_error_line(err) and "File name too long" in err and len(err) < 250
    with pytest.raises(ZeroDivisionError):
        run_cli(raiser(ZeroDivisionError("boom")), ["--debug"])
    seen = []
    assert run_cli(lambda args: seen.append(args) or 0, ["a", "--debug", "b"]) == 0 and seen == [["a", "b"]]


ENTRY_POINTS = {
    "crossing-data": ("crossing_assist.data_tools.cli", "main", ["stats", "/nonexistent-dataset"]),
    "crossing-train": ("crossing_assist.models.cli", "train_main", ["--data", "/nonexistent", "--out", "/tmp/x",
                                                                    "--epochs", "0"]),
    "crossing-eval": ("crossing_assist.models.cli", "eval_main", ["--data", "/nonexistent"]),
    "crossing-export": ("crossing_assist.export.cli", "main", ["--run", "/nonexistent", "--out", "/tmp/x",
                                                                "--samples", "0"]),
    "crossing-demo": ("crossing_assist.runtime.demo", "main", ["--watchdog", "0"]),
    "crossing-iil": ("crossing_assist.iil.cli", "main", ["run", "--env", "toy", "--algo", "dagger", "--out",
                                                         "/tmp/x", "--lr", "-1"]),
}


@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
def test_all_six_commands_use_the_wrapper(name, capsys):
    """A user error: exit 2 and one line; with --debug the same error propagates (traceback)."""
    import importlib

    mod, func, args = ENTRY_POINTS[name]
    main = getattr(importlib.import_module(mod), func)
    assert main(args) == 2
    assert one_error_line(capsys.readouterr().err)
    with pytest.raises(UserError):
        main(args + ["--debug"])


# ----------------------------------------------------------------------------- 1. data loss


@pytest.fixture()
def toy_bytes():
    meta = toy_meta()
    return toy_model_bytes(meta=meta), meta


def _run_folder(root: Path) -> Path:
    (root / "weights").mkdir(parents=True)
    for name in ("weights/best.pt", "weights/last.pt", "results.csv"):
        (root / name).write_text("precious")
    return root


@pytest.mark.parametrize("kind", ["run", "dataset", "file", "bundle_plus_eval"])
def test_write_bundle_never_deletes_what_is_not_a_bundle(tmp_path, toy_bytes, kind):
    target = tmp_path / "target"
    if kind == "run":
        _run_folder(target)
    elif kind == "dataset":
        (target / "images").mkdir(parents=True)
        (target / "manifest.csv").write_text("precious")
    elif kind == "file":
        target.write_text("precious")
    else:
        make_toy_bundle(target)
        (target / "eval_val").mkdir()
        (target / "eval_val" / "metrics.json").write_text("precious")
    before = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    with pytest.raises(BundleError, match="--force"):
        write_bundle(target, *toy_bytes)
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == before
    write_bundle(target, *toy_bytes, force=True)  # an explicit --force replaces it
    assert read_bundle(target).model_path.is_file()


def test_write_bundle_replaces_a_bundle_or_an_empty_folder(tmp_path, toy_bytes):
    (tmp_path / "empty").mkdir()
    write_bundle(tmp_path / "empty", *toy_bytes)
    write_bundle(tmp_path / "empty", *toy_bytes)  # a bundle over a bundle
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]  # no temporary folder left


def test_crossing_export_refuses_the_run_folder_before_any_work(tmp_path, capsys):
    from crossing_assist.export.cli import main

    run = _run_folder(tmp_path / "run")
    assert main(["--run", str(run), "--out", str(run), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert one_error_line(err) and "not a bundle" in err and "--force" in err
    assert all((run / n).read_text() == "precious" for n in ("weights/best.pt", "weights/last.pt", "results.csv"))


# ----------------------------------------------------------------------------- 2. segfault


@pytest.mark.parametrize("camera", ["-1", "-5", "100000"])
def test_demo_refuses_a_bad_camera_index(camera, capsys):
    from crossing_assist.runtime.demo import main

    assert main(["--camera", camera, "--live"]) == 2  # before cv2.VideoCapture(-1) could crash
    assert "--camera" in capsys.readouterr().err


# ----------------------------------------------------------------------------- 3. truncated video


def _avi(path: Path, xs, fps: float = 10.0) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (96, 72))
    for x in xs:
        writer.write(cv2.cvtColor(bar_frame(x), cv2.COLOR_RGB2BGR))
    writer.release()
    return path


@pytest.mark.parametrize("watchdog", [None, 1.0])
def test_truncated_video_warns_and_ends_on_a_stop(tmp_path, toy_bundle, capsys, watchdog):  # noqa: F811
    """... and the stop comes ``--watchdog`` after the last frame, offline as live."""
    from crossing_assist.runtime.beacon import BeaconConfig
    from crossing_assist.runtime.demo import main
    from crossing_assist.runtime.offline import STOP_TAIL_S

    full = _avi(tmp_path / "full.avi", [0.8] * 40)
    cut = tmp_path / "cut.avi"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    out = tmp_path / "out"
    period = ["--watchdog", str(watchdog)] if watchdog else []
    assert main([str(cut), "--bundle", str(toy_bundle), "--out", str(out), "--no-video", "--quiet", *period]) == 0
    err = capsys.readouterr().err
    warning = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    assert len(warning) == 1 and "of 40 frames" in warning[0], err
    n = int(warning[0].split("after ")[1].split(" of")[0])
    assert 0 < n < 40
    trace = [json.loads(ln) for ln in (out / "trace.jsonl").read_text().splitlines()]
    assert len(trace) == n + 1 and trace[-2]["stop"] is False  # it was guiding when the video died
    assert trace[-1]["stop"] is True and trace[-1]["reason"] in ("stale", "failed") and trace[-1]["cue"] == "stop"
    assert trace[-1]["t"] - trace[-2]["t"] == pytest.approx(watchdog or DEFAULT_WATCHDOG_S, rel=1e-3)
    audio, sr = sf.read(out / "beacon.wav")
    assert len(audio) == pytest.approx((trace[-1]["t"] + STOP_TAIL_S) * sr, abs=2)
    # the last second is the stop cue (centred: both channels alike), not the panned beacon
    tail = audio[-sr // 2:]
    el, er = (tail ** 2).sum(0)
    assert abs(el - er) <= 0.05 * (el + er) + 1e-9
    assert BeaconConfig  # (imported for the reader: the cue config is the default one)


def test_complete_video_has_no_warning(tmp_path, toy_bundle, capsys):  # noqa: F811
    from crossing_assist.runtime.demo import main

    full = _avi(tmp_path / "full.avi", [0.5] * 12)
    assert main([str(full), "--bundle", str(toy_bundle), "--out", str(tmp_path / "o"), "--no-video",
                 "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err


# ----------------------------------------------------------------------------- 5. tracebacks


def _ptl(root: Path, body: bytes) -> Path:
    (root / "images").mkdir(parents=True, exist_ok=True)
    save_rgb(root / "images" / "a.png", np.zeros((8, 8, 3), np.uint8))
    (root / "labels.csv").write_bytes(b"image,split,photographer,far_x,bin12\n" + body)
    return root


def _manifest(root: Path, body: bytes) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "manifest.csv").write_bytes(b"image,label,far_x,source,split,votes,flags\n" + body)
    return root


def _frames(root: Path) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "frames.csv").write_text("image,source,t\nv1/f.jpg,vid:v1,0\n")
    return root


def _ls(tasks) -> bytes:
    return tasks if isinstance(tasks, bytes) else json.dumps(tasks).encode()


def _ann(**kw):
    base = {"id": 7, "completed_by": 1, "result": [{"type": "choices", "value": {"choices": ["7"]}}]}
    base.update(kw)
    return base


BIG = b"x" * 200_000  # over the csv module's field limit (131072)
DATA_CASES = {
    "labels.csv non-UTF-8": ("ptl", b"images/a.png,train,j\xff\xfe,0.5,7\n", "not UTF-8"),
    "labels.csv field over the csv limit": ("ptl", b"images/a.png,train," + BIG + b",0.5,7\n", "field larger"),
    "labels.csv NUL in the image path": ("ptl", b"images/a\x00.png,train,j,0.5,7\n", "control characters"),
    "labels.csv 300-character file name": ("ptl", b"images/" + b"a" * 300 + b".png,train,j,0.5,7\n", "not found"),
    "manifest.csv non-UTF-8": ("manifest", b"a.png,7,0.5,s\xff,train,,\n", "not UTF-8"),
    "manifest.csv field over the csv limit": ("manifest", b"a.png,7,0.5," + BIG + b",train,,\n", "field larger"),
    "manifest.csv NUL in the image path": ("manifest", b"a\x00.png,7,0.5,s,train,,\n", "control characters"),
    "manifest.csv 300-character file name": ("manifest", b"a" * 300 + b".png,7,0.5,s,train,,\n", "not found"),
    "votes CSV non-UTF-8": ("csv", b"frame,annotator,label\nf.jpg,\xff,7\n", "not UTF-8"),
    "votes CSV field over the csv limit": ("csv", b"frame,annotator,label\nf.jpg," + BIG + b",7\n", "field larger"),
    "Label Studio non-UTF-8": ("ls", b'[{"id":1,"data":{"image":"f.jpg\xff"}}]', "not UTF-8"),
    "Label Studio data not an object": ("ls", [{"id": 1, "data": "x"}], "no data.image"),
    "Label Studio annotations a string": ("ls", [{"id": 1, "data": {"image": "f.jpg"}, "annotations": "x"}],
                                          "expected a list"),
    "Label Studio annotation a number": ("ls", [{"id": 1, "data": {"image": "f.jpg"}, "annotations": [5]}],
                                         "expected an object"),
    "Label Studio result a string": ("ls", [{"id": 1, "data": {"image": "f.jpg"}, "annotations": [_ann(result="x")]}],
                                     "expected a list"),
    "Label Studio value a string": ("ls", [{"id": 1, "data": {"image": "f.jpg"},
                                            "annotations": [_ann(result=[{"type": "choices", "value": "x"}])]}],
                                    "expected an object"),
    "Label Studio choices a string": ("ls", [{"id": 1, "data": {"image": "f.jpg"},
                                              "annotations": [_ann(result=[{"type": "choices",
                                                                            "value": {"choices": "7"}}])]}],
                                      "expected a list"),
}


@pytest.mark.parametrize("case", sorted(DATA_CASES))
def test_bad_data_files_give_one_line(case, tmp_path, capsys):
    kind, body, message = DATA_CASES[case]
    if kind == "ptl":
        args = ["import-ptl", str(_ptl(tmp_path / "ptl", body)), "--out", str(tmp_path / "o"), "--quiet"]
    elif kind == "manifest":
        args = ["stats", str(_manifest(tmp_path / "ds", body)), "--no-plot"]
    else:
        votes = tmp_path / ("v.csv" if kind == "csv" else "v.json")
        votes.write_bytes(body if kind == "csv" else _ls(body))
        args = ["votes", str(_frames(tmp_path / "fr")), str(votes)]
    assert data_main(args) == 2
    err = capsys.readouterr().err
    assert one_error_line(err) and message in err, err


def test_manifest_unknown_split_is_a_user_error(tmp_path):
    from crossing_assist.data_tools.manifest import Dataset, ManifestError

    with pytest.raises(ManifestError, match="bogus"):
        Dataset(tmp_path, ()).split("bogus")


def test_crossing_eval_split_bogus_is_a_usage_error(capsys):
    from crossing_assist.models.cli import eval_main

    with pytest.raises(SystemExit) as exc:
        eval_main(["--data", "x", "--run", "y", "--split", "bogus"])
    assert exc.value.code == 2 and "invalid choice: 'bogus'" in capsys.readouterr().err


BUNDLE_CASES = {  # field -> raw JSON text put there
    "400-digit integer": ("fov_deg", "9" * 400),
    "over 4300-digit integer": ("fov_deg", "9" * 5000),
    "3000-deep nesting": ("training", "[" * 3000 + "]" * 3000),
    "over-long model_file": ("model_file", '"' + "m" * 400 + '.onnx"'),
    "NUL in model_file": ("model_file", '"m\\u0000.onnx"'),
    "huge model_size": ("model_size", "1" + "0" * 500),
    "huge package_version": ("package_version", "7" * 5000),
}


@pytest.mark.parametrize("case", sorted(BUNDLE_CASES))
def test_bad_bundle_json_gives_one_line(case, tmp_path):
    folder = make_toy_bundle(tmp_path / "b")
    field, raw = BUNDLE_CASES[case]
    meta = json.loads((folder / "bundle.json").read_text())
    meta[field] = "@@RAW@@"
    (folder / "bundle.json").write_text(json.dumps(meta).replace('"@@RAW@@"', raw))
    with pytest.raises(BundleError) as exc:
        read_bundle(folder)
    assert "\n" not in str(exc.value) and len(str(exc.value)) < 400


IIL_CASES = [("--lr", "-1"), ("--ensemble", "0"), ("--expert-threshold", "0"), ("--learner-threshold", "nan"),
             ("--mc-samples", "0"), ("--epochs", "0")]


@pytest.mark.parametrize("flag, value", IIL_CASES)
def test_iil_run_refuses_impossible_numbers(flag, value, tmp_path, capsys):
    from crossing_assist.iil.cli import main

    out = tmp_path / "iil"
    assert main(["run", "--env", "toy", "--algo", "dagger", "--episodes", "1", "--horizon", "2", "--seeds", "1",
                 "--out", str(out), "--quiet", flag, value]) == 2
    err = capsys.readouterr().err
    assert one_error_line(err) and flag in err
    assert not out.exists()  # refused before any work (no NaN results written)


# ----------------------------------------------------------------------------- 6. safety switches


@pytest.mark.parametrize("value", ["inf", "nan", "0", "-1", "2.5", "1e9"])
def test_demo_watchdog_is_bounded(value, capsys):
    from crossing_assist.runtime.demo import MAX_WATCHDOG_S, main

    assert MAX_WATCHDOG_S <= 2.0
    assert main(["--watchdog", value]) == 2
    assert "--watchdog" in capsys.readouterr().err


def test_edited_fov_in_bundle_json_is_caught_against_the_graph(tmp_path):
    import onnxruntime as ort

    from crossing_assist.bundle import check_session

    folder = make_toy_bundle(tmp_path / "b")
    meta = json.loads((folder / "bundle.json").read_text())
    meta["fov_deg"] = 120.0
    (folder / "bundle.json").write_text(json.dumps(meta))
    bundle = read_bundle(folder)  # the json alone is valid...
    sess = ort.InferenceSession(str(bundle.model_path), providers=["CPUExecutionProvider"])
    with pytest.raises(BundleError, match="fov_deg"):  # ...but disagrees with the graph's facts
        check_session(bundle, sess)


# ----------------------------------------------------------------------------- 7. leftovers


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_sweep_removes_only_dead_writers_temporaries(tmp_path):
    dead, live = _dead_pid(), os.getpid()
    names = {f".last.ab12.tmp{dead}.pt": True, f".bundle.tmp{dead}-x1y2": True, f".trace.tmp{dead}-q.jsonl": True,
             f".annotated.tmp{dead}.mp4": True, f".last.cd34.tmp{live}.pt": False, "last.pt": False,
             ".bashrc": False, f"notes.tmp{dead}": False, "results.csv": False}
    for name in names:
        (tmp_path / name).mkdir() if name.startswith(".bundle") else (tmp_path / name).write_text("x")
    removed = {p.name for p in sweep_orphans(tmp_path)}
    assert removed == {n for n, gone in names.items() if gone}
    assert {p.name for p in tmp_path.iterdir()} == {n for n, gone in names.items() if not gone}


def test_offline_demo_sweeps_what_a_killed_run_left(tmp_path, toy_bundle):  # noqa: F811
    from crossing_assist.runtime.offline import OfflineConfig, run_offline

    out = tmp_path / "out"
    out.mkdir()
    dead = _dead_pid()
    for name in (f".trace.tmp{dead}-abc.jsonl", f".annotated.tmp{dead}.mp4"):
        (out / name).write_text("partial")
    clip = _avi(tmp_path / "c.avi", [0.5] * 5)
    run_offline(OfflineConfig(video=clip, bundle=toy_bundle, out_dir=out, annotate=False, progress=False, plot=False))
    assert sorted(p.name for p in out.iterdir()) == ["beacon.wav", "trace.jsonl"]


def test_write_bundle_sweeps_a_killed_writers_partial_bundle(tmp_path, toy_bytes):
    dead = _dead_pid()
    partial = tmp_path / f".bundle.tmp{dead}-abcd"
    partial.mkdir()
    (partial / "model.onnx").write_bytes(b"\x08partial")
    write_bundle(tmp_path / "bundle", *toy_bytes)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle"]


# ----------------------------------------------------------------------------- 8. weak messages


def test_label_studio_without_completed_by_counts_each_annotation(tmp_path, capsys):
    from crossing_assist.data_tools.manifest import read_manifest

    fr = _frames(tmp_path / "fr")
    (fr / "v1").mkdir()
    save_rgb(fr / "v1" / "f.jpg", np.zeros((8, 8, 3), np.uint8))
    anns = [{"id": k, "result": [{"type": "choices", "value": {"choices": [c]}}]} for k, c in ((1, "7"), (2, "7"))]
    (tmp_path / "v.json").write_text(json.dumps([{"id": 1, "data": {"image": "f.jpg"}, "annotations": anns}]))
    assert data_main(["votes", str(fr), str(tmp_path / "v.json")]) == 0, capsys.readouterr().err
    assert read_manifest(fr).rows[0].votes == {7: 2}


@pytest.mark.parametrize("kind", ["text", "truncated jpeg", "truncated png", "empty"])
def test_import_ptl_checks_images(kind, tmp_path, capsys):
    ptl = _ptl(tmp_path / "ptl", b"images/b.jpg,train,j,0.5,7\n")
    good = cv2.imencode(".png" if "png" in kind else ".jpg", np.full((32, 32, 3), 90, np.uint8))[1].tobytes()
    data = {"text": b"hello, not a picture", "empty": b""}.get(kind, good[: len(good) // 2])
    (ptl / "images" / "b.jpg").write_bytes(data)
    assert data_main(["import-ptl", str(ptl), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert one_error_line(err) and "line 2" in err and "b.jpg" in err
    assert not (tmp_path / "o" / "manifest.csv").exists()


def test_garbage_weights_file_is_one_short_line(tmp_path, capsys):
    from crossing_assist.models.cli import train_main

    bad = tmp_path / "w.pth"
    bad.write_bytes(b"garbage" * 100)
    ds = _manifest(tmp_path / "ds", b"a.png,7,0.55,s,train,,\n")
    save_rgb(ds / "a.png", np.zeros((8, 8, 3), np.uint8))
    assert train_main(["--data", str(ds), "--out", str(tmp_path / "run"), "--backbone", "mobilenet_v3_small",
                       "--weights", str(bad), "--select-on", "last", "--cache-dir", str(tmp_path / "c"),
                       "--quiet"]) == 2
    err = capsys.readouterr().err
    assert one_error_line(err) and "w.pth" in err and len(err) < 300


def test_ctrl_c_hint_says_resume_only_when_there_is_something_to_resume(tmp_path):
    from crossing_assist.models.cli import _resume_hint

    hint = _resume_hint(str(tmp_path / "run"))
    assert "nothing to resume" in hint() and "--resume" not in hint().split("nothing")[0]
    (tmp_path / "run" / "weights").mkdir(parents=True)
    (tmp_path / "run" / "weights" / "last.pt").write_bytes(b"x")
    assert "--resume" in hint()


def test_sigterm_cleans_up_like_ctrl_c(tmp_path):
    """``kill PID`` (SIGTERM) mid-write: exit 143 and the temporary file is removed."""
    code = ("import sys, time\n"
            "from crossing_assist.errors import run_cli\n"
            "from crossing_assist.fileio import atomic_path\n"
            "def body(args):\n"
            "    with atomic_path(sys.argv[1]) as tmp:\n"
            "        tmp.write_text('half'); print('ready', flush=True); time.sleep(60)\n"
            "sys.exit(run_cli(body, []))\n")
    target = tmp_path / "out.txt"
    proc = subprocess.Popen([sys.executable, "-c", code, str(target)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    ready = proc.stdout.readline().strip()
    proc.terminate()
    _, err = proc.communicate(timeout=120)
    assert ready == "ready" and proc.returncode == 143, err
    assert list(tmp_path.iterdir()) == []


def test_short_repr_keeps_an_error_line_short_and_on_one_line():
    """The one cut-to-length repr (errors.short_repr) behind bundle.json and Label Studio errors:
    the values the long fuzz found (a 2000-character list of huge ints, an id with a newline)."""
    import sys as _sys

    from crossing_assist.errors import short_repr

    huge = [10 ** 400] * 5
    assert len(short_repr(huge)) == 60 and short_repr(huge).endswith("...")
    assert short_repr("a\nb") == "'a\\nb'" and "\n" not in short_repr("a\nb")
    assert short_repr(7) == "7" and short_repr("x" * 100, 40).endswith("...")
    assert short_repr(10 ** (_sys.get_int_max_str_digits() + 10)) == "<int too long to show>"

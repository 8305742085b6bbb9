"""Hostile-user cases of issue 16 against a code tree (the audit behind the issue's numbers).

    python scripts/reliability_audit.py CODE_ROOT WORK_DIR      # e.g. . /tmp/audit (WORK_DIR: new, or an earlier audit's)

Each case runs a command in a subprocess and is classed: clean (expected outcome, at most one
error line), traceback, crash (killed by a signal), data-loss (a file that must survive is gone),
wrong (no traceback but not the expected outcome: silently accepted, wrong count, no warning).
"""
import json, os, shutil, subprocess, sys
from pathlib import Path

CODE, WORK = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
sys.path.insert(0, str(CODE)); sys.path.insert(0, str(CODE / "tests"))
import numpy as np, cv2
from crossing_assist.data_tools.images import save_rgb
from runtime_toy import make_toy_bundle, bar_frame

MARK = ".reliability_audit"
if WORK.exists() and any(WORK.iterdir()) and not (WORK / MARK).is_file():
    sys.exit(f"error: {WORK} is not empty and not an earlier audit folder; pick a new WORK_DIR")
if WORK.exists():
    shutil.rmtree(WORK)  # an earlier audit's folder (it holds the mark)
WORK.mkdir(parents=True)
(WORK / MARK).write_text("")
PY = sys.executable
ENV = {**os.environ, "PYTHONPATH": str(CODE), "OMP_NUM_THREADS": "1"}
CLI = {"data": [PY, "-m", "crossing_assist.data_tools.cli"], "train": [PY, "-m", "crossing_assist.models.cli", "train"],
       "eval": [PY, "-m", "crossing_assist.models.cli", "eval"], "export": [PY, "-m", "crossing_assist.export"],
       "demo": [PY, "-m", "crossing_assist.runtime.demo"], "iil": [PY, "-m", "crossing_assist.iil.cli"]}
results = []


def case(name, cmd, args, expect_rc=(2,), survive=(), check=None, timeout=300):
    r = subprocess.run(CLI[cmd] + [str(a) for a in args], capture_output=True, text=True, env=ENV, timeout=timeout,
                       cwd=WORK)
    lines = [l for l in r.stderr.splitlines() if l.strip() and not l.startswith(("warning:", "note:", "[", " "))]
    if lines and lines[0].startswith("usage:"):  # argparse: usage lines, then one "PROG: error: ..." line
        lines = [l for l in lines if ": error:" in l]
    lost = [str(p) for p in survive if not Path(p).exists() or (Path(p).suffix and not Path(p).is_file())]
    if lost:
        kind = "data-loss"
    elif r.returncode < 0 or r.returncode >= 128 and r.returncode != 130:
        kind = "crash"
    elif "Traceback" in r.stderr:
        kind = "traceback"
    elif r.returncode not in expect_rc or (r.returncode != 0 and len(lines) != 1) or (check and not check(r)):
        kind = "wrong"
    else:
        kind = "clean"
    results.append((name, kind, r.returncode, (lines[-1] if lines else "")[:150]))
    print(f"{kind:9s} rc={r.returncode:4d} {name}: {(lines[-1] if lines else '')[:110]}", flush=True)


# ---------------------------------------------------------------- data files
def ptl(name, body, extra=None):
    d = WORK / name; (d / "images").mkdir(parents=True)
    save_rgb(d / "images" / "a.png", np.zeros((8, 8, 3), np.uint8))
    if extra:
        extra(d)
    (d / "labels.csv").write_bytes(b"image,split,photographer,far_x,bin12\n" + body)
    return d


def manifest(name, body):
    d = WORK / name; d.mkdir()
    (d / "manifest.csv").write_bytes(b"image,label,far_x,source,split,votes,flags\n" + body)
    return d


frames = WORK / "frames"; (frames / "v1").mkdir(parents=True)
(frames / "frames.csv").write_text("image,source,t\nv1/f.jpg,vid:v1,0\n")
save_rgb(frames / "v1" / "f.jpg", np.zeros((8, 8, 3), np.uint8))
BIG = b"x" * 200_000
for nm, body in [("nonutf8", b"images/a.png,train,j\xff,0.5,7\n"), ("bigfield", b"images/a.png,train," + BIG + b",0.5,7\n"),
                 ("nul", b"images/a\x00.png,train,j,0.5,7\n"), ("longname", b"images/" + b"a" * 300 + b".png,train,j,0.5,7\n")]:
    case(f"labels.csv {nm}", "data", ["import-ptl", ptl("ptl_" + nm, body), "--out", WORK / ("o_" + nm), "--quiet"])
case("import-ptl text .jpg", "data", ["import-ptl", ptl("ptl_text", b"images/t.jpg,train,j,0.5,7\n",
                                                         lambda d: (d / "images/t.jpg").write_text("hello")),
                                      "--out", WORK / "o_text", "--quiet"])
jpg = cv2.imencode(".jpg", np.full((64, 64, 3), 90, np.uint8))[1].tobytes()
case("import-ptl truncated .jpg", "data", ["import-ptl", ptl("ptl_trunc", b"images/t.jpg,train,j,0.5,7\n",
                                                              lambda d: (d / "images/t.jpg").write_bytes(jpg[:len(jpg) // 2])),
                                           "--out", WORK / "o_trunc", "--quiet"])
for nm, body in [("nonutf8", b"a.png,7,0.5,s\xff,train,,\n"), ("bigfield", b"a.png,7,0.5," + BIG + b",train,,\n"),
                 ("nul", b"a\x00.png,7,0.5,s,train,,\n"), ("longname", b"a" * 300 + b".png,7,0.5,s,train,,\n")]:
    case(f"manifest.csv {nm}", "data", ["stats", manifest("m_" + nm, body), "--no-plot"])
for nm, body in [("nonutf8", b"frame,annotator,label\nf.jpg,\xff,7\n"), ("bigfield", b"frame,annotator,label\nf.jpg," + BIG + b",7\n")]:
    (WORK / f"v_{nm}.csv").write_bytes(body)
    case(f"votes CSV {nm}", "data", ["votes", frames, WORK / f"v_{nm}.csv"])
ann = lambda **kw: {"id": 7, "completed_by": 1, "result": [{"type": "choices", "value": {"choices": ["7"]}}], **kw}
LS = {"nonutf8": b'[{"id":1,"data":{"image":"f.jpg\xff"}}]',
      "data a string": [{"id": 1, "data": "x"}],
      "annotations a string": [{"id": 1, "data": {"image": "f.jpg"}, "annotations": "x"}],
      "annotation a number": [{"id": 1, "data": {"image": "f.jpg"}, "annotations": [5]}],
      "result a string": [{"id": 1, "data": {"image": "f.jpg"}, "annotations": [ann(result="x")]}],
      "value a string": [{"id": 1, "data": {"image": "f.jpg"}, "annotations": [ann(result=[{"type": "choices", "value": "x"}])]}]}
for nm, body in LS.items():
    (WORK / "ls.json").write_bytes(body if isinstance(body, bytes) else json.dumps(body).encode())
    case(f"Label Studio {nm}", "data", ["votes", frames, WORK / "ls.json"])
anon = [{"id": k, "result": [{"type": "choices", "value": {"choices": ["7"]}}]} for k in (1, 2)]
(WORK / "ls.json").write_text(json.dumps([{"id": 1, "data": {"image": "f.jpg"}, "annotations": anon}]))
case("Label Studio without completed_by (2 votes)", "data", ["votes", frames, WORK / "ls.json"], expect_rc=(0,))

# ---------------------------------------------------------------- bundles / demo
toy = make_toy_bundle(WORK / "toy")
clip = WORK / "clip.avi"
w = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 10, (96, 72))
for i in range(40):
    w.write(cv2.cvtColor(bar_frame(0.8), cv2.COLOR_RGB2BGR))
w.release()


def edited(name, field, raw):
    d = WORK / name; shutil.copytree(toy, d)
    meta = json.loads((d / "bundle.json").read_text()); meta[field] = "@@"
    (d / "bundle.json").write_text(json.dumps(meta).replace('"@@"', raw))
    return d


for nm, field, raw in [("400-digit int", "fov_deg", "9" * 400), ("5000-digit int", "fov_deg", "9" * 5000),
                       ("3000-deep nesting", "training", "[" * 3000 + "]" * 3000),
                       ("over-long model_file", "model_file", '"' + "m" * 400 + '.onnx"')]:
    case(f"bundle.json {nm}", "demo", [clip, "--bundle", edited("b_" + nm.replace(" ", "_"), field, raw), "--out",
                                       WORK / "d", "--no-video", "--quiet"])
case("bundle.json edited fov_deg", "demo", [clip, "--bundle", edited("b_fov", "fov_deg", "120.0"), "--out", WORK / "d",
                                            "--no-video", "--quiet"])
case("demo --camera -1 --live", "demo", ["--camera", "-1", "--live", "--bundle", toy])
case("demo --watchdog inf", "demo", [clip, "--bundle", toy, "--watchdog", "inf", "--out", WORK / "d", "--no-video", "--quiet"])
cut = WORK / "cut.avi"; cut.write_bytes(clip.read_bytes()[: clip.stat().st_size // 2])


def ends_on_stop(r):
    trace = [json.loads(l) for l in (WORK / "dcut" / "trace.jsonl").read_text().splitlines()]
    return "warning:" in r.stderr and trace[-1]["stop"] is True


case("demo on a truncated video", "demo", [cut, "--bundle", toy, "--out", WORK / "dcut", "--no-video", "--quiet"],
     expect_rc=(0,), check=ends_on_stop)

# ---------------------------------------------------------------- iil
for flag, value in [("--lr", "-1"), ("--ensemble", "0"), ("--expert-threshold", "0"), ("--learner-threshold", "nan"),
                    ("--mc-samples", "0")]:
    case(f"crossing-iil run {flag} {value}", "iil", ["run", "--env", "toy", "--algo", "dagger", "--episodes", "1",
                                                     "--horizon", "4", "--seeds", "1", "--out", WORK / f"iil{flag}", "--quiet",
                                                     flag, value], timeout=600)

# ---------------------------------------------------------------- train / eval / export
sys.path.insert(0, str(CODE / "tests"))
from test_models_train import make_tiny_dataset
data = make_tiny_dataset(WORK / "tiny")
run = WORK / "run"
base = ["--data", data, "--out", run, "--backbone", "mobilenet_v3_small", "--weights", "none", "--input-size", "64",
        "--batch-size", "4", "--cache-dir", WORK / "cache", "--quiet"]
case("train 2 epochs", "train", base + ["--epochs", "2"], expect_rc=(0,))
case("train --resume --epochs 4 (extension)", "train", base + ["--epochs", "4", "--resume"], expect_rc=(0, 2),
     check=lambda r: r.returncode == 2 or ("trained 4 epochs" in r.stdout and "4" == open(run / "results.csv").read().splitlines()[-1].split(",")[0]))
case("train --resume --actions 4 (changed)", "train", base + ["--actions", "4", "--resume"])
(WORK / "garbage.pth").write_bytes(b"garbage" * 50)
case("train --weights garbage", "train", ["--data", data, "--out", WORK / "run2", "--backbone", "mobilenet_v3_small",
                                          "--weights", WORK / "garbage.pth", "--cache-dir", WORK / "cache", "--quiet"])
case("eval --split bogus", "eval", ["--run", run, "--data", data, "--split", "bogus", "--quiet"])
for k in ("a", "b"):
    shutil.copytree(run, WORK / f"run_{k}")
survive = [run / "weights" / "best.pt", run / "weights" / "last.pt", run / "results.csv"]
case("export --out RUN_FOLDER", "export", ["--run", run, "--out", run, "--samples", "2", "--parity-frames", "2",
                                           "--quiet"], survive=survive)
case("export --out DATASET", "export", ["--run", WORK / "run_a", "--out", data, "--samples", "2", "--parity-frames", "2", "--quiet"],
     survive=[data / "manifest.csv"])
(WORK / "notes.txt").write_text("precious")
case("export --out PLAIN_FILE", "export", ["--run", WORK / "run_b", "--out", WORK / "notes.txt", "--samples", "2",
                                           "--parity-frames", "2", "--quiet"], survive=[WORK / "notes.txt"],
     check=lambda r: (WORK / "notes.txt").is_file())

kinds = [k for _, k, _, _ in results]
print({k: kinds.count(k) for k in ("clean", "traceback", "crash", "data-loss", "wrong")}, "of", len(kinds))
json.dump(results, open(WORK / "results.json", "w"), indent=1)

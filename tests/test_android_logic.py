"""The phone app's JavaScript against the Python runtime, in Node (android_demo/).

Runs the app's Node unit tests (which replay android_demo/test_vectors.json), checks the JS
ports of the action vocabulary, the defaults and the decision logic against the Python
modules on fresh random scenarios, and the build step's bundle checks. Skips cleanly when
Node.js (>= 18) is not installed; the build tests also need `npm ci` in android_demo.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.actions import get_space, x_to_heading
from crossing_assist.runtime.beacon import BeaconConfig
from crossing_assist.runtime.decide import Decider, DecisionConfig, Observation
from crossing_assist.runtime.live import LiveConfig

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "android_demo"
JS = DEMO / "www" / "js"
NODE = shutil.which("node")


def _node_major() -> int:
    out = subprocess.run([NODE, "--version"], capture_output=True, text=True, timeout=30).stdout
    m = re.match(r"v(\d+)", out.strip())
    return int(m.group(1)) if m else 0


pytestmark = pytest.mark.skipif(NODE is None or _node_major() < 18,
                                reason="Node.js >= 18 is not installed (apt-get install nodejs)")


def run_node(script: str, *, timeout: float = 60) -> str:
    """Run an ES-module snippet with Node; returns stdout (fails the test on a non-zero exit)."""
    proc = subprocess.run([NODE, "--input-type=module", "-e", script], capture_output=True, text=True,
                          timeout=timeout, cwd=DEMO)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def js_module(name: str) -> str:
    return (JS / name).as_uri()


def test_node_unit_tests_pass() -> None:
    proc = subprocess.run([NODE, "--test", "test/"], capture_output=True, text=True, timeout=180, cwd=DEMO)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    passed = int(re.search(r"^# pass (\d+)", out, re.M).group(1))
    assert passed >= 10 and re.search(r"^# fail 0$", out, re.M), out[-2000:]
    if (DEMO / "test_vectors.json").is_file():
        assert re.search(r"^# skipped 0$", out, re.M), "the vectors test was skipped although the file exists"


def test_action_vocabulary_port_matches_python() -> None:
    out = json.loads(run_node(f"""
        import {{ actionHeading, headingToPan, spaceGroups, spaceNames, xToHeading }} from '{js_module("actions.js")}';
        const r = {{}};
        for (const n of [4, 8, 13]) {{
          const g = spaceGroups(n);
          r[n] = {{ groups: g, names: spaceNames(n),
                   headings: g.map((_, a) => (a === 0 ? null : actionHeading(g, a, 70))) }};
        }}
        r.x = [0, 0.1, 0.37, 0.5, 0.93, 1].map((x) => xToHeading(x, 90));
        r.pan = [-80, -45, -10, 0, 12.5, 44.9, 60].map((h) => headingToPan(h, 45));
        console.log(JSON.stringify(r));
    """))
    for n in (4, 8, 13):
        space = get_space(n)
        assert out[str(n)]["groups"] == [list(g) for g in space.groups]
        assert out[str(n)]["names"] == list(space.names)
        want = [None] + [space.action_heading(a, 70.0) for a in range(1, n)]
        assert out[str(n)]["headings"][0] is None
        assert np.allclose(out[str(n)]["headings"][1:], want[1:], rtol=0, atol=1e-12)
    assert np.allclose(out["x"], [x_to_heading(x, 90.0) for x in (0, 0.1, 0.37, 0.5, 0.93, 1)], atol=1e-12)
    assert out["pan"] == [max(-1.0, min(1.0, h / 45)) for h in (-80, -45, -10, 0, 12.5, 44.9, 60)]


def test_js_defaults_are_the_python_defaults() -> None:
    out = json.loads(run_node(f"""
        import {{ decisionConfig }} from '{js_module("logic.js")}';
        import {{ SOUND }} from '{js_module("audio.js")}';
        import {{ WATCHDOG_S }} from '{js_module("live.js")}';
        console.log(JSON.stringify({{ decision: decisionConfig({{}}), sound: SOUND, watchdog: WATCHDOG_S }}));
    """))
    assert out["decision"] == asdict(DecisionConfig())
    beacon = asdict(BeaconConfig())
    for key, value in out["sound"].items():
        assert beacon[key] == value, key
    assert out["watchdog"] == LiveConfig().watchdog_s


def test_js_gyroscope_integrator_and_check_match_python() -> None:
    """The Python runtime's gyroscope (runtime/gyro.py) is the app's: the same turns between two
    times over irregular samples with gaps, the same reporting, the same verdicts and
    confirmations of the picture's check over random pairs of turn rates and a walker's sway."""
    from crossing_assist.runtime.gyro import GYRO_CHECK, GyroCheck, YawIntegrator

    rng = np.random.default_rng(11)
    t, samples = 0.0, []
    for _ in range(400):
        t += float(rng.choice([rng.uniform(0.005, 0.02), rng.uniform(0.2, 0.5)], p=[0.97, 0.03]))
        samples.append([t, float(rng.uniform(-80, 80))])
    queries = [sorted(map(float, rng.uniform(0, t + 0.3, 2))) for _ in range(60)] + [[1.0, 1.0], [2.0, 1.5]]
    pairs = [[float(rng.choice([-1, 1]) * rng.uniform(0, 40)), float(rng.choice([-1, 1]) * rng.uniform(0, 40))]
             for _ in range(120)]
    # the picture agreeing with the gyroscope on most turns, then (a wrong sign) disagreeing
    same = [[g, math.copysign(c, g) if i % 5 else c] for i, (g, c) in enumerate(pairs)]
    flip = [[g, -c if i > 50 else c] for i, (g, c) in enumerate(same)]
    pairs = same
    # a walker's sway read by the picture with noise, misreads and frames read as no turn
    # (stamped 0.12 s late against the gyroscope: the lags' windows find it), with the gyroscope's
    # turn over each frame's interval moved back by each of sway_lags_s
    yaw = lambda s: 2.5 * np.sin(2 * np.pi * 0.9 * s)  # noqa: E731
    t = np.arange(81) / 10
    rates, late = np.diff(yaw(t)) * 10, np.diff(yaw(t - 0.12)) * 10
    back = [np.diff(yaw(t - lag)) * 10 for lag in GYRO_CHECK.sway_lags_s[1:]]
    sway = [[float(r), float(0.0 if i % 9 == 4 else -200.0 if i % 13 == 7 else 1.03 * late[i] + rng.normal(0, 1)),
             [float(b[i]) for b in back]] for i, r in enumerate(rates)]
    out = json.loads(run_node(f"""
        import {{ GyroCheck, YawIntegrator }} from '{js_module("live.js")}';
        const samples = {json.dumps(samples)}, queries = {json.dumps(queries)};
        const y = new YawIntegrator();
        // one query a sample, as the app asks while samples arrive (the integrator keeps 3 s)
        const between = [], reporting = [];
        samples.forEach(([t, r], i) => {{
          y.add(r, t);
          const [t0, t1] = queries[i % queries.length];
          between.push(y.between(Math.max(t0, t - 2.5), t + t1 % 0.3));
          reporting.push(y.reporting(t + t1 % 0.3));
        }});
        const verdicts = (pairs) => {{ const g = new GyroCheck(); return pairs.map(([a, b, l]) => [g.add(a, b, l), g.confirmation()]); }};
        console.log(JSON.stringify({{ between, reporting, same: verdicts({json.dumps(pairs)}),
                                      flip: verdicts({json.dumps(flip)}), sway: verdicts({json.dumps(sway)}) }}));
    """))
    y, between, reporting = YawIntegrator(), [], []
    for i, (t, r) in enumerate(samples):
        y.add(r, t)
        t0, t1 = queries[i % len(queries)]
        between.append(y.between(max(t0, t - 2.5), t + t1 % 0.3))
        reporting.append(y.reporting(t + t1 % 0.3))
    np.testing.assert_allclose(out["between"], between, rtol=1e-9, atol=1e-9)
    assert out["reporting"] == reporting and 0 < sum(reporting) < len(reporting)
    for key, seq in (("same", pairs), ("flip", flip), ("sway", sway)):
        g = GyroCheck(GYRO_CHECK)
        assert out[key] == [[g.add(*pair), g.confirmation()] for pair in seq], key
    assert out["flip"][-1][0] == "wrong" and any(c for _, c in out["same"])
    assert out["sway"][-1] == ["unchecked", "sway"]   # confirmed by the sway alone


def test_the_app_s_field_recording_log_is_what_crossing_demo_imu_reads(tmp_path) -> None:
    """record.js writes the motion log the app records (?record=1) in runtime/imu.py's format:
    Python reads back each kept sample's time, rate and roll (an unknown roll: none), the rows a
    gyroscope's integrator would drop (not after the one before, not a number) left out."""
    from crossing_assist.runtime.imu import ImuLog

    rows = [[0.0, 12.5, None], [0.01, -3.25, 4.5], [0.01, 99.0, 1.0], [0.02, float("nan"), 2.0],
            [0.03, 40.0, -12.0], [0.5, 1.0, None], [0.51, 2.0, 3.0]]
    js_rows = json.dumps(rows)   # NaN is JavaScript's too
    out = json.loads(run_node(f"""
        import {{ imuCsv, videoType }} from '{js_module("record.js")}';
        console.log(JSON.stringify({{ csv: imuCsv({js_rows}),
          type: videoType((t) => t === 'video/webm'), none: videoType(() => false) }}));
    """))
    assert out["type"] == "video/webm" and out["none"] == ""
    (tmp_path / "walk.imu.csv").write_text(out["csv"])
    log = ImuLog.load(tmp_path / "walk.imu.csv")
    assert log.t == (0.0, 0.01, 0.03, 0.5, 0.51) and log.yaw_dps == (12.5, -3.25, 40.0, 1.0, 2.0)
    assert log.roll_at(0.01) == 4.5 and log.roll_at(0.02) == pytest.approx(4.5 + 0.5 * (-12.0 - 4.5))
    assert log.roll_at(0.0) is None and log.roll_at(0.505) is None and log.roll_at(0.51) == 3.0
    assert log.turn(0.0, 0.03) == pytest.approx(-3.25 * 0.01 + 40.0 * 0.02)


def _random_scenario(rng: np.random.Generator, cfg: DecisionConfig, n: int) -> dict:
    """Random frames, ticks, failures, irregular times and yaw; expected decisions from Python."""
    decider = Decider(cfg)
    steps, t = [], 0.0
    for _ in range(n):
        t += float(rng.choice([0.0, rng.uniform(0.0, 0.12), rng.uniform(0.3, 0.9)], p=[0.05, 0.85, 0.1]))
        yaw = float(rng.uniform(-50, 50)) if rng.uniform() < 0.3 else 0.0
        r = rng.uniform()
        if r < 0.1:
            obs = None
        elif r < 0.15:
            obs = Observation(None, math.inf, ok=False)
        else:
            probs = rng.dirichlet(np.full(cfg.n_actions, 0.3))
            obs = Observation(probs, float(rng.uniform(0.0, 2.5 * cfg.threshold)))
        d = decider.step(t, obs, yaw)
        steps.append({"t": t, "yaw_rate_dps": yaw, "expect": d.to_json(),
                      "obs": None if obs is None else {
                          "ok": obs.ok, "probs": None if obs.probs is None else obs.probs.tolist(),
                          "uncertainty": obs.uncertainty if math.isfinite(obs.uncertainty) else None}})
    return {"name": f"random_{cfg.n_actions}_{cfg.measure}", "config": asdict(cfg), "steps": steps}


def test_js_decider_matches_python_on_random_scenarios(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    base = DecisionConfig()
    cfgs = [base, replace(base, n_actions=4, fov_deg=70.0), replace(base, n_actions=8, measure="mutual_info",
                                                                    threshold=0.3, watchdog_s=0.3)]
    vectors = {"version": 1, "tolerance": 1e-9, "scenarios": [_random_scenario(rng, c, 150) for c in cfgs]}
    path = tmp_path / "random_vectors.json"
    path.write_text(json.dumps(vectors))
    out = json.loads(run_node(f"""
        import {{ readFileSync }} from 'node:fs';
        import {{ replayVectors }} from '{js_module("vectors.js")}';
        console.log(JSON.stringify(replayVectors(JSON.parse(readFileSync({json.dumps(str(path))}, 'utf8')))));
    """))
    assert out["steps"] == 450
    assert out["failures"] == [] and out["nFailures"] == 0
    stops = sum(s["expect"]["stop"] for sc in vectors["scenarios"] for s in sc["steps"])
    assert 0 < stops < 450  # the scenarios exercise both beacon and stop


def test_js_view_rows_matches_python_on_random_frames(tmp_path: Path) -> None:
    """geometry.js viewRows against crossing_assist.geometry.view_rows (the view crop, schema 3) on
    random frame sizes, FOVs, canvases and training FOVs: the same integers, every time."""
    from crossing_assist.geometry import view_rows

    rng = np.random.default_rng(11)
    cases = []
    for _ in range(3000):
        w, h = (int(v) for v in rng.integers(1, 4097, size=2))
        fov, train = (float(v) for v in rng.uniform(20.0, 170.0, size=2))
        if rng.uniform() < 0.3:
            fov, train = float(rng.integers(20, 171)), float(rng.integers(20, 171))   # whole degrees too
        canvas = [int(v) for v in rng.integers(16, 4097, size=2)]
        cases.append([h, w, fov, canvas, train, list(view_rows(h, w, fov, tuple(canvas), train))])
    path = tmp_path / "cases.json"
    path.write_text(json.dumps(cases))
    bad = json.loads(run_node(f"""
        import {{ readFileSync }} from 'node:fs';
        import {{ viewRows }} from '{js_module("geometry.js")}';
        const cases = JSON.parse(readFileSync({json.dumps(str(path))}, 'utf8'));
        const bad = cases.filter(([h, w, fov, canvas, train, want]) =>
          JSON.stringify(viewRows(h, w, fov, canvas, train)) !== JSON.stringify(want));
        console.log(JSON.stringify(bad));
    """))
    assert bad == []
    assert 0 < sum(c[5][1] < c[0] for c in cases) < len(cases)   # both cropped and whole frames


# ----------------------------------------------------------------------------- build step

NO_NPM = not (DEMO / "node_modules" / "onnxruntime-web" / "dist").is_dir()
needs_npm = pytest.mark.skipif(NO_NPM, reason="npm packages not installed: run `npm ci` in android_demo")


def _make_bundle(out: Path) -> Path:
    pytest.importorskip("onnx", reason="onnx is needed to make the test bundle (pip install -e '.[train]')")
    from crossing_assist.testing.toy_bundle import APP_TOY, make_toy_bundle

    return make_toy_bundle(out, APP_TOY)


@needs_npm
def test_build_copies_only_the_wasm_runtime_and_lists_the_cache(tmp_path: Path) -> None:
    www = tmp_path / "www"
    shutil.copytree(DEMO / "www", www, ignore=shutil.ignore_patterns("vendor", "bundle", "precache.json"))
    bundle = _make_bundle(tmp_path / "bundle")
    proc = subprocess.run([NODE, "tools/build.mjs", "--bundle", str(bundle), "--www", str(www)],
                          capture_output=True, text=True, timeout=120, cwd=DEMO)
    assert proc.returncode == 0, proc.stderr
    vendor = sorted(p.name for p in (www / "vendor").iterdir() if not p.name.endswith(".gz"))
    wasm_only = ["ort.wasm.min.mjs", "ort-wasm-simd-threaded.mjs", "ort-wasm-simd-threaded.wasm"]
    webgpu = ["ort.webgpu.min.mjs", "ort-wasm-simd-threaded.asyncify.mjs", "ort-wasm-simd-threaded.asyncify.wasm"]
    assert vendor == sorted(wasm_only + webgpu)
    pre = json.loads((www / "precache.json").read_text())
    urls = {f["url"] for f in pre["files"]}
    assert not {f"vendor/{n}" for n in webgpu} & urls  # fetched only by a phone with WebGPU
    assert not [u for u in urls if u.endswith(".gz")]
    # gzip twins: the wasm shrinks to under a third, and decompresses to the same bytes
    import gzip

    raw = (www / "vendor" / "ort-wasm-simd-threaded.wasm").read_bytes()
    twin = (www / "vendor" / "ort-wasm-simd-threaded.wasm.gz").read_bytes()
    assert len(twin) < len(raw) / 3 and gzip.decompress(twin) == raw
    assert {"index.html", "js/app.js", "bundle/model.onnx", "bundle/bundle.json",
            "vendor/ort-wasm-simd-threaded.wasm", "manifest.webmanifest"} <= urls
    assert "sw.js" not in urls and len(pre["version"]) == 16
    assert ("test_vectors.json" in urls) == (DEMO / "test_vectors.json").is_file()  # the self-test's data
    # a different bundle gives a different cache version (phones pick up the swap); metrics are
    # not checked against the graph's copy (an edited threshold is refused: below)
    meta = json.loads((bundle / "bundle.json").read_text())
    meta["metrics"] = {"edited": 1}
    (bundle / "bundle.json").write_text(json.dumps(meta))
    subprocess.run([NODE, "tools/build.mjs", "--bundle", str(bundle), "--www", str(www)],
                   capture_output=True, text=True, timeout=120, cwd=DEMO, check=True)
    assert json.loads((www / "precache.json").read_text())["version"] != pre["version"]


@needs_npm
@pytest.mark.parametrize("damage", ["model", "json", "missing", "edited"])
def test_build_refuses_a_bad_bundle_with_one_line(tmp_path: Path, damage: str) -> None:
    bundle = _make_bundle(tmp_path / "bundle")
    if damage == "model":
        data = bytearray((bundle / "model.onnx").read_bytes())
        data[-1] ^= 0xFF
        (bundle / "model.onnx").write_bytes(bytes(data))
    elif damage == "json":
        meta = json.loads((bundle / "bundle.json").read_text())
        meta["actions"]["n"] = 5
        (bundle / "bundle.json").write_text(json.dumps(meta))
    elif damage == "edited":  # valid on its own, but no longer what the graph embeds
        meta = json.loads((bundle / "bundle.json").read_text())
        meta["calibration"]["uncertainty"]["threshold"] = 0.9
        (bundle / "bundle.json").write_text(json.dumps(meta))
    else:
        bundle = tmp_path / "nowhere"
    proc = subprocess.run([NODE, "tools/build.mjs", "--bundle", str(bundle), "--www", str(tmp_path / "www")],
                          capture_output=True, text=True, timeout=120, cwd=DEMO)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert {"model": "SHA-256", "json": "actions.n", "missing": "no bundle",
            "edited": "calibration.uncertainty.threshold = 0.9 disagrees with the model's"}[damage] in lines[0]


@needs_npm
def test_build_into_a_new_folder_writes_a_whole_app_and_refuses_a_foreign_one(tmp_path: Path) -> None:
    bundle = _make_bundle(tmp_path / "bundle")

    def build(www: Path) -> subprocess.CompletedProcess:
        return subprocess.run([NODE, "tools/build.mjs", "--bundle", str(bundle), "--www", str(www)],
                              capture_output=True, text=True, timeout=120, cwd=DEMO)

    www = tmp_path / "new" / "www"
    assert build(www).returncode == 0
    sources = {p.relative_to(DEMO / "www") for p in (DEMO / "www").rglob("*") if p.is_file()
               and p.parts[len(DEMO.parts) + 1] not in ("vendor", "bundle") and p.suffix != ".gz"
               and p.name not in ("precache.json", "test_vectors.json")}
    assert {"index.html", "js/app.js", "sw.js", "manifest.webmanifest"} <= {str(p) for p in sources}
    for rel in sources:
        assert (www / rel).read_bytes() == (DEMO / "www" / rel).read_bytes(), rel
    urls = {f["url"] for f in json.loads((www / "precache.json").read_text())["files"]}
    assert {"index.html", "js/app.js", "bundle/model.onnx"} <= urls
    assert build(www).returncode == 0  # a folder built before is rebuilt
    foreign = tmp_path / "notes"
    foreign.mkdir()
    (foreign / "todo.txt").write_text("keep")
    proc = build(foreign)
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [
        f"error: --www {foreign} exists and is not an app folder (no index.html); pass a new or empty folder"]
    assert sorted(p.name for p in foreign.iterdir()) == ["todo.txt"]


def test_server_serves_wasm_and_modules_and_stays_inside_its_root(tmp_path: Path) -> None:
    import urllib.error
    import urllib.request

    root = tmp_path / "www"
    root.mkdir()
    (root / "index.html").write_text("<p>hi</p>")
    (root / "a.wasm").write_bytes(b"\0asm\1\0\0\0")
    (root / "m.mjs").write_text("export const x = 1;")
    (tmp_path / "secret.txt").write_text("no")
    proc = subprocess.Popen([NODE, "tools/serve.mjs", "--port", "0", "--root", str(root)], cwd=DEMO,
                            stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        m = re.match(r"serving (http://127\.0\.0\.1:\d+/)", line)
        assert m, line
        base = m.group(1)
        with urllib.request.urlopen(base) as r:
            assert r.read() == b"<p>hi</p>" and r.headers["Content-Type"].startswith("text/html")
        with urllib.request.urlopen(base + "a.wasm") as r:
            assert r.headers["Content-Type"] == "application/wasm"
        with urllib.request.urlopen(base + "m.mjs") as r:
            assert r.headers["Content-Type"].startswith("text/javascript")
        for path, code in (("..%2fsecret.txt", 403), ("%2e%2e/secret.txt", 404), ("missing.js", 404)):
            with pytest.raises(urllib.error.HTTPError) as err:
                urllib.request.urlopen(base + path)
            assert err.value.code == code, path
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    assert proc.returncode == 0  # SIGTERM: a clean shutdown


def test_server_bad_port_is_one_line_error() -> None:
    proc = subprocess.run([NODE, "tools/serve.mjs", "--port", "99999"], cwd=DEMO, capture_output=True, text=True,
                          timeout=30)
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0
    assert proc.stderr.startswith("error: invalid --port")


def test_npm_scripts_point_at_existing_tools() -> None:
    scripts = json.loads((DEMO / "package.json").read_text())["scripts"]
    assert {"build", "serve", "test", "bench"} <= set(scripts)
    for cmd in scripts.values():
        target = cmd.split()[-1] if cmd.startswith("node --test") else cmd.split()[1]
        assert (DEMO / target).exists(), cmd

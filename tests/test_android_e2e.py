"""End to end: the phone app in Debian's headless Chromium, fed a fake camera clip.

Two runs of ``android_demo/tools/e2e_driver.mjs`` (playwright-core) per module, each serving a
built copy of the app on 127.0.0.1:

* landscape (844 x 390 screen, 160 x 120 camera), a tiny test bundle whose bundle.json is
  schema 2 (FOV 67 deg landscape, 53 portrait): first load (requests counted), accessibility
  tree, self-test (the shared test vectors, in the page), first-run sound tutorial, guidance on
  a clip (goal left, sweep, right, hopping at the 7.5 deg boundary, grey, frozen) with no tilt
  sensor at all (no deviceorientation event: "No tilt sensor" said once per start), a single
  tap, audio suspended and resumed, app hidden and shown, camera stalled, double tap, a failed
  then a good start, long press, and a reload with the server stopped (offline);
* portrait (390 x 844 screen, 180 x 240 camera): the real default bundle with its MC-dropout
  noise made constant (so onnxruntime-web 1.30 and Python's onnxruntime must agree number for
  number) on the sample clip cut to portrait (it pans right for a while), then 4 s held still on
  a view the model is unsure of; no URL flag and no sensor setting stored (the app's defaults:
  turns read from the camera picture), a synthetic tilt sensor reporting the phone level, then
  rolled 12 deg (levelled), 75 deg (stop), silent while still at 75 deg (no stale roll; "No tilt
  sensor"), then pointed down;
* portrait with the view crop (bundle schema 3, ``geometry.view_crop``): a tiny test bundle
  whose letterbox geometry crops the frame's rows to the training camera's view, on a clip whose
  kept rows and cut-off rows point to different strips (the app must crop as Engine.predict).

The tests below judge what they recorded, against the Python runtime on the same frames.

Tolerances (stated once): model outputs within 1e-5 of onnxruntime's (same deterministic
graph, WASM vs native float32); the Python Decider fed the Python engine's outputs for the
app's frames, at the app's capture times, agrees with every app decision on the discrete
fields (gate, reason, stop, learner action) and within 1e-4 degrees on headings; the frames
the model saw are the clip's (mean absolute difference <= 4 grey levels to their nearest clip
frame) and the Python pipeline on those *source* frames agrees with the app on >= 90% of the
decisions (stop/go and side).

Needs node >= 18, chromium (apt-get install chromium) and `npm ci` in android_demo; skips
with the reason otherwise. Takes about 90 s.
"""

from __future__ import annotations

import base64
import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from crossing_assist import inference
from crossing_assist.geometry import Geometry, orientation, view_rows
from crossing_assist.runtime.decide import Decider, Observation, edge_side
from crossing_assist.runtime.engine import Engine, measure_value
from crossing_assist.runtime.status import STATUS_STOP, status_message
from crossing_assist.testing import toy_bundle

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "android_demo"
NODE = shutil.which("node")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FPS = 10
FLIP_S = 6
SPEECH_GAP_S = 2.0  # speech.js SPEECH.min_gap_s: a change between stop sentences waits this long
SIDEWAYS_AFTER_S = 1.0  # the portrait run's wait for the hold-it-sideways advice (the app's: 5 s)
ROLL_DEG = 12.0  # the portrait run turns the phone this far clockwise about the camera axis
NO_TILT = "No tilt sensor: hold the phone level."  # live.js NO_TILT_TEXT
NO_TILT_AFTER_S = 2.0  # live.js TiltSilence: said when the tilt sensor gave nothing for this long
ROLL_FRESH_S = 0.5  # live.js TILT.roll_fresh_s: an older roll reading is no roll known
RUN_S = 18.0  # longer than the 17 s clip: every segment, the frozen one included, is seen
WATCHDOG_S = 0.5
BAR_PX = 80  # the helper bar under the control (4rem of 20 px)
DEFAULT_BUNDLE = REPO / "crossing_assist" / "assets" / "default_bundle"
SAMPLE_CLIP = REPO / "crossing_assist" / "assets" / "sample_clip.mp4"
#: The portrait clip's still ending: its frame 71 (as the pan reaches the crossing: the default
#: bundle's far mass 0.33-0.40 on it with noise, over the 0.027 portrait threshold, its top action a
#: strip) held for STILL_S seconds.
STILL_FRAME, STILL_S = 71, 4
#: The test bundle's geometry: distinct default FOVs per orientation, so the tests see which one
#: the app chose; the toy graph resizes whatever it gets to its canvas, hence ``fit: stretch``.
APP_GEOMETRY = Geometry(fit="stretch", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0)
#: The view-crop run's bundle geometry (schema 3): letterbox with the view crop on. The toy graph
#: resizes whatever rows it is given, which is all the crop needs; its (24, 48) canvas at 53 deg
#: keeps about half of a 3:4 portrait frame's rows.
CROP_GEOMETRY = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0, view_crop=True)
CROP_CAMERA = (180, 240)  # width x height: a phone held in portrait


def _why_skip() -> str | None:
    if NODE is None:
        return "Node.js is not installed (apt-get install nodejs)"
    if CHROMIUM is None:
        return "Chromium is not installed (apt-get install chromium)"
    for pkg in ("playwright-core", "onnxruntime-web"):
        if not (DEMO / "node_modules" / pkg / "package.json").is_file():
            return f"npm package {pkg} missing: run `npm ci` in android_demo"
    return None


pytestmark = pytest.mark.skipif(_why_skip() is not None, reason=_why_skip() or "")


def _clip_tool():
    """android_demo/tools/clip.py (Y4M clips for the fake camera); skips without onnx, which
    builds the test bundles."""
    pytest.importorskip("onnx", reason="onnx is needed to make the test bundle (pip install -e '.[train]')")
    sys.path.insert(0, str(DEMO / "tools"))
    try:
        import clip
    finally:
        sys.path.pop(0)
    return clip


def _build(tmp: Path, bundle: Path) -> Path:
    www = tmp / "www"
    shutil.copytree(DEMO / "www", www, ignore=shutil.ignore_patterns("vendor", "bundle", "precache.json", "*.gz"))
    subprocess.run([NODE, "tools/build.mjs", "--bundle", str(bundle), "--www", str(www)], cwd=DEMO, check=True,
                   capture_output=True, timeout=180)
    return www


def _drive(tmp: Path, www: Path, clip_path: Path, run_s: float, *extra: str) -> dict:
    cmd = [NODE, "tools/e2e_driver.mjs", "--clip", str(clip_path), "--out", str(tmp / "result.json"),
           "--run-s", str(run_s), "--www", str(www), "--chromium", CHROMIUM, *extra]
    proc = subprocess.run(cmd, cwd=DEMO, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        # Chromium refuses to cache anything when the disk is nearly full (it did at 1.5 GB free),
        # and the app then says its service worker could not cache it: say how much was free.
        pytest.fail(f"{proc.stderr[-3000:]}\n(disk free: {shutil.disk_usage(tmp).free / 1e9:.1f} GB)")
    result = json.loads((tmp / "result.json").read_text())
    deliberate = ("NotReadableError: Could not start video source",   # the driver's failed start
                  "injected fault")                                   # the driver's fault in the loop
    errors = [c for c in result["console"] if c.startswith(("error", "pageerror")) and not any(d in c for d in deliberate)]
    assert not errors, result["console"]
    return result


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> dict:
    """Build the app with the test bundle (schema-2 json), run the driver once, return its record."""
    clip = _clip_tool()
    tmp = tmp_path_factory.mktemp("android_e2e")
    bundle = toy_bundle.make_toy_bundle(tmp / "bundle", toy_bundle.APP_TOY, geometry=APP_GEOMETRY)
    www = _build(tmp, bundle)
    frames, strips, frozen = clip.bar_clip(fps=FPS, flip_s=FLIP_S)
    clip.write_y4m(tmp / "clip.y4m", frames, FPS)
    result = _drive(tmp, www, tmp / "clip.y4m", RUN_S)
    return {"result": result, "engine": Engine(bundle), "clip": np.stack(frames), "strips": strips,
            "frozen": frozen, "vectors": (DEMO / "test_vectors.json").is_file(), "www": www,
            "geometry": APP_GEOMETRY.to_json()}


@pytest.fixture(scope="module")
def portrait(tmp_path_factory) -> dict:
    """The real default bundle (MC noise made constant), portrait screen and camera."""
    if not (DEFAULT_BUNDLE / "bundle.json").is_file() or not SAMPLE_CLIP.is_file():
        pytest.skip("the default bundle or the sample clip is not in crossing_assist/assets")
    import cv2

    clip = _clip_tool()
    tmp = tmp_path_factory.mktemp("android_e2e_portrait")
    det = toy_bundle.deterministic_copy(DEFAULT_BUNDLE, tmp / "bundle")
    www = _build(tmp, det)
    cap = cv2.VideoCapture(str(SAMPLE_CLIP))
    frames = []
    while len(frames) < 120:
        ok, bgr = cap.read()
        if not ok:
            break
        h, w = bgr.shape[:2]
        pw = (h * 3 // 4) // 2 * 2  # a 3:4 portrait window from the middle
        x0 = (w - pw) // 2
        frames.append(cv2.cvtColor(bgr[: h // 2 * 2, x0:x0 + pw], cv2.COLOR_BGR2RGB))
    # Then, after the guidance at the end of the pan, the phone held still (sensor noise of +-2) on
    # STILL_FRAME, a view the model sees a crossing in but is unsure of: an unbroken "not sure"
    # stop for the hold-it-sideways advice. The pan itself no longer gives one: followed with the
    # turn read from the picture, its unsure frames no longer break off from the not-seeing ones.
    rng = np.random.default_rng(STILL_FRAME)
    frames += [np.clip(frames[STILL_FRAME].astype(np.int16) + rng.integers(-2, 3, frames[STILL_FRAME].shape), 0, 255)
               .astype(np.uint8) for _ in range(STILL_S * 10)]
    clip.write_y4m(tmp / "clip.y4m", frames, 10)
    result = _drive(tmp, www, tmp / "clip.y4m", 8.0, "--phases", "short", "--viewport", "390x844", "--tilt", "1",
                    "--sideways-after", str(SIDEWAYS_AFTER_S), "--roll", str(ROLL_DEG), "--level", "1",
                    "--sensor-stops", "1")
    meta = json.loads((det / "bundle.json").read_text())
    return {"result": result, "engine": Engine(det), "geometry": meta["geometry"], "clip": np.stack(frames)}


def _app_steps(run: dict, least: int = 60) -> list[tuple[dict, np.ndarray]]:
    """The app's processed frames (trace entries of kind 'frame') with the RGB it fed the model;
    a frame after an entry of kind 'fov' (start, phone turned, return from the background) is
    marked ``new_decider`` (the app started a fresh Decider with that FOV)."""
    pixels = {}
    for f in run["result"]["frames"]:
        pixels[f["id"]] = np.frombuffer(base64.b64decode(f["rgb"]), np.uint8).reshape(
            f["height"], f["width"], 3)
    steps, fresh_decider = [], False
    for e in run["result"]["trace"]:
        if e["kind"] == "fov":
            fresh_decider = True
        elif e["kind"] == "frame":
            if e["id"] in pixels:
                steps.append(({**e, "new_decider": fresh_decider}, pixels[e["id"]]))
            fresh_decider = False
    assert len(steps) >= least, f"only {len(steps)} frames recorded"
    return steps


def _python_decisions(engine: Engine, steps, predict=None):
    """The Python Decider on the app's frames at the app's times, a fresh one with the app's FOV
    and the frame orientation's gate threshold wherever the app started one: yields (app entry,
    python decision json)."""
    py = None
    for entry, rgb in steps:
        if entry["new_decider"] or py is None:
            py = Decider(engine.decision_config(orientation(rgb.shape[1], rgb.shape[0]), fov_deg=entry["fov_deg"]))
        # a frame the app did not give the model (rolled beyond levelling) is a failed one there
        obs = (Observation(None, math.inf, ok=False) if entry["outputs"] is None
               else (predict or engine.predict)(rgb).observation())
        yield entry, py.step(entry["t"], obs, entry["yaw_rate_dps"]).to_json()


def _obs(pred) -> Observation:
    return pred.observation()


def test_shared_vectors_pass_in_the_browser(run: dict) -> None:
    """The app's own self-test button replays the Python runtime's vectors in the page: the
    decisions, the live-loop guards, the status sentences, the orientation -> FOV choice and the
    view crop's rows."""
    if not run["vectors"]:
        pytest.skip("android_demo/test_vectors.json is missing")
    v = run["result"]["vectors"]
    want = json.loads((DEMO / "test_vectors.json").read_text())
    assert v["steps"] == sum(len(sc["steps"]) for sc in want["scenarios"]), v
    n_other = (len(want["guards"]["same_frame"]) + len(want["guards"]["fresh"]) + len(want["guards"]["watchdog"]["ops"])
               + len(want["status"]) + len(want["geometry"]["fov_choice"]) + len(want["geometry"]["view_rows"]["cases"]))
    assert v["checks"] >= n_other, v
    assert v["failures"] == [] and v["nFailures"] == 0, v
    assert run["result"]["vectors_text"].startswith("Decision logic OK"), run["result"]["vectors_text"]


def test_model_outputs_match_onnxruntime_on_the_same_frames(run: dict) -> None:
    engine = run["engine"]
    worst = 0.0
    for entry, rgb in _app_steps(run):
        pred = engine.predict(rgb)
        assert pred.ok, pred.error
        worst = max(worst, float(np.abs(np.asarray(entry["outputs"]["probs"]) - pred.probs).max()),
                    abs(entry["outputs"]["entropy"] - pred.entropy))
    assert worst <= 1e-5, f"largest difference {worst}"


def _assert_same_decisions(engine: Engine, steps, tol_deg: float = 1e-4, predict=None) -> set:
    space = engine.space
    gates = set()
    for entry, d in _python_decisions(engine, steps, predict):
        app = entry["decision"]
        top2 = np.sort(space.bin_probs_to_action_probs(np.asarray(d["belief"])))[-2:]
        if top2[1] - top2[0] < 1e-6:
            continue  # a genuine tie: float32 noise may break it either way
        for key in ("gate", "reason", "stop", "learner_action"):
            assert app[key] == d[key], (entry["t"], key, app[key], d[key])
        for key in ("heading_deg", "learner_heading"):
            assert (app[key] is None) == (d[key] is None), (entry["t"], key)
            if d[key] is not None:
                assert abs(app[key] - d[key]) <= tol_deg, (entry["t"], key, app[key], d[key])
        gates.add(d["gate"])
    return gates


def test_decisions_match_the_python_runtime_on_the_same_frames(run: dict) -> None:
    gates = _assert_same_decisions(run["engine"], _app_steps_in_order(run))
    assert "learner" in gates and len(gates) >= 2, gates  # the clip exercises more than one gate state


def _app_steps_in_order(run: dict, least: int = 60) -> list[tuple[dict, np.ndarray]]:
    """All of the run's frame steps must be present (the Decider is stateful)."""
    steps = _app_steps(run, least)
    n_frames = sum(e["kind"] == "frame" for e in run["result"]["trace"])
    assert len(steps) == n_frames, "some frames the app processed were not kept; raise MAX_FRAMES in app.js"
    return steps


def test_the_model_saw_the_clip_and_python_agrees_on_the_source_frames(run: dict) -> None:
    clip = run["clip"].astype(np.int16)
    engine = run["engine"]
    agree = total = 0

    def nearest_clip_frame(rgb):
        mad = np.abs(clip - rgb.astype(np.int16)[None]).mean(axis=(1, 2, 3))
        k = int(np.argmin(mad))
        assert mad[k] <= 4.0, f"a frame is {mad[k]:.1f} levels from every clip frame"
        return engine.predict(run["clip"][k])

    for entry, d in _python_decisions(engine, _app_steps_in_order(run), predict=nearest_clip_frame):
        app = entry["decision"]
        total += 1
        same_side = d["stop"] or app["stop"] or math.copysign(1, d["heading_deg"]) == math.copysign(1, app["heading_deg"])
        agree += (d["stop"] == app["stop"]) and same_side
    assert agree >= 0.9 * total, f"{agree}/{total} decisions agree"


def test_landscape_frames_use_the_landscape_fov(run: dict) -> None:
    fovs = [e for e in run["result"]["trace"] if e["kind"] == "fov" and e["fov_deg"] != 60]  # 60: the user's
    assert fovs and all(e["orientation"] == "landscape" and e["fov_deg"] == run["geometry"]["camera_fov_deg"]["landscape"]
                        for e in fovs), fovs


def test_gyroscope_turn_reaches_the_decider(run: dict) -> None:
    """The driver's synthetic gyroscope turns right at 3 deg/s (rotation about the phone's
    upward axis of -3 deg/s): the app feeds the Decider +3 deg/s (right), per frame interval."""
    frames = [e for e in run["result"]["trace"] if e["kind"] == "frame"]
    yaws = [e["yaw_rate_dps"] for e in frames[1:] if e["t"] < run["result"]["samples"][-1]["t"]]
    assert 2.5 <= float(np.median(yaws)) <= 3.5, np.percentile(yaws, [10, 50, 90])
    assert {e["yaw_source"] for e in frames} == {"gyro"}   # ?gyro=1: the gyroscope wins over the camera picture


def test_the_beacon_turns_with_the_gyroscope_until_the_next_decision(run: dict) -> None:
    """Decision step 10 in the app: a decision is played turned by the gyroscope's turn since its
    frame's capture (here 3 deg/s right), when it is decided and again at each gyroscope sample
    until another cue plays, as decide.turned computes it."""
    trace = run["result"]["trace"]
    frames = {e["id"]: e for e in trace if e["kind"] == "frame"}
    turned = [e for e in trace if e["kind"] == "turned" and e["frame"] in frames]
    assert turned, "no decision was played turned with the gyroscope"
    per_decision = np.bincount([e["frame"] for e in turned])
    assert np.median(per_decision[per_decision > 0]) >= 3, "the beacon is not followed between decisions"
    close = 0
    for e in turned:
        f = frames[e["frame"]]
        assert f["fresh"] and not f["decision"]["stop"] and f["yaw_source"] == "gyro", f
        h, fov = f["decision"]["heading_deg"], f["decision_fov_deg"]
        want = h - (e["turn_deg"] / 2 if edge_side(h, fov) * e["turn_deg"] > 0 else e["turn_deg"])
        assert abs(e["heading_deg"] - want) <= 1e-9, (e, f["decision"])
        close += abs(e["turn_deg"] - 3.0 * (e["t"] - f["t"])) <= 0.1   # the turn since the capture
    assert close >= 0.95 * len(turned), f"{close}/{len(turned)} turns match 3 deg/s since the capture"


def test_no_tilt_sensor_is_said_once_per_start_and_guidance_goes_on(run: dict) -> None:
    """The landscape run sends no deviceorientation event at all (headless Chromium has no
    sensor): NO_TILT_AFTER_S after each start the user hears and sees "No tilt sensor: hold the
    phone level." once (spoken whole; shown in a line kept until guidance ends), and guidance goes
    on unlevelled: fresh decisions after it, no frame turned, no roll stop."""
    trace = run["result"]["trace"]
    starts = [i for i, e in enumerate(trace) if e["kind"] == "start"]
    assert len(starts) >= 2, "the landscape run starts guidance twice"
    for n, i in enumerate(starts):
        end = next((j for j in range(i + 1, len(trace)) if trace[j]["kind"] in ("stopped", "start")), len(trace))
        session = trace[i:end]
        said = [e for e in session if e["kind"] == "speech" and e["text"] == NO_TILT]
        long_enough = end == len(trace) or trace[end]["t"] - trace[i]["t"] > NO_TILT_AFTER_S + 1.0
        assert len(said) == (1 if long_enough else len(said[:1])), (n, [e["t"] - trace[i]["t"] for e in said])
        if not said:
            continue
        assert NO_TILT_AFTER_S <= said[0]["t"] - trace[i]["t"] <= NO_TILT_AFTER_S + 1.0, (n, said[0]["t"] - trace[i]["t"])
        assert any(e["kind"] == "frame" and e["fresh"] and e["t"] > said[0]["t"] for e in session), n
        assert all(e["roll_deg"] == 0 for e in session if e["kind"] == "frame")
        assert [e["permission"] for e in session if e["kind"] == "no_tilt"] == ["granted"]
    st = run["result"]["states"]
    assert st["running"]["notice"] == NO_TILT and st["running"]["running"], st["running"]["notice"]
    assert st["running"]["tilt_text"].startswith("no reading yet"), st["running"]["tilt_text"]
    heard = [h for h in st["running"]["heard"] if h["text"] == NO_TILT]
    assert len(heard) == 1 and heard[0]["how"] == "whole", heard
    assert st["ended_double"]["notice"] is None   # gone with the guidance


PAN_GLIDE_WINDOW_S = 0.25   # >> the app's pan glide time constant (GLIDE_S = 0.02 s, android_demo/www/js/audio.js)


def _steady(samples: list[dict], side: float) -> list[dict]:
    """Samples whose decision has pointed to ``side`` (pan sign, |pan| > 0.5) for >= 1.0 s
    (longer than the level meter's 0.68 s window, so only the beacon is in it)."""
    out = []
    for i, s in enumerate(samples):
        window = [w for w in samples[: i + 1] if s["t"] - w["t"] <= 1.1]
        if s["t"] - window[0]["t"] < 1.0:
            continue
        if all(w["decision"] and not w["decision"]["stop"] and w["audio"]["kind"] == "beacon"
               and w["decision"]["pan"] * side > 0.5 for w in window):
            out.append(s)
    return out


@pytest.mark.parametrize("side", [1.0, -1.0], ids=["right", "left"])
def test_audio_graph_pans_to_the_goal_side(run: dict, side: float) -> None:
    samples = run["result"]["samples"]
    steady = _steady(samples, side)
    timeline = [(round(s["t"], 2), s["decision"] and s["decision"]["pan"], s["audio"] and s["audio"]["kind"])
                for s in samples]
    assert len(steady) >= 2, f"the goal was never on this side for 1 s: {timeline}"
    for s in steady:
        audio = s["audio"]
        # the pan glides to each new decision (time constant GLIDE_S = 20 ms in audio.js) and a
        # sample may come a few ms after a decision: the audio lies between the decisions of the
        # last PAN_GLIDE_WINDOW_S (from the one it glides from to the one it glides to)
        recent = [w["decision"]["pan"] for w in samples if 0 <= s["t"] - w["t"] <= PAN_GLIDE_WINDOW_S]
        assert audio["pan"] * side > 0.5 and min(recent) - 0.05 < audio["pan"] < max(recent) + 0.05, (s, recent)
        near, far = (audio["levels"][1], audio["levels"][0]) if side > 0 else audio["levels"]
        assert near > 0.2 and near > 1.5 * far, f"levels L/R {audio['levels']} at pan {audio['pan']:.2f}"


def test_frozen_camera_frames_trigger_the_stop_cue(run: dict) -> None:
    """The clip's last 2 s repeat one frame exactly: the app skips them and the watchdog stops."""
    trace = [e for e in run["result"]["trace"] if e["kind"] in ("frame", "frozen", "watchdog")]
    # the clip's frozen segment: a run of repeats (a single repeat is a duplicate the camera may deliver)
    i = next(i for i in range(len(trace) - 3) if all(e["kind"] == "frozen" for e in trace[i:i + 3]))
    last_fresh = max(e["t"] for e in trace[:i] if e["kind"] == "frame" and e["fresh"])
    dog = next(e for e in trace[i:] if e["kind"] != "frozen")
    assert dog["kind"] == "watchdog", "a decision was made on a frozen frame"
    assert WATCHDOG_S < dog["t"] - last_fresh <= WATCHDOG_S + 0.25  # polled every 20 ms; slack for a busy CI


def test_a_model_too_slow_for_the_phone_stops_the_beacon_and_says_so(run: dict) -> None:
    """Each model run made 800 ms long (over the 0.5 s watchdog) while the camera keeps giving
    frames: the stop cue plays, the phone says it is too slow (not that the camera stalled) and
    vibrates that pattern; the watchdog names the same reason; at normal speed the beacon returns
    (the driver waits for it)."""
    s = run["result"]["slow"]
    trace = run["result"]["trace"]
    assert s["after"]["audio"]["kind"] == "stop"
    assert s["state"]["status"] == STATUS_STOP["slow"]
    during = [e for e in trace if s["t_slow"] < e["t"] <= s["t_fast"]]
    frames = [e for e in during if e["kind"] == "frame" and e["t"] > s["t_slow"] + 0.1]
    assert frames and not any(e["fresh"] for e in frames), "a decision 800 ms late counted as fresh"
    assert all(e["latency_ms"] >= 790 for e in frames)
    dogs = [e for e in during if e["kind"] == "watchdog"]
    assert dogs and all(e["reason"] == "slow" for e in dogs), dogs
    assert _vibrations(during, "slow") and not _vibrations(during, "stale")
    offset = s["state"]["now_s"] - s["state"]["t"]       # speech is stamped in page time, the trace from the app's start
    spoken = [e["text"] for e in s["state"]["speech"] if e["t"] - offset > s["t_slow"]]
    assert STATUS_STOP["slow"] in spoken and STATUS_STOP["stale"] not in spoken, spoken
    assert "too slow for this phone" in s["speed_text"], (s["speed_text"], s["perf"])    # the helper view says why, and the fix


def _vibrations(trace: list[dict], reason: str) -> list[dict]:
    return [e for e in trace if e["kind"] == "vibrate" and e["reason"] == reason]


def test_stalled_camera_triggers_the_stop_cue(run: dict) -> None:
    """The <video> stops presenting frames: within the watchdog period the stop cue plays
    (centred, audible), the phone vibrates the 'stalled' pattern and says so."""
    f = run["result"]["freeze"]
    trace = run["result"]["trace"]
    dog = [e["t"] for e in trace if e["kind"] == "watchdog" and e["t"] > f["t_freeze"]]
    assert dog and dog[0] - f["t_freeze"] <= WATCHDOG_S + 0.25, (f["t_freeze"], dog)
    assert f["t_stop"] - f["t_freeze"] <= WATCHDOG_S + 0.5  # as seen by the driver's 100 ms polling
    after = f["after"]["audio"]
    assert after["kind"] == "stop"
    left, right = after["levels"]
    assert left > 0.2 and abs(left - right) < 0.02, after["levels"]
    assert [e for e in _vibrations(trace, "stale") if dog[0] - 0.05 <= e["t"] <= dog[0] + 0.1], "no vibration at the stall"
    assert f["state"]["status"] == STATUS_STOP["stale"]


def test_audio_suspended_counts_as_failed_guidance(run: dict) -> None:
    """AudioContext suspended under the app (a call): stop, its own vibration, the spoken
    sentence and a control that says how to resume; a tap resumes the audio."""
    st = run["result"]["states"]
    failed = st["audio_failed"]
    assert failed["audio"]["contextState"] == "suspended" and failed["audio_failed"]
    assert failed["audio"]["kind"] == "stop"
    assert failed["status"] == "Audio stopped. Tap to resume." == STATUS_STOP["audio"]
    assert failed["label"] == "Tap to resume audio"
    t_lost = failed["now_s"] - (failed["t"] - failed["t_suspend"])  # the page clock at the suspension
    assert any(s["text"] == "Audio stopped. Tap to resume." and s["t"] >= t_lost for s in failed["speech"]), failed["speech"]
    assert any(v["pattern"] == [400, 150, 400, 150, 400] and v["t"] >= t_lost for v in failed["vibrations"])
    trace = run["result"]["trace"]
    i0 = next(i for i, e in enumerate(trace) if e["kind"] == "audio_failed")
    i1 = next(i for i, e in enumerate(trace) if e["kind"] == "audio_resumed")
    assert trace[i1]["how"] == "tap" and i1 > i0
    spoken = [e["text"] for e in trace[i0:i1] if e["kind"] == "speech"]
    assert spoken == ["Audio stopped. Tap to resume."], f"spoken while audio was out: {spoken}"
    resumed = st["audio_resumed"]
    assert resumed["audio"]["contextState"] == "running" and not resumed["audio_failed"]
    assert resumed["running"] and resumed["label"] == "End guidance"


def test_audio_given_back_without_a_tap_resumes_with_a_fresh_decider(run: dict) -> None:
    """The AudioContext suspended, then running again by itself (a call ended; no tap): guidance
    resumes, and only with decisions a fresh Decider made after the return."""
    st = run["result"]["states"]["audio_given_back"]
    assert st["audio"]["contextState"] == "running" and not st["audio_failed"], st["audio"]
    assert st["running"] and st["label"] == "End guidance", st["label"]
    trace = run["result"]["trace"]
    i = next((i for i, e in enumerate(trace) if e["kind"] == "audio_resumed" and e["t"] >= st["t_given"]), None)
    assert i is not None and trace[i]["how"] == "os", [e for e in trace if e["kind"] == "audio_resumed"]
    first = next(e for e in trace[i:] if e["kind"] in ("fov", "frame"))
    assert first["kind"] == "fov", "a decision after the audio came back reused the old Decider"
    assert any(e["kind"] == "frame" and e["fresh"] for e in trace[i:] if e["t"] <= st["t"])


def test_hidden_and_shown_during_a_model_run_drops_its_result(run: dict) -> None:
    """Hidden and shown again within 150 ms while a model run is in flight: the return resets the
    decisions, so that run's result is dropped (its Decider is gone); guidance goes on with a
    fresh Decider (the bug: a TypeError in the loop, guidance dead until a restart)."""
    h = run["result"]["hideshow"]
    trace = run["result"]["trace"]
    i_hidden = max(i for i, e in enumerate(trace) if e["kind"] == "hidden" and e["t"] <= h["t_hide"] + 0.05)
    assert trace[i_hidden]["t"] >= h["t_hide"] - 0.05, "the quick hide was not recorded"
    i_visible = next(i for i, e in enumerate(trace[i_hidden:], i_hidden) if e["kind"] == "visible")
    assert trace[i_visible]["t"] - trace[i_hidden]["t"] < 0.3
    assert not [e for e in trace[i_hidden:] if e["kind"] == "frame" and e["t"] <= h["inflight"]], "the in-flight run's result was used"
    first = next(e for e in trace[i_visible:] if e["kind"] in ("fov", "frame"))
    assert first["kind"] == "fov", "a decision after the return reused the old Decider"
    after = [e for e in trace[i_visible:] if e["kind"] == "frame" and e["t"] <= h["state"]["t"]]
    assert len(after) >= 5 and any(e["fresh"] for e in after if e["t"] > h["t_fast"]), len(after)
    st = h["state"]
    assert st["running"] and st["mode"] == "running" and st["error"] is None and not st["paused"], st["error"]


def test_a_fault_outside_the_model_stops_then_guidance_goes_on(run: dict) -> None:
    """One frame's handling throws outside the model (the driver injects it into levelling): the
    loop records it, the decisions start afresh and guidance goes on (before: the loop died, the
    watchdog's stop cue played for good and the screen still said guidance was running)."""
    f = run["result"]["fault"]
    trace = run["result"]["trace"]
    i_err = next(i for i, e in enumerate(trace) if e["kind"] == "loop_error" and e["t"] >= f["t"] - 0.05)
    assert "injected fault" in trace[i_err]["error"]
    first = next(e for e in trace[i_err:] if e["kind"] in ("fov", "frame"))
    assert first["kind"] == "fov", "a decision after the fault reused the old Decider"
    assert len([e for e in trace[i_err:] if e["kind"] == "frame"]) >= 5
    st = f["state"]
    assert st["running"] and st["mode"] == "running" and st["error"] is None, st["error"]


def test_freshness_is_judged_by_the_frame_s_own_capture_time(run: dict) -> None:
    """A 450 ms model run at 10 frames/s: the next frame came while the model ran and waited up
    to 100 ms to be grabbed. By its own capture time (the driver's requestVideoFrameCallback log,
    independent of the app), no decision older than the watchdog period counts as fresh (plays a
    beacon), and the app never takes a frame for younger than it is."""
    a = run["result"]["aged"]
    t0 = run["result"]["t0"]
    presented = a["presented"]
    assert len(presented) >= 30, len(presented)
    ages = []
    for e in run["result"]["trace"]:
        if e["kind"] != "frame" or not a["t_start"] + 0.6 <= e["grabbed"] <= a["t_end"]:
            continue
        grab_ms = 1000 * (t0 + e["grabbed"])
        newest = [p for p in presented if p["at"] <= grab_ms][-1]  # the frame the <video> showed at the grab
        captured = newest["capture"] / 1000 - t0
        assert e["t"] <= captured + 1e-3, (e["t"], captured, e["grabbed"])
        ages.append((e["decided"] - captured, e["fresh"], e["latency_ms"]))
    assert len(ages) >= 8, ages
    assert [x for x in ages if x[0] > WATCHDOG_S], f"no frame waited for the model: the phase tests nothing {ages}"
    too_old = [x for x in ages if x[1] and x[0] > WATCHDOG_S + 1e-3]
    assert not too_old, f"fresh decisions from frames older than {WATCHDOG_S} s: {too_old}"


def test_the_camera_lost_instruction_is_heard_whole(run: dict) -> None:
    """The camera track ends and the video stalls: the sentence saying how to recover is spoken
    whole (the driver's fake voice: 60 ms a character), not cut by the watchdog's stop sentence
    half a second later, which follows it if it comes at all."""
    c = run["result"]["camera_lost"]
    st = c["state"]
    offset = st["now_s"] - st["t"]  # the page clock minus the app's
    assert st["error"] and st["error"].startswith("The camera stopped"), st["error"]
    dogs = [e for e in run["result"]["trace"] if e["kind"] == "watchdog" and e["t"] >= c["t"]]
    assert dogs and dogs[0]["t"] - c["t"] <= WATCHDOG_S + 0.25, dogs
    lost = [h for h in c["heard"] if h["text"] == st["error"] and h["start"] >= c["t"] + offset - 0.01]
    assert len(lost) == 1 and lost[0]["how"] == "whole", c["heard"]
    # the watchdog's stop sentence, when it comes (it races the track's end, which ends guidance:
    # 3 runs in 9 here heard none), follows the instruction and never cuts it
    stalled = [h for h in c["heard"] if h["text"] == STATUS_STOP["stale"] and h["start"] >= c["t"] + offset]
    assert all(h["start"] >= lost[0]["end"] - 0.01 for h in stalled), c["heard"]


def test_background_pauses_and_wake_lock_is_requested_again(run: dict) -> None:
    st = run["result"]["states"]
    hidden, visible = st["hidden"], st["visible"]
    assert hidden["paused"] and hidden["audio"]["kind"] == "stop"
    assert hidden["status"] == STATUS_STOP["background"]
    trace = run["result"]["trace"]
    i_hidden = next(i for i, e in enumerate(trace) if e["kind"] == "hidden")
    i_visible = next(i for i, e in enumerate(trace) if e["kind"] == "visible")
    assert not [e for e in trace[i_hidden:i_visible] if e["kind"] == "frame"], "inference ran in the background"
    assert _vibrations(trace[i_hidden:i_visible], "background")
    assert len(visible["wake_locks"]) == len(hidden["wake_locks"]) + 1, (hidden["wake_locks"], visible["wake_locks"])
    assert visible["wake_locks"][-1]["visible"] == "visible"
    resumed = [e for e in trace[i_hidden:] if e["kind"] == "audio_resumed"]
    assert resumed and resumed[0]["how"] == "return", "audio suspended in the background was not resumed on return"
    assert visible["audio"]["contextState"] == "running" and not visible["audio_failed"]
    first = next(e for e in trace[i_visible:] if e["kind"] in ("fov", "frame"))
    assert first["kind"] == "fov", "the first decision after the return reused the old Decider (stale heading)"
    assert not visible["paused"] and visible["running"]


def test_the_control_never_moves(run: dict) -> None:
    """One full-width control above the helper bar; its box is the same in every state."""
    r = run["result"]
    vw, vh = r["viewport"]["width"], r["viewport"]["height"]
    want = [0, 0, vw, vh - BAR_PX]
    boxes = {name: st["control"] for name, st in r["states"].items()}
    boxes.update({f"sample {i}": s["control"] for i, s in enumerate(r["samples"])})
    boxes["frozen"] = r["freeze"]["state"]["control"]
    assert all(b == want for b in boxes.values()), {k: b for k, b in boxes.items() if b != want}
    labels = {st["label"] for st in r["states"].values()}
    assert {"Start", "End guidance", "Tap to resume audio", "Sound check"} <= labels, labels


def test_ending_needs_a_double_tap_or_a_long_press(run: dict) -> None:
    st = run["result"]["states"]
    assert st["single_tap"]["running"], "a single tap ended guidance"
    hint = "Double tap or hold to end guidance."
    assert st["single_tap"]["speech"][-1]["text"] == hint
    n_hint = sum(s["text"] == hint for s in st["single_tap"]["speech"])
    assert sum(s["text"] == hint for s in st["ended_double"]["speech"]) == n_hint  # a double tap is not hinted at
    assert st["ended_double"]["mode"] == "ready" and st["ended_long"]["mode"] == "ready"
    ends = [e["how"] for e in run["result"]["trace"] if e["kind"] == "end"]
    assert ends == ["double tap", "long press"], ends
    for name in ("ended_double", "ended_long"):
        assert st[name]["status"] == "Guidance ended. Tap to start." and st[name]["label"] == "Start"


def test_no_leftovers_after_stop_or_a_later_start(run: dict) -> None:
    """The strip highlight goes with the guidance; an old error goes with a successful start."""
    st = run["result"]["states"]
    assert st["running"]["strips_on"] > 0 and st["ended_double"]["strips_on"] == 0
    assert st["error"]["error"] and "camera" in st["error"]["error"].lower()
    assert st["restarted"]["error"] is None and st["restarted"]["running"]


def _raw_and_spoken(run: dict, t0: float, t1: float):
    trace = run["result"]["trace"]
    raw = [status_message(e["decision"]["stop"], e["decision"]["reason"], e["decision"]["heading_deg"])[0]
           for e in trace if e["kind"] == "frame" and e["fresh"] and t0 <= e["t"] < t1]
    spoken = [e for e in trace if e["kind"] == "speech" and t0 <= e["t"] < t1]
    return raw, spoken


def test_speech_has_hysteresis_at_a_boundary(run: dict) -> None:
    """During the clip's hops between strips 7 and 8 the heading crosses the 7.5 deg boundary
    again and again; the spoken advice changes at most once. Directions are spoken at least
    2 s apart, each after holding for 1 s."""
    trace = run["result"]["trace"]
    start = next(e["t"] for e in trace if e["kind"] == "start")
    flip0 = start + (3 + 2 + 2.5) + 1.0  # the hops begin 7.5 s into the clip; 1 s for the belief to follow
    raw, spoken = _raw_and_spoken(run, flip0, flip0 + FLIP_S - 1.5)
    flips = sum(a != b for a, b in zip(raw, raw[1:]))
    assert flips >= 4, f"the clip did not cross the boundary: {raw}"
    assert len(spoken) <= 1, [s["text"] for s in spoken]
    end = next(e["t"] for e in trace if e["kind"] == "audio_failed")
    directions = [e for e in trace if e["kind"] == "speech" and start <= e["t"] < end
                  and not e["text"].startswith(("Stop", "Audio", "Double", "No tilt"))]
    gaps = [b["t"] - a["t"] for a, b in zip(directions, directions[1:])]
    assert directions and min(gaps, default=9) >= SPEECH_GAP_S - 1e-9, gaps


def test_status_is_a_polite_live_region(run: dict) -> None:
    assert 'id="status" class="status" role="status" aria-live="polite"' in (DEMO / "www" / "index.html").read_text()
    aria = run["result"]["aria"]
    assert "- status: Ready. Tap to start." in aria, aria


def test_first_run_tutorial_then_settings_are_kept(run: dict) -> None:
    trace = run["result"]["trace"]
    tut = [e for e in trace if e["kind"] == "tutorial"]
    texts = [e["text"] for e in tut]
    assert texts[0].startswith("Sound check") and "Right ear." in texts and "Centre." in texts
    pans = [e["cue"].get("pan") for e in tut if e["cue"]["kind"] == "beacon"]
    assert pans[:3] == [-1, 1, 0], pans
    assert any(e["cue"]["kind"] == "stop" for e in tut)
    i_done = next(i for i, e in enumerate(trace) if e["kind"] == "tutorial_done")
    i_start = next(i for i, e in enumerate(trace) if e["kind"] == "start")
    assert i_done < i_start and not trace[i_done]["skipped"]
    # the screen 0.3 s after the first tap: the tutorial has begun (on a loaded machine the
    # snapshot can come late enough to hold its next sentence too)
    spoken = [s["text"] for s in run["result"]["states"]["tutorial"]["speech"]]
    assert spoken[:1] == ["Sound check. A beep in your left ear."] and set(spoken[1:]) <= set(texts), spoken
    assert run["result"]["offline"]["tutorial"] == 0, "the tutorial came back after a reload"


def test_each_stop_reason_has_its_own_vibration(run: dict, portrait: dict) -> None:
    """Both runs together: the portrait one has 'not sure' stops, the landscape one the rest."""
    trace = run["result"]["trace"] + portrait["result"]["trace"]
    patterns = {}
    for e in trace:
        if e["kind"] == "vibrate" and e["reason"] != "direction":  # the direction code: its own test
            patterns.setdefault(e["reason"], set()).add(tuple(e["pattern"]))
    assert {"uncertain", "stale", "audio", "background"} <= set(patterns), patterns
    assert all(len(p) == 1 for p in patterns.values()), patterns
    assert len({next(iter(p)) for p in patterns.values()}) == len(patterns), "two reasons share a pattern"
    landscape = {e["reason"] for e in run["result"]["trace"] if e["kind"] == "vibrate"}
    assert "direction" not in landscape  # the direction code is off unless the user turns it on


def test_a_phone_pointed_at_the_ground_is_told_to_raise_it(portrait: dict) -> None:
    """After the portrait run the driver tilts the phone 50 deg down (deviceorientation beta 40):
    a "not sure" stop then vibrates "raise it" at once and says it (at once, or after the speech's
    gap between two stop sentences); the decisions themselves stay the Decider's (never a tilt reason)."""
    trace = portrait["result"]["trace"]
    t = portrait["result"]["tilt"]["t_spoken"]
    spoken = next(e for e in trace if e["kind"] == "speech" and e["t"] == t)
    assert spoken["text"] == STATUS_STOP["tilt_down"]
    felt = [e["t"] for e in trace if e["kind"] == "vibrate" and e["reason"] == "tilt_down"]
    assert any(t - SPEECH_GAP_S - 1e-6 <= f <= t for f in felt), (felt, t)
    before = [e for e in trace if e["kind"] == "frame" and e["t"] <= t]
    assert before[-1]["decision"]["stop"] and before[-1]["decision"]["reason"] == "uncertain"
    assert {e["decision"]["reason"] for e in trace if e["kind"] == "frame"} <= {"ok", "uncertain", "stale", "failed"}
    t_tilt = portrait["result"]["tilt"]["t_tilt"]   # no advice before the sensor said anything (held level)
    advice = {STATUS_STOP["tilt_down"], STATUS_STOP["tilt_up"]}
    assert t >= t_tilt and not any(e["kind"] == "speech" and e["text"] in advice
                                   or e["kind"] == "vibrate" and e["reason"].startswith("tilt")
                                   for e in trace if e["t"] < t_tilt)


def test_an_upright_phone_unsure_for_a_while_is_told_to_hold_it_sideways(portrait: dict) -> None:
    """The portrait run gives the advice after SIDEWAYS_AFTER_S s (the app's 5 s, shortened):
    vibrated once a "not sure" stop has lasted that long, never before, and spoken (at once or
    after the speech's gap between two stop sentences); the decisions stay the Decider's."""
    trace = portrait["result"]["trace"]
    t_said = portrait["result"]["sideways"]["t_spoken"]
    said = next(e for e in trace if e["kind"] == "speech" and e["t"] == t_said)
    assert said["text"] == STATUS_STOP["sideways"]
    i = next(k for k, e in enumerate(trace) if e["kind"] == "vibrate" and e["reason"] == "sideways")
    t = trace[i]["t"]
    assert t <= t_said
    # the frame whose decision gave the advice: the next frame entry (each frame's feedback is
    # recorded just before it); frames captured before t may be decided after it
    j = next(k for k in range(i + 1, len(trace)) if trace[k]["kind"] == "frame")
    frames = [e for e in trace[:j + 1] if e["kind"] == "frame" and e["fresh"]]
    assert frames[-1]["decision"]["stop"] and frames[-1]["decision"]["reason"] == "uncertain"
    since = frames[-1]["t"]  # the unbroken "not sure" stop before the advice
    for f in reversed(frames):
        if f["decision"]["reason"] != "uncertain":
            break
        since = f["t"]
    assert t - since >= SIDEWAYS_AFTER_S - 1e-6, (since, t)
    assert {e["decision"]["reason"] for e in trace if e["kind"] == "frame"} <= {"ok", "uncertain", "stale", "failed"}


def test_direction_code_vibrates_when_turned_on(portrait: dict) -> None:
    """The portrait run has "Vibrate the direction" on: each code matches the heading's side."""
    trace = portrait["result"]["trace"]
    codes = {"left": [120], "ahead": [450], "right": [120, 150, 120]}
    seen = 0
    for i, e in enumerate(trace):
        if e["kind"] == "vibrate" and e["reason"] == "direction":  # recorded just before its frame's entry
            h = next(f for f in trace[i:] if f["kind"] == "frame")["decision"]["heading_deg"]
            want = "ahead" if abs(h) < 7.5 else "left" if h < 0 else "right"
            assert e["pattern"] == codes[want], (h, e["pattern"])
            seen += 1
    assert seen >= 1, "no direction code"


def test_user_fov_setting_is_checked_kept_and_used(run: dict) -> None:
    ui = run["result"]["fov_ui"]
    assert ui["refused"].startswith("Refused: Invalid field of view: 10"), ui
    assert ui["saved"] == "landscape: 60° saved" and ui["stored"] == {"landscape": 60, "portrait": None}
    assert "field of view 60.0° (your setting)" in ui["camera_text"], ui
    fovs = [e["fov_deg"] for e in run["result"]["trace"] if e["kind"] == "fov"]
    assert fovs[-1] == 60 and 67.0 in fovs  # the decisions test replays both with a fresh Decider each


def test_inference_is_capped_at_10_hz(run: dict) -> None:
    ts = [e["grabbed"] for e in run["result"]["trace"] if e["kind"] == "frame"]  # t: the frame's capture
    gaps = np.diff(ts)
    assert float(np.min(gaps[gaps > 0])) >= 0.1 - 1e-3, np.sort(gaps)[:5]  # 1 ms: timer granularity


def test_first_load_downloads_each_file_once_compressed(run: dict) -> None:
    reqs = run["result"]["first_load"]
    pre = json.loads((run["www"] / "precache.json").read_text())
    big = [f for f in pre["files"] if f["bytes"] > 100_000]
    for f in big:
        n = sum(r["url"] == "/" + f["url"] for r in reqs)
        assert n == 1, f"{f['url']} downloaded {n} times"
    wasm = next(r for r in reqs if r["url"].endswith(".wasm"))
    assert wasm["bytes"] < 0.5 * next(f["bytes"] for f in big if f["url"].endswith(".wasm")), "wasm not compressed"
    total = sum(r["bytes"] for r in reqs)
    cached = sum(f["bytes"] for f in pre["files"])
    assert total < cached, (total, cached)


def test_helper_view_shows_speed_duty_backend_and_bundle(run: dict) -> None:
    r = run["result"]
    assert re.search(r"frames/s, model \d+ ms/frame, duty \d+%", r["speed_text"]), r["speed_text"]
    meta = r["meta"]
    assert meta["model_sha256"][:12] in r["bundle_text"] and meta["provenance"]["created"] in r["bundle_text"]
    assert r["backend"]["isolated"] is True and r["backend"]["backend"] == "wasm" and r["backend"]["threads"] >= 1


def test_screen_reader_sees_one_control_and_the_helper_only_when_opened(run: dict) -> None:
    """The accessibility tree (what TalkBack reads): the heading, the big control, the status;
    the helper view is hidden from assistive technology until its button opens it."""
    aria = run["result"]["aria"]
    lines = [line.strip() for line in aria.splitlines()]
    assert any('button "Start' in line for line in lines), aria
    assert "View for a sighted helper" not in aria and "Check the decision logic" not in aria, aria
    assert '- button "Helper view"' in lines, aria
    opened = run["result"]["aria_helper_open"]
    assert 'region "View for a sighted helper"' in opened, opened
    assert 'checkbox "Level the camera with the tilt sensor' in opened and '- button "Check the decision logic"' in opened
    assert 'checkbox "Follow turns with the gyroscope' in opened, opened


def test_app_is_installable(run: dict) -> None:
    """Chromium's own installability check (what offers "Install app" on Android) finds nothing."""
    assert run["result"]["installability"] == [], run["result"]["installability"]
    assert run["result"]["manifest_errors"] == []
    manifest = json.loads((run["www"] / "manifest.webmanifest").read_text())
    assert manifest["orientation"] == "any"  # the app follows the phone; no forced portrait


def test_app_works_offline_after_first_load(run: dict) -> None:
    off = run["result"]["offline"]
    assert off["loaded"] and off.get("error") is None, off
    assert not [c for c in off["console"] if c.startswith(("error", "pageerror"))], off["console"]
    assert off["decisions"] >= 5


# ----------------------------------------------------------------------------- portrait, real bundle

def test_portrait_real_bundle_outputs_match_onnxruntime(portrait: dict) -> None:
    """onnxruntime-web (package.json) and Python's onnxruntime run the real default graph (its
    MC noise made constant) on the same portrait frames: probabilities within 1e-4 for an fp32
    graph. This is the parity proof while the two versions differ. An int8 graph is held to 0.15:
    the two runtimes' int8 kernels (x86 VNNI vs WASM) round the requantised activations
    differently (measured on the default bundle: 0.020 on whole portrait frames, up to 0.069 on
    the view-cropped ones the schema-3 bundle sees, which sit at the training scale; 0.103 with the
    `--unfreeze 8` default of 2026-11-29 evening, whose last 8 blocks were retrained), so exact
    agreement is not a property int8 has (a wrong crop, scale or channel order moves them by
    0.5 or more); the toy bundle's view-crop run holds the crop itself to 1e-5."""
    worst = 0.0
    for entry, rgb in _app_steps(portrait, least=10):
        if entry["outputs"] is None:   # rolled beyond levelling: the model was not asked
            continue
        pred = portrait["engine"].predict(rgb)
        worst = max(worst, float(np.abs(np.asarray(entry["outputs"]["probs"]) - pred.probs).max()))
    assert worst <= (0.15 if portrait["engine"].bundle.precision == "int8" else 1e-4), worst


def test_portrait_uses_the_portrait_fov_and_decides_as_python(portrait: dict) -> None:
    trace = portrait["result"]["trace"]
    fovs = [e for e in trace if e["kind"] == "fov"]
    assert fovs and all(e["orientation"] == "portrait" and e["height"] > e["width"] for e in fovs), fovs
    assert {e["fov_deg"] for e in fovs} == {portrait["geometry"]["camera_fov_deg"]["portrait"]}
    unc = portrait["engine"].bundle.calibration.uncertainty   # the portrait gate threshold, when the bundle has one
    assert {e["threshold"] for e in fovs} == {unc.threshold_for("portrait")}
    engine, steps = portrait["engine"], _app_steps(portrait, least=10)
    if engine.bundle.precision != "int8":
        _assert_same_decisions(engine, steps, tol_deg=1e-3)
        return
    # int8: the two runtimes' kernels differ by up to ~0.1 in probability (the parity test), which
    # can flip a gate near its threshold (seen with the view crop on). The decision logic is held
    # exactly on the app's own outputs; the Python engine's outputs agree on stop/go and side on
    # >= 90% of the frames.
    outputs = {id(rgb): entry["outputs"] for entry, rgb in steps}

    def app_outputs(rgb):
        o = outputs[id(rgb)]
        probs = np.asarray(o["probs"], np.float64)
        unc = measure_value(engine.measure, o["entropy"], o["mutual_info"], np.asarray(o["variance"]), probs)
        return SimpleNamespace(observation=lambda: Observation(probs, unc))

    _assert_same_decisions(engine, steps, tol_deg=1e-6, predict=app_outputs)
    agree = 0
    for entry, d in _python_decisions(engine, steps):
        a = entry["decision"]
        same_side = d["stop"] or a["stop"] or math.copysign(1, d["heading_deg"]) == math.copysign(1, a["heading_deg"])
        agree += (d["stop"] == a["stop"]) and same_side
    assert agree >= 0.9 * len(steps), f"{agree}/{len(steps)} decisions agree"


def test_a_phone_rolled_beyond_what_can_be_levelled_stops_and_says_so(portrait: dict) -> None:
    """Turned 75 deg (the screen's rotation locked, the phone sideways): levelled by at most 45
    its frames stay rolled 30 deg, beyond the training views' 15, where the default bundle played
    4 % confidently wrong held out. The model is not asked; the beacon stops; the user hears to
    hold the phone level."""
    far = portrait["result"]["roll"]["too_far"]
    frames = [e for e in portrait["result"]["trace"] if e["kind"] == "frame" and far["t_start"] + 0.3 < e["t"]
              and e["grabbed"] < far["t_end"]]   # the roll is read when the frame is grabbed
    assert len(frames) >= 5, far
    assert all(e["decision"]["stop"] and not e["obs"]["ok"] and e["outputs"] is None for e in frames)
    assert far["t_spoken"] - far["t_start"] < 3.0


def test_a_rolled_phone_s_frames_are_levelled_as_python_levels_them(portrait: dict) -> None:
    """The portrait run, turned ROLL_DEG clockwise about the camera's axis (synthetic
    deviceorientation events): the app levels the frames it gives the model, and each is the
    Python runtime's ``level`` of a clip frame by that roll, to within the fake camera's colour
    loss; the clip frame un-levelled, or levelled the other way, is far from it. Before the roll,
    and during the tilt phase (level camera), nothing is turned."""
    from crossing_assist.geometry import level

    pad = tuple(portrait["geometry"]["pad_rgb"])
    clip = portrait["clip"].astype(np.int16)
    steps = _app_steps(portrait, least=10)
    too_far = portrait["result"]["roll"]["too_far"]["t_start"]   # then turned beyond levelling (test above)
    # the roll is read when a frame is grabbed, which may be after its capture (a model run was going)
    rolled = [(e, rgb) for e, rgb in steps if e["roll_deg"] != 0 and e["grabbed"] < too_far]
    assert len(rolled) >= 8 and all(abs(e["roll_deg"] - ROLL_DEG) < 0.01 for e, _ in rolled), \
        [e["roll_deg"] for e, _ in rolled]
    assert all(e["roll_deg"] == 0 for e, _ in steps if e["grabbed"] < portrait["result"]["roll"]["t_start"])

    def nearest(frames, rgb):
        return float(np.abs(frames - rgb.astype(np.int16)[None]).mean(axis=(1, 2, 3)).min())

    levelled = np.stack([level(f, ROLL_DEG, pad) for f in portrait["clip"]]).astype(np.int16)
    wrong_way = np.stack([level(f, -ROLL_DEG, pad) for f in portrait["clip"]]).astype(np.int16)
    for entry, rgb in rolled:
        same, raw, other = nearest(levelled, rgb), nearest(clip, rgb), nearest(wrong_way, rgb)
        assert same <= 2.0 and raw >= 5 * same and other >= 5 * same, (entry["t"], same, raw, other)
    assert "to level" in portrait["result"]["roll"]["camera_text"], portrait["result"]["roll"]["camera_text"]


def test_the_tilt_sensor_is_on_without_any_url_flag_or_setting(portrait: dict) -> None:
    """The portrait run loads the app with no URL flag for the sensors and no sensor setting
    stored (a user who never opened the settings): the tilt sensor is used all the same, so the
    levelling and the roll stop above are the app's defaults; the gyroscope stays off, and turns
    are read from the camera picture (the next test)."""
    r = portrait["result"]
    query = r["page_url"].split("?", 1)[-1]
    assert "gyro" not in query and "tilt" not in query and "visualyaw" not in query, r["page_url"]
    stored = json.loads(r["stored_settings"])
    assert "gyro" not in stored and "tilt" not in stored and "visualYaw" not in stored, stored
    frames = [e for e in r["trace"] if e["kind"] == "frame"]
    assert any(e["roll_deg"] != 0 for e in frames), "nothing levelled with the defaults"
    assert {e["yaw_source"] for e in frames} == {"camera"}   # no gyroscope unless turned on: the picture's turn
    assert "rolled" in r["roll"]["tilt_text"] and "too far" in r["roll"]["tilt_text"], r["roll"]["tilt_text"]


def test_without_the_gyroscope_the_turn_is_read_from_the_picture_as_python_reads_it(portrait: dict) -> None:
    """The portrait run (the app's defaults: no gyroscope) feeds the Decider the turn read from
    the camera picture: each frame's rate is Python's ``VisualYaw`` fed the same frames (the
    levelled frame the model ran on, before any view crop) at the app's capture times and FOVs,
    started afresh wherever the app started a fresh Decider, within 1e-6 deg/s (relative above
    1; the two compute the same sums, in another order). The sample clip pans right for about 5 s
    (Python reads up to ~45 deg/s on it), so the rates are not all zero."""
    from crossing_assist.runtime.visual_yaw import VisualYaw

    seen, worst, turning = VisualYaw(), 0.0, 0
    for entry, rgb in _app_steps_in_order(portrait, least=10):
        assert entry["yaw_source"] == "camera", entry["yaw_source"]
        if entry["new_decider"]:
            seen.reset()
        want = seen.update(rgb, entry["t"], entry["fov_deg"])
        worst = max(worst, abs(entry["yaw_rate_dps"] - want) / max(1.0, abs(want)))
        turning += abs(want) >= 5.0
    assert worst <= 1e-6, worst
    assert turning >= 5, f"only {turning} frames turning 5 deg/s or more"


def test_without_a_gyroscope_a_decision_the_picture_turn_makes_stale_plays_as_a_stop(portrait: dict) -> None:
    """No gyroscope reports in the portrait run, so nothing turns a decision once its frame is read.
    A decision plays until the next one, so one whose turn read from the picture, carried from its
    capture past its decision by a frame interval, passes half a strip plays as a stop (trace
    ``picture_stale``), as Python's live loop plays it (``Pipeline.heard``): every frame whose turn
    up to its decision alone passes half a strip, and no frame whose whole turn stays within it.
    One that plays is checked again when the next frame is read (``cut``): the turn read since its
    capture, carried on through the next model run. The sample clip pans right at up to ~45 deg/s,
    so some decisions are stopped."""
    r = portrait["result"]
    frames = {e["id"]: e for e in r["trace"] if e["kind"] == "frame"}
    records = [e for e in r["trace"] if e["kind"] == "picture_stale"]
    stale = {e["frame"]: e for e in records if not e.get("cut")}
    assert stale, "no decision was made stale by the picture's turn"
    for i, e in stale.items():
        f = frames[i]
        half = f["decision_fov_deg"] / 24
        assert f["fresh"] and not f["decision"]["stop"] and f["yaw_source"] == "camera"
        assert abs(e["turn_deg"]) > half and abs(e["turn_deg"]) >= abs(f["yaw_rate_dps"]) * (f["decided"] - f["t"]) - 1e-9
    for i, f in frames.items():
        if not f["fresh"] or f["decision"]["stop"] or f["yaw_source"] != "camera":
            continue
        if abs(f["yaw_rate_dps"]) * (f["decided"] - f["t"]) > f["decision_fov_deg"] / 24:
            assert i in stale, f
        if abs(f["yaw_rate_dps"]) <= f["decision_fov_deg"] / 24:   # within half a strip even a second on
            assert i not in stale, (f, stale.get(i))
    for e in records:
        if e.get("cut"):   # played when decided, stopped once the next frame (captured after it) is read
            f = frames[e["frame"]]
            assert e["frame"] not in stale and not f["decision"]["stop"] and e["t"] > f["t"]
            assert abs(e["turn_deg"]) > f["decision_fov_deg"] / 24


def test_a_tilt_sensor_that_stops_leaves_no_stale_roll_and_is_said_once(portrait: dict) -> None:
    """The sensor falls silent while its last reading says 75 deg (beyond levelling): frames
    grabbed more than ROLL_FRESH_S after that reading are neither turned nor stopped as rolled
    (the model is asked again); NO_TILT_AFTER_S later the user hears and sees "No tilt sensor"
    once, and guidance goes on. With the sensor working before, it was never said."""
    r = portrait["result"]
    silent = r["sensor_stopped"]
    t0 = silent["t_start"]
    frames = [e for e in r["trace"] if e["kind"] == "frame" and e["grabbed"] > t0 + ROLL_FRESH_S + 0.05
              and e["t"] < silent["t_end"]]
    assert len(frames) >= 5, silent
    assert all(e["roll_deg"] == 0 and e["outputs"] is not None and e["obs"]["ok"] for e in frames), \
        [(e["t"] - t0, e["roll_deg"], e["obs"]["ok"]) for e in frames]
    said = [e for e in r["trace"] if e["kind"] == "speech" and e["text"] == NO_TILT]
    assert len(said) == 1 and NO_TILT_AFTER_S - 0.06 <= said[0]["t"] - t0 <= NO_TILT_AFTER_S + 1.0, \
        ([e["t"] - t0 for e in said], t0)
    st = silent["state"]
    assert st["notice"] == NO_TILT and st["running"] and st["mode"] == "running", st
    heard = [h for h in st["heard"] if h["text"] == NO_TILT]
    assert len(heard) == 1 and heard[0]["how"] in ("whole", None), heard   # None: still being spoken
    assert any(e["kind"] == "frame" and e["fresh"] and e["t"] > said[0]["t"] for e in r["trace"])


def test_portrait_screen_control_fills_the_screen(portrait: dict) -> None:
    r = portrait["result"]
    want = [0, 0, r["viewport"]["width"], r["viewport"]["height"] - BAR_PX]
    assert all(s["control"] == want for s in r["samples"]) and r["states"]["ended_double"]["control"] == want


def test_onnxruntime_versions_are_recorded() -> None:
    """onnxruntime-web (the phone) and onnxruntime (Python) are pinned; where their versions
    differ, test_portrait_real_bundle_outputs_match_onnxruntime is the parity proof."""
    import onnxruntime

    web = json.loads((DEMO / "package.json").read_text())["devDependencies"]["onnxruntime-web"]
    assert re.fullmatch(r"\d+\.\d+\.\d+", web) and onnxruntime.__version__


# ----------------------------------------------------------------------------- portrait, view crop

@pytest.fixture(scope="module")
def portrait_crop(tmp_path_factory) -> dict:
    """A schema-3 test bundle with the view crop, a portrait camera (180 x 240) whose clip holds
    one bar in the rows the crop keeps and a brighter one in the rows it cuts off."""
    clip = _clip_tool()
    tmp = tmp_path_factory.mktemp("android_e2e_crop")
    bundle = toy_bundle.make_toy_bundle(tmp / "bundle", toy_bundle.APP_TOY, geometry=CROP_GEOMETRY)
    engine = Engine(bundle)
    assert engine.bundle.schema_version == 3 and engine.bundle.geometry.view_crop
    w, h = CROP_CAMERA
    keep = view_rows(h, w, engine.camera_fov(w, h), engine.bundle.input.size, CROP_GEOMETRY.train_fov_deg)
    frames, strips = clip.view_crop_clip(w, h, keep)
    clip.write_y4m(tmp / "clip.y4m", frames, 10)
    www = _build(tmp, bundle)
    result = _drive(tmp, www, tmp / "clip.y4m", 5.0, "--phases", "short", "--viewport", "390x844")
    return {"result": result, "engine": engine, "keep": keep}


def test_view_crop_the_app_keeps_the_rows_python_keeps(portrait_crop: dict) -> None:
    """Each portrait frame's FOV is the portrait default (decided on the whole frame), and the
    rows the app gave the graph are view_rows of that frame: [top, rows], a real crop."""
    engine = portrait_crop["engine"]
    g = engine.bundle.geometry
    frames = [e for e in portrait_crop["result"]["trace"] if e["kind"] == "frame"]
    assert len(frames) >= 20, len(frames)
    for e in frames:
        assert e["height"] > e["width"] and e["fov_deg"] == g.camera_fov_deg[1], e
        want = view_rows(e["height"], e["width"], e["fov_deg"], engine.bundle.input.size, g.train_fov_deg)
        assert e["view_rows"] == list(want), (e["width"], e["height"], e["view_rows"], want)
        assert 0 < e["view_rows"][1] < e["height"]
    assert {tuple(e["view_rows"]) for e in frames} == {portrait_crop["keep"]}   # the camera's 180 x 240


def test_view_crop_outputs_and_decisions_match_the_python_engine(portrait_crop: dict) -> None:
    """The same portrait frames through Engine.predict (which crops them itself) and through the
    app: outputs within 1e-5, every decision the same. The crop matters: the whole frame through
    the same graph points elsewhere on nearly every frame (the clip's cut-off rows hold a
    brighter bar at another strip)."""
    engine = portrait_crop["engine"]
    steps = _app_steps_in_order(portrait_crop, least=20)
    worst, elsewhere = 0.0, 0
    for entry, rgb in steps:
        pred = engine.predict(rgb)
        assert pred.ok, pred.error
        app_probs = np.asarray(entry["outputs"]["probs"])
        worst = max(worst, float(np.abs(app_probs - pred.probs).max()), abs(entry["outputs"]["entropy"] - pred.entropy))
        whole = np.asarray(inference.run(engine.session, rgb[None])["probs"])[0]
        elsewhere += int(np.argmax(whole)) != int(np.argmax(app_probs))
    assert worst <= 1e-5, f"largest difference {worst}"
    assert elsewhere >= 0.9 * len(steps), f"the uncropped frame pointed elsewhere on only {elsewhere}/{len(steps)}"
    gates = _assert_same_decisions(engine, steps)
    assert "learner" in gates, gates


NARROW_CAMERA = (144, 256)  # width x height: 9:16 portrait video (~41 deg with sensor_aspect 4:3)


@pytest.fixture(scope="module")
def narrow_video(tmp_path_factory) -> dict:
    """A toy bundle whose portrait threshold silences everything and whose narrow camera's
    threshold (portrait frames at most 42 deg across) does not, its landscape one a third value,
    filmed as 9:16 portrait video with a bar at strip 4."""
    clip = _clip_tool()
    tmp = tmp_path_factory.mktemp("android_e2e_narrow")
    geometry = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0, view_crop=True,
                        sensor_aspect=4 / 3)
    bundle = toy_bundle.make_toy_bundle(tmp / "bundle", toy_bundle.APP_TOY, geometry=geometry, threshold=2.0,
                                        portrait_threshold=1e-6, narrow_threshold=toy_bundle.APP_TOY.threshold,
                                        narrow_fov_deg=42.0)
    w, h = NARROW_CAMERA
    rng = np.random.default_rng(4)
    frames = [np.clip(clip.bar_frame(w, h, 4.0).astype(np.int16) + rng.integers(-3, 4, (h, w, 3)), 0, 255)
              .astype(np.uint8) for _ in range(50)]
    clip.write_y4m(tmp / "clip.y4m", frames, 10)
    result = _drive(tmp, _build(tmp, bundle), tmp / "clip.y4m", 4.0, "--phases", "short", "--viewport", "390x844",
                    "--visual-yaw", "0")
    return {"result": result, "engine": Engine(bundle)}


def test_9_16_video_takes_the_narrow_cameras_threshold_and_decides_as_python(narrow_video: dict) -> None:
    """The app gives 9:16 portrait frames their crop's FOV (~41 deg) and so the narrow camera's
    gate threshold: the beacon guides where the portrait threshold would keep it silent, and
    every decision is Python's on the same frames."""
    engine = narrow_video["engine"]
    unc = engine.bundle.calibration.uncertainty
    fovs = [e for e in narrow_video["result"]["trace"] if e["kind"] == "fov"]
    assert fovs and all(e["fov_deg"] == pytest.approx(41.005, abs=1e-3) for e in fovs), fovs
    assert {e["threshold"] for e in fovs} == {unc.narrow_threshold} != {unc.portrait_threshold}
    assert "a narrow camera’s gate threshold" in narrow_video["result"]["camera_text"]
    # the helper view reads each frame's uncertainty against the threshold that frame took
    text = narrow_video["result"]["uncertainty_text"]
    assert f"(threshold {unc.narrow_threshold:.2f})" in text and unc.threshold != unc.narrow_threshold, text
    gates = _assert_same_decisions(engine, _app_steps_in_order(narrow_video, least=15))
    assert "learner" in gates, gates


def test_visualyaw_0_follows_no_turn_and_says_so(narrow_video: dict) -> None:
    """The narrow-video run loads the app with ?visualyaw=0: no frame's turn is read from the
    picture (the source is off, the Decider told 0 deg/s), the helper view says turns are not
    followed, and the flag is this visit's only (not stored)."""
    r = narrow_video["result"]
    assert "visualyaw=0" in r["page_url"], r["page_url"]
    frames = [e for e in r["trace"] if e["kind"] == "frame"]
    assert len(frames) >= 15 and {e["yaw_source"] for e in frames} == {"off"}, {e["yaw_source"] for e in frames}
    assert all(e["yaw_rate_dps"] == 0 for e in frames)
    assert r["turning_text"].startswith("not followed"), r["turning_text"]
    assert "visualYaw" not in json.loads(r["stored_settings"])


def _panning_run(tmp: Path, *driver_args: str, bars: bool = False) -> dict:
    """The toy bundle, a portrait camera panning right over a textured scene (6 px a frame at 10
    fps: about 30 deg/s at the portrait FOV), 6 s of the short phases. ``bars``: the texture dimmed
    and a bright bar every 150 px, so the toy (a brightness detector) sees a goal most of the time."""
    clip = _clip_tool()
    bundle = toy_bundle.make_toy_bundle(tmp / "bundle", toy_bundle.APP_TOY, geometry=APP_GEOMETRY)
    rng = np.random.default_rng(7)
    h, w, step = 160, 120, 6
    scene = rng.uniform(0, 255, (h, w + step * 80, 3))
    for axis in (0, 1):   # a smooth random scene: enough texture for the picture's turn
        scene = sum(np.roll(scene, k, axis=axis) for k in range(-3, 4)) / 7
    scene = np.clip((scene - scene.mean()) * 4 + 128, 0, 255)
    if bars:
        scene *= 0.5
        for x in range(100, scene.shape[1], 150):
            scene[:, x:x + 8] = 255
    scene = scene.astype(np.uint8)
    frames = [np.ascontiguousarray(scene[:, step * k:step * k + w]) for k in range(80)]
    clip.write_y4m(tmp / "clip.y4m", frames, 10)
    return _drive(tmp, _build(tmp, bundle), tmp / "clip.y4m", 6.0, "--phases", "short", "--viewport", "390x844",
                  *driver_args)


@pytest.fixture(scope="module")
def wrong_gyro(tmp_path_factory) -> dict:
    """The panning camera, and a gyroscope that reads its turn as a turn left (?gyro=1): its sign
    is wrong on this phone."""
    return {"result": _panning_run(tmp_path_factory.mktemp("android_e2e_gyro"), "--gyro", "-30")}


def test_a_gyroscope_turning_the_wrong_way_is_found_out_and_left(wrong_gyro: dict) -> None:
    """?gyro=1 on a phone whose gyroscope reads the camera's turn right as a turn left: the
    picture's turn (GyroCheck) finds it out after its first clear turns, the user hears and sees
    so once, and from then on the Decider follows the picture's turn (rightwards), not the
    gyroscope's, for the rest of the guidance."""
    r = wrong_gyro["result"]
    frames = [e for e in r["trace"] if e["kind"] == "frame"]
    checks = [e for e in r["trace"] if e["kind"] == "gyro_check"]
    assert len(checks) == 1 and checks[0]["verdict"] == "wrong", checks
    before = [e for e in frames if e["t"] < checks[0]["t"]]
    after = [e for e in frames if e["t"] >= checks[0]["t"]]
    assert before and {e["yaw_source"] for e in before} == {"gyro"}, {e["yaw_source"] for e in before}
    assert all(e["yaw_rate_dps"] < -20 for e in before[1:]), [e["yaw_rate_dps"] for e in before]
    assert len(before) <= 20, len(before)   # found out within a couple of seconds of turning
    assert len(after) >= 10 and {e["yaw_source"] for e in after} == {"camera"}
    assert np.median([e["yaw_rate_dps"] for e in after]) > 15   # the picture's turn: right
    spoken = [e["text"] for e in r["trace"] if e["kind"] == "speech" and "gyroscope" in e["text"]]
    assert spoken == ["The gyroscope reads turns the wrong way: turns are followed from the camera picture."], spoken
    assert r["turning_text"].endswith("(camera picture)"), r["turning_text"]


@pytest.fixture(scope="module")
def confirmed_gyro(tmp_path_factory) -> dict:
    """The panning camera with the app's own settings (turns read from the picture), and a
    gyroscope that reads the same turn right; a field recording made all along (?record=1)."""
    return {"result": _panning_run(tmp_path_factory.mktemp("android_e2e_gyro_ok"), "--motion", "30", "--record", "1",
                                   bars=True)}


def test_a_field_recording_replays_in_crossing_demo_with_its_motion_log(confirmed_gyro: dict, tmp_path) -> None:
    """?record=1: when guidance ends the helper view offers the camera's video and the motion log
    side by side (NAME.webm, NAME.imu.csv). crossing-demo --imu reads both: the log holds the
    gyroscope's 30 deg/s turn right on the recording's clock, and Python's own check of the
    recorded video's turn confirms its sign, so the app's sign and timing reach Python intact."""
    from crossing_assist.runtime.imu import ImuLog
    from crossing_assist.runtime.offline import OfflineConfig, run_offline
    from crossing_assist.runtime.sources import VideoSource

    rec = confirmed_gyro["result"]["recording"]
    assert not rec["hidden"] and rec["extension"] == "webm", rec
    names = [link["download"] for link in rec["links"]]
    assert len(names) == 2 and names[0].endswith(".webm") and names[1] == names[0][:-5] + ".imu.csv", names
    assert all(link["href"] == "blob:" for link in rec["links"])
    video = tmp_path / names[0]
    video.write_bytes(base64.b64decode(rec["video_b64"]))
    (tmp_path / names[1]).write_text(rec["csv"])
    log = ImuLog.load(tmp_path / names[1])
    assert rec["samples"] == len(log.t) > 100
    assert np.median(log.yaw_dps) == pytest.approx(30.0, abs=0.01)
    assert -0.5 < log.t[0] < 1.0 and rec["seconds"] - 1.0 < log.t[-1] <= rec["seconds"]
    frames = [f for _, f in VideoSource(video)]
    assert len(frames) >= 3 * rec["seconds"] and frames[0].shape[:2] == (160, 120)
    bundle = toy_bundle.make_toy_bundle(tmp_path / "bundle", toy_bundle.APP_TOY, geometry=APP_GEOMETRY)
    summary = run_offline(OfflineConfig(video=video, bundle=bundle, out_dir=tmp_path / "demo", annotate=False,
                                        progress=False, imu=tmp_path / names[1]))
    assert summary.gyro is not None and "once the picture's turn had confirmed it" in summary.gyro, summary.gyro
    covered = int(re.search(r"reported on (\d+)%", summary.gyro).group(1))
    assert covered >= 90, summary.gyro


def test_a_gyroscope_the_picture_confirms_is_followed_by_default(confirmed_gyro: dict) -> None:
    """By default the Decider follows the turn read from the picture. A gyroscope is listened to
    as well: once the picture has confirmed its turns (GyroCheck), it is followed instead, and each
    decision is played turned by the gyroscope's turn since its frame's capture (step 10), never
    before (before, a decision the turn has made half a strip stale plays as a stop); nothing is said."""
    r = confirmed_gyro["result"]
    assert "gyro=1" not in r["page_url"]
    frames = {e["id"]: e for e in r["trace"] if e["kind"] == "frame"}
    checks = [e for e in r["trace"] if e["kind"] == "gyro_check"]
    assert [e["verdict"] for e in checks] == ["ok"], checks
    before = [e for e in frames.values() if e["t"] <= checks[0]["t"]]
    after = [e for e in frames.values() if e["t"] > checks[0]["t"]]
    assert len(before) >= 8 and {e["yaw_source"] for e in before} == {"camera"}   # 8 clear turns first
    assert len(after) >= 15 and {e["yaw_source"] for e in after} == {"gyro"}
    assert all(25 <= e["yaw_rate_dps"] <= 35 for e in after[1:]), [e["yaw_rate_dps"] for e in after]
    turned = [e for e in r["trace"] if e["kind"] == "turned" and e["frame"] in frames]
    assert turned, "a confirmed gyroscope never turned the beacon"
    assert all(frames[e["frame"]]["t"] >= checks[0]["t"] for e in turned), "turned before the picture confirmed it"
    assert all(e["turn_deg"] >= 0 for e in turned) and max(e["turn_deg"] for e in turned) > 2.0   # 30 deg/s right
    # before that, the gyroscope reports but is not followed: only the size of its turn is trusted, so a
    # decision plays as decided until the turn since its capture passes half a strip (13 actions), then
    # as a stop; never turned
    stale = [e for e in r["trace"] if e["kind"] == "stale" and e["frame"] in frames]
    assert stale and all(frames[e["frame"]]["t"] <= checks[0]["t"] for e in stale), stale
    for e in stale:
        f = frames[e["frame"]]
        half = f["decision_fov_deg"] / 12 / 2
        assert e["heading_deg"] == (None if abs(e["turn_deg"]) > half else f["decision"]["heading_deg"]), (e, f["decision"])
    assert any(e["heading_deg"] is None for e in stale)   # ~30 deg/s for 0.3-0.5 s: well past half a strip
    assert not any("gyroscope" in e.get("text", "") for e in r["trace"] if e["kind"] == "speech")
    assert r["turning_text"].endswith("(gyroscope)"), r["turning_text"]   # the helper view says which


# ----------------------------------------------------------------------------- the shipped bundle



@pytest.mark.slow
def test_default_bundle_on_the_sample_clip_agrees_with_python(tmp_path: Path) -> None:
    """The embedded bundle (MC dropout: outputs are random) on the embedded clip, in Chromium.

    Tolerance, stated for sampling noise: on >= 90% of the app's frames its top action is one
    of the top actions of 5 onnxruntime runs on the same frame; entropies differ by <= 0.15
    nats at the median; the Python Decider fed the Python engine's outputs for the app's
    frames at the app's times agrees with the app on stop/go and side on >= 80% of the
    decisions (measured with an interim EfficientNet-Lite0 96x96 bundle: 94%).
    """
    if not (DEFAULT_BUNDLE / "bundle.json").is_file() or not SAMPLE_CLIP.is_file():
        pytest.skip("the default bundle or the sample clip is not in crossing_assist/assets yet")
    import cv2

    clip = _clip_tool()
    cap = cv2.VideoCapture(str(SAMPLE_CLIP))
    fps = cap.get(cv2.CAP_PROP_FPS) or 15.0
    frames = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(bgr[: bgr.shape[0] // 2 * 2, : bgr.shape[1] // 2 * 2], cv2.COLOR_BGR2RGB))
    clip.write_y4m(tmp_path / "clip.y4m", frames, round(fps))
    www = _build(tmp_path, DEFAULT_BUNDLE)
    result = _drive(tmp_path, www, tmp_path / "clip.y4m", len(frames) / fps, "--phases", "short")
    run = {"result": result}
    engine = Engine(DEFAULT_BUNDLE)
    top_in = agree = total = 0
    dent = []
    outs = {}

    def five(rgb):
        preds = [engine.predict(rgb) for _ in range(5)]
        outs["preds"] = preds
        return preds[0]

    for entry, d in _python_decisions(engine, _app_steps_in_order(run, least=20), predict=five):
        preds = outs["preds"]
        top_in += int(np.argmax(entry["outputs"]["probs"])) in {int(np.argmax(p.probs)) for p in preds}
        dent.append(abs(entry["outputs"]["entropy"] - preds[0].entropy))
        a = entry["decision"]
        total += 1
        same_side = d["stop"] or a["stop"] or math.copysign(1, d["heading_deg"]) == math.copysign(1, a["heading_deg"])
        agree += (d["stop"] == a["stop"]) and same_side
    assert top_in >= 0.9 * total, f"the app's top action is among onnxruntime's on {top_in}/{total} frames"
    assert float(np.median(dent)) <= 0.15
    assert agree >= 0.8 * total, f"{agree}/{total} decisions agree"


# ----------------------------------------------------------------------------- a hand-edited bundle

#: Opens the app at ?bundle=NAME/ for each NAME (argv: www, chromium, names...), clicks the control
#: of a page that did not get ready, and prints what each page showed, said and did as JSON.
_LOAD_SCRIPT = r"""
import { spawn } from 'node:child_process';
import { chromium } from 'playwright-core';
const [www, executablePath, ...names] = process.argv.slice(1);
const server = spawn(process.execPath, ['tools/serve.mjs', '--port', '0', '--root', www], { stdio: ['ignore', 'pipe', 'inherit'] });
const url = await new Promise((ok) => server.stdout.on('data', (c) => { const m = /serving (\S+)/.exec(String(c)); if (m) ok(m[1]); }));
const browser = await chromium.launch({ executablePath, args: ['--headless=new', '--no-sandbox', '--disable-gpu',
  '--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream'] });
const out = {};
try {
  for (const name of names) {
    const page = await browser.newPage();
    await page.addInitScript(() => {
      window.__said = [];
      if (window.speechSynthesis) window.speechSynthesis.speak = (u) => window.__said.push(u.text);
    });
    await page.goto(`${url}?test=1&bundle=${name}/`);
    await page.waitForFunction(() => window.crossingAssist && (window.crossingAssist.ready || window.crossingAssist.error),
      null, { timeout: 180000 });
    const ready = await page.evaluate(() => window.crossingAssist.ready);
    if (!ready) await page.locator('#control').click({ force: true, timeout: 2000 }).catch(() => null);
    await page.waitForTimeout(500);
    out[name] = await page.evaluate(() => {
      const a = window.crossingAssist;
      const err = document.getElementById('error');
      return { ready: a.ready, mode: a.mode, running: Boolean(a.running), error: a.error, shown: err.hidden ? null : err.textContent,
        disabled: document.getElementById('control').disabled, label: document.getElementById('control-label').textContent,
        said: window.__said };
    });
    await page.close();
  }
} finally {
  await browser.close();
  server.kill();
}
console.log(JSON.stringify(out));
"""


def test_a_hand_edited_bundle_json_is_refused_and_nothing_guides(tmp_path: Path) -> None:
    """The default bundle copied beside the app twice, one with bundle.json's gate threshold
    edited by hand, loaded with ?bundle=: the edited one is refused with one line naming the leaf
    and both values (shown and spoken; the control stays disabled and a tap starts nothing), the
    unedited copy gets ready."""
    if not (DEFAULT_BUNDLE / "bundle.json").is_file():
        pytest.skip("the default bundle is not in crossing_assist/assets")
    www = _build(tmp_path, DEFAULT_BUNDLE)
    for name in ("edited", "same"):
        shutil.copytree(DEFAULT_BUNDLE, www / name)
    meta = json.loads((www / "edited" / "bundle.json").read_text())
    was = meta["calibration"]["uncertainty"]["threshold"]
    meta["calibration"]["uncertainty"]["threshold"] = 0.05
    (www / "edited" / "bundle.json").write_text(json.dumps(meta, indent=2))
    proc = subprocess.run([NODE, "--input-type=module", "-e", _LOAD_SCRIPT, str(www), CHROMIUM, "edited", "same"],
                          cwd=DEMO, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr[-3000:]
    pages = json.loads(proc.stdout.strip().splitlines()[-1])
    line = (f"bundle.json: calibration.uncertainty.threshold = 0.05 disagrees with the model's {was!r}; "
            "re-export the bundle")
    edited = pages["edited"]
    assert edited["error"].endswith(line) and edited["shown"] == edited["error"], edited
    assert line in " ".join(edited["said"])
    assert not edited["ready"] and not edited["running"] and edited["mode"] != "running"
    assert edited["disabled"] and edited["label"] == "Not ready"
    assert pages["same"]["ready"] and pages["same"]["error"] is None and not pages["same"]["disabled"]

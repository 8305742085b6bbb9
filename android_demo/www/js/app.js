// The phone app, the browser twin of crossing_assist/runtime/live.py: bundle -> session;
// Start -> (first run: headphone check and sound tutorial) -> camera + audio; each new camera
// frame, at most 10 a second -> (frozen check) -> model -> Decider (logic.js) -> beacon
// (audio.js), spoken sentence (speech.js), vibration (haptics.js) and the helper view.
//
// Guards (each one a stop: the beacon never plays a direction it cannot vouch for):
// * a decision plays only if it is fresh (made within the watchdog period of its frame's
//   capture: the camera's own time for the frame, camera.js, not when the app grabbed it); a
//   watchdog polled every 20 ms plays the stop cue when no fresh decision arrived for 0.5 s
//   (frozen or covered camera, a hung model);
// * audio that cannot play (the AudioContext suspended or interrupted by a call or another
//   app) is failed guidance: its own vibration and "Audio stopped. Tap to resume."; a tap, the
//   return to the app or the audio given back by itself (after a call) resumes it, with a fresh
//   Decider (resetDecisions);
// * in the background guidance pauses (stop cue, no inference); back in front, the Decider
//   starts afresh (no stale heading) and the screen wake lock is requested again;
// * a decision state reset (resetDecisions) starts a new generation: a model run still going
//   from the one before is dropped when it ends (its Decider and frame are gone);
// * an instruction the user needs to recover (an error: camera lost, ...) is spoken whole, not
//   cut by a routine stop sentence (speech.js Speaker, urgent);
// * a frame whose handling throws outside the model (a bug) plays the stop cue and starts the
//   decisions afresh; guidance goes on, and ends with the error's message only when
//   MAX_LOOP_ERRORS frames in a row throw;
// * the field of view comes from the frame's orientation (portrait / landscape): the user's
//   setting for it, else the bundle's default (geometry.js cameraFov: a crop narrower than the
//   sensor, e.g. 9:16 video, gets its own with geometry.sensor_aspect); a new FOV starts a fresh Decider,
//   and an invalid one stops;
// * a bundle with geometry.view_crop (schema 3) sees only the frame's middle rows at the training
//   camera's angular scale (geometry.js viewRows, from the whole frame's FOV), as Engine.predict;
// * with the tilt sensor on (the DEFAULT: settings.js `tilt`), a frame from a camera rolled about
//   its axis is turned level first (camera.js FrameGrabber.level, the roll from TiltWatch), as
//   Engine.predict(roll_deg), and a camera rolled beyond levelling (rolledTooFar, over 60 deg) is
//   not given to the model: stop, "hold it level". It is on by default because a blind user will
//   not tick a box, and unlevelled a camera rolled 35-45 deg was confidently wrong on 9.5 % of 200
//   real photos (0.5 % levelled). Only a fresh roll counts (TILT.roll_fresh_s, 0.5 s): an older
//   reading is no roll known (no levelling, no roll stop);
// * a tilt sensor refused (iOS asks inside the start tap) or silent for 2 s while guiding is said
//   and shown once per guidance, "No tilt sensor: hold the phone level." (TiltSilence); guidance
//   goes on unlevelled.
//
// Advice on a "not sure" stop (the decision is unchanged, only the sentence and the vibration):
// with the tilt sensor on, a phone pointed far down or up is told which way to tilt (TiltWatch);
// a phone held upright and unsure for 5 s is told to hold it sideways (SidewaysHint).
// Following turns (the Decider's yaw rate, so the beacon turns with a sweeping phone): the
// gyroscope when it is on (settings.js `gyro`, OFF by default: its sign on a given phone needs a
// sighted check first) and the camera picture has not found it turning the wrong way (live.js
// GyroCheck: then the user is told once, and the picture's turn is followed for the rest of the
// guidance); else the turn read from the camera picture, the shift between the frame
// the model ran on and the one before (visualyaw.js VisualYaw, the Python pipeline's; settings.js
// `visualYaw`, ON by default), started afresh with every fresh Decider; else none (0). Each frame's
// trace entry says which (yaw_source 'gyro' | 'camera' | 'off').
//
// The whole screen above the helper bar is one control: tap to start; while guiding, a double
// tap or a long press ends guidance (a single tap only says how), and a tap resumes lost audio.
//
// URL flags: ?test=1 keeps a trace of every step (and copies of the camera frames, levelled,
// before any view crop) in window.crossingAssist for the end-to-end test; ?bundle=URL loads another bundle
// folder; ?gyro=1 turns on the gyroscope and the tilt sensor, ?tilt=0 turns the tilt sensor off
// (?tilt=1 on), ?visualyaw=0 turns off following turns from the camera picture (?visualyaw=1 on),
// for this visit only (never saved); ?threads=N sets the WASM threads;
// ?record=1 records the camera's video and the motion sensors' log while guidance runs, offered as
// downloads in the helper view when it ends (record.js; for crossing-demo VIDEO --imu LOG.csv);
// ?tutorial_speed=K plays the tutorial K times faster; ?sideways_after_s=S gives the hold-it-sideways
// advice after S s instead of 5.

import { BeaconAudio } from './audio.js';
import { CameraError, FrameGrabber, openCamera } from './camera.js';
import { cameraFov, defaultFovText, FovError, frameView, gateKind, gateThreshold, orientation, PAD_RGB, rolledTooFar, zoomedFov } from './geometry.js';
import { Haptics } from './haptics.js';
import { GYRO_CHECK, GYRO_WRONG_TEXT, GyroCheck, isFresh, NO_TILT_TEXT, sameFrame, SidewaysHint, TiltSilence, TiltWatch, Watchdog, WATCHDOG_S, YawIntegrator,
  yawRateFromRotation } from './live.js';
import { argmax, configFromBundle, cueFor, Decider, KIND_STOP, observationFromOutputs, REASON_UNCERTAIN, staleDecision, turnedDecision } from './logic.js';
import { fetchBundle, openBest } from './model.js';
import { loadSettings, saveSettings, urlOverrides } from './settings.js';
import { Speaker, SpeechPolicy } from './speech.js';
import { FieldRecorder } from './record.js';
import { playTutorial } from './tutorial.js';
import { replayVectors } from './vectors.js';
import { HelperView } from './view.js';
import { VisualYaw } from './visualyaw.js';

const POLL_MS = 20;
const FRAME_WAIT_MS = 100;
const MAX_LOOP_ERRORS = 5; // frames in a row that may throw outside the model before guidance ends
export const MIN_FRAME_INTERVAL_S = 0.1; // inference at most 10 times a second
export const DOUBLE_TAP_MS = 500;
export const LONG_PRESS_MS = 700;
const STOP_CUE = { kind: KIND_STOP };
const params = new URLSearchParams(location.search);
const TEST = params.get('test') === '1';
const RECORD = params.get('record') === '1'; // a researcher's field recording (record.js)
const TUTORIAL_SPEED = Math.max(1, Number(params.get('tutorial_speed')) || 1);
const SIDEWAYS_AFTER_S = Number(params.get('sideways_after_s')) || undefined; // tests: a shorter wait
const OVERRIDES = urlOverrides(params); // ?gyro=1, ?tilt=0|1, ?visualyaw=0|1: this visit only
const MAX_TRACE = 5000;
const MAX_FRAMES = 600;

const $ = (id) => document.getElementById(id);
const app = {
  ready: false, running: false, mode: 'loading', meta: null, model: null, decider: null, fov: null, audio: null,
  stream: null, grabber: null, watchdog: null, trace: [], frames: [], last: null, error: null, offline: 'not yet',
  inflight: null, // capture time of the frame the model is running on (null: none)
  generation: 0, // bumped by resetDecisions: a model run from an older generation is dropped
  t0: performance.now(), settings: loadSettings(), policy: new SpeechPolicy(), haptics: new Haptics(),
  speaker: new Speaker(true), audioFailed: false, paused: false, wakeLock: null, wakeLockRequests: 0,
  perf: { frames: 0, busyS: 0, startedS: 0, recentMs: 0 },
  visualYaw: new VisualYaw(), // turns read from the camera picture (without the gyroscope)
  cameraTurn: null, // its last rate (deg/s) for the helper view; null while it is not the source
  turning: null, // the decision played turned with the gyroscope (followTurn), until another cue plays
  playing: null, // no gyroscope: the decision playing, checked again when the next frame is read (checkPlaying)
  modelS: 0, // the last frame's capture to its decision (s): how long a decision waits for the next
};
window.crossingAssist = app;
const view = new HelperView(document);

/** A performance.now() time (ms: a frame's capture, a sensor event's timeStamp) on the Decider's clock (s). */
function appTime(ms) {
  return (ms - app.t0) / 1000;
}

/** Seconds since the page loaded (the Decider's clock). */
function now() {
  return appTime(performance.now());
}

function record(entry) {
  if (!TEST) return;
  app.trace.push(entry);
  if (app.trace.length > MAX_TRACE) app.trace.shift();
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// ----------------------------------------------------------------------------- screen, speech, touch

/** The control's label and hint (its box never changes: see style.css). */
function setControl(label, hint = '', state = '') {
  $('control-label').textContent = label;
  $('control-hint').textContent = hint;
  $('control').className = `control ${state}`;
}

function showError(message) {
  app.error = message;
  $('error').textContent = message;
  $('error').hidden = false;
  app.speaker.say(message, { urgent: true }); // how to recover: heard whole
}

function clearError() {
  app.error = null;
  $('error').textContent = '';
  $('error').hidden = true;
}

/** Show and speak one sentence ([text, cls] from statusMessage). */
function announce([text, cls], t = now()) {
  view.status(text, cls);
  app.speaker.say(text);
  record({ kind: 'speech', t, text });
}

/** What a decision means for the user beyond the beacon: the sentence (hysteresis) and the vibration.
 * A stop for "not sure" while the phone points far down or up says which way to tilt it instead;
 * one that has lasted a while with the phone upright, the model placing a crossing on most of its
 * frames (`seeing`), says to hold it sideways (live.js). */
function feedback(t, d, seeing = true) {
  const unsure = d.stop && d.reason === REASON_UNCERTAIN;
  const sideways = app.sideways?.update(t, unsure, app.orientation === 'portrait', seeing);
  const advice = unsure ? (app.tilt?.reason(t) || sideways) : null;
  if (advice) d = { ...d, reason: advice };
  const msg = app.policy.step(t, d);
  if (msg) announce(msg, t);
  const pattern = d.stop ? app.haptics.stop(d.reason) : app.haptics.go(t, d.heading_deg);
  if (pattern) record({ kind: 'vibrate', t, reason: d.stop ? d.reason : 'direction', pattern });
}

/** A stop the app itself decides (audio lost, background, invalid FOV): said and felt at once. */
function appStop(reason) {
  const t = now();
  app.audio?.render(STOP_CUE);
  const msg = app.policy.force(t, reason);
  if (msg) announce(msg, t);
  const pattern = app.haptics.stop(reason);
  if (pattern) record({ kind: 'vibrate', t, reason, pattern });
}

let lastTapMs = -Infinity;
let pressTimer = null;
let hintTimer = null;
let longPressed = false;

function onControlDown() {
  longPressed = false;
  clearTimeout(pressTimer);
  if (app.mode !== 'running') return;
  pressTimer = setTimeout(() => {
    longPressed = true;
    record({ kind: 'end', t: now(), how: 'long press' });
    stop();
  }, LONG_PRESS_MS);
}

function onControlUp() {
  clearTimeout(pressTimer);
}

function onControlClick() {
  if (longPressed) {
    longPressed = false;
    return;
  }
  const ms = performance.now();
  if (app.mode === 'ready') {
    start();
  } else if (app.mode === 'tutorial') {
    app.skipTutorial = true;
  } else if (app.mode === 'running') {
    if (app.audioFailed) {
      resumeAudio('tap');
    } else if (ms - lastTapMs <= DOUBLE_TAP_MS) {
      clearTimeout(hintTimer);
      lastTapMs = -Infinity;
      record({ kind: 'end', t: now(), how: 'double tap' });
      stop();
      return;
    } else {
      record({ kind: 'tap', t: now() });
      // Said only if no second tap follows (the first half of a double tap stays silent).
      hintTimer = setTimeout(() => app.running && app.speaker.say('Double tap or hold to end guidance.'), DOUBLE_TAP_MS);
    }
  }
  lastTapMs = ms;
}

function toggleHelper(open) {
  const helper = $('helper');
  helper.classList.toggle('closed', !open);
  helper.toggleAttribute('inert', !open);
  helper.setAttribute('aria-hidden', String(!open));
  $('helper-toggle').setAttribute('aria-expanded', String(open));
  $('helper-toggle').textContent = open ? 'Close the helper view' : 'Helper view';
  if (open) helper.scrollTop = 0;
}

// ----------------------------------------------------------------------------- the live loop

/** The FOV (degrees) for a width x height frame, and a sentence saying where it came from. */
function currentFov(width, height) {
  const o = orientation(width, height);
  const user = app.settings.fov[o];
  let fov = cameraFov(app.meta.geometry, width, height, user);
  let source = user === null ? 'the bundle’s default' : 'your setting';
  const track = app.stream?.getVideoTracks()[0];
  const zoomed = zoomedFov(fov, track?.getSettings?.(), track?.getCapabilities?.());
  if (zoomed !== fov) {
    fov = cameraFov(app.meta.geometry, width, height, zoomed);
    source += ', narrowed by the camera’s zoom';
  }
  return { fov, orientation: o, source };
}

const plain = (o) => ({ probs: Array.from(o.probs), entropy: o.entropy, mutual_info: o.mutual_info,
  variance: Array.from(o.variance), votes: Array.from(o.votes) });

/** A fresh start for the decisions (back from the background, audio back): no stale heading or
 * belief; a model run still going is dropped when it ends (step compares generations). */
function resetDecisions() {
  app.generation += 1;
  app.decider = null;
  app.fov = null;
  app.playing = null;
  app.visualYaw.reset(); // no turn read against a frame from before
}

/** One new (not frozen) camera frame, captured at `captured` s and grabbed at `grabbed` s, end to
 * end (live.run_live's loop body). `tooRolled`: the sensor says the camera is rolled beyond what
 * can be levelled (rolledTooFar): the model is not asked, the frame fails, the stop says why. */
async function step(frame, captured, grabbed, dt, tooRolled = false) {
  const generation = app.generation;
  let cam;
  try {
    cam = currentFov(frame.width, frame.height);
  } catch (err) {
    if (!(err instanceof FovError)) throw err;
    record({ kind: 'fov_error', t: captured, message: err.message });
    app.fov = null;
    appStop('fov');
    return;
  }
  app.orientation = cam.orientation;
  const threshold = gateThreshold(app.meta.calibration.uncertainty, frame.width, frame.height, cam.fov);
  if (cam.fov !== app.fov || threshold !== app.decider?.cfg.threshold) {
    // The phone turned (or the setting changed): strips mean other headings, and the
    // orientation (a narrow camera in portrait) has its own gate threshold; start afresh.
    app.decider = new Decider(configFromBundle(app.meta, { fov_deg: cam.fov, threshold }));
    app.visualYaw.reset(); // a turn is read only between frames of one FOV and one Decider
    app.fov = cam.fov;
    record({ kind: 'fov', t: captured, fov_deg: cam.fov, orientation: cam.orientation, threshold,
      width: frame.width, height: frame.height });
  }
  // The view crop (schema 3): the graph sees the rows the training camera would have seen at
  // this frame's FOV; the FOV, orientation and threshold above are the whole frame's.
  const seen = frameView(frame, app.meta.geometry, cam.fov, app.meta.input.size);
  const crop = seen.rows < frame.height ? `, rows ${seen.top}–${seen.top + seen.rows} seen`
    : seen.rows > frame.height ? `, padded to ${seen.rows} rows (a camera narrower than its default)` : '';
  const narrow = gateKind(app.meta.calibration.uncertainty, frame.width, frame.height, cam.fov) === 'narrow'
    ? ', a narrow camera’s gate threshold' : '';
  const levelled = frame.roll_deg ? `, turned ${Math.abs(frame.roll_deg).toFixed(0)}° ${frame.roll_deg > 0 ? 'clockwise' : 'counter-clockwise'} to level` : '';
  view.camera(`${cam.orientation} ${frame.width}×${frame.height}, field of view ${cam.fov.toFixed(1)}° (${cam.source})${crop}${narrow}${levelled}`);
  // The turn since the last frame: the gyroscope's (taken below), else read from this frame (the
  // whole levelled frame, at the whole frame's FOV), else none. Read before the model runs: a
  // result dropped below leaves this frame as the last one only until resetDecisions.
  // With the gyroscope on, the picture's turn is read too, to check the gyroscope's (GyroCheck).
  const picture = sensorOn('visualYaw');
  let yawSource = gyroFollowed() ? 'gyro' : picture ? 'camera' : 'off';
  if (!picture) app.visualYaw.reset(); // turned on later: afresh, not against an old frame
  const cameraTurn = picture ? app.visualYaw.update(frame, captured, cam.fov) : 0;
  app.cameraTurn = picture ? cameraTurn : null;
  if (yawSource === 'camera') checkPlaying(cameraTurn, captured);
  const decider = app.decider;
  let outputs = null;
  let obs;
  const t0 = performance.now();
  app.inflight = captured; // a model run holds the decision up: a stall now is the phone's speed, not the camera
  if (tooRolled) {
    obs = { probs: null, uncertainty: Infinity, ok: false }; // not levelled into what the model learned
  } else {
    try {
      outputs = await app.model.run(seen.rgb, seen.height, seen.width);
      obs = observationFromOutputs(outputs, decider.cfg.measure);
    } catch (err) {
      console.error(err);
      obs = { probs: null, uncertainty: Infinity, ok: false };
    }
  }
  const latencyMs = performance.now() - t0;
  app.inflight = null;
  // paused, ended, or the decisions reset while the model ran (e.g. hidden and shown again): drop it
  if (!app.running || app.paused || generation !== app.generation) return;
  let yaw = yawSource === 'camera' ? cameraTurn : 0;
  if (app.yaw) {
    // the gyroscope's turn since the frame before (not since the last decision), checked against
    // the picture's whether or not it is followed: by default the picture confirms it first
    const gyro = app.yaw.between(captured - dt, captured);
    const before = app.gyroCheck.verdict;
    const wasConfirmed = app.gyroCheck.confirmation();
    const lagged = () => (app.gyroCheck.swayed ? [] // the sway at later lags: only while it can still confirm
      : GYRO_CHECK.sway_lags_s.slice(1).map((lag) => app.yaw.between(captured - dt - lag, captured - lag)));
    const verdict = picture ? app.gyroCheck.add(gyro, cameraTurn, lagged()) : before;
    const confirmed = app.gyroCheck.confirmation(); // 'clear turns', 'sway' or null
    if (verdict !== before || confirmed !== wasConfirmed) {
      record({ kind: 'gyro_check', t: captured, verdict, confirmed, turns: app.gyroCheck.turns.slice(), sway: app.gyroCheck.sway.map((w) => w.slice()) });
    }
    if (yawSource === 'gyro' && verdict === 'wrong') {
      notice(captured, GYRO_WRONG_TEXT); // found out by the picture: not followed for the rest of this guidance
      yawSource = 'camera';
      yaw = cameraTurn;
    } else if (yawSource === 'gyro') {
      yaw = gyro;
    }
  }
  const d = decider.step(captured, obs, yaw);
  const decided = now();
  app.modelS = decided - captured;
  app.playing = null; // this frame's decision replaces it
  const fresh = isFresh(decided, captured);
  if (fresh) app.watchdog.beat(captured);
  app.last = d;
  app.turning = null;
  if (!app.audioFailed) {
    let heard = d; // what the beacon plays now, which the direction vibration and speech follow
    if (fresh && d.heading_deg !== null && (gyroFollowed() || gyroReporting())) {
      // its play ends at the next decision, about a frame interval after this one
      app.turning = { id: (app.frameId || 0) + 1, d, captured, until: decided + dt, fov: decider.cfg.fov_deg, rendered: null };
      heard = followTurn(); // turned by the turn made while the model ran (or stopped once stale)
    } else if (fresh && yawSource === 'camera') {
      // No gyroscope: nothing measures the turn once the frame is read, so the decision cannot turn
      // with the user. It plays until the next one, about a frame interval after it: a stop when
      // the turn read from the picture, carried that far from the capture, passes half a strip
      // (staleDecision; Python's Pipeline.heard). Played as decided, a 30 deg/s scan heard 0.2 s
      // late was 10.5 % confidently wrong (docs/runtime.md, step 10).
      const id = (app.frameId || 0) + 1; // this frame's, assigned below
      const turn = cameraTurn * (decided - captured + dt);
      heard = staleDecision(d, turn, decider.cfg.fov_deg);
      if (heard !== d) record({ kind: 'picture_stale', t: decided, frame: id, turn_deg: turn });
      app.audio.render(cueFor(heard));
      if (!heard.stop) app.playing = { id, d, captured, fov: decider.cfg.fov_deg, rendered: app.audio.cue };
    } else {
      app.audio.render(fresh ? cueFor(d) : STOP_CUE);
    }
    // a frame the camera gave but the model answered too late for: the phone is too slow
    // the model placed a crossing somewhere on this frame (not unsure because nothing is one)
    const seeing = obs.ok && argmax(obs.probs) !== 0;
    feedback(now(), !fresh ? { ...d, stop: true, reason: 'slow', heading_deg: null } : tooRolled ? { ...d, reason: 'rolled' } : heard,
      seeing);
  }
  app.frameId = (app.frameId || 0) + 1; // unique over restarts (seq restarts with the camera)
  record({ kind: 'frame', id: app.frameId, t: captured, grabbed, decided, seq: frame.seq, fresh, latency_ms: latencyMs, yaw_rate_dps: yaw, yaw_source: yawSource, obs, decision: d,
    fov_deg: cam.fov, decision_fov_deg: decider.cfg.fov_deg, width: frame.width, height: frame.height, view_rows: [seen.top, seen.rows], roll_deg: frame.roll_deg ?? 0,
    outputs: outputs && plain(outputs) });
  if (TEST) {
    app.frames.push({ id: app.frameId, seq: frame.seq, width: frame.width, height: frame.height, rgb: frame.rgb.slice() });
    if (app.frames.length > MAX_FRAMES) app.frames.shift();
  }
  view.decision(d);
  if (outputs) view.outputs(outputs, app.meta, decider.cfg.threshold);
}

async function runLoop() {
  const p = app.perf;
  p.frames = 0;
  p.busyS = 0;
  p.startedS = now();
  let prev = null;
  let prevCaptured = null;
  let lastRun = -Infinity;
  let generation = app.generation;
  let errors = 0; // frames in a row whose step threw outside the model
  while (app.running) {
    if (app.paused || generation !== app.generation) {
      if (app.paused) await sleep(FRAME_WAIT_MS);
      generation = app.generation;
      prev = null;
      prevCaptured = null;
      continue;
    }
    while (now() < lastRun + MIN_FRAME_INTERVAL_S) await sleep(Math.max(1, 1000 * (lastRun + MIN_FRAME_INTERVAL_S - now())));
    if (!(await app.grabber.waitForNewFrame(FRAME_WAIT_MS)) || !app.running || app.paused) continue;
    try {
      const grabbed = now();
      const frame = app.grabber.grab();
      if (!frame) continue;
      // the frame's own capture time (camera.js), on the app's clock: it may have waited for a model run
      const captured = Math.min(grabbed, appTime(frame.timeMs));
      if (sameFrame(prev, frame)) {
        // A frozen camera repeats its last frame: not fresh; let the watchdog act.
        record({ kind: 'frozen', t: captured, seq: frame.seq });
        continue;
      }
      prev = { ...frame, rgb: frame.rgb.slice() };
      lastRun = grabbed;
      const t0 = performance.now();
      // With the motion sensors on, the frame is turned level first (the frozen check above reads
      // the camera's own pixels, which a moving phone's levelling would otherwise keep changing).
      const roll = app.tilt?.rollDeg(grabbed) ?? null;
      const levelled = app.grabber.level(frame, roll, app.meta.geometry.pad_rgb ?? PAD_RGB);
      await step(levelled, captured, grabbed, prevCaptured === null ? 0 : captured - prevCaptured, rolledTooFar(roll));
      prevCaptured = captured;
      const ms = performance.now() - t0;
      p.busyS += ms / 1000;
      p.frames += 1;
      p.recentMs = p.frames === 1 ? ms : 0.5 * (p.recentMs + ms); // the last two or three frames' time
      const elapsed = Math.max(1e-3, now() - p.startedS);
      view.speed(p.frames / elapsed, (1000 * p.busyS) / p.frames, p.busyS / elapsed, 1000 * WATCHDOG_S, p.recentMs);
      errors = 0;
    } catch (err) {
      // a fault outside the model (the model's own are failed frames): stop, start the decisions
      // afresh and go on; the same fault frame after frame ends guidance with its message (fail)
      if (++errors > MAX_LOOP_ERRORS) throw err;
      console.error(err);
      record({ kind: 'loop_error', t: now(), error: String(err?.message || err) });
      resetDecisions();
      if (!app.audioFailed) app.audio.render(STOP_CUE);
      await sleep(FRAME_WAIT_MS);
    }
  }
}

/** The watchdog's poll (watchdog.Watchdog.poll), and a check that audio can still play. */
function poll() {
  const t = now();
  if (app.running && !app.audioFailed && !app.audio.playing()) onAudioLost(app.audio.ctx.state);
  if (app.paused) return;
  const { fired } = app.watchdog.poll(t);
  if (fired) {
    // no fresh decision for WATCHDOG_S: while a model run is still going the model is too slow
    // for this phone; otherwise no new frame came (the camera stalled)
    const reason = app.inflight !== null ? 'slow' : 'stale';
    record({ kind: 'watchdog', t, reason });
    if (!app.audioFailed) {
      app.audio.render(STOP_CUE);
      feedback(t, { stop: true, reason, heading_deg: null });
    }
  }
  // no tilt sensor (refused, missing, or silent): said once, held back while the audio is out
  if (!app.audioFailed && app.tiltSilence?.due(t, app.tilt?.lastT ?? null)) noTiltSensor(t);
  app.polls = (app.polls || 0) + 1;
  if (app.polls % 10 === 0) {
    view.levels(app.audio.levels());
    if (gyroFollowed()) view.turning(app.turnRate || 0, 'gyroscope');
    else view.turning(sensorOn('visualYaw') ? app.cameraTurn ?? 0 : null, 'camera picture'); // null: not followed
    view.tilt(tiltText(t));
  }
}

/**
 * The gyroscope's turn is followed (the Decider's yaw rate, and the beacon turned between
 * decisions: followTurn) while the camera picture has not found it out (GyroCheck): when it is
 * turned on ("Follow turns with the gyroscope"), and by default (turns read from the picture)
 * once the picture has confirmed it, for as long as it does and the gyroscope keeps reporting.
 * Otherwise the picture's turn.
 */
function gyroFollowed() {
  if (!app.yaw || app.gyroCheck.verdict === 'wrong') return false;
  return sensorOn('gyro') || (sensorOn('visualYaw') && app.gyroCheck.confirmed() && app.yaw.reporting(now()));
}

/** A gyroscope reports, whether or not it is followed: the size of a turn since a capture is known. */
function gyroReporting() {
  return !!app.yaw && app.yaw.reporting(now());
}

/** Something the user must know for the rest of this guidance: spoken whole (routine sentences
 * wait for it) and shown in a line kept until guidance ends. */
function notice(t, text) {
  view.status(text, '');
  $('notice').textContent = text;
  $('notice').hidden = false;
  app.speaker.say(text, { urgent: true });
  record({ kind: 'speech', t, text });
}

/** The tilt sensor gives nothing: guidance goes on unlevelled, and the user is told (notice). */
function noTiltSensor(t) {
  record({ kind: 'no_tilt', t, permission: app.sensors?.tilt ?? null });
  notice(t, NO_TILT_TEXT);
}

/** The helper view's tilt sensor line. */
function tiltText(t) {
  if (!sensorOn('tilt')) return 'off (setting): frames are not levelled';
  if (!app.tilt) return `${app.sensors?.tilt === 'denied' ? 'not allowed' : 'none'}: frames are not levelled`;
  if (app.tilt.lastT === null) return 'no reading yet: frames are not levelled';
  if (!app.tilt.fresh(t, app.tilt.cfg.roll_fresh_s)) return 'silent: frames are not levelled';
  const roll = app.tilt.rollDeg(t);
  if (roll === null) return 'pointed down or up: no horizon to level';
  return `camera rolled ${Math.abs(roll).toFixed(0)}°${rolledTooFar(roll) ? ': too far, stop' : ''}`;
}

/** The AudioContext stopped (suspended, interrupted, closed): guidance has failed until it plays again. */
function onAudioLost(state) {
  if (!app.running || app.audioFailed) return;
  app.audioFailed = true;
  record({ kind: 'audio_failed', t: now(), state });
  setControl('Tap to resume audio', 'Audio stopped', 'failed');
  appStop('audio');
}

async function resumeAudio(how) {
  if (!app.audio) return;
  app.resuming = how; // the context's own 'running' event may come first: it is this resume
  try {
    await app.audio.ctx.resume();
  } catch (err) {
    console.warn(`audio resume failed: ${err.message || err}`);
  } finally {
    app.resuming = null;
  }
  audioBack(how);
}

/** Audio plays again (a tap, the return to the app, or given back by the OS after a call):
 * guidance resumes with fresh decisions only; the stop cue until the first one. */
function audioBack(how) {
  if (!app.running || !app.audioFailed || !app.audio?.playing()) return;
  app.audioFailed = false;
  resetDecisions(); // a direction decided before or during the loss never plays
  record({ kind: 'audio_resumed', t: now(), how });
  setControl('End guidance', 'Double tap or hold', 'running');
  app.audio.render(STOP_CUE); // until the next fresh decision
  app.policy.reset(); // the next advice is announced afresh
  app.haptics.reset();
  announce(['Audio back. Scan slowly.', '']);
}

function onAudioState(state) {
  if (state !== 'running') onAudioLost(state);
  else if (!app.paused) audioBack(app.resuming || 'os'); // in the background: the return resumes
}

function onOrientation(e) {
  app.tilt?.add(e.beta, e.gamma, now(), screen.orientation?.angle ?? 0);
}

function onMotion(e) {
  const rate = yawRateFromRotation(e.rotationRate, screen.orientation?.angle ?? 0);
  const t = appTime(e.timeStamp); // the clock of the frames' capture times
  app.yaw?.add(rate, t);
  app.recorder?.motion(t, rate, app.tilt?.rollDeg(t) ?? null);
  app.turnRate = rate;
  if (app.turning) followTurn();
}

const RATE_S = 0.1; // the gyroscope's present rate: its mean over this long (Python's gyro.RATE_S)

/**
 * The beacon turned with the user (decision step 10, logic.js turnedDecision; docs/android.md).
 * A decision is played from its model run's end until the next one, 0.28-0.51 s after its frame's
 * capture in the e2e run, so while the user turns it lags their facing by the turn since that capture. With the
 * gyroscope followed, the decision is played turned by the gyroscope's turn since the capture,
 * at its decision and again at each gyroscope sample until the next decision. Only while the
 * cue it played is still the one playing: any other cue (a stop, the watchdog's, a pause) ends it.
 * A gyroscope that reports but is not followed (not yet confirmed by the picture, or found turning
 * the wrong way) gives only the size of the turn: the decision plays as decided until it is half a
 * strip stale, then as a stop (logic.js staleDecision), the turn since the capture carried on at the
 * gyroscope's present rate to the end of the play (the next decision). Judged only as it stands, a
 * walker's sway (2.5 deg at 0.9 Hz, which never confirms the gyroscope: its turns stay under
 * GYRO_CHECK.turn_dps) left held-out landscape frames 1.25 % confidently wrong, heard 0.2 s late;
 * carried, 0.23 % (docs/results.md, "A walker's sway"). Returns the decision as played (null once ended).
 */
function followTurn() {
  const f = app.turning;
  const followed = gyroFollowed();
  if (!app.audio || app.audioFailed || (f.rendered !== null && (app.audio.cue !== f.rendered || !(followed || gyroReporting())))) {
    app.turning = null;
    return null;
  }
  const t = now();
  const turn = app.yaw.between(f.captured, t) * (t - f.captured); // 0 before the capture
  // not followed: judged by the turn at the end of the play, carried on at the rate of the last RATE_S
  const judged = followed ? turn : turn + app.yaw.between(t - RATE_S, t) * Math.max(0, f.until - t);
  const played = followed ? turnedDecision(f.d, turn, f.fov) : staleDecision(f.d, judged, f.fov);
  app.audio.render(cueFor(played));
  f.rendered = app.audio.cue;
  record({ kind: followed ? 'turned' : 'stale', t, frame: f.id, turn_deg: judged, heading_deg: played.heading_deg });
  return played;
}

/**
 * No gyroscope, the turn read from the picture followed: the decision still playing (the last
 * frame's), checked when the next frame is read, before its model run. The turn read since its
 * frame's capture, carried on at this frame's rate through the model run to come (as long as the
 * last one took), past half a strip makes it stale: the stop cue from now on (staleDecision;
 * Python's run_live checks it the same way). Only while its cue is still the one playing.
 */
function checkPlaying(cameraTurn, captured) {
  const p = app.playing;
  if (!p || !app.audio || app.audioFailed || app.audio.cue !== p.rendered) return;
  const turn = cameraTurn * (captured - p.captured + app.modelS);
  const played = staleDecision(p.d, turn, p.fov);
  if (played === p.d) return;
  app.playing = null;
  app.audio.render(cueFor(played));
  record({ kind: 'picture_stale', t: captured, frame: p.id, turn_deg: turn, cut: true });
}

/** A sensor setting for this visit: the URL flag's (?gyro=1, ?tilt=0, ?visualyaw=0) else the kept setting. */
function sensorOn(key) {
  return OVERRIDES[key] ?? app.settings[key];
}

/**
 * Ask for the motion sensors the settings want: 'granted', 'denied', 'unavailable' (no such
 * sensor API) or 'off' (not wanted), each a promise. iOS asks the user only from inside the tap's
 * own handler, so both requests are made here, synchronously, before start() awaits anything.
 */
function askSensors() {
  const ask = (E) => {
    if (typeof E?.requestPermission === 'function') {
      try {
        return E.requestPermission().catch(() => 'denied');
      } catch {
        return Promise.resolve('denied');
      }
    }
    return Promise.resolve(E ? 'granted' : 'unavailable');
  };
  return {
    tilt: sensorOn('tilt') ? ask(globalThis.DeviceOrientationEvent) : Promise.resolve('off'),
    // the gyroscope is followed once the picture confirms it, so it is asked with the tilt sensor too
    motion: sensorOn('gyro') || sensorOn('tilt') ? ask(globalThis.DeviceMotionEvent) : Promise.resolve('off'),
  };
}

/** Listen to the sensors that were allowed: tilt (TiltWatch: levelling, the roll limit, tilt
 * advice) and the gyroscope (the turn rate, YawIntegrator). A tilt sensor refused or missing is
 * told by the poll's TiltSilence check, as one that sends nothing. */
async function startSensors(asked) {
  const [tilt, motion] = await Promise.all([asked.tilt, asked.motion]);
  app.sensors = { tilt, motion };
  app.tilt = null;
  app.yaw = null;
  if (tilt === 'granted') {
    app.tilt = new TiltWatch();
    window.addEventListener('deviceorientation', onOrientation);
  }
  if (motion === 'granted') {
    window.addEventListener('devicemotion', onMotion);
    app.yaw = new YawIntegrator();
    app.gyroCheck = new GyroCheck();
  } else if (motion === 'denied' && sensorOn('gyro')) {
    showError('The gyroscope was not allowed: turns are not followed.');
  }
}

/** Keep the screen on while guiding (a sleeping phone stops its camera); asked again on every return. */
async function requestWakeLock() {
  app.wakeLockRequests += 1;
  const lock = await navigator.wakeLock?.request('screen').catch(() => null);
  record({ kind: 'wakelock', t: now(), ok: Boolean(lock) });
  return lock || null;
}

/** The headphone check and sound tutorial (first run, or on request; tutorial.js); a tap skips it. */
async function runTutorial() {
  app.mode = 'tutorial';
  app.skipTutorial = false;
  setControl('Sound check', 'Tap to skip', 'running');
  const done = await playTutorial({
    audio: app.audio,
    say: (text) => {
      view.status(text, '');
      app.speaker.say(text);
    },
    vibrate: (p) => app.haptics.vibrate(p),
    onStep: (step) => record({ kind: 'tutorial', t: now(), ...step }),
    speed: TUTORIAL_SPEED,
    skipped: () => app.skipTutorial,
  });
  app.speaker.cancel();
  app.settings.tutorialDone = true;
  saveSettings(app.settings);
  record({ kind: 'tutorial_done', t: now(), skipped: !done });
}

async function start({ tutorial = !app.settings.tutorialDone } = {}) {
  app.mode = 'starting';
  $('control').disabled = true;
  try {
    // Inside the tap itself, before anything is awaited: iOS asks for the motion sensors only
    // there, and the AudioContext must be created and resumed there (browsers' autoplay rules).
    const asked = askSensors();
    const ctx = new AudioContext({ latencyHint: 'interactive' });
    const resumed = ctx.resume();
    await startSensors(asked);
    await resumed;
    app.audio = new BeaconAudio(ctx);
    app.speaker.cancel(); // nothing left waiting in the old one
    app.speaker = new Speaker(app.settings.speech);
    app.policy.reset();
    app.haptics = new Haptics({ directions: app.settings.hapticDirections });
    $('control').disabled = false;
    if (tutorial) await runTutorial();
    app.stream = await openCamera($('video'));
    app.stream.getVideoTracks()[0]?.addEventListener('ended', () => {
      showError('The camera stopped (another app took it, or it was switched off). Double tap to end, then tap to start.');
    });
    app.grabber = new FrameGrabber($('video'));
    resetDecisions();
    app.orientation = null;
    app.cameraTurn = null;
    app.sideways = new SidewaysHint(SIDEWAYS_AFTER_S ? { after_s: SIDEWAYS_AFTER_S } : undefined);
    app.audioFailed = false;
    app.paused = false;
    app.audio.onStateChange = onAudioState;
    app.running = true;
    app.mode = 'running';
    clearError(); // a successful start clears what an earlier failure left on screen
    record({ kind: 'start', t: now() });
    if (RECORD) startRecording();
    app.audio.render(STOP_CUE); // nothing known yet: scan
    app.watchdog = new Watchdog(WATCHDOG_S, now());
    app.tiltSilence = sensorOn('tilt') ? new TiltSilence(now()) : null;
    app.tick = setInterval(poll, POLL_MS);
    app.loop = runLoop().catch((err) => fail(err));
    setControl('End guidance', 'Double tap or hold', 'running');
    view.status('Guidance on. Scan slowly.', '');
    app.wakeLock = await requestWakeLock();
  } catch (err) {
    await stop({ quiet: true });
    fail(err);
  } finally {
    $('control').disabled = false;
  }
}

/** ?record=1: record the camera's video and the motion log from now until guidance ends. */
function startRecording() {
  try {
    app.recorder = new FieldRecorder(app.stream, now);
    record({ kind: 'recording', t: now() });
  } catch (err) {
    app.recorder = null;
    showError(`Not recording: ${err.message}`);
  }
}

/** The recording, once its video is complete: offered in the helper view (app.recording for tests). */
async function offerRecording(saving) {
  try {
    app.recording = await saving;
    view.recording(app.recording, `walk-${new Date().toISOString().slice(0, 19).replace(/[-:]/g, '').replace('T', '-')}`);
  } catch (err) {
    showError(`The recording could not be saved: ${err.message}`);
  }
}

async function stop({ quiet = false } = {}) {
  const wasRunning = app.running;
  app.running = false;
  app.mode = 'stopping';
  clearInterval(app.tick);
  clearTimeout(pressTimer);
  window.removeEventListener('devicemotion', onMotion);
  window.removeEventListener('deviceorientation', onOrientation);
  app.yaw = null;
  app.tilt = null;
  app.tiltSilence = null;
  $('notice').hidden = true;
  $('notice').textContent = '';
  app.grabber?.close();
  const saving = app.recorder?.stop(); // before the tracks end: the recorder keeps what it has
  app.recorder = null;
  app.stream?.getTracks().forEach((t) => t.stop());
  app.stream = null;
  await app.loop;
  if (app.audio) app.audio.onStateChange = null;
  await app.audio?.close().catch(() => null);
  app.audio = null;
  await app.wakeLock?.release().catch(() => null);
  app.wakeLock = null;
  app.audioFailed = false;
  app.paused = false;
  app.last = null;
  view.clear();
  if (saving) await offerRecording(saving);
  setControl('Start', 'Tap to start guidance');
  app.mode = 'ready';
  if (!quiet || wasRunning) {
    record({ kind: 'stopped', t: now() });
    view.status('Guidance ended. Tap to start.', '');
    app.speaker.say('Guidance ended.');
  }
}

function fail(err) {
  console.error(err);
  showError(err instanceof CameraError ? err.message : `${err.name || 'Error'}: ${err.message || err}`);
}

/** In the background the camera pauses and timers slow down: stop guiding at once; resume on return. */
async function onVisibility() {
  if (!app.running) return;
  if (document.hidden) {
    app.paused = true;
    record({ kind: 'hidden', t: now() });
    appStop('background');
    return;
  }
  app.paused = false;
  resetDecisions(); // no stale heading or belief from before the pause, nor a model run from then
  app.watchdog.beat(now()); // the watchdog's period runs from the return
  app.tiltSilence?.restart(now()); // the sensor's events paused in the background too
  record({ kind: 'visible', t: now() });
  if (app.audioFailed || !app.audio.playing()) await resumeAudio('return');
  app.policy.reset();
  view.status('Guidance on. Scan slowly.', '');
  app.wakeLock = await requestWakeLock();
}

// ----------------------------------------------------------------------------- start-up

async function registerWorker(version) {
  if (!('serviceWorker' in navigator) || !version) {
    app.offline = 'unavailable (no service worker here)';
    view.offline(app.offline);
    return;
  }
  try {
    const reg = await navigator.serviceWorker.register(`sw.js?v=${version}`);
    if (!navigator.serviceWorker.controller) {
      // First visit: wait until the worker has cached everything (however long the download
      // takes) and claimed this page; the model and the runtime are then read from its cache,
      // so each file is downloaded once. A worker that fails to install ends 'redundant'.
      const worker = reg.installing || reg.waiting || reg.active;
      if (!worker) throw new Error('no service worker after registering');
      await new Promise((ok) => {
        const check = () => (['activated', 'redundant'].includes(worker.state) ? ok() : null);
        worker.addEventListener('statechange', check);
        check();
      });
      if (worker.state === 'redundant') throw new Error('the service worker could not cache the app');
      if (!navigator.serviceWorker.controller) {
        await new Promise((ok) => {
          navigator.serviceWorker.addEventListener('controllerchange', ok, { once: true });
          setTimeout(ok, 3000);
        });
      }
    }
    await navigator.serviceWorker.ready;
    app.offline = 'ready';
  } catch (err) {
    app.offline = `unavailable (${err.message})`;
  }
  view.offline(app.offline);
}

/** Replay the Python runtime's test vectors through this browser's JavaScript engine. */
async function selfTest() {
  const out = $('selftest-result');
  out.textContent = 'Checking…';
  try {
    const resp = await fetch('test_vectors.json');
    if (!resp.ok) throw new Error(`test_vectors.json: HTTP ${resp.status} (build with android_demo/test_vectors.json present)`);
    const r = replayVectors(await resp.json());
    app.selftest = r;
    out.textContent = r.nFailures === 0
      ? `Decision logic OK: ${r.steps} decisions and ${r.checks} other checks match the Python runtime.`
      : `Decision logic MISMATCH: ${r.nFailures} differences (first: ${JSON.stringify(r.failures[0])}). Do not rely on this app.`;
  } catch (err) {
    app.selftest = { error: err.message };
    out.textContent = `Self-test could not run: ${err.message}`;
  }
}

function bindSettings() {
  const s = app.settings;
  const boxes = { speech: 'speech', 'haptic-dir': 'hapticDirections', 'tilt-sensor': 'tilt', gyro: 'gyro', 'visual-yaw': 'visualYaw' };
  for (const [id, key] of Object.entries(boxes)) {
    $(id).checked = OVERRIDES[key] ?? s[key]; // a URL flag shows (this visit only)
    $(id).addEventListener('change', () => {
      s[key] = $(id).checked;
      delete OVERRIDES[key]; // the user's choice wins over the URL flag from now on
      saveSettings(s);
      if (key === 'speech') app.speaker.enabled = s.speech;
      if (key === 'hapticDirections') app.haptics.directions = s.hapticDirections;
    });
  }
  view.tilt(sensorOn('tilt') ? 'on: read from the start of guidance' : 'off (setting): frames are not levelled');
  for (const o of ['landscape', 'portrait']) {
    const input = $(`fov-${o}`);
    input.value = s.fov[o] ?? '';
    input.addEventListener('change', () => {
      const text = input.value.trim();
      const value = text === '' ? null : Number(text);
      try {
        if (value !== null) cameraFov({ camera_fov_deg: {} }, 1, 1, value);
        s.fov[o] = value;
        saveSettings(s);
        app.fov = null; // the next frame starts a Decider with the new value
        $('fov-result').textContent = value === null ? `${o}: the bundle’s default` : `${o}: ${value}° saved`;
      } catch (err) {
        input.value = s.fov[o] ?? '';
        $('fov-result').textContent = `Refused: ${err.message}`;
      }
    });
  }
}

async function init() {
  $('control').addEventListener('click', onControlClick);
  $('control').addEventListener('pointerdown', onControlDown);
  for (const ev of ['pointerup', 'pointercancel', 'pointerleave']) $('control').addEventListener(ev, onControlUp);
  $('control').addEventListener('contextmenu', (e) => e.preventDefault()); // a long press must not open a menu
  $('helper-toggle').addEventListener('click', () => toggleHelper($('helper').classList.contains('closed')));
  $('helper-close').addEventListener('click', () => toggleHelper(false));
  document.addEventListener('visibilitychange', onVisibility);
  $('selftest').addEventListener('click', selfTest);
  $('tutorial').addEventListener('click', () => {
    toggleHelper(false);
    if (app.mode === 'ready') start({ tutorial: true });
  });
  bindSettings();
  try {
    let version = null;
    try {
      version = (await (await fetch('precache.json', { cache: 'no-store' })).json()).version;
    } catch {
      version = null;
    }
    await registerWorker(version);
    const base = new URL(params.get('bundle') || 'bundle/', location.href);
    if (!base.pathname.endsWith('/')) base.pathname += '/';
    const bundle = await fetchBundle(base.href);
    app.meta = bundle.meta;
    view.bundle(bundle.meta);
    for (const o of ['landscape', 'portrait']) $(`fov-default-${o}`).textContent = defaultFovText(bundle.meta.geometry, o);
    const threads = Number(params.get('threads')) || undefined; // ?threads=N: for benchmarks
    app.model = await openBest(bundle, new URL('vendor/', location.href).href, { threads });
    view.backend(app.model);
    app.ready = true;
    app.mode = 'ready';
    $('control').disabled = false;
    setControl('Start', app.settings.tutorialDone ? 'Tap to start guidance' : 'Tap to start: first a short sound check');
    $('control').focus();
    view.status('Ready. Tap to start.', '');
  } catch (err) {
    view.status('Not ready', 'stop');
    setControl('Not ready', 'See the message above');
    fail(err);
  }
}

init();

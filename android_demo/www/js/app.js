// The phone app, the browser twin of crossing_assist/runtime/live.py: bundle -> session;
// Start -> camera + audio; each new camera frame -> (frozen check) -> model -> Decider
// (logic.js) -> beacon (audio.js) and the helper view. A decision plays only if it is fresh
// (made within the watchdog period of its frame's capture); a watchdog polled every 20 ms
// stops the beacon and plays the stop/scan cue when no fresh decision arrived for 0.5 s
// (frozen or covered camera, a hung model).
//
// With "Use the gyroscope" on, the turn the user made between two frames (DeviceMotionEvent)
// is the Decider's yaw input (the hold and the belief follow the turn); off, it is 0, as in
// the desktop live loop.
//
// URL flags: ?test=1 keeps a trace of every step (and copies of the frames the model saw) in
// window.crossingAssist for the end-to-end test; ?bundle=URL loads another bundle folder;
// ?gyro=1 ticks "Use the gyroscope".

import { BeaconAudio } from './audio.js';
import { CameraError, FrameGrabber, openCamera } from './camera.js';
import { isFresh, sameFrame, Watchdog, WATCHDOG_S, YawIntegrator, yawRateFromRotation } from './live.js';
import { configFromBundle, cueFor, Decider, KIND_STOP, observationFromOutputs } from './logic.js';
import { fetchBundle, openBest } from './model.js';
import { replayVectors } from './vectors.js';
import { HelperView, statusMessage } from './view.js';

const POLL_MS = 20;
const FRAME_WAIT_MS = 100;
const STOP_CUE = { kind: KIND_STOP };
const params = new URLSearchParams(location.search);
const TEST = params.get('test') === '1';
const MAX_TRACE = 5000;
const MAX_FRAMES = 400;

const $ = (id) => document.getElementById(id);
const app = {
  ready: false, running: false, meta: null, model: null, decider: null, audio: null, stream: null,
  grabber: null, watchdog: null, trace: [], frames: [], last: null, error: null, offline: 'not yet', t0: 0,
};
window.crossingAssist = app;
const view = new HelperView(document);

function showError(message) {
  app.error = message;
  $('error').textContent = message;
  $('error').hidden = false;
}

/** Seconds since Start (the Decider's clock). */
function now() {
  return (performance.now() - app.t0) / 1000;
}

function record(entry) {
  if (!TEST) return;
  app.trace.push(entry);
  if (app.trace.length > MAX_TRACE) app.trace.shift();
}

const plain = (o) => ({ probs: Array.from(o.probs), entropy: o.entropy, mutual_info: o.mutual_info,
  variance: Array.from(o.variance), votes: Array.from(o.votes) });

/** One new (not frozen) camera frame, captured at `captured` s, end to end (live.run_live's loop body). */
async function step(frame, captured, dt) {
  let outputs = null;
  let obs;
  const t0 = performance.now();
  try {
    outputs = await app.model.run(frame.rgb, frame.height, frame.width);
    obs = observationFromOutputs(outputs, app.decider.cfg.measure);
  } catch (err) {
    console.error(err);
    obs = { probs: null, uncertainty: Infinity, ok: false };
  }
  const latencyMs = performance.now() - t0;
  if (!app.running) return;
  const yaw = app.yaw ? app.yaw.take(dt) : 0;
  const d = app.decider.step(captured, obs, yaw);
  const fresh = isFresh(now(), captured);
  app.audio.render(fresh ? cueFor(d) : STOP_CUE);
  if (fresh) app.watchdog.beat(captured);
  app.last = d;
  record({ kind: 'frame', t: captured, seq: frame.seq, fresh, latency_ms: latencyMs, yaw_rate_dps: yaw, obs, decision: d,
    outputs: outputs && plain(outputs) });
  if (TEST) {
    app.frames.push({ seq: frame.seq, width: frame.width, height: frame.height, rgb: frame.rgb.slice() });
    if (app.frames.length > MAX_FRAMES) app.frames.shift();
  }
  view.decision(d, fresh ? statusMessage(d) : statusMessage({ ...d, stop: true, reason: 'stale' }));
  if (outputs) view.outputs(outputs, app.meta);
}

async function runLoop() {
  let frames = 0;
  let busyS = 0;
  let prev = null;
  let prevCaptured = null;
  const started = performance.now();
  while (app.running) {
    if (!(await app.grabber.waitForNewFrame(FRAME_WAIT_MS)) || !app.running) continue;
    const captured = now();
    const frame = app.grabber.grab();
    if (!frame) continue;
    if (sameFrame(prev, frame)) {
      // A frozen camera repeats its last frame: not fresh; let the watchdog act.
      record({ kind: 'frozen', t: captured, seq: frame.seq });
      continue;
    }
    prev = { ...frame, rgb: frame.rgb.slice() };
    const t0 = performance.now();
    await step(frame, captured, prevCaptured === null ? 0 : captured - prevCaptured);
    prevCaptured = captured;
    busyS += (performance.now() - t0) / 1000;
    frames += 1;
    view.speed(frames / ((performance.now() - started) / 1000), (1000 * busyS) / frames);
  }
}

/** The watchdog's poll: stop cue on the transition to stale (watchdog.Watchdog.poll). */
function poll() {
  const t = now();
  const { fired } = app.watchdog.poll(t);
  if (fired) {
    app.audio.render(STOP_CUE);
    record({ kind: 'watchdog', t });
    view.status(...statusMessage({ stop: true, reason: 'stale' }));
  }
  app.polls = (app.polls || 0) + 1;
  if (app.polls % 10 === 0) {
    view.levels(app.audio.levels());
    view.turning(app.yaw ? app.turnRate || 0 : null);
  }
}

function onMotion(e) {
  const rate = yawRateFromRotation(e.rotationRate, screen.orientation?.angle ?? 0);
  app.yaw?.add(rate, e.timeStamp / 1000);
  app.turnRate = rate;
}

/** Gyroscope on: ask for it (iOS asks the user; must run inside the tap) and listen. */
async function startGyro() {
  if (!$('gyro').checked || typeof DeviceMotionEvent === 'undefined') return null;
  if (typeof DeviceMotionEvent.requestPermission === 'function'
      && (await DeviceMotionEvent.requestPermission().catch(() => 'denied')) !== 'granted') {
    showError('Motion sensors were not allowed: turns are not followed (gyroscope off).');
    return null;
  }
  window.addEventListener('devicemotion', onMotion);
  return new YawIntegrator();
}

async function start() {
  $('start').disabled = true;
  try {
    app.yaw = await startGyro(); // first: iOS only asks inside the tap itself
    // The AudioContext must be created/resumed inside the tap (browsers' autoplay rules).
    const ctx = new AudioContext({ latencyHint: 'interactive' });
    await ctx.resume();
    app.audio = new BeaconAudio(ctx);
    app.stream = await openCamera($('video'));
    app.stream.getVideoTracks()[0]?.addEventListener('ended', () => {
      showError('The camera stopped (another app took it, or it was switched off). Tap Stop, then Start.');
    });
    app.grabber = new FrameGrabber($('video'));
    app.decider = new Decider(configFromBundle(app.meta));
    app.trace = [];
    app.frames = [];
    app.t0 = performance.now();
    app.running = true;
    app.audio.render(STOP_CUE); // nothing known yet: scan
    app.watchdog = new Watchdog(WATCHDOG_S, 0);
    app.tick = setInterval(poll, POLL_MS);
    app.loop = runLoop().catch((err) => fail(err));
    $('start').textContent = 'Stop';
    $('start').classList.add('running');
    // Keep the screen on while guiding: a sleeping phone stops its camera.
    app.wakeLock = await navigator.wakeLock?.request('screen').catch(() => null);
  } catch (err) {
    await stop();
    fail(err);
  } finally {
    $('start').disabled = false;
  }
}

async function stop() {
  app.running = false;
  clearInterval(app.tick);
  window.removeEventListener('devicemotion', onMotion);
  app.yaw = null;
  app.grabber?.close();
  app.stream?.getTracks().forEach((t) => t.stop());
  await app.loop;
  await app.audio?.close();
  app.audio = null;
  await app.wakeLock?.release().catch(() => null);
  app.wakeLock = null;
  $('start').textContent = 'Start';
  $('start').classList.remove('running');
  view.status('Stopped. Tap Start to begin.', 'stop');
}

function fail(err) {
  console.error(err);
  showError(err instanceof CameraError ? err.message : `${err.name || 'Error'}: ${err.message || err}`);
}

async function registerWorker(version) {
  if (!('serviceWorker' in navigator) || !version) {
    app.offline = 'unavailable (no service worker here)';
    view.offline(app.offline);
    return;
  }
  try {
    await navigator.serviceWorker.register(`sw.js?v=${version}`);
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
      ? `Decision logic OK: ${r.steps} decisions and ${r.checks} beacon and action checks match the Python runtime.`
      : `Decision logic MISMATCH: ${r.nFailures} differences (first: ${JSON.stringify(r.failures[0])}). Do not rely on this app.`;
  } catch (err) {
    app.selftest = { error: err.message };
    out.textContent = `Self-test could not run: ${err.message}`;
  }
}

/** In the background the camera pauses and timers slow down: stop guiding at once. */
function onVisibility() {
  if (document.hidden && app.running) {
    app.audio.render(STOP_CUE);
    record({ kind: 'hidden', t: now() });
    view.status('Stop. The app is in the background.', 'stop');
  }
}

async function init() {
  $('start').addEventListener('click', () => (app.running ? stop() : start()));
  document.addEventListener('visibilitychange', onVisibility);
  $('selftest').addEventListener('click', selfTest);
  $('gyro').checked = params.get('gyro') === '1';
  try {
    let version = null;
    try {
      version = (await (await fetch('precache.json')).json()).version;
    } catch {
      version = null;
    }
    const workerReady = registerWorker(version);
    const base = new URL(params.get('bundle') || 'bundle/', location.href);
    if (!base.pathname.endsWith('/')) base.pathname += '/';
    const bundle = await fetchBundle(base.href);
    app.meta = bundle.meta;
    view.bundle(bundle.meta);
    const threads = Number(params.get('threads')) || undefined; // ?threads=N: for benchmarks
    app.model = await openBest(bundle, new URL('vendor/', location.href).href, { threads });
    app.ready = true;
    $('start').disabled = false;
    $('start').focus();
    view.status('Ready. Tap Start.', '');
    await workerReady;
  } catch (err) {
    view.status('Not ready', 'stop');
    fail(err);
  }
}

init();

#!/usr/bin/env node
// End-to-end driver: serves www/ on 127.0.0.1 (logging every request), starts Debian's
// headless Chromium through playwright-core with a fake camera playing a Y4M clip, uses the
// app as a person would, and writes what it saw as JSON for tests/test_android_e2e.py to judge
// (against the Python runtime, among others):
//
//   node tools/e2e_driver.mjs --clip clip.y4m --out result.json [--run-s 8] [--www DIR]
//        [--chromium /usr/bin/chromium] [--phases full|short] [--viewport 844x390]
//
// Speech (speechSynthesis.speak), vibration (navigator.vibrate) and the screen wake lock are
// wrapped so their calls are recorded. Headless Chromium has no voice (each utterance fails at
// once), so speechSynthesis is a fake voice: an utterance lasts 60 ms a character and ends
// ('end'), unless cancel() cuts it ('error'); window.__heard says how each one went.
//
// Phases "full": first load (requests counted until the service worker holds the app) ->
// accessibility tree with the helper view closed and open -> the self-test (shared vectors) ->
// first tap: the headphone check and sound tutorial, then guidance with a synthetic gyroscope
// (3 deg/s right) while sampling the audio graph and the control's box every 100 ms -> a single
// tap (must not end) -> AudioContext suspended (must stop, vibrate, speak) and a tap (resumes)
// -> app hidden (audio suspended there too) and shown again (pause; audio resumed and wake
// lock asked again on the return) -> camera frozen (watchdog) ->
// the audio taken and given back by itself (no tap) -> the app hidden and shown while a model run
// is in flight -> a model run of 450 ms at 10 frames/s (frames wait for the model: their own
// capture time, logged by the driver's own requestVideoFrameCallback, must decide freshness) ->
// the camera track ends (the camera-lost instruction must be heard whole) ->
// double tap ends -> a failed start, then a good one (the error must go) -> the landscape FOV
// set in the helper view (10 refused, 60 taken) -> long press ends ->
// server stopped, reload, start again (offline; settings kept: no tutorial).
// Phases "short": load with the tutorial marked done and the direction vibration on (no URL flag,
// no sensor setting stored: the app's defaults), (--level 1: a tilt sensor reporting the phone
// upright and level every 50 ms from the load on), start, run, (--sideways-after S: the
// hold-it-sideways advice after S s of a "not sure" stop, waited for), (--roll DEG: the phone
// turned DEG clockwise about the camera's axis until 8 frames were levelled, then 75 deg until the
// stop says to hold it level; --sensor-stops 1 after it: the sensor falls silent while the phone
// is still turned 75 deg, until the app says it has no tilt sensor and 5 frames came more than
// 0.6 s after the last reading, then reports level again), (--tilt 1: the phone tilted down until
// a "not sure" stop says to raise it), (--visual-yaw 0|1: the page loaded with ?visualyaw=0|1),
// (--gyro DPS: loaded with ?gyro=1, a gyroscope reading a steady turn of DPS deg/s, + right),
// (--record 1: loaded with ?record=1; after the double tap, the field recording the helper view
// offers: its motion log, its video as base64 and the download links),
// collect, double tap.
// Landscape "full" phases dispatch no deviceorientation event at all: no tilt sensor.
// The driver asserts nothing; it exits non-zero only when it could not run.

import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const HERE = dirname(fileURLToPath(import.meta.url));
const ROOT = resolve(HERE, '..');
const CHROMIUM_FLAGS = ['--headless=new', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream', '--autoplay-policy=no-user-gesture-required'];

function parseArgs(argv) {
  const args = { runS: 8, chromium: '/usr/bin/chromium', www: join(ROOT, 'www'), phases: 'full', viewport: '844x390' };
  for (let i = 0; i < argv.length; i += 2) {
    const [k, v] = [argv[i], argv[i + 1]];
    if (v === undefined) throw new Error(`missing value for ${k}`);
    if (k === '--clip') args.clip = resolve(v);
    else if (k === '--out') args.out = resolve(v);
    else if (k === '--run-s') args.runS = Number(v);
    else if (k === '--chromium') args.chromium = v;
    else if (k === '--www') args.www = resolve(v);
    else if (k === '--phases') args.phases = v;
    else if (k === '--viewport') args.viewport = v;
    else if (k === '--tilt') args.tilt = v === '1';
    else if (k === '--roll') args.roll = Number(v);
    else if (k === '--level') args.level = v === '1';
    else if (k === '--sensor-stops') args.sensorStops = v === '1';
    else if (k === '--sideways-after') args.sidewaysAfter = Number(v);
    else if (k === '--visual-yaw') args.visualYaw = v;
    else if (k === '--gyro') args.gyro = Number(v); // ?gyro=1 and a steady gyroscope at this rate (deg/s, + right)
    else if (k === '--motion') args.motion = Number(v); // the same gyroscope, the app's own settings
    else if (k === '--record') args.record = v === '1';
    else throw new Error(`unknown argument ${k}`);
  }
  if (!args.clip || !args.out) throw new Error('usage: e2e_driver.mjs --clip clip.y4m --out result.json [--run-s S] [--www DIR]');
  const m = /^(\d+)x(\d+)$/.exec(args.viewport);
  if (!m) throw new Error(`invalid --viewport ${args.viewport}; expected WxH`);
  args.size = { width: Number(m[1]), height: Number(m[2]) };
  return args;
}

/** Start tools/serve.mjs --log on a free port; resolves {proc, url, requests} (requests grows). */
function startServer(www) {
  return new Promise((ok, fail) => {
    const proc = spawn(process.execPath, [join(ROOT, 'tools', 'serve.mjs'), '--port', '0', '--root', www, '--log'],
      { stdio: ['ignore', 'pipe', 'inherit'] });
    const requests = [];
    let out = '';
    let url = null;
    const timer = setTimeout(() => fail(new Error('server did not start in 10 s')), 10000);
    proc.stdout.on('data', (chunk) => {
      out += chunk;
      const lines = out.split('\n');
      out = lines.pop();
      for (const line of lines) {
        const r = /^request (\S+) (\S+) (\d+) (\d+)$/.exec(line);
        if (r) requests.push({ method: r[1], url: r[2], status: Number(r[3]), bytes: Number(r[4]) });
        const m = line.match(/serving (http:\/\/127\.0\.0\.1:\d+\/)/);
        if (m && !url) {
          url = m[1];
          clearTimeout(timer);
          ok({ proc, url, requests });
        }
      }
    });
    proc.on('exit', (code) => fail(new Error(`server exited with ${code}`)));
  });
}

function stopServer(proc) {
  return new Promise((ok) => {
    if (proc.exitCode !== null) return ok();
    proc.once('exit', () => ok());
    proc.kill('SIGTERM');
  });
}

const APP_TIMEOUT_MS = 240000; // the first load, cold: see waitForApp
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/**
 * Wait for the app to be ready with its service worker holding it. A worker that failed is
 * reported at once with the page's reason; the wait itself is long, since a cold Chromium on
 * a slow machine (first start, first WASM compile) takes far longer than a warm one.
 */
async function waitForApp(page) {
  const state = await waitFor(page, () => {
    const a = window.crossingAssist;
    if (!a?.ready) return null;
    return a.offline === 'ready' || a.offline.startsWith('unavailable') ? a.offline : null;
  }, null, APP_TIMEOUT_MS, 'the app and its service worker');
  if (state !== 'ready') throw new Error(`the app loaded but its service worker did not: offline ${state}`);
}

async function waitFor(page, fn, arg, timeoutMs, what) {
  const t0 = Date.now();
  for (;;) {
    const v = await page.evaluate(fn, arg);
    if (v) return v;
    if (Date.now() - t0 > timeoutMs) {
      const err = await page.evaluate(() => {
        const a = window.crossingAssist;
        return `${a?.error || document.getElementById('status')?.textContent}; offline: ${a?.offline}`;
      });
      throw new Error(`timed out after ${timeoutMs} ms waiting for ${what} (page says: ${err})`);
    }
    await sleep(100);
  }
}

/** Records speech, vibration and wake-lock calls; can make the camera fail once (window.__failCameraOnce). */
function instrument() {
  const t = () => performance.now() / 1000;
  window.__vibrations = [];
  window.__speech = [];
  window.__wakeLocks = [];
  navigator.vibrate = (p) => { window.__vibrations.push({ t: t(), pattern: Array.isArray(p) ? p : [p] }); return true; };
  window.__heard = [];
  if (window.speechSynthesis) {
    let current = null; // {u, heard, timer}
    const over = (how) => {
      const c = current;
      current = null;
      clearTimeout(c.timer);
      c.heard.end = t();
      c.heard.how = how;
      c.u.dispatchEvent(new Event(how === 'whole' ? 'end' : 'error'));
    };
    speechSynthesis.cancel = () => current && over('cut');
    speechSynthesis.speak = (u) => {
      window.__speech.push({ t: t(), text: u.text });
      if (current) over('cut'); // one voice: the app cancels first; a leftover would be cut
      const heard = { text: u.text, start: t(), end: null, how: null };
      window.__heard.push(heard);
      current = { u, heard, timer: setTimeout(() => over('whole'), 60 * u.text.length) };
    };
  }
  Object.defineProperty(navigator, 'wakeLock', { configurable: true, value: {
    request: async (type) => {
      window.__wakeLocks.push({ t: t(), type, visible: document.visibilityState });
      return { released: false, type, release: async () => {}, addEventListener() {} };
    } } });
  const gum = navigator.mediaDevices.getUserMedia.bind(navigator.mediaDevices);
  navigator.mediaDevices.getUserMedia = (c) => {
    if (window.__failCameraOnce) {
      window.__failCameraOnce = false;
      return Promise.reject(new DOMException('Could not start video source', 'NotReadableError'));
    }
    return gum(c);
  };
}

const sample = () => {
  const a = window.crossingAssist;
  const frames = a.trace.filter((e) => e.kind === 'frame');
  const last = frames[frames.length - 1];
  const r = document.getElementById('control').getBoundingClientRect();
  return { t: (performance.now() - a.t0) / 1000, last_frame_t: last ? last.t : null, fresh: last ? last.fresh : null,
    watchdog_stale: a.watchdog ? a.watchdog.stale : null, mode: a.mode,
    decision: a.last && { reason: a.last.reason, stop: a.last.stop, pan: a.last.pan, heading_deg: a.last.heading_deg },
    audio: a.audio ? a.audio.state() : null, status: document.getElementById('status').textContent,
    control: [r.x, r.y, r.width, r.height], label: document.getElementById('control-label').textContent };
};

/** The page's state as a person and a screen reader meet it. */
const screenState = () => {
  const a = window.crossingAssist;
  const r = document.getElementById('control').getBoundingClientRect();
  const err = document.getElementById('error');
  const notice = document.getElementById('notice');
  return { notice: !notice || notice.hidden ? null : notice.textContent, tilt_text: document.getElementById('tilt')?.textContent ?? null, mode: a.mode, running: a.running, status: document.getElementById('status').textContent,
    label: document.getElementById('control-label').textContent, control: [r.x, r.y, r.width, r.height],
    error: err.hidden ? null : err.textContent, strips_on: document.querySelectorAll('#grid .on, #strips .on').length,
    audio: a.audio ? a.audio.state() : null, audio_failed: a.audioFailed, paused: a.paused,
    speech: window.__speech.slice(), heard: window.__heard.slice(), vibrations: window.__vibrations.slice(), wake_locks: window.__wakeLocks.slice(),
    t: (performance.now() - a.t0) / 1000, now_s: performance.now() / 1000 };
};

async function collect(page) {
  return page.evaluate(() => {
    const a = window.crossingAssist;
    const b64 = (u8) => {
      let s = '';
      for (let i = 0; i < u8.length; i += 0x8000) s += String.fromCharCode.apply(null, u8.subarray(i, i + 0x8000));
      return btoa(s);
    };
    return {
      trace: a.trace,
      frames: a.frames.map((f) => ({ id: f.id, seq: f.seq, width: f.width, height: f.height, rgb: b64(f.rgb) })),
      meta: a.meta.raw, t0: a.t0 / 1000, backend: { backend: a.model.backend, threads: a.model.threads,
        isolated: window.crossOriginIsolated },
      speed_text: document.getElementById('speed').textContent, bundle_text: document.getElementById('bundle').textContent,
      camera_text: document.getElementById('camera').textContent,
      uncertainty_text: document.getElementById('uncertainty').textContent,
      turning_text: document.getElementById('turning').textContent,
    };
  });
}

const control = (page) => page.locator('#control');
const hideShow = (hidden) => {
  Object.defineProperty(document, 'hidden', { configurable: true, get: () => hidden });
  Object.defineProperty(document, 'visibilityState', { configurable: true, get: () => (hidden ? 'hidden' : 'visible') });
  document.dispatchEvent(new Event('visibilitychange'));
};

async function guide(page, runS, samples) {
  const tEnd = Date.now() + runS * 1000;
  while (Date.now() < tEnd) {
    samples.push(await page.evaluate(sample));
    await sleep(100);
  }
}

async function fullPhases(page, context, server, args, result) {
  // First load: everything the page and the service worker fetch before the app is ready.
  await page.goto(`${server.url}?test=1&gyro=1&tutorial_speed=8`);
  await waitForApp(page);
  await sleep(500);
  result.first_load = server.requests.slice();
  result.states = { ready: await page.evaluate(screenState) };

  // What a screen reader gets: helper view closed, then open.
  result.aria = await page.locator('body').ariaSnapshot();
  await page.click('#helper-toggle');
  result.aria_helper_open = await page.locator('body').ariaSnapshot();
  result.states.helper_open = await page.evaluate(screenState);
  const cdp = await context.newCDPSession(page);
  result.installability = (await cdp.send('Page.getInstallabilityErrors')).installabilityErrors;
  result.manifest_errors = (await cdp.send('Page.getAppManifest')).errors;
  await page.click('#selftest');
  result.vectors = await waitFor(page, () => window.crossingAssist.selftest, null, 60000, 'the self-test');
  result.vectors_text = await page.textContent('#selftest-result');
  await page.click('#helper-close');

  // First tap: the sound tutorial, then guidance.
  await control(page).click();
  await sleep(300);
  result.states.tutorial = await page.evaluate(screenState);
  await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'tutorial_done'), null, 30000, 'the tutorial');
  await steadyGyro(page, 3);
  await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'frame'), null, 30000, 'the first frame decision');
  const samples = [];
  await guide(page, args.runS, samples);
  result.samples = samples;
  result.states.running = await page.evaluate(screenState);

  // A single tap must not end guidance.
  await control(page).click();
  await sleep(800);
  result.states.single_tap = await page.evaluate(screenState);

  // Audio taken away (a phone call): guidance counts as failed; a tap resumes it.
  const tSuspend = await page.evaluate(async () => {
    const t = (performance.now() - window.crossingAssist.t0) / 1000;
    await window.crossingAssist.audio.ctx.suspend();
    return t;
  });
  await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'audio_failed'), null, 5000, 'the audio failure');
  await sleep(1500);
  result.states.audio_failed = { ...(await page.evaluate(screenState)), t_suspend: tSuspend };
  await control(page).click();
  await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'audio_resumed'), null, 5000, 'audio resumed');
  await sleep(1500);
  result.states.audio_resumed = await page.evaluate(screenState);

  // The audio taken again and given back without a tap (the call ended): guidance resumes with a
  // fresh Decider.
  await page.evaluate(() => window.crossingAssist.audio.ctx.suspend());
  await waitFor(page, () => window.crossingAssist.trace.filter((e) => e.kind === 'audio_failed').length >= 2, null, 5000, 'the second audio failure');
  await sleep(1000);
  const tGiven = await page.evaluate(async () => {
    const t = (performance.now() - window.crossingAssist.t0) / 1000;
    await window.crossingAssist.audio.ctx.resume();
    return t;
  });
  await sleep(1500);
  result.states.audio_given_back = { ...(await page.evaluate(screenState)), t_given: tGiven };

  // The app goes to the background (where the OS also suspends its audio) and comes back.
  await page.evaluate(hideShow, true);
  await sleep(1000);
  result.states.hidden = await page.evaluate(screenState);
  await page.evaluate(() => window.crossingAssist.audio.ctx.suspend());
  await sleep(300);
  await page.evaluate(hideShow, false);
  await sleep(1500);
  result.states.visible = await page.evaluate(screenState);

  // A fault outside the model on one frame (a bug, injected): the stop cue, then guidance goes on.
  const tFault = await page.evaluate(() => {
    const g = window.crossingAssist.grabber;
    const level = g.level.bind(g);
    let left = 1;
    g.level = (...a) => { if (left-- > 0) throw new Error('injected fault'); return level(...a); };
    return (performance.now() - window.crossingAssist.t0) / 1000;
  });
  await waitFor(page, (t) => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.t > t).length >= 5,
    tFault, 30000, 'frames after the injected fault');
  result.fault = { t: tFault, state: await page.evaluate(screenState) };

  // Freeze the camera: the video element stops presenting new frames (after a live beacon).
  await waitFor(page, () => window.crossingAssist.audio.state().kind === 'beacon', null, 20000, 'a beacon before the freeze');
  const tFreeze = await page.evaluate(() => {
    document.getElementById('video').pause();
    return (performance.now() - window.crossingAssist.t0) / 1000;
  });
  const stopped = await waitFor(page, () => {
    const a = window.crossingAssist;
    return a.watchdog.stale && a.audio.state().kind === 'stop' ? (performance.now() - a.t0) / 1000 : null;
  }, null, 5000, 'the stop cue after freezing the camera');
  await sleep(1200);
  result.freeze = { t_freeze: tFreeze, t_stop: stopped, after: await page.evaluate(sample),
    state: await page.evaluate(screenState) };
  await page.evaluate(() => document.getElementById('video').play());

  // A phone too slow for the model: each run takes 800 ms, over the 0.5 s watchdog. The camera
  // keeps giving frames, so the stop cue plays and the app says the phone is too slow, not that
  // the camera stalled; at normal speed again, the beacon comes back.
  await waitFor(page, () => window.crossingAssist.audio.state().kind === 'beacon', null, 20000, 'a beacon before the slow model');
  const tSlow = await page.evaluate(() => {
    const a = window.crossingAssist;
    a.fastRun = a.model.run;
    a.model.run = async (...args) => { await new Promise((r) => setTimeout(r, 800)); return a.fastRun.apply(a.model, args); };
    return (performance.now() - a.t0) / 1000;
  });
  await waitFor(page, () => window.crossingAssist.audio.state().kind === 'stop', null, 5000, 'the stop cue with a slow model');
  await sleep(2500);
  result.slow = { t_slow: tSlow, after: await page.evaluate(sample), state: await page.evaluate(screenState),
    speed_text: await page.evaluate(() => document.getElementById('speed').textContent),
    perf: await page.evaluate(() => ({ ...window.crossingAssist.perf })) };
  await page.evaluate(() => { const a = window.crossingAssist; a.model.run = a.fastRun; });
  result.slow.t_fast = await page.evaluate(() => (performance.now() - window.crossingAssist.t0) / 1000);
  await waitFor(page, () => window.crossingAssist.audio.state().kind === 'beacon', null, 20000, 'a beacon at normal speed again');

  // Hidden and shown again within 150 ms while a model run (300 ms) is in flight: the run's
  // result belongs to the Decider from before and is dropped; guidance goes on.
  result.hideshow = await page.evaluate(async () => {
    const a = window.crossingAssist;
    a.model.run = async (...args) => { await new Promise((r) => setTimeout(r, 300)); return a.fastRun.apply(a.model, args); };
    while (a.inflight === null) await new Promise((r) => setTimeout(r, 5));
    const r = { inflight: a.inflight, t_hide: (performance.now() - a.t0) / 1000 };
    const hs = (hidden) => {
      Object.defineProperty(document, 'hidden', { configurable: true, get: () => hidden });
      Object.defineProperty(document, 'visibilityState', { configurable: true, get: () => (hidden ? 'hidden' : 'visible') });
      document.dispatchEvent(new Event('visibilitychange'));
    };
    hs(true);
    await new Promise((ok) => setTimeout(ok, 150));
    hs(false);
    await new Promise((ok) => setTimeout(ok, 1000));
    a.model.run = a.fastRun;
    r.t_fast = (performance.now() - a.t0) / 1000;
    return r;
  });
  await sleep(1500);
  result.hideshow.state = await page.evaluate(screenState);

  // A model run of 450 ms at 10 frames/s: the frame the app grabs next came while the model ran
  // and has already waited up to 100 ms. The driver logs every frame the <video> presents
  // (requestVideoFrameCallback: its capture time, else presentation time; page clock, ms).
  const tAged = await page.evaluate(() => {
    const a = window.crossingAssist;
    const video = document.getElementById('video');
    window.__presented = [];
    window.__logFrames = true;
    const onFrame = (nowMs, m) => {
      window.__presented.push({ at: performance.now(), capture: m.captureTime ?? m.presentationTime ?? m.expectedDisplayTime ?? nowMs });
      if (window.__logFrames) video.requestVideoFrameCallback(onFrame);
    };
    video.requestVideoFrameCallback(onFrame);
    a.model.run = async (...args) => { await new Promise((r) => setTimeout(r, 450)); return a.fastRun.apply(a.model, args); };
    return (performance.now() - a.t0) / 1000;
  });
  await sleep(6000);
  result.aged = await page.evaluate((t) => {
    const a = window.crossingAssist;
    a.model.run = a.fastRun;
    window.__logFrames = false;
    return { t_start: t, t_end: (performance.now() - a.t0) / 1000, presented: window.__presented };
  }, tAged);
  await waitFor(page, () => window.crossingAssist.audio.state().kind === 'beacon', null, 20000, 'a beacon at normal speed again');

  // The camera track ends (another app took the camera) and the video stalls: the instruction
  // how to recover is said, and the watchdog's stop sentence half a second later must not cut it.
  result.camera_lost = { t: await page.evaluate(() => {
    document.getElementById('video').pause();
    window.crossingAssist.stream.getVideoTracks()[0].dispatchEvent(new Event('ended'));
    return (performance.now() - window.crossingAssist.t0) / 1000;
  }) };
  await sleep(8000);
  result.camera_lost.state = await page.evaluate(screenState);
  result.camera_lost.heard = await page.evaluate(() => window.__heard.slice());

  // Double tap ends guidance.
  await control(page).dblclick();
  await waitFor(page, () => window.crossingAssist.mode === 'ready', null, 10000, 'the end of guidance');
  result.states.ended_double = await page.evaluate(screenState);

  // A failed start leaves an error; the next, successful start must clear it.
  await page.evaluate(() => { window.__failCameraOnce = true; });
  await control(page).click();
  await waitFor(page, () => window.crossingAssist.error && window.crossingAssist.mode === 'ready', null, 10000, 'the camera error');
  result.states.error = await page.evaluate(screenState);
  await control(page).click();
  await waitFor(page, () => window.crossingAssist.running && window.crossingAssist.trace.filter((e) => e.kind === 'start').length >= 2,
    null, 10000, 'the second start');
  await sleep(1000);
  result.states.restarted = await page.evaluate(screenState);

  // The helper sets this phone's landscape field of view: 10 is refused, 60 is taken at once.
  await page.click('#helper-toggle');
  await page.fill('#fov-landscape', '10');
  await page.dispatchEvent('#fov-landscape', 'change');
  const refused = await page.textContent('#fov-result');
  await page.fill('#fov-landscape', '60');
  await page.dispatchEvent('#fov-landscape', 'change');
  const saved = await page.textContent('#fov-result');
  await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'fov' && e.fov_deg === 60), null, 5000, 'the new FOV');
  await sleep(800);
  result.fov_ui = { refused, saved, camera_text: await page.textContent('#camera'),
    stored: await page.evaluate(() => JSON.parse(localStorage.getItem('crossing-assist-settings')).fov) };
  await page.click('#helper-close');

  // A long press ends guidance.
  const box = await control(page).boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await sleep(1000);
  await page.mouse.up();
  await waitFor(page, () => window.crossingAssist.mode === 'ready', null, 5000, 'the end by long press');
  result.states.ended_long = await page.evaluate(screenState);
  Object.assign(result, await collect(page));
}

/**
 * The synthetic tilt sensor: one deviceorientation event every 50 ms with window.__orient's
 * angles ({beta, gamma}; null: none sent, a sensor that is missing or stopped). Returns the app's
 * clock at the change.
 */
const orient = (page, angles) => page.evaluate((o) => {
  window.__orient = o;
  if (!window.__orientTimer) {
    window.__orientTimer = setInterval(() => window.__orient && window.dispatchEvent(new DeviceOrientationEvent('deviceorientation',
      { alpha: 0, beta: window.__orient.beta, gamma: window.__orient.gamma })), 50);
  }
  return (performance.now() - (window.crossingAssist?.t0 ?? 0)) / 1000;
}, angles);
const LEVEL_PORTRAIT = { beta: 90, gamma: 0 }; // upright portrait, camera at the horizon, not rolled

/** The phone pointed at the ground (camera 50 deg down) until a "not sure" stop says to raise it. */
async function tiltPhase(page, result, base) {
  const tTilt = await orient(page, { beta: 40, gamma: 0 });
  const tSpoken = await waitFor(page, () => window.crossingAssist.trace.find((e) => e.kind === 'speech' && e.text.includes('raise it'))?.t ?? null,
    null, 60000, 'the tilt advice');
  await orient(page, base);
  result.tilt = { t_tilt: tTilt, t_spoken: tSpoken };
}

/**
 * The phone upright, camera level, turned `deg` clockwise about the camera's axis (the W3C angles
 * beta = 90 + deg, gamma = -90 give that rotation) until 8 frames were levelled.
 */
async function rollPhase(page, result, deg, base, sensorStops) {
  const t0 = await orient(page, { beta: 90 + deg, gamma: -90 });
  await waitFor(page, () => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.roll_deg !== 0).length >= 8,
    null, 60000, 'levelled frames');
  result.roll = { deg, t_start: t0, screen_angle: await page.evaluate(() => screen.orientation?.angle ?? null),
    camera_text: await page.textContent('#camera') };
  // then turned 75 deg: beyond what can be levelled (rolledTooFar): stop, and say to hold it level
  const tFar = await orient(page, { beta: 90 + 75, gamma: -90 });
  const tSaid = await waitFor(page, (t) => window.crossingAssist.trace.find((e) => e.kind === 'speech' && e.t >= t && e.text.includes('hold it level'))?.t ?? null,
    tFar, 60000, 'the hold-it-level stop');
  await waitFor(page, (t) => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.t > t + 0.3).length >= 5,
    tFar, 60000, 'frames rolled beyond levelling');
  result.roll.tilt_text = await page.evaluate(() => document.getElementById('tilt')?.textContent ?? null);
  if (!sensorStops) {
    result.roll.too_far = { deg: 75, t_start: tFar, t_spoken: tSaid, t_end: await orient(page, base) };
    return;
  }
  // the sensor falls silent, the phone still turned 75 deg: its last reading must not be used
  const tSilent = await orient(page, null);
  result.roll.too_far = { deg: 75, t_start: tFar, t_spoken: tSaid, t_end: tSilent };
  const tTold = await waitFor(page, (t) => window.crossingAssist.trace.find((e) => e.kind === 'speech' && e.t >= t && e.text.startsWith('No tilt sensor'))?.t ?? null,
    tSilent, 20000, 'no tilt sensor said');
  await waitFor(page, (t) => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.t > t + 0.6).length >= 5,
    tSilent, 60000, 'frames after the sensor stopped');
  const state = await page.evaluate(screenState);
  result.sensor_stopped = { t_start: tSilent, t_told: tTold, t_end: await orient(page, base), state };
}

/** Waits until a "not sure" stop held upright says to hold the phone sideways. */
async function sidewaysPhase(page, result) {
  const tSpoken = await waitFor(page, () => window.crossingAssist.trace.find((e) => e.kind === 'speech' && e.text.includes('sideways'))?.t ?? null,
    null, 60000, 'the hold-it-sideways advice');
  result.sideways = { t_spoken: tSpoken };
}

/** A gyroscope reading a steady turn of `rate` deg/s (+ right) at 60 Hz: an upright phone turns
 * about its y axis, right being negative. */
async function steadyGyro(page, rate) {
  await page.evaluate((r) => setInterval(() => window.dispatchEvent(new DeviceMotionEvent('devicemotion',
    { rotationRate: { alpha: 0, beta: 0, gamma: -r }, interval: 16 })), 16), rate);
}

async function shortPhases(page, server, args, result) {
  // no sensor setting stored and no URL flag for them: the app's defaults (tilt sensor on)
  await page.addInitScript(() => localStorage.setItem('crossing-assist-settings',
    JSON.stringify({ tutorialDone: true, hapticDirections: true })));
  await page.goto(`${server.url}?test=1${args.sidewaysAfter ? `&sideways_after_s=${args.sidewaysAfter}` : ''}`
    + `${args.visualYaw !== undefined ? `&visualyaw=${args.visualYaw}` : ''}${args.gyro !== undefined ? '&gyro=1' : ''}`
    + `${args.record ? '&record=1' : ''}`);
  result.page_url = page.url();
  result.stored_settings = await page.evaluate(() => localStorage.getItem('crossing-assist-settings'));
  const base = args.level ? LEVEL_PORTRAIT : null;
  await orient(page, base);
  await waitForApp(page);
  result.first_load = server.requests.slice();
  result.states = { ready: await page.evaluate(screenState) };
  await control(page).click();
  if (args.gyro !== undefined || args.motion !== undefined) await steadyGyro(page, args.gyro ?? args.motion);
  await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'frame'), null, 60000, 'the first frame decision');
  const samples = [];
  await guide(page, args.runS, samples);
  result.samples = samples;
  result.states.running = await page.evaluate(screenState);
  if (args.sidewaysAfter) await sidewaysPhase(page, result);
  if (args.roll !== undefined) await rollPhase(page, result, args.roll, base, args.sensorStops);
  if (args.tilt) await tiltPhase(page, result, base);
  Object.assign(result, await collect(page));
  await control(page).dblclick();
  await waitFor(page, () => window.crossingAssist.mode === 'ready', null, 10000, 'the end of guidance');
  result.states.ended_double = await page.evaluate(screenState);
  if (args.record) {
    await waitFor(page, () => window.crossingAssist.recording, null, 20000, 'the field recording');
    result.recording = await page.evaluate(async () => {
      const rec = window.crossingAssist.recording;
      const bytes = new Uint8Array(await rec.video.arrayBuffer());
      let bin = '';
      for (let i = 0; i < bytes.length; i += 0x8000) bin += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
      const links = [...document.querySelectorAll('#recording a')].map((a) => ({ download: a.download, text: a.textContent,
        href: a.href.slice(0, 5) }));
      return { csv: rec.csv, type: rec.type, extension: rec.extension, samples: rec.samples, seconds: rec.seconds,
        video_b64: btoa(bin), links, text: document.getElementById('recording').textContent,
        hidden: document.getElementById('recording').hidden };
    });
  }
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  const { chromium } = await import('playwright-core');
  const profile = mkdtempSync(join(tmpdir(), 'crossing-chromium-'));
  let server = await startServer(args.www);
  const result = { url: server.url, console: [], viewport: args.size };
  let context;
  try {
    context = await chromium.launchPersistentContext(profile, {
      executablePath: args.chromium, headless: true, viewport: args.size,
      args: [...CHROMIUM_FLAGS, `--use-file-for-fake-video-capture=${args.clip}`],
      ignoreDefaultArgs: ['--mute-audio'],
    });
    const page = context.pages()[0] || await context.newPage();
    let sink = result.console; // the offline phase gets its own list
    page.on('console', (m) => sink.push(`${m.type()}: ${m.text()}`.slice(0, 500)));
    page.on('pageerror', (e) => sink.push(`pageerror: ${e.message}`.slice(0, 500)));
    await page.addInitScript(instrument);
    if (args.phases === 'short') {
      await shortPhases(page, server, args, result);
    } else {
      await fullPhases(page, context, server, args, result);
      // Offline: stop the server, reload, start again (the tutorial was done: it must not come back).
      await stopServer(server.proc);
      server = null;
      await page.reload();
      const offline = { loaded: false, console: [] };
      sink = offline.console;
      try {
        await waitFor(page, () => window.crossingAssist?.ready, null, 30000, 'the app offline');
        offline.loaded = true;
        await control(page).click();
        await waitFor(page, () => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.obs.ok).length >= 5,
          null, 20000, 'decisions offline');
        offline.decisions = await page.evaluate(() => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.obs.ok).length);
        offline.tutorial = await page.evaluate(() => window.crossingAssist.trace.filter((e) => e.kind === 'tutorial').length);
        offline.error = await page.evaluate(() => window.crossingAssist.error);
      } catch (err) {
        offline.error = err.message;
      }
      result.offline = offline;
    }
  } finally {
    if (context) await context.close();
    if (server) await stopServer(server.proc);
    rmSync(profile, { recursive: true, force: true });
  }
  writeFileSync(args.out, JSON.stringify(result));
}

main().catch((err) => {
  console.error(`error: ${err.message}`);
  process.exit(1);
});

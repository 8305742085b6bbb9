#!/usr/bin/env node
// End-to-end driver: serves www/ on 127.0.0.1, starts Debian's headless Chromium through
// playwright-core with a fake camera playing a Y4M clip, runs the app, and writes what it saw
// as JSON for tests/test_android_e2e.py to judge against the Python runtime:
//
//   node tools/e2e_driver.mjs --clip clip.y4m --out result.json [--run-s 8] [--www DIR]
//                            [--chromium /usr/bin/chromium]
//
// Phases: load (service worker ready) -> the app's self-test (shared test vectors) -> Start
// (with a synthetic gyroscope turning right at 3 deg/s), run the clip for --run-s seconds while sampling the audio graph every 100 ms -> freeze the
// camera (the <video> stops presenting frames) and time the stop cue -> collect the decision
// trace and the frames the model saw -> stop the server, reload, Start again (offline).
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
  const args = { runS: 8, chromium: '/usr/bin/chromium', www: join(ROOT, 'www') };
  for (let i = 0; i < argv.length; i += 2) {
    const [k, v] = [argv[i], argv[i + 1]];
    if (v === undefined) throw new Error(`missing value for ${k}`);
    if (k === '--clip') args.clip = resolve(v);
    else if (k === '--out') args.out = resolve(v);
    else if (k === '--run-s') args.runS = Number(v);
    else if (k === '--chromium') args.chromium = v;
    else if (k === '--www') args.www = resolve(v);
    else throw new Error(`unknown argument ${k}`);
  }
  if (!args.clip || !args.out) throw new Error('usage: e2e_driver.mjs --clip clip.y4m --out result.json [--run-s S] [--www DIR]');
  return args;
}

/** Start tools/serve.mjs on a free port; resolves {proc, url}. */
function startServer(www) {
  return new Promise((ok, fail) => {
    const proc = spawn(process.execPath, [join(ROOT, 'tools', 'serve.mjs'), '--port', '0', '--root', www],
      { stdio: ['ignore', 'pipe', 'inherit'] });
    let out = '';
    const timer = setTimeout(() => fail(new Error('server did not start in 10 s')), 10000);
    proc.stdout.on('data', (chunk) => {
      out += chunk;
      const m = out.match(/serving (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) {
        clearTimeout(timer);
        ok({ proc, url: m[1] });
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

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function waitFor(page, fn, arg, timeoutMs, what) {
  const t0 = Date.now();
  for (;;) {
    const v = await page.evaluate(fn, arg);
    if (v) return v;
    if (Date.now() - t0 > timeoutMs) {
      const err = await page.evaluate(() => window.crossingAssist?.error || document.getElementById('status')?.textContent);
      throw new Error(`timed out after ${timeoutMs} ms waiting for ${what} (page says: ${err})`);
    }
    await sleep(100);
  }
}

const sampleAudio = () => {
  const a = window.crossingAssist;
  const frames = a.trace.filter((e) => e.kind === 'frame');
  const last = frames[frames.length - 1];
  return { t: (performance.now() - a.t0) / 1000, last_frame_t: last ? last.t : null, fresh: last ? last.fresh : null,
    watchdog_stale: a.watchdog ? a.watchdog.stale : null,
    decision: a.last && { reason: a.last.reason, stop: a.last.stop, pan: a.last.pan, heading_deg: a.last.heading_deg },
    audio: a.audio ? a.audio.state() : null };
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
      frames: a.frames.map((f) => ({ seq: f.seq, width: f.width, height: f.height, rgb: b64(f.rgb) })),
      meta: a.meta.raw, t0: a.t0 / 1000,
    };
  });
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  const { chromium } = await import('playwright-core');
  const profile = mkdtempSync(join(tmpdir(), 'crossing-chromium-'));
  let server = await startServer(args.www);
  const result = { url: server.url, console: [] };
  let context;
  try {
    context = await chromium.launchPersistentContext(profile, {
      executablePath: args.chromium, headless: true,
      args: [...CHROMIUM_FLAGS, `--use-file-for-fake-video-capture=${args.clip}`],
      ignoreDefaultArgs: ['--mute-audio'],
    });
    const page = context.pages()[0] || await context.newPage();
    let sink = result.console; // the offline phase gets its own list
    page.on('console', (m) => sink.push(`${m.type()}: ${m.text()}`.slice(0, 500)));
    page.on('pageerror', (e) => sink.push(`pageerror: ${e.message}`.slice(0, 500)));
    await page.addInitScript(() => {
      window.__vibrations = [];
      navigator.vibrate = (p) => { window.__vibrations.push(p); return true; };
    });
    const url = `${server.url}?test=1&gyro=1`;
    await page.goto(url);
    await waitFor(page, () => window.crossingAssist?.ready && window.crossingAssist.offline === 'ready', null, 60000, 'the app and its service worker');

    // What a screen reader gets: the page's accessibility tree.
    result.aria = await page.locator('body').ariaSnapshot();
    // What Chrome on a phone would say about installing the app ("Add to Home screen").
    const cdp = await context.newCDPSession(page);
    result.installability = (await cdp.send('Page.getInstallabilityErrors')).installabilityErrors;
    result.manifest_errors = (await cdp.send('Page.getAppManifest')).errors;

    // The app's self-test button: the shared test vectors replayed in this browser.
    await page.click('#selftest');
    result.vectors = await waitFor(page, () => window.crossingAssist.selftest, null, 30000, 'the self-test');
    result.vectors_text = await page.textContent('#selftest-result');

    await page.click('#start');
    // A gyroscope reporting a slow, steady right turn (3 deg/s = rotation of -3 deg/s about the
    // phone's upward y axis), at 60 Hz as phones do.
    await page.evaluate(() => setInterval(() => window.dispatchEvent(new DeviceMotionEvent('devicemotion',
      { rotationRate: { alpha: 0, beta: 0, gamma: -3 }, interval: 16 })), 16));
    await waitFor(page, () => window.crossingAssist.trace.some((e) => e.kind === 'frame'), null, 20000, 'the first frame decision');
    const samples = [];
    const tEnd = Date.now() + args.runS * 1000;
    while (Date.now() < tEnd) {
      samples.push(await page.evaluate(sampleAudio));
      await sleep(100);
    }
    result.samples = samples;

    // Freeze the camera: the video element stops presenting new frames.
    // Wait for a live beacon first, so that the stop is caused by the freeze.
    await waitFor(page, () => window.crossingAssist.audio.state().kind === 'beacon', null, 15000, 'a beacon before the freeze');
    const tFreeze = await page.evaluate(() => {
      document.getElementById('video').pause();
      return (performance.now() - window.crossingAssist.t0) / 1000;
    });
    const stopped = await waitFor(page, () => {
      const a = window.crossingAssist;
      return a.watchdog.stale && a.audio.state().kind === 'stop' ? (performance.now() - a.t0) / 1000 : null;
    }, null, 5000, 'the stop cue after freezing the camera');
    await sleep(1200);
    result.freeze = { t_freeze: tFreeze, t_stop: stopped, after: await page.evaluate(sampleAudio),
      vibrations: await page.evaluate(() => window.__vibrations) };
    Object.assign(result, await collect(page));

    // Offline: stop the server, reload, start again.
    await page.click('#start'); // stop
    await stopServer(server.proc);
    server = null;
    await page.reload();
    const offline = { loaded: false, console: [] };
    sink = offline.console;
    try {
      await waitFor(page, () => window.crossingAssist?.ready, null, 30000, 'the app offline');
      offline.loaded = true;
      await page.click('#start');
      const ok = () => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.obs.ok).length;
      await waitFor(page, () => window.crossingAssist.trace.filter((e) => e.kind === 'frame' && e.obs.ok).length >= 5,
        null, 20000, 'decisions offline');
      offline.decisions = await page.evaluate(ok);
      offline.error = await page.evaluate(() => window.crossingAssist.error);
    } catch (err) {
      offline.error = err.message;
    }
    result.offline = offline;
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

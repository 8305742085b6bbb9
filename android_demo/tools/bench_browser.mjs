#!/usr/bin/env node
// Model latency in headless Chromium, as the app runs it, plus what the first visit costs:
// serves a built www/ on 127.0.0.1 (logging requests), loads the app in a fresh profile, waits
// for its session and service worker, then times `runs` calls of the app's Model.run on a
// synthetic H x W RGB frame (after `warmup` untimed ones).
//
//   node tools/bench_browser.mjs [--www www] [--size 480x640] [--runs 20] [--warmup 3]
//        [--threads N]   (0 = the app's choice: cores - 1, at most 4, when cross-origin isolated)
//
// Prints one JSON line: {"bundle", "backend", "threads", "size": [H, W], "runs", "median_ms",
// "p90_ms", "first_load_bytes" (bytes the server sent until the app was ready and cached for
// offline use), "first_load_requests", "cache_bytes" (what the service worker's cache holds)}.

import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const ROOT = resolve(dirname(fileURLToPath(import.meta.url)), '..');
const FLAGS = ['--headless=new', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync'];

function args(argv) {
  const a = { www: join(ROOT, 'www'), size: '480x640', runs: 20, warmup: 3, chromium: '/usr/bin/chromium', threads: 0 };
  for (let i = 0; i < argv.length; i += 2) {
    const key = argv[i].replace(/^--/, '');
    if (!(key in a) || argv[i + 1] === undefined) throw new Error(`unknown argument ${argv[i]}`);
    a[key] = ['runs', 'warmup', 'threads'].includes(key) ? Number(argv[i + 1]) : argv[i + 1];
  }
  const m = /^(\d+)x(\d+)$/.exec(a.size);
  if (!m) throw new Error(`invalid --size ${a.size}; expected HxW, e.g. 480x640`);
  a.hw = [Number(m[1]), Number(m[2])];
  return a;
}

async function main() {
  const a = args(process.argv.slice(2));
  const { chromium } = await import('playwright-core');
  const server = spawn(process.execPath, [join(ROOT, 'tools', 'serve.mjs'), '--port', '0', '--root', resolve(a.www), '--log'],
    { stdio: ['ignore', 'pipe', 'inherit'] });
  const requests = [];
  const url = await new Promise((ok, fail) => {
    let out = '';
    server.stdout.on('data', (c) => {
      out += c;
      const lines = out.split('\n');
      out = lines.pop();
      for (const line of lines) {
        const r = /^request \S+ (\S+) (\d+) (\d+)$/.exec(line);
        if (r) requests.push({ url: r[1], bytes: Number(r[3]) });
        const m = line.match(/serving (http:\/\/\S+\/)/);
        if (m) ok(m[1]);
      }
    });
    server.on('exit', (code) => fail(new Error(`server exited with ${code}`)));
  });
  const profile = mkdtempSync(join(tmpdir(), 'crossing-bench-'));
  const ctx = await chromium.launchPersistentContext(profile, { executablePath: a.chromium, headless: true, args: FLAGS });
  try {
    const page = ctx.pages()[0] || await ctx.newPage();
    await page.goto(a.threads ? `${url}?threads=${a.threads}` : url);
    await page.waitForFunction(() => (window.crossingAssist?.ready && window.crossingAssist.offline === 'ready')
      || window.crossingAssist?.error, null, { timeout: 180000 });
    const firstLoad = requests.slice();
    const r = await page.evaluate(async ({ hw, runs, warmup }) => {
      const app = window.crossingAssist;
      if (!app.ready) return { error: app.error };
      let cacheBytes = 0;
      for (const name of await caches.keys()) {
        const cache = await caches.open(name);
        for (const req of await cache.keys()) cacheBytes += (await (await cache.match(req)).arrayBuffer()).byteLength;
      }
      const [h, w] = hw;
      const rgb = new Uint8Array(h * w * 3);
      for (let i = 0; i < rgb.length; i += 1) rgb[i] = (i * 2654435761) >>> 24;
      for (let i = 0; i < warmup; i += 1) await app.model.run(rgb, h, w);
      const ms = [];
      for (let i = 0; i < runs; i += 1) {
        const t0 = performance.now();
        await app.model.run(rgb, h, w);
        ms.push(performance.now() - t0);
      }
      ms.sort((x, y) => x - y);
      const { modelName } = await import('./js/view.js');   // the helper view's name for the bundle's model
      return { bundle: `${modelName(app.meta.raw.training)} ${app.meta.input.size.join('x')} T=${app.meta.mc.samples} ${app.meta.precision}`,
        backend: app.model.backend, threads: app.model.threads, isolated: crossOriginIsolated,
        size: hw, runs, median_ms: ms[Math.floor(runs / 2)], p90_ms: ms[Math.floor(0.9 * (runs - 1))], cache_bytes: cacheBytes };
    }, { hw: a.hw, runs: a.runs, warmup: a.warmup });
    if (r.error) throw new Error(r.error);
    r.first_load_bytes = firstLoad.reduce((s, q) => s + q.bytes, 0);
    r.first_load_requests = firstLoad.length;
    console.log(JSON.stringify(r));
  } finally {
    await ctx.close();
    server.kill('SIGTERM');
    rmSync(profile, { recursive: true, force: true });
  }
}

main().catch((err) => {
  console.error(`error: ${err.message}`);
  process.exit(1);
});

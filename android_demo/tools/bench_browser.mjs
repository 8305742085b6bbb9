#!/usr/bin/env node
// Model latency in headless Chromium (onnxruntime-web WASM, one thread), as the app runs it:
// serves a built www/ on 127.0.0.1, waits for the app's session, then times `runs` calls of
// the app's Model.run on a synthetic H x W RGB frame (after `warmup` untimed ones).
//
//   node tools/bench_browser.mjs [--www www] [--size 480x640] [--runs 20] [--warmup 3]
//
// Prints one JSON line: {"bundle": ..., "size": [H, W], "runs": n, "median_ms": ..., "p90_ms": ...}.

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
  const server = spawn(process.execPath, [join(ROOT, 'tools', 'serve.mjs'), '--port', '0', '--root', resolve(a.www)],
    { stdio: ['ignore', 'pipe', 'inherit'] });
  const url = await new Promise((ok, fail) => {
    let out = '';
    server.stdout.on('data', (c) => {
      out += c;
      const m = out.match(/serving (http:\/\/\S+\/)/);
      if (m) ok(m[1]);
    });
    server.on('exit', (code) => fail(new Error(`server exited with ${code}`)));
  });
  const profile = mkdtempSync(join(tmpdir(), 'crossing-bench-'));
  const ctx = await chromium.launchPersistentContext(profile, { executablePath: a.chromium, headless: true, args: FLAGS });
  try {
    const page = ctx.pages()[0] || await ctx.newPage();
    await page.goto(a.threads ? `${url}?threads=${a.threads}` : url);
    await page.waitForFunction(() => window.crossingAssist?.ready || window.crossingAssist?.error, null, { timeout: 120000 });
    const r = await page.evaluate(async ({ hw, runs, warmup }) => {
      const app = window.crossingAssist;
      if (!app.ready) return { error: app.error };
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
      const t = app.meta.raw.training || {};
      return { backend: app.model.backend, threads: app.model.threads, isolated: crossOriginIsolated, bundle: `${t.backbone || '?'} ${app.meta.input.size.join('x')} T=${app.meta.mc.samples} ${app.meta.precision}`,
        size: hw, runs, median_ms: ms[Math.floor(runs / 2)], p90_ms: ms[Math.floor(0.9 * (runs - 1))] };
    }, { hw: a.hw, runs: a.runs, warmup: a.warmup });
    if (r.error) throw new Error(r.error);
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

#!/usr/bin/env node
// Build step of the phone app: copy the few onnxruntime-web files the app uses (the WASM
// backend only) from node_modules into www/vendor/, copy a bundle (model.onnx + bundle.json,
// validated, SHA-256 checked) into www/bundle/, copy test_vectors.json (for the app's
// self-test) into www/, and write www/precache.json: every file the
// service worker caches for offline use, with its SHA-256, and a version that changes when
// any of them changes (so phones pick up a new app or bundle on their next online visit).
// Every compressible file also gets a gzip twin (FILE.gz, written only where it saves >= 10%;
// tools/serve.mjs sends it to browsers that accept gzip; not listed for the cache, which holds
// the decoded bytes). The WebGPU build of onnxruntime-web is copied too but not precached: a
// phone with WebGPU fetches it on first use (model.js), others never download it.
//
//   node tools/build.mjs [--bundle DIR] [--www DIR]
//
// DIR defaults: ../crossing_assist/assets/default_bundle, www (relative to android_demo/). Another
// --www folder (new, empty, or built before) first gets the app's own files from www/ (pages,
// scripts, icons), so it is a whole app; a folder holding anything else is refused.

import { createHash } from 'node:crypto';
import { copyFileSync, existsSync, mkdirSync, readdirSync, readFileSync, renameSync, rmSync, statSync, writeFileSync } from 'node:fs';
import { dirname, extname, join, relative, resolve, sep } from 'node:path';
import { fileURLToPath } from 'node:url';
import { gzipSync } from 'node:zlib';
import { BundleError, checkEmbedded, parseBundleMeta } from '../www/js/bundle.js';

const HERE = dirname(dirname(fileURLToPath(import.meta.url)));
const SOURCE_WWW = join(HERE, 'www');
export const ORT_FILES = ['ort.wasm.min.mjs', 'ort-wasm-simd-threaded.mjs', 'ort-wasm-simd-threaded.wasm'];
export const ORT_WEBGPU_FILES = ['ort.webgpu.min.mjs', 'ort-wasm-simd-threaded.asyncify.mjs', 'ort-wasm-simd-threaded.asyncify.wasm'];
const NOT_CACHED = new Set(['precache.json', 'sw.js', ...ORT_WEBGPU_FILES.map((f) => `vendor/${f}`)]);
const COMPRESSIBLE = new Set(['.wasm', '.mjs', '.js', '.json', '.html', '.css', '.onnx', '.webmanifest', '.svg']);

class BuildError extends Error {}

function sha256(path) {
  return createHash('sha256').update(readFileSync(path)).digest('hex');
}

/** Copy src to dst through a temporary file and a rename (never a half-written file). */
function copyAtomic(src, dst) {
  mkdirSync(dirname(dst), { recursive: true });
  const tmp = `${dst}.tmp-${process.pid}`;
  copyFileSync(src, tmp);
  renameSync(tmp, dst);
}

function writeAtomic(dst, text) {
  const tmp = `${dst}.tmp-${process.pid}`;
  writeFileSync(tmp, text);
  renameSync(tmp, dst);
}

function copyOrt(www) {
  const dist = join(HERE, 'node_modules', 'onnxruntime-web', 'dist');
  for (const name of [...ORT_FILES, ...ORT_WEBGPU_FILES]) {
    const src = join(dist, name);
    if (!existsSync(src)) throw new BuildError(`${src} is missing; run 'npm ci' in android_demo first`);
    copyAtomic(src, join(www, 'vendor', name));
  }
}

/** Validate and copy a bundle folder into www/bundle/; returns the parsed meta. */
export function copyBundle(bundleDir, www) {
  const jsonPath = join(bundleDir, 'bundle.json');
  if (!existsSync(jsonPath)) {
    throw new BuildError(`no bundle at ${bundleDir} (bundle.json missing); pass --bundle DIR, a folder written by crossing-export`);
  }
  let meta;
  try {
    meta = parseBundleMeta(JSON.parse(readFileSync(jsonPath, 'utf8')));
  } catch (err) {
    if (err instanceof SyntaxError) throw new BuildError(`${jsonPath} is not valid JSON; re-export the bundle`);
    throw err;
  }
  const modelPath = join(bundleDir, meta.model_file);
  if (!existsSync(modelPath)) throw new BuildError(`${modelPath} is missing; copy the whole bundle folder`);
  const model = readFileSync(modelPath);
  if (model.length !== meta.model_size || createHash('sha256').update(model).digest('hex') !== meta.model_sha256) {
    throw new BuildError(`${modelPath} differs from bundle.json (size or SHA-256); copy the bundle again or re-export it`);
  }
  checkEmbedded(meta.raw, model); // as the app will: a hand-edited bundle.json is refused here already
  const out = join(www, 'bundle');
  rmSync(out, { recursive: true, force: true });
  copyAtomic(modelPath, join(out, meta.model_file));
  copyAtomic(jsonPath, join(out, 'bundle.json'));
  return meta;
}

/** The app's own files in www/ (pages, scripts, icons): everything but what the build writes. */
function appFiles() {
  const built = (p) => ['vendor/', 'bundle/'].some((d) => p.startsWith(d)) || ['precache.json', 'test_vectors.json'].includes(p);
  return listFiles(SOURCE_WWW).filter((p) => !built(p));
}

/**
 * Copy the app's files into another --www folder (new, empty, or an app folder built before), so
 * that it is a whole app; refuse a folder that holds other things (the build would delete its bundle/).
 */
function copyPages(www) {
  if (www === SOURCE_WWW) return;
  if (existsSync(www) && (!statSync(www).isDirectory() || (readdirSync(www).length && !existsSync(join(www, 'index.html'))))) {
    throw new BuildError(`--www ${www} exists and is not an app folder (no index.html); pass a new or empty folder`);
  }
  for (const rel of appFiles()) copyAtomic(join(SOURCE_WWW, rel), join(www, rel));
}

/** Write FILE.gz next to every compressible file where gzip saves >= 10% (kept when up to date); returns the twins. */
export function writeGzipTwins(www) {
  const twins = [];
  for (const rel of listFiles(www)) {
    const path = join(www, rel);
    if (!COMPRESSIBLE.has(extname(rel))) continue;
    const gz = `${path}.gz`;
    if (existsSync(gz) && statSync(gz).mtimeMs >= statSync(path).mtimeMs) {
      twins.push(rel);
      continue;
    }
    const data = readFileSync(path);
    const packed = gzipSync(data, { level: 9 });
    if (packed.length <= 0.9 * data.length) {
      writeAtomic(gz, packed);
      twins.push(rel);
    } else {
      rmSync(gz, { force: true });
    }
  }
  return twins;
}

function listFiles(root, dir = root) {
  const out = [];
  for (const entry of readdirSync(dir, { withFileTypes: true })) {
    const path = join(dir, entry.name);
    if (entry.isDirectory()) out.push(...listFiles(root, path));
    else if (entry.isFile() && !entry.name.includes('.tmp-') && !entry.name.endsWith('.gz')) out.push(relative(root, path).split(sep).join('/'));
  }
  return out.sort();
}

/** Copy ../test_vectors.json (the Python runtime's decision vectors) for the app's self-test, if present. */
function copyVectors(www) {
  const src = join(HERE, 'test_vectors.json');
  const dst = join(www, 'test_vectors.json');
  if (existsSync(src)) copyAtomic(src, dst);
  else rmSync(dst, { force: true });
  return existsSync(src);
}

/** Write www/precache.json: {version, files: [{url, sha256, bytes}]} for the service worker. */
export function writePrecache(www) {
  const files = listFiles(www)
    .filter((p) => !NOT_CACHED.has(p))
    .map((p) => ({ url: p, sha256: sha256(join(www, p)), bytes: statSync(join(www, p)).size }));
  const version = createHash('sha256').update(JSON.stringify(files)).digest('hex').slice(0, 16);
  writeAtomic(join(www, 'precache.json'), `${JSON.stringify({ version, files }, null, 1)}\n`);
  return { version, files };
}

function parseArgs(argv) {
  const args = { bundle: resolve(HERE, '..', 'crossing_assist', 'assets', 'default_bundle'), www: SOURCE_WWW };
  for (let i = 0; i < argv.length; i += 1) {
    const key = argv[i];
    if ((key === '--bundle' || key === '--www') && i + 1 < argv.length) args[key.slice(2)] = resolve(argv[++i]);
    else if (key === '-h' || key === '--help') args.help = true;
    else throw new BuildError(`unknown argument ${JSON.stringify(key)}; usage: node tools/build.mjs [--bundle DIR] [--www DIR]`);
  }
  return args;
}

function main() {
  try {
    const args = parseArgs(process.argv.slice(2));
    if (args.help) {
      console.log('usage: node tools/build.mjs [--bundle DIR] [--www DIR]');
      return 0;
    }
    copyPages(args.www);
    copyOrt(args.www);
    const meta = copyBundle(args.bundle, args.www);
    copyVectors(args.www);
    const { version, files } = writePrecache(args.www);
    writeGzipTwins(args.www);
    const total = files.reduce((s, f) => s + f.bytes, 0);
    const wire = files.reduce((s, f) => s + (existsSync(join(args.www, `${f.url}.gz`)) ? statSync(join(args.www, `${f.url}.gz`)).size : f.bytes), 0);
    console.log(`built ${args.www}: ${meta.actions.n}-action bundle, ${files.length} files, `
      + `${(total / 1e6).toFixed(1)} MB cached offline (${(wire / 1e6).toFixed(1)} MB to download with gzip), version ${version}`);
    return 0;
  } catch (err) {
    if (err instanceof BuildError || err instanceof BundleError) {
      console.error(`error: ${err.message}`);
      return 2;
    }
    throw err;
  }
}

if (process.argv[1] && resolve(process.argv[1]) === fileURLToPath(import.meta.url)) process.exit(main());

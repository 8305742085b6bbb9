// The bundle on the phone: fetch bundle.json + model.onnx, check the model's SHA-256 against
// the json and the json against the model's embedded copy, open an onnxruntime-web session and
// run one RGB frame through it.
//
// Backend: WebGPU where the browser has an adapter (vendor/ort.webgpu.min.mjs, loaded only
// then, not cached for offline use), else WASM with SIMD, on several threads when the page is
// cross-origin isolated (SharedArrayBuffer; the server sends COOP/COEP) and on one otherwise.
// Model.open says which it got ({backend, threads}); the helper view shows it.
//
// The graph takes raw uint8 NHWC RGB frames and resizes/normalises itself (contracts.md
// section 3), so the app only turns the camera's RGBA pixels into RGB (and, for a schema-3
// view-crop bundle, hands over the frame's middle rows: geometry.js frameView).

import { BundleError, INPUT_NAME, OUTPUT_NAMES, checkEmbedded, parseBundleMeta } from './bundle.js';

const hex = (buf) => Array.from(new Uint8Array(buf), (b) => b.toString(16).padStart(2, '0')).join('');

/**
 * Fetch and validate a bundle folder (URL ending in '/'): bundle.json, the model's size and
 * SHA-256, and bundle.json against the copy embedded in the model (bundle.js checkEmbedded).
 * @returns {Promise<{meta: object, modelBytes: Uint8Array}>}
 */
export async function fetchBundle(baseUrl) {
  const jsonResp = await fetch(new URL('bundle.json', baseUrl));
  if (!jsonResp.ok) throw new BundleError(`bundle: ${baseUrl}bundle.json: HTTP ${jsonResp.status}; build the app with a bundle (npm run build)`);
  let raw;
  try {
    raw = await jsonResp.json();
  } catch {
    throw new BundleError('bundle: bundle.json is not valid JSON; re-export the bundle');
  }
  const meta = parseBundleMeta(raw);
  const modelResp = await fetch(new URL(meta.model_file, baseUrl));
  if (!modelResp.ok) throw new BundleError(`bundle: ${meta.model_file}: HTTP ${modelResp.status}; copy the whole bundle folder`);
  const buf = await modelResp.arrayBuffer();
  if (buf.byteLength !== meta.model_size) {
    throw new BundleError(`bundle: ${meta.model_file} has ${buf.byteLength} bytes but bundle.json says ${meta.model_size}; copy the bundle again`);
  }
  if (globalThis.crypto?.subtle) {
    const digest = hex(await crypto.subtle.digest('SHA-256', buf));
    if (digest !== meta.model_sha256) {
      throw new BundleError(`bundle: ${meta.model_file} SHA-256 differs from bundle.json (corrupt or replaced); copy the bundle again`);
    }
  }
  checkEmbedded(raw, buf);
  return { meta, modelBytes: new Uint8Array(buf) };
}

/** One frame's model outputs (action axis length A). */
export class ModelOutputs {
  constructor(probs, entropy, mutualInfo, variance, votes) {
    this.probs = probs; // Float32Array(A), mean softmax over the T samples
    this.entropy = entropy; // nats
    this.mutual_info = mutualInfo; // nats, >= 0
    this.variance = variance; // Float32Array(A)
    this.votes = votes; // Float32Array(A), fraction of samples voting for each action
  }
}

export class Model {
  /** Use Model.open(). */
  constructor(ort, session, meta) {
    this.ort = ort;
    this.session = session;
    this.meta = meta;
  }

  /**
   * Open a session for a fetched bundle. `ort` is the onnxruntime-web module
   * (vendor/ort.wasm.min.mjs); `wasmBase` the URL of the folder holding its .wasm/.mjs.
   */
  static async open(ort, { meta, modelBytes }, wasmBase, { threads = 1, backend = 'wasm' } = {}) {
    ort.env.wasm.wasmPaths = wasmBase;
    ort.env.wasm.numThreads = threads;
    ort.env.wasm.proxy = false;
    const session = await ort.InferenceSession.create(modelBytes, {
      executionProviders: backend === 'webgpu' ? ['webgpu', 'wasm'] : ['wasm'],
      graphOptimizationLevel: 'all',
    });
    if (session.inputNames.length !== 1 || session.inputNames[0] !== INPUT_NAME) {
      throw new BundleError(`bundle: graph inputs ${JSON.stringify(session.inputNames)} disagree with the contract (one uint8 input '${INPUT_NAME}'); re-export the bundle`);
    }
    const missing = OUTPUT_NAMES.filter((n) => !session.outputNames.includes(n));
    if (missing.length) throw new BundleError(`bundle: graph lacks outputs ${JSON.stringify(missing)}; re-export the bundle`);
    const model = new Model(ort, session, meta);
    model.backend = backend;
    model.threads = backend === 'wasm' ? threads : null;
    return model;
  }

  /**
   * Run one frame. `rgb` is a Uint8Array of height * width * 3 bytes (row-major RGB).
   * @returns {Promise<ModelOutputs>}
   */
  async run(rgb, height, width) {
    const A = this.meta.actions.n;
    const frames = new this.ort.Tensor('uint8', rgb, [1, height, width, 3]);
    const out = await this.session.run({ [INPUT_NAME]: frames });
    const probs = Float32Array.from(out.probs.data);
    if (probs.length !== A) throw new BundleError(`bundle: graph returned ${probs.length} actions but bundle.json says ${A}; re-export the bundle`);
    const result = new ModelOutputs(probs, out.entropy.data[0], out.mutual_info.data[0],
      Float32Array.from(out.variance.data), Float32Array.from(out.votes.data));
    for (const t of Object.values(out)) t.dispose?.();
    return result;
  }
}

/** RGBA (canvas ImageData) -> RGB, in place into `rgb` (length w * h * 3); returns rgb. */
export function rgbaToRgb(rgba, rgb = new Uint8Array((rgba.length / 4) * 3)) {
  for (let i = 0, j = 0; i < rgba.length; i += 4, j += 3) {
    rgb[j] = rgba[i];
    rgb[j + 1] = rgba[i + 1];
    rgb[j + 2] = rgba[i + 2];
  }
  return rgb;
}

/** WASM threads to ask for: cores - 1, at most 4, where SharedArrayBuffer works (cross-origin isolated), else 1. */
export function wasmThreads(isolated = globalThis.crossOriginIsolated, cores = globalThis.navigator?.hardwareConcurrency) {
  return isolated ? Math.max(1, Math.min(4, (cores || 1) - 1)) : 1; // one core left for the camera, audio and page
}

/**
 * Load onnxruntime-web and open the bundle on the best backend this browser has: WebGPU when an
 * adapter is there (falls back to WASM if that fails), else WASM SIMD on wasmThreads() threads.
 * `vendor`: URL of the folder holding the onnxruntime-web files.
 */
export async function openBest(bundle, vendor, { allowWebGpu = true, threads = wasmThreads() } = {}) {
  if (allowWebGpu && globalThis.navigator?.gpu) {
    try {
      if (await navigator.gpu.requestAdapter()) {
        const ort = await import(new URL('ort.webgpu.min.mjs', vendor).href);
        return await Model.open(ort, bundle, vendor, { backend: 'webgpu' });
      }
    } catch (err) {
      console.warn(`WebGPU unavailable, using WASM: ${err.message || err}`);
    }
  }
  const ort = await import(new URL('ort.wasm.min.mjs', vendor).href);
  return Model.open(ort, bundle, vendor, { threads });
}

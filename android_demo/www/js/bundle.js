// bundle.json (schemas 1 to 4, docs/contracts.md section 3) validation, ported from
// crossing_assist/bundle.py: the phone refuses a bundle the Python runtime would refuse, with
// one line naming the field and the fix; checkEmbedded compares it with the graph's own copy. Pure (no DOM): runs in Node (build step, tests) and
// in the browser.

import { DEFAULT_FOV_DEG, spaceGroups, spaceNames } from './actions.js';
import { FOV_RANGE_DEG } from './geometry.js';
import { onnxMetadata } from './onnxmeta.js';

export const SCHEMA_VERSION = 4;
export const SCHEMA_VERSIONS = [1, 2, 3, 4];
export const FITS = ['letterbox', 'stretch'];
export const INPUT_NAME = 'frames';
export const OUTPUT_NAMES = ['probs', 'entropy', 'mutual_info', 'variance', 'votes'];
export const UNCERTAINTY_MEASURES = ['entropy', 'mutual_info', 'variance', 'far_mass'];
/** The bundle.json keys checked against the graph's embedded copy (bundle.py check_session). */
export const EMBEDDED_KEYS = ['schema_version', 'actions', 'fov_deg', 'input', 'geometry', 'mc', 'calibration', 'precision'];

export class BundleError extends Error {
  constructor(message) {
    super(message);
    this.name = 'BundleError';
  }
}

function get(obj, key, where) {
  if (obj === null || typeof obj !== 'object' || Array.isArray(obj)) {
    throw new BundleError(`bundle.json: ${where || 'the top level'} must be an object; re-export the bundle`);
  }
  if (!(key in obj)) {
    throw new BundleError(`bundle.json: missing field '${where ? `${where}.` : ''}${key}'; re-export the bundle with crossing-export`);
  }
  return obj[key];
}

function num(value, name, lo, hi, { loOpen = false, hiOpen = false } = {}) {
  if (typeof value !== 'number' || !Number.isFinite(value)) {
    throw new BundleError(`bundle.json: ${name} = ${JSON.stringify(value)} is not a finite number`);
  }
  const okLo = loOpen ? value > lo : value >= lo;
  const okHi = hiOpen ? value < hi : value <= hi;
  if (!okLo || !okHi) {
    throw new BundleError(`bundle.json: ${name} = ${value} is out of range; valid: ${loOpen ? '(' : '['}${lo}, ${hi}${hiOpen ? ')' : ']'}`);
  }
  return value;
}

function int(value, name, lo, hi = Infinity) {
  if (!Number.isInteger(value) || value < lo || value > hi) {
    throw new BundleError(`bundle.json: ${name} = ${JSON.stringify(value)} must be an integer in ${lo}..${hi === Infinity ? '' : hi}`);
  }
  return value;
}

function bool(value, name) {
  if (typeof value !== 'boolean') throw new BundleError(`bundle.json: ${name} = ${JSON.stringify(value)} must be true or false`);
  return value;
}

const same = (a, b) => JSON.stringify(a) === JSON.stringify(b);

function parseActions(d) {
  const n = get(d, 'n', 'actions');
  if (![4, 8, 13].includes(n)) throw new BundleError(`bundle.json: actions.n = ${JSON.stringify(n)} invalid; valid: 4, 8, 13`);
  const names = get(d, 'names', 'actions');
  const bins = get(d, 'bins', 'actions');
  if (!same(names, spaceNames(n))) {
    throw new BundleError(`bundle.json: actions.names disagree with the ${n}-action space; re-export the bundle`);
  }
  if (!same(bins, spaceGroups(n))) {
    throw new BundleError(`bundle.json: actions.bins disagree with the ${n}-action space; re-export the bundle`);
  }
  return { n, names, bins };
}

function parseInput(d) {
  for (const [key, want] of [['layout', 'NHWC'], ['dtype', 'uint8'], ['color', 'RGB']]) {
    const got = get(d, key, 'input');
    if (got !== want) throw new BundleError(`bundle.json: input.${key} = ${JSON.stringify(got)} unsupported; valid: '${want}'`);
  }
  const size = get(d, 'size', 'input');
  if (!Array.isArray(size) || size.length !== 2 || !size.every((s) => Number.isInteger(s) && s >= 16 && s <= 4096)) {
    throw new BundleError(`bundle.json: input.size = ${JSON.stringify(size)} invalid; valid: [H, W] integers in 16..4096`);
  }
  const triple = (key, positive) => {
    const v = get(d, key, 'input');
    if (!Array.isArray(v) || v.length !== 3) throw new BundleError(`bundle.json: input.${key} must be a list of 3 numbers (R, G, B)`);
    return v.map((x, i) => num(x, `input.${key}[${i}]`, 0, 1e6, { loOpen: positive }));
  };
  return { size, mean: triple('mean', false), std: triple('std', true) };
}

function parseCalibration(d) {
  const c = get(d, 'conformal', 'calibration');
  const u = get(d, 'uncertainty', 'calibration');
  const measure = get(u, 'measure', 'calibration.uncertainty');
  if (!UNCERTAINTY_MEASURES.includes(measure)) {
    throw new BundleError(`bundle.json: calibration.uncertainty.measure = ${JSON.stringify(measure)} unknown; valid: ${UNCERTAINTY_MEASURES.join(', ')}`);
  }
  if ((u.narrow_threshold == null) !== (u.narrow_fov_deg == null)) {
    throw new BundleError('bundle.json: calibration.uncertainty.narrow_threshold and narrow_fov_deg go together; set both or neither');
  }
  if (u.wide_fov_deg != null && u.narrow_fov_deg != null && !(u.wide_fov_deg > u.narrow_fov_deg)) {
    throw new BundleError(`bundle.json: calibration.uncertainty: wide_fov_deg ${u.wide_fov_deg} must exceed narrow_fov_deg ${u.narrow_fov_deg}`);
  }
  return {
    temperature: num(get(d, 'temperature', 'calibration'), 'calibration.temperature', 0, 100, { loOpen: true }),
    conformal: {
      coverage: num(get(c, 'coverage', 'calibration.conformal'), 'calibration.conformal.coverage', 0, 1, { loOpen: true, hiOpen: true }),
      threshold: num(get(c, 'threshold', 'calibration.conformal'), 'calibration.conformal.threshold', 0, 1),
      n_frames: int(get(c, 'n_frames', 'calibration.conformal'), 'calibration.conformal.n_frames', 0),
    },
    uncertainty: {
      measure,
      threshold: num(get(u, 'threshold', 'calibration.uncertainty'), 'calibration.uncertainty.threshold', 0, 1e6, { loOpen: true }),
      // optional: portrait frames' threshold (absent or null: portrait uses `threshold`)
      portrait_threshold: u.portrait_threshold == null ? null
        : num(u.portrait_threshold, 'calibration.uncertainty.portrait_threshold', 0, 1e6, { loOpen: true }),
      // optional, together: portrait frames at most narrow_fov_deg across (e.g. 9:16 video) use narrow_threshold
      narrow_threshold: u.narrow_threshold == null ? null
        : num(u.narrow_threshold, 'calibration.uncertainty.narrow_threshold', 0, 1e6, { loOpen: true }),
      narrow_fov_deg: u.narrow_fov_deg == null ? null
        : num(u.narrow_fov_deg, 'calibration.uncertainty.narrow_fov_deg', FOV_RANGE_DEG[0], FOV_RANGE_DEG[1]),
      // optional: the camera's width picks the threshold (frames under wide_fov_deg: portrait's)
      wide_fov_deg: u.wide_fov_deg == null ? null
        : num(u.wide_fov_deg, 'calibration.uncertainty.wide_fov_deg', FOV_RANGE_DEG[0], FOV_RANGE_DEG[1]),
    },
  };
}

/**
 * The geometry block (schema 2; schema 3 adds view_crop, schema 4 view_zoom), or schema 1's implied
 * one: fit 'stretch' and one field of view (fov_deg) for both orientations. Returns {fit, pad_rgb,
 * strips, camera_fov_deg: {landscape, portrait}, train_fov_deg, view_crop, sensor_aspect, view_zoom}.
 * view_crop (crop the frame's rows to the training camera's view, geometry.js viewRows) is read
 * only for a letterbox bundle of schema >= 3 (absent = false), as crossing_assist/bundle.py
 * reads it; train_fov_deg is optional (default: the landscape FOV) in (0, 180); sensor_aspect
 * (long / short side of the sensor camera_fov_deg describes, geometry.js defaultFov) is optional
 * in 1..3 (absent or null = null: every frame gets its orientation's FOV); view_zoom (frames from a
 * camera narrower than the training one shown magnified up to it, geometry.js viewRows) is read
 * only from schema >= 4, in 1..4, and needs view_crop (absent or null = 1).
 */
export function parseGeometry(meta, version, fovDeg) {
  if (version < 2) {
    return { fit: 'stretch', pad_rgb: null, strips: 'frame', camera_fov_deg: { landscape: fovDeg, portrait: fovDeg },
      train_fov_deg: fovDeg, view_crop: false, sensor_aspect: null, view_zoom: 1 };
  }
  const g = get(meta, 'geometry', '');
  const fit = get(g, 'fit', 'geometry');
  if (!FITS.includes(fit)) throw new BundleError(`bundle.json: geometry.fit = ${JSON.stringify(fit)} unknown; valid: ${FITS.join(', ')}`);
  let pad = null;
  if (fit === 'letterbox') {
    pad = get(g, 'pad_rgb', 'geometry');
    if (!Array.isArray(pad) || pad.length !== 3 || !pad.every((v) => Number.isInteger(v) && v >= 0 && v <= 255)) {
      throw new BundleError(`bundle.json: geometry.pad_rgb = ${JSON.stringify(pad)} invalid; valid: 3 integers in 0..255`);
    }
  }
  const strips = g.strips ?? 'frame';
  if (strips !== 'frame') throw new BundleError(`bundle.json: geometry.strips = ${JSON.stringify(strips)} unsupported; valid: 'frame'`);
  const fovs = get(g, 'camera_fov_deg', 'geometry');
  const [lo, hi] = FOV_RANGE_DEG;
  const camera = {};
  for (const o of ['landscape', 'portrait']) camera[o] = num(get(fovs, o, 'geometry.camera_fov_deg'), `geometry.camera_fov_deg.${o}`, lo, hi);
  const train = num(g.train_fov_deg === undefined ? camera.landscape : g.train_fov_deg, 'geometry.train_fov_deg', 0, 180,
    { loOpen: true, hiOpen: true });
  const crop = fit === 'letterbox' && version >= 3 && bool(g.view_crop === undefined ? false : g.view_crop, 'geometry.view_crop');
  const aspect = g.sensor_aspect == null ? null : num(g.sensor_aspect, 'geometry.sensor_aspect', 1, 3);
  let zoom = 1;
  if (version >= 4 && g.view_zoom != null) {
    zoom = num(g.view_zoom, 'geometry.view_zoom', 1, 4);
    if (zoom !== 1 && !crop) throw new BundleError(`bundle.json: geometry.view_zoom = ${JSON.stringify(g.view_zoom)} needs geometry.view_crop true`);
  }
  return { fit, pad_rgb: pad, strips, camera_fov_deg: camera, train_fov_deg: train, view_crop: crop, sensor_aspect: aspect,
    view_zoom: zoom };
}

/**
 * Validate a parsed bundle.json object; returns a normalised copy
 * ({schema_version, model_file, actions: {n, names, bins}, fov_deg, geometry, input, mc, calibration,
 * precision, model_sha256, model_size, raw}) or throws BundleError (one line).
 */
export function parseBundleMeta(meta) {
  const version = get(meta, 'schema_version', '');
  if (!Number.isInteger(version)) throw new BundleError(`bundle.json: schema_version = ${JSON.stringify(version)} must be an integer`);
  if (!SCHEMA_VERSIONS.includes(version)) {
    const fix = version > SCHEMA_VERSION ? 'update the app' : 're-export the bundle';
    throw new BundleError(`bundle.json: schema_version ${version} unsupported (this app reads ${SCHEMA_VERSIONS.join(', ')}); ${fix}`);
  }
  const modelFile = get(meta, 'model_file', '');
  if (typeof modelFile !== 'string' || !/^[^/\\]+\.onnx$/.test(modelFile) || modelFile.startsWith('.')) {
    throw new BundleError(`bundle.json: model_file = ${JSON.stringify(modelFile)} must be a plain file name ending in .onnx`);
  }
  const sha = get(meta, 'model_sha256', '');
  if (typeof sha !== 'string' || !/^[0-9a-f]{64}$/.test(sha)) {
    throw new BundleError(`bundle.json: model_sha256 = ${JSON.stringify(sha)} is not a lowercase hex SHA-256`);
  }
  const precision = get(meta, 'precision', '');
  if (!['fp32', 'int8'].includes(precision)) {
    throw new BundleError(`bundle.json: precision = ${JSON.stringify(precision)} unknown; valid: fp32, int8`);
  }
  const mc = get(meta, 'mc', '');
  const fovDeg = num(get(meta, 'fov_deg', ''), 'fov_deg', 0, 180, { loOpen: true, hiOpen: true });
  return {
    schema_version: version,
    model_file: modelFile,
    actions: parseActions(get(meta, 'actions', '')),
    fov_deg: fovDeg,
    geometry: parseGeometry(meta, version, fovDeg),
    input: parseInput(get(meta, 'input', '')),
    mc: { samples: int(get(mc, 'samples', 'mc'), 'mc.samples', 1, 1024), p: num(get(mc, 'p', 'mc'), 'mc.p', 0, 1, { hiOpen: true }) },
    calibration: parseCalibration(get(meta, 'calibration', '')),
    precision,
    model_sha256: sha,
    model_size: int(get(meta, 'model_size', ''), 'model_size', 64),
    raw: meta,
  };
}

// ----------------------------------------------------------------------------- bundle.json vs the graph

/** Non-finite numbers become null, recursively (bundle.py _strict: the exporter's copy is strict JSON). */
const strict = (v) => (typeof v === 'number' ? (Number.isFinite(v) ? v : null)
  : Array.isArray(v) ? v.map(strict)
    : v !== null && typeof v === 'object' ? Object.fromEntries(Object.entries(v).map(([k, x]) => [k, strict(x)])) : v);

const kind = (v) => (v === undefined ? 'absent' : v === null ? 'null' : Array.isArray(v) ? 'list'
  : typeof v === 'boolean' ? 'number' : typeof v); // Python: True == 1, 1 == 1.0
const own = (o, k) => (Object.hasOwn(o, k) ? o[k] : undefined);

/**
 * The first leaf (a's keys in order, then b's others; list items in order) where two JSON values
 * differ as Python's == sees them (1 == 1.0, true == 1, key order ignored): [path, a, b]
 * (undefined: absent), or null when equal. bundle.py _first_difference is the same walk.
 */
export function firstDifference(a, b, path = '') {
  const k = kind(a);
  if (k !== kind(b)) return [path, a, b];
  if (k === 'list') {
    for (let i = 0; i < Math.max(a.length, b.length); i += 1) {
      const d = firstDifference(a[i], b[i], `${path}[${i}]`);
      if (d) return d;
    }
    return null;
  }
  if (k === 'object') {
    for (const key of new Set([...Object.keys(a), ...Object.keys(b)])) {
      const d = firstDifference(own(a, key), own(b, key), path ? `${path}.${key}` : key);
      if (d) return d;
    }
    return null;
  }
  return (k === 'number' ? Number(a) === Number(b) : a === b) ? null : [path, a, b];
}

const show = (v) => {
  const s = v === undefined ? 'absent' : JSON.stringify(v);
  return s.length <= 60 ? s : `${s.slice(0, 57)}...`;
};

/**
 * Refuse a bundle.json (parsed, `raw`) that disagrees with the copy the exporter embedded in the
 * model's metadata (`bundle_json`) on any of EMBEDDED_KEYS, as bundle.py check_session does: a
 * hand-edited threshold, label list or field of view would guide the wrong way. Throws
 * BundleError naming the first differing leaf and both values.
 */
export function checkEmbedded(raw, modelBytes) {
  let props;
  try {
    props = onnxMetadata(modelBytes);
  } catch (err) {
    throw new BundleError(`bundle: ${raw.model_file} is not a valid ONNX model (${err.message}); re-export the bundle`);
  }
  if (!props.has('bundle_json')) throw new BundleError("bundle: the graph has no 'bundle_json' metadata; re-export the bundle");
  let graph = null;
  try {
    graph = JSON.parse(props.get('bundle_json'));
  } catch { /* refused below */ }
  if (kind(graph) !== 'object') throw new BundleError("bundle: the graph's 'bundle_json' metadata is not a JSON object; re-export the bundle");
  for (const key of EMBEDDED_KEYS) {
    const d = firstDifference(strict(own(raw, key)) ?? null, own(graph, key) ?? null, key); // absent = null, as dict.get
    if (d) throw new BundleError(`bundle.json: ${d[0]} = ${show(d[1])} disagrees with the model's ${show(d[2])}; re-export the bundle`);
  }
}

export { DEFAULT_FOV_DEG };

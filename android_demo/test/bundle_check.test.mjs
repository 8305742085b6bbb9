// bundle.json against the copy the exporter embedded in the model (bundle.js checkEmbedded,
// onnxmeta.js): the protobuf walk on hand-made, malformed and real model bytes, the comparison
// (Python's == on JSON values), and fetchBundle refusing a hand-edited bundle.

import assert from 'node:assert/strict';
import { existsSync, readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { test } from 'node:test';
import { fileURLToPath } from 'node:url';

import { BundleError, checkEmbedded, firstDifference } from '../www/js/bundle.js';
import { fetchBundle } from '../www/js/model.js';
import { OnnxFormatError, onnxMetadata } from '../www/js/onnxmeta.js';

const HERE = dirname(fileURLToPath(import.meta.url));
const DEFAULT = join(HERE, '..', '..', 'crossing_assist', 'assets', 'default_bundle');
const noDefault = existsSync(join(DEFAULT, 'model.onnx')) ? false : 'crossing_assist/assets/default_bundle is missing';

// A few protobuf writers for hand-made ModelProto bytes.
const varint = (n) => {
  const out = [];
  do {
    out.push((n % 128) + (n >= 128 ? 128 : 0));
    n = Math.floor(n / 128);
  } while (n > 0);
  return out;
};
const utf8 = (s) => [...new TextEncoder().encode(s)];
const field = (num, wire, payload) => [...varint(num * 8 + wire), ...(wire === 2 ? varint(payload.length) : []), ...payload];
const entry = (key, value, extra = []) => field(14, 2, [...field(1, 2, utf8(key)), ...extra, ...field(2, 2, utf8(value))]);
const model = (...parts) => new Uint8Array(parts.flat());

const DEFAULT_RAW = () => JSON.parse(readFileSync(join(DEFAULT, 'bundle.json'), 'utf8'));
// the shipped gate's thresholds (re-chosen now and then, so read, not written in)
const SHIPPED_GATE = () => DEFAULT_RAW().calibration.uncertainty;
const defaultBytes = () => new Uint8Array(readFileSync(join(DEFAULT, 'model.onnx')));

test('the walk finds metadata_props among every wire type and skips the graph', () => {
  const json = JSON.stringify({ a: 'x'.repeat(300) }); // a length over 127: a two-byte varint
  const bytes = model(
    field(1, 0, varint(10)), // ir_version
    field(2, 2, utf8('pytorch')),
    field(7, 2, [...entry('bundle_json', 'inside the graph: not metadata'), 0x10, 0x01]), // graph: skipped whole
    field(30, 1, [1, 2, 3, 4, 5, 6, 7, 8]), // fixed64
    field(31, 5, [1, 2, 3, 4]), // fixed32
    entry('bundle_json', json, field(3, 0, varint(2 ** 40))), // an unknown field inside the entry
    entry('schema_version', '3'),
    field(8, 2, field(2, 0, varint(17))), // opset_import, after the metadata
  );
  const props = onnxMetadata(bytes);
  assert.deepEqual([...props.keys()], ['bundle_json', 'schema_version']);
  assert.equal(props.get('bundle_json'), json);
  assert.equal(props.get('schema_version'), '3');
  assert.deepEqual([...onnxMetadata(bytes.buffer).keys()], ['bundle_json', 'schema_version']); // ArrayBuffer too
  assert.equal(onnxMetadata(model(field(1, 0, [8]))).size, 0);
});

test('malformed model bytes are refused with a clear error', () => {
  const good = model(field(1, 0, [8]), entry('bundle_json', '{}'));
  const cases = [
    [good.subarray(0, good.length - 3), /claims \d+ bytes, \d+ left/],
    [model([0x08, 0x80]), /truncated varint/],
    [model([0x08], Array(10).fill(0xff), [0x01]), /varint longer than 10 bytes/],
    [model([0x0b, 0x00]), /wire type 3/], // a group: not in ONNX
    [model([0x02, 0x00]), /field number 0/],
    [model(field(14, 0, [1])), /metadata_props is not a message/],
    [model(field(14, 2, field(2, 2, [0xc3, 0x28]))), /not UTF-8/],
    [model(field(9, 1, [1, 2, 3])), /truncated fixed-size field 9/],
  ];
  for (const [bytes, message] of cases) assert.throws(() => onnxMetadata(bytes), (e) => e instanceof OnnxFormatError && message.test(e.message));
  assert.throws(() => checkEmbedded({ model_file: 'model.onnx' }, model([0x08, 0x80])),
    (e) => e instanceof BundleError && /^bundle: model\.onnx is not a valid ONNX model \(truncated varint at byte 2\); re-export/.test(e.message));
});

test('the real default bundle: the walk reads its embedded copy in well under a few ms, and it agrees', { skip: noDefault }, () => {
  const bytes = defaultBytes();
  const raw = DEFAULT_RAW();
  const props = onnxMetadata(bytes);
  assert.equal(props.get('schema_version'), String(raw.schema_version));
  assert.equal(JSON.parse(props.get('bundle_json')).calibration.uncertainty.threshold, raw.calibration.uncertainty.threshold);
  const times = [];
  for (let i = 0; i < 20; i += 1) {
    const t = performance.now();
    checkEmbedded(raw, bytes);
    times.push(performance.now() - t);
  }
  times.sort((a, b) => a - b);
  assert.ok(times[10] < 20, `checkEmbedded took ${times[10].toFixed(2)} ms (median) on a ${bytes.length}-byte model`);
});

test('each hand edit of bundle.json is refused naming the leaf and both values', { skip: noDefault }, () => {
  const bytes = defaultBytes();
  const edits = [
    [(m) => { m.calibration.uncertainty.threshold = 0.05; }, `calibration.uncertainty.threshold = 0.05 disagrees with the model's ${JSON.stringify(SHIPPED_GATE().threshold)}`],
    [(m) => { m.calibration.conformal.threshold = 0.5; }, 'calibration.conformal.threshold = 0.5 disagrees with the model\'s 0.2644445300102234'],
    [(m) => { delete m.calibration.uncertainty.portrait_threshold; }, `calibration.uncertainty.portrait_threshold = absent disagrees with the model's ${JSON.stringify(SHIPPED_GATE().portrait_threshold)}`],
    [(m) => { m.actions.names[1] = 'left'; }, 'actions.names[1] = "left" disagrees with the model\'s "1"'],
    [(m) => { m.actions.bins.push([13]); }, 'actions.bins[13] = [13] disagrees with the model\'s absent'],
    [(m) => { m.fov_deg = 90; }, 'fov_deg = 90 disagrees with the model\'s 67'],
    [(m) => { m.geometry.camera_fov_deg.portrait = 60; }, 'geometry.camera_fov_deg.portrait = 60 disagrees with the model\'s 53'],
    [(m) => { m.geometry.view_zoom = 2; }, 'geometry.view_zoom = 2 disagrees with the model\'s absent'],
    [(m) => { m.input.mean[1] = 0.5; }, 'input.mean[1] = 0.5 disagrees with the model\'s 0.4980392156862745'],
    [(m) => { m.mc.samples = 8; }, 'mc.samples = 8 disagrees with the model\'s 16'],
    [(m) => { m.mc.mirror = true; }, 'mc.mirror = true disagrees with the model\'s absent'],
    [(m) => { m.precision = 'fp32'; }, 'precision = "fp32" disagrees with the model\'s "int8"'],
    [(m) => { m.schema_version = 4; }, 'schema_version = 4 disagrees with the model\'s 3'],
    [(m) => { delete m.geometry; }, 'geometry = null disagrees with the model\'s {"camera_fov_deg":{"landscape":67,"portrait":53},"fit":"l...'],
  ];
  for (const [edit, line] of edits) {
    const raw = DEFAULT_RAW();
    edit(raw);
    assert.throws(() => checkEmbedded(raw, bytes), (e) => e instanceof BundleError && e.message === `bundle.json: ${line}; re-export the bundle`, line);
  }
  // not compared (as in Python): the metrics, the provenance, the byte fields
  const raw = DEFAULT_RAW();
  Object.assign(raw, { metrics: {}, provenance: { edited: true }, model_sha256: '0'.repeat(64), package_version: 'x' });
  checkEmbedded(raw, bytes);
});

test('the comparison is Python\'s == on JSON values: 1 == 1.0, key order ignored, absent == null only at the top', { skip: noDefault }, () => {
  const bytes = defaultBytes();
  const text = readFileSync(join(DEFAULT, 'bundle.json'), 'utf8');
  assert.match(text, /"fov_deg": 67\.0/);
  checkEmbedded(JSON.parse(text.replace('"fov_deg": 67.0', '"fov_deg": 67').replace('"temperature": 1.0', '"temperature": 1')), bytes);
  const reordered = DEFAULT_RAW();
  reordered.calibration = Object.fromEntries(Object.entries(reordered.calibration).reverse());
  checkEmbedded(reordered, bytes);
  assert.equal(firstDifference({ a: 1, b: [2, { c: true }] }, { b: [2.0, { c: 1 }], a: 1.0 }), null);
  assert.deepEqual(firstDifference({ a: null }, {}, 'k'), ['k.a', null, undefined]); // {"a": None} != {}
  assert.deepEqual(firstDifference([1, '2'], [1, 2], 'k'), ['k[1]', '2', 2]);
  assert.deepEqual(firstDifference({ x: [1] }, { x: { 0: 1 } }, 'k'), ['k.x', [1], { 0: 1 }]);
  // a schema-1 bundle.json and its graph copy both without geometry: absent == absent
  const one = { schema_version: 1, model_file: 'm.onnx', fov_deg: 90 };
  const onnx = model(field(1, 0, [8]), entry('bundle_json', JSON.stringify({ schema_version: 1, fov_deg: 90.0, model_file: 'm.onnx' })));
  checkEmbedded(one, onnx);
  // non-finite numbers in bundle.json count as null, as bundle.py _strict makes them
  checkEmbedded({ ...one, mc: { p: Infinity } }, model(entry('bundle_json', JSON.stringify({ ...one, mc: { p: null } }))));
});

test('a model without the embedded copy, or with one that is not a JSON object, is refused as Python refuses it', () => {
  const meta = { schema_version: 1, model_file: 'model.onnx' };
  assert.throws(() => checkEmbedded(meta, model(field(1, 0, [8]), entry('schema_version', '1'))),
    { name: 'BundleError', message: "bundle: the graph has no 'bundle_json' metadata; re-export the bundle" });
  for (const bad of ['{not json', '[1, 2]', 'null']) {
    assert.throws(() => checkEmbedded(meta, model(entry('bundle_json', bad))),
      { name: 'BundleError', message: "bundle: the graph's 'bundle_json' metadata is not a JSON object; re-export the bundle" });
  }
});

test('fetchBundle (the app\'s load) refuses a bundle whose bundle.json was edited by hand, and takes it unedited', { skip: noDefault }, async () => {
  const files = { 'model.onnx': readFileSync(join(DEFAULT, 'model.onnx')) };
  const serve = async (url) => {
    const body = files[new URL(url).pathname.split('/').pop()];
    return body ? new Response(body) : new Response('', { status: 404 });
  };
  const saved = globalThis.fetch;
  globalThis.fetch = serve;
  try {
    files['bundle.json'] = readFileSync(join(DEFAULT, 'bundle.json'));
    const ok = await fetchBundle('http://phone.test/bundle/');
    assert.equal(ok.meta.calibration.uncertainty.threshold, SHIPPED_GATE().threshold);
    const edited = DEFAULT_RAW();
    edited.calibration.uncertainty.threshold = 0.05;
    files['bundle.json'] = JSON.stringify(edited);
    await assert.rejects(fetchBundle('http://phone.test/bundle/'), {
      name: 'BundleError',
      message: `bundle.json: calibration.uncertainty.threshold = 0.05 disagrees with the model's ${JSON.stringify(SHIPPED_GATE().threshold)}; re-export the bundle`,
    });
  } finally {
    globalThis.fetch = saved;
  }
});

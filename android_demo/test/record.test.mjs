// Node tests of record.js (the researchers' field recording, ?record=1) with a stand-in
// MediaRecorder: the log's clock, the length cap, and a stop that never hangs.

import assert from 'node:assert/strict';
import { test } from 'node:test';

import { FieldRecorder, imuCsv, IMU_HEADER } from '../www/js/record.js';

/** A MediaRecorder stand-in: start/stop fire their events as a browser does (stop: the last chunk, then 'stop'). */
class FakeRecorder extends EventTarget {
  static silent = false; // true: never fires 'stop' (a broken recorder)
  constructor(stream, options) {
    super();
    this.options = options;
    this.state = 'inactive';
    this.mimeType = 'video/webm';
  }
  static isTypeSupported(t) { return t === 'video/webm'; }
  start() {
    this.state = 'recording';
    setTimeout(() => this.dispatchEvent(new Event('start')), 1);
  }
  stop() {
    this.state = 'inactive';
    if (FakeRecorder.silent) return;
    setTimeout(() => {
      const e = new Event('dataavailable');
      e.data = new Blob(['last chunk']);
      this.dispatchEvent(e);
      this.dispatchEvent(new Event('stop'));
    }, 5);
  }
}

const sleep = (ms) => new Promise((r) => { setTimeout(r, ms); });

test('the log is on the recording clock, from its start event, and ends when it stops', async () => {
  globalThis.MediaRecorder = FakeRecorder;
  FakeRecorder.silent = false;
  let now = 10;
  const rec = new FieldRecorder({}, () => now);
  now = 10.25;
  await sleep(5); // the start event: t = 0 from here
  rec.motion(10.5, 30, null);
  rec.motion(10.51, 31, 4.5);
  const done = await rec.stop();
  rec.motion(10.6, 99, 0); // after the stop: not recorded
  assert.equal(done.csv, `${IMU_HEADER}\n0.25,30,\n0.26,31,4.5\n`);
  assert.equal(done.samples, 2);
  assert.equal(done.capped, false);
  assert.equal(await done.video.text(), 'last chunk');
  assert.equal(done.extension, 'webm');
});

test('a recording left running stops at the cap, and says so', async () => {
  globalThis.MediaRecorder = FakeRecorder;
  FakeRecorder.silent = false;
  const t0 = performance.now() / 1000;
  const rec = new FieldRecorder({}, () => performance.now() / 1000 - t0, { maxSeconds: 0.05 });
  await sleep(120);
  rec.motion(1.0, 5, 0); // after the cap: not recorded
  const done = await rec.stop();
  assert.equal(done.capped, true);
  assert.equal(done.samples, 0);
  assert.ok(done.seconds >= 0.04 && done.seconds < 0.1, `${done.seconds}`);
});

test('ending never hangs on a recorder that never says it stopped', async () => {
  globalThis.MediaRecorder = FakeRecorder;
  FakeRecorder.silent = true;
  const rec = new FieldRecorder({}, () => 0);
  const t = performance.now();
  const done = await rec.stop();
  assert.ok(performance.now() - t < 3000);
  assert.equal(done.video.size, 0);
  FakeRecorder.silent = false;
});

test('imuCsv keeps time order and drops rows that are not numbers', () => {
  assert.equal(imuCsv([[0, 1, null], [0, 2, null], [0.1, NaN, 1], [0.2, 3, 2]]), `${IMU_HEADER}\n0,1,\n0.2,3,2\n`);
});

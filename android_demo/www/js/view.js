// What the screen shows: a big status line for the user (a polite screen-reader live region
// that changes only when speech.js announces a change of advice) and the helper view for a
// sighted companion: the camera with its 12 strips, the probability of each strip, the
// decision, heading, uncertainty against the gate threshold the frame took, the audio levels, speed.

import { N_BINS } from './actions.js';
import { measureValue } from './logic.js';

/** Stop sentences by reason: the Decider's (uncertain, stale, failed) and the app's own. */
export const STATUS_STOP = Object.freeze({
  uncertain: 'Stop. Not sure: scan slowly.',
  stale: 'Stop. Camera stalled.',
  slow: 'Stop. The phone is too slow to guide.',
  failed: 'Stop. The model failed.',
  audio: 'Audio stopped. Tap to resume.',
  background: 'Stop. The app is in the background.',
  fov: 'Stop. The camera field of view setting is invalid.',
  tilt_down: 'Stop. The phone points at the ground: raise it.',
  tilt_up: 'Stop. The phone points too high: lower it.',
  rolled: 'Stop. The phone is turned sideways: hold it level.',
  sideways: 'Stop. Not sure: hold the phone sideways, it guides better.',
});
export const STRAIGHT_DEG = 7.5;
export const SLIGHT_DEG = 22.5;

/**
 * The one sentence shown and spoken for a decision ({stop, reason, heading_deg}) and its
 * style: [text, 'stop' | 'go']. Pure; the same as status_message in Python (runtime/status.py;
 * the shared test vectors' `status` section).
 */
export function statusMessage(d) {
  if (d.stop || d.heading_deg === null || d.heading_deg === undefined) return [STATUS_STOP[d.reason] || STATUS_STOP.uncertain, 'stop'];
  const h = d.heading_deg;
  const side = h < 0 ? 'left' : 'right';
  if (Math.abs(h) < STRAIGHT_DEG) return ['Go straight ahead.', 'go'];
  if (Math.abs(h) < SLIGHT_DEG) return [`Bear slightly ${side}.`, 'go'];
  return [`Turn ${side}.`, 'go'];
}

/** The bundle's model: its backbone, or "ensemble of K × backbone" for an ensemble bundle (training.ensemble). */
export function modelName(training) {
  const t = training || {};
  if (Array.isArray(t.ensemble)) return `ensemble of ${t.ensemble.length} × ${t.ensemble[0]?.backbone || 'unknown backbone'}`;
  return t.backbone || 'unknown backbone';
}

/** One line naming the bundle: its model's SHA-256 (first 12 hex digits) and date, and its facts. */
export function bundleSummary(meta) {
  const created = meta.raw.provenance?.created || 'date unknown';
  return `model ${meta.model_sha256.slice(0, 12)}, ${created}; schema ${meta.schema_version}, ${meta.actions.n} actions, `
    + `${meta.input.size.join('×')} canvas (${meta.geometry.fit}), T=${meta.mc.samples}, ${meta.precision}, `
    + `${modelName(meta.raw.training)}; gate: ${meta.calibration.uncertainty.measure} ≤ `
    + `${fmt(meta.calibration.uncertainty.threshold)}`;
}

const fmt = (v, digits = 2) => (v === null || v === undefined || !Number.isFinite(v) ? '–' : v.toFixed(digits));

export class HelperView {
  constructor(doc) {
    this.el = (id) => doc.getElementById(id);
    this.lastStatus = null;
    const strips = this.el('strips');
    const grid = this.el('grid');
    this.bars = [];
    this.cells = [];
    for (let k = 0; k <= N_BINS; k += 1) {
      const bar = doc.createElement('div');
      if (k === 0) bar.className = 'unknown';
      strips.appendChild(bar);
      this.bars.push(bar);
      if (k > 0) {
        const cell = doc.createElement('div');
        grid.appendChild(cell);
        this.cells.push(cell);
      }
    }
    this.meta = null;
  }

  status(text, cls) {
    if (text === this.lastStatus) return;
    this.lastStatus = text;
    const s = this.el('status');
    s.textContent = text;
    s.className = `status ${cls || ''}`;
  }

  bundle(meta) {
    this.meta = meta;
    this.el('bundle').textContent = bundleSummary(meta);
  }

  backend(model) {
    this.el('backend').textContent = model.backend === 'wasm'
      ? `onnxruntime-web, WASM SIMD, ${model.threads} thread${model.threads === 1 ? '' : 's'}`
      : `onnxruntime-web, ${model.backend}`;
  }

  /** Which field of view the headings use now, and where it came from. */
  camera(text) {
    this.el('camera').textContent = text;
  }

  /** Back to "nothing known": no strip highlighted, no heading (after stopping). */
  clear() {
    this.cells.forEach((cell) => cell.classList.remove('on'));
    this.bars.forEach((bar) => bar.classList.remove('on'));
    for (const id of ['decision', 'heading', 'beacon', 'uncertainty']) this.el(id).textContent = '–';
  }

  /**
   * Offer a field recording (record.js) as two downloads, `NAME.webm` (or .mp4) and `NAME.imu.csv`:
   * the names crossing-demo's --imu expects side by side. A new one replaces the last.
   */
  recording(rec, name) {
    const p = this.el('recording');
    (this.recordingUrls || []).forEach((u) => URL.revokeObjectURL(u));
    const link = (blob, file, text) => {
      const a = p.ownerDocument.createElement('a');
      a.href = URL.createObjectURL(blob);
      a.download = file;
      a.textContent = text;
      return a;
    };
    const video = link(rec.video, `${name}.${rec.extension}`, `the video (${name}.${rec.extension})`);
    const log = link(new Blob([rec.csv], { type: 'text/csv' }), `${name}.imu.csv`, `the motion log (${name}.imu.csv)`);
    this.recordingUrls = [video.href, log.href];
    p.replaceChildren(`Recorded ${rec.seconds.toFixed(1)} s${rec.capped ? ' (the longest a recording can be: it stopped there)' : ''}, `
      + `${rec.samples} gyroscope samples. Download `, video, ' and ', log, rec.samples ? '.' : ' (empty: no gyroscope reported).');
    p.hidden = false;
  }

  offline(text) {
    this.el('offline').textContent = text;
  }

  /**
   * Show one frame's model outputs: probability per strip (an action's mass on each of its bins),
   * and its uncertainty against `threshold`, the gate threshold this frame took (its orientation
   * and camera's: gateThreshold).
   */
  outputs(out, meta, threshold) {
    const groups = meta.actions.bins;
    const perBin = new Array(N_BINS + 1).fill(0);
    perBin[0] = out.probs[0];
    groups.forEach((g, a) => g.forEach((k) => { perBin[k] = out.probs[a]; }));
    let best = 0;
    out.probs.forEach((p, a) => { if (p > out.probs[best]) best = a; });
    this.bars.forEach((bar, k) => {
      bar.style.height = `${Math.max(2, 100 * perBin[k])}%`;
      bar.classList.toggle('on', k > 0 && groups[best].includes(k));
    });
    const label = Array.from(perBin, (p, k) => `${k === 0 ? 'unknown' : k} ${Math.round(100 * p)}%`).join(', ');
    this.el('strips').setAttribute('aria-label', `Goal probability per strip: ${label}`);
    const measure = meta.calibration.uncertainty.measure;
    const u = measureValue(measure, out.entropy, out.mutual_info, out.variance, out.probs);
    this.el('uncertainty').textContent = `${measure} ${fmt(u)} (threshold ${fmt(threshold)}), `
      + `mutual info ${fmt(out.mutual_info, 3)}, top ${meta.actions.names[best]} ${Math.round(100 * out.probs[best])}%`;
  }

  /** Show a decision in the helper view (the status line is speech.js's: it has hysteresis). */
  decision(d) {
    this.el('decision').textContent = `${d.gate} (${d.reason})${d.stop ? ' — stop cue' : ''}`;
    this.el('heading').textContent = d.heading_deg === null ? '–' : `${fmt(d.heading_deg, 1)}° (pan ${fmt(d.pan)})`;
    this.el('beacon').textContent = d.stop ? 'stop / scan cue' : `${fmt(d.rate_hz, 1)} pulses/s`;
    const x = d.heading_deg === null ? null : d.learner_action;
    this.cells.forEach((cell, i) => cell.classList.toggle('on', x !== null && this.meta?.actions.bins[x]?.includes(i + 1)));
  }

  levels([l, r]) {
    this.el('levelL').value = l;
    this.el('levelR').value = r;
  }

  /** The turn rate the Decider is told (deg/s, + = right) and where it comes from; null: not followed. */
  turning(rateDps, source = 'gyroscope') {
    const side = rateDps >= 0 ? 'right' : 'left';
    this.el('turning').textContent = rateDps === null ? 'not followed (gyroscope and camera picture off)'
      : `${fmt(Math.abs(rateDps), 0)}°/s ${side} (${source})`;
  }

  /** What the tilt sensor says now (levelling, roll limit): one line for the helper. */
  tilt(text) {
    this.el('tilt').textContent = text;
  }

  /**
   * Frames per second, model ms per frame and the duty cycle (share of the time spent in the
   * model); when the last frames' time `recentMs` is over `limitMs` (the watchdog period), a
   * frame's decision comes too late to play, which the helper is told, with the fix.
   */
  speed(fps, ms, duty, limitMs = Infinity, recentMs = ms) {
    const slow = recentMs > limitMs
      ? ` — too slow for this phone: decisions come after ${fmt(limitMs, 0)} ms, so it says stop; build the app with fewer ensemble members`
      : '';
    this.el('speed').textContent = `${fmt(fps, 1)} frames/s, model ${fmt(ms, 0)} ms/frame, duty ${fmt(100 * duty, 0)}%${slow}`;
  }
}

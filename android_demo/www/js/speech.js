// What the app says (speechSynthesis, for users without a screen reader) and writes into the
// polite status live region (for users with one): one sentence per change of advice, with
// hysteresis and a rate limit so that a heading hovering at a boundary does not chatter.
//
// SpeechPolicy (pure, the clock is passed in) decides WHEN a sentence is announced:
// * directions fall in five bands of |heading| (statusMessage: < 7.5 deg straight ahead,
//   < 22.5 bear slightly, else turn); the band announced last is kept while the heading stays
//   within its edges widened by `margin_deg`;
// * a new direction is announced once it has held for `hold_s` and at least `min_gap_s` after
//   the previous announcement;
// * a stop is announced at once when guidance was going (safety first); a change between stop
//   reasons waits for `min_gap_s`; `force` announces now (audio lost, app in the background).
// Speaker sends the sentences to speechSynthesis (cancelling one still being spoken), except
// that an urgent sentence (how to recover: the camera lost, ...) is heard whole: a routine
// sentence that comes while it is spoken waits for its end (the latest such sentence only).

import { SLIGHT_DEG, statusMessage, STRAIGHT_DEG } from './view.js';

export const SPEECH = Object.freeze({ hold_s: 1.0, margin_deg: 2.5, min_gap_s: 2.0 });
const EDGES = [-Infinity, -SLIGHT_DEG, -STRAIGHT_DEG, STRAIGHT_DEG, SLIGHT_DEG, Infinity];
const REPRESENTATIVE = [-45, -15, 0, 15, 45]; // a heading inside each band

/** Band of a heading: 0 turn left, 1 bear slightly left, 2 straight, 3 slightly right, 4 turn right. */
export function band(headingDeg) {
  if (headingDeg <= -SLIGHT_DEG) return 0;
  if (headingDeg <= -STRAIGHT_DEG) return 1;
  if (headingDeg < STRAIGHT_DEG) return 2;
  if (headingDeg < SLIGHT_DEG) return 3;
  return 4;
}

/** The band to announce: `current` while the heading is within its edges +- margin, else the heading's own band. */
export function stickyBand(headingDeg, current, marginDeg) {
  if (current !== null && headingDeg >= EDGES[current] - marginDeg && headingDeg <= EDGES[current + 1] + marginDeg) return current;
  return band(headingDeg);
}

export class SpeechPolicy {
  constructor(cfg = {}) {
    this.cfg = { ...SPEECH, ...cfg };
    this.reset();
  }

  reset() {
    this.shown = null; // key of the last announcement: 'go:<band>' or 'stop:<reason>'
    this.candidate = null;
    this.since = 0;
    this.lastT = -Infinity;
    this.count = 0;
  }

  /** A decision ({stop, reason, heading_deg}) at time t (s): the [text, cls] to announce now, or null. */
  step(t, d) {
    let key;
    let msg;
    if (d.stop || d.heading_deg === null) {
      key = `stop:${d.reason}`;
      msg = statusMessage({ stop: true, reason: d.reason });
    } else {
      const current = this.shown?.startsWith('go:') ? Number(this.shown.slice(3)) : null;
      const b = stickyBand(d.heading_deg, current, this.cfg.margin_deg);
      key = `go:${b}`;
      msg = statusMessage({ stop: false, heading_deg: REPRESENTATIVE[b] });
    }
    if (key !== this.candidate) {
      this.candidate = key;
      this.since = t;
    }
    if (key === this.shown) return null;
    const gapOk = t - this.lastT >= this.cfg.min_gap_s;
    const ready = key.startsWith('stop:')
      ? this.shown === null || this.shown.startsWith('go:') || gapOk
      : t - this.since >= this.cfg.hold_s && gapOk;
    if (!ready) return null;
    return this.announce(t, key, msg);
  }

  /** Announce a stop reason now, whatever the rate limit (audio lost, background, FOV refused). */
  force(t, reason) {
    const key = `stop:${reason}`;
    this.candidate = key;
    this.since = t;
    if (key === this.shown) return null;
    return this.announce(t, key, statusMessage({ stop: true, reason }));
  }

  announce(t, key, msg) {
    this.shown = key;
    this.lastT = t;
    this.count += 1;
    return msg;
  }
}

/** The longest an urgent sentence holds routine ones back (ms), in case its end event never comes. */
export const urgentHoldMs = (text) => 1000 + 80 * text.length; // ~12 characters a second, and a margin

/** speechSynthesis, when the browser has it and the user wants it. */
export class Speaker {
  constructor(enabled = true, clock = () => performance.now()) {
    this.enabled = enabled;
    this.synth = globalThis.speechSynthesis || null;
    this.clock = clock;
    this.urgent = null; // the urgent utterance being spoken
    this.urgentUntil = -Infinity; // ... at the latest until then (clock ms)
    this.waiting = null; // a routine sentence said after it
    this.timer = null;
  }

  /** Speak `text` now, cutting what is being said; with `urgent`, routine sentences cannot cut it. */
  say(text, { urgent = false } = {}) {
    if (!this.enabled || !this.synth || typeof SpeechSynthesisUtterance === 'undefined') return false;
    const t = this.clock();
    if (!urgent && this.urgent && t < this.urgentUntil) {
      this.waiting = text;
      clearTimeout(this.timer);
      this.timer = setTimeout(() => this.release(this.urgent), this.urgentUntil - t);
      return true;
    }
    clearTimeout(this.timer);
    this.urgent = null;
    this.waiting = null;
    this.synth.cancel();
    const u = new SpeechSynthesisUtterance(text);
    u.lang = 'en';
    u.rate = 1.1;
    if (urgent) {
      this.urgent = u;
      this.urgentUntil = t + urgentHoldMs(text);
      for (const ev of ['end', 'error']) u.addEventListener(ev, () => this.release(u));
    }
    this.synth.speak(u);
    return true;
  }

  /** The urgent utterance `u` is over: say the routine sentence that waited for it, if any. */
  release(u) {
    if (this.urgent !== u || !u) return;
    this.urgent = null;
    clearTimeout(this.timer);
    const text = this.waiting;
    this.waiting = null;
    if (text !== null) this.say(text);
  }

  cancel() {
    clearTimeout(this.timer);
    this.urgent = null;
    this.waiting = null;
    this.synth?.cancel();
  }
}

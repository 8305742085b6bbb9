// Vibration (navigator.vibrate), for everyone and especially without headphones:
// * each stop reason has its own pattern, played when the reason changes (not only when the
//   cue switches from beacon to stop), so "not sure" and "camera stalled" feel different;
// * with "Vibrate the direction" on, a direction code each time the announced direction
//   changes and every `repeat_s` while guidance goes on: left = one short, ahead = one long,
//   right = two short.
// Patterns are in milliseconds (vibrate, pause, vibrate, ...).

export const STOP_PATTERNS = Object.freeze({
  uncertain: [200, 100, 200],
  stale: [600],
  slow: [600, 150, 100], // the model answered too late (long, short)
  failed: [100, 60, 100, 60, 100],
  audio: [400, 150, 400, 150, 400],
  background: [80, 80, 80],
  fov: [100, 60, 600],
  tilt_down: [400, 100, 80], // the phone points at the ground (long, short)
  tilt_up: [80, 100, 400], // the phone points too high (short, long)
  rolled: [400, 100, 400], // the phone is turned sideways (long, long)
  sideways: [80, 100, 80, 100, 400], // hold the phone sideways (short, short, long)
});
export const DIRECTION_PATTERNS = Object.freeze({ left: [120], ahead: [450], right: [120, 150, 120] });
export const DIRECTION_REPEAT_S = 3.0;

/** Direction code of a heading (degrees, negative = left): ahead within +-7.5 deg. */
export function directionCode(headingDeg) {
  if (Math.abs(headingDeg) < 7.5) return 'ahead';
  return headingDeg < 0 ? 'left' : 'right';
}

export class Haptics {
  constructor({ directions = false, vibrate = (p) => globalThis.navigator?.vibrate?.(p) } = {}) {
    this.directions = directions;
    this.vibrate = vibrate;
    this.reset();
  }

  reset() {
    this.lastReason = null;
    this.lastCode = null;
    this.lastCodeT = -Infinity;
  }

  /** A stop for `reason` at time t: its pattern when the reason changed; returns the pattern or null. */
  stop(reason) {
    this.lastCode = null;
    if (reason === this.lastReason) return null;
    this.lastReason = reason;
    const p = STOP_PATTERNS[reason] || STOP_PATTERNS.uncertain;
    this.vibrate(p);
    return p;
  }

  /** Guidance towards headingDeg at time t: the direction code when it changed or is due again (if on). */
  go(t, headingDeg) {
    this.lastReason = null;
    if (!this.directions) return null;
    const code = directionCode(headingDeg);
    if (code === this.lastCode && t - this.lastCodeT < DIRECTION_REPEAT_S) return null;
    this.lastCode = code;
    this.lastCodeT = t;
    this.vibrate(DIRECTION_PATTERNS[code]);
    return DIRECTION_PATTERNS[code];
  }
}

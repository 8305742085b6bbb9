// The live loop's guards, ported from crossing_assist/runtime/live.py and watchdog.py (pure:
// the clock is passed in, so Node tests can freeze time):
//
// * frozen camera: a frame identical to the previous one (compared on every 7th row and
//   column, as live._same does) is not fresh: it is skipped and does not feed the Decider;
// * freshness: a decision counts only if it is made within watchdog_s of its frame's capture
//   (a slow model makes stale decisions, and a stale direction is worse than silence);
// * watchdog: when no fresh decision arrived for more than watchdog_s, the beacon stops and
//   the stop/scan cue plays, independently of the Decider (defence in depth).

export const WATCHDOG_S = 0.5; // live.LiveConfig.watchdog_s
export const FROZEN_STRIDE = 7;

/**
 * True when two frames are the same size and equal on every 7th row and column (all three
 * channels): live._same(a, b) with a[::7, ::7]. Frames: {rgb: Uint8Array(h * w * 3), width, height}.
 */
export function sameFrame(prev, cur) {
  if (!prev || prev.width !== cur.width || prev.height !== cur.height) return false;
  const { width: w, height: h } = cur;
  for (let y = 0; y < h; y += FROZEN_STRIDE) {
    for (let x = 0; x < w; x += FROZEN_STRIDE) {
      const i = (y * w + x) * 3;
      if (prev.rgb[i] !== cur.rgb[i] || prev.rgb[i + 1] !== cur.rgb[i + 1] || prev.rgb[i + 2] !== cur.rgb[i + 2]) return false;
    }
  }
  return true;
}

/** Whether a decision made at `now` from a frame captured at `captured` (seconds) is fresh. */
export function isFresh(now, captured, watchdogS = WATCHDOG_S) {
  return now - captured <= watchdogS;
}

/** Fires once each time `now - lastBeat > periodS` becomes true (watchdog.Watchdog). */
export class Watchdog {
  constructor(periodS, now) {
    if (!(periodS > 0)) throw new RangeError(`Invalid watchdog period: ${periodS}; valid: > 0 seconds`);
    this.periodS = periodS;
    this.last = now;
    this.stale = false;
    this.fired = 0;
  }

  /** A fresh decision, made from a frame captured at time t. */
  beat(t) {
    this.last = t;
    this.stale = false;
  }

  age(now) {
    return now - this.last;
  }

  /** Check at `now`; returns {stale, fired} where fired is true on the transition to stale only. */
  poll(now) {
    if (this.age(now) > this.periodS) {
      const fired = !this.stale;
      if (fired) {
        this.stale = true;
        this.fired += 1;
      }
      return { stale: true, fired };
    }
    return { stale: false, fired: false };
  }
}

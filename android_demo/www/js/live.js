// The live loop's guards, ported from crossing_assist/runtime/live.py and watchdog.py (pure:
// the clock is passed in, so Node tests can freeze time):
//
// * frozen camera: a frame identical to the previous one (same size, every byte equal: the
//   rule of live.same_frame) is not fresh: it is skipped and does not feed the Decider;
// * freshness: a decision counts only if it is made within watchdog_s of its frame's capture
//   (a slow model makes stale decisions, and a stale direction is worse than silence);
// * watchdog: when no fresh decision arrived for more than watchdog_s, the beacon stops and
//   the stop/scan cue plays, independently of the Decider (defence in depth).

export const WATCHDOG_S = 0.5; // live.LiveConfig.watchdog_s

/**
 * The frozen-frame rule, live.same_frame's: true when both frames have the same width and
 * height and every byte of their RGB is equal (a live sensor's noise changes some pixel of
 * every real frame). Frames: {rgb: Uint8Array(h * w * 3), width, height}; compared 4 bytes at a
 * time where the buffers allow (a 640 x 480 frame: well under a millisecond).
 */
export function sameFrame(prev, cur) {
  if (!prev || prev.width !== cur.width || prev.height !== cur.height) return false;
  const a = prev.rgb;
  const b = cur.rgb;
  if (a.length !== b.length) return false;
  const n4 = a.length >> 2;
  let i = 0;
  if (a.byteOffset % 4 === 0 && b.byteOffset % 4 === 0) {
    const a32 = new Uint32Array(a.buffer, a.byteOffset, n4);
    const b32 = new Uint32Array(b.buffer, b.byteOffset, n4);
    for (let k = 0; k < n4; k += 1) if (a32[k] !== b32[k]) return false;
    i = n4 << 2;
  }
  for (; i < a.length; i += 1) if (a[i] !== b[i]) return false;
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

/**
 * The user's turn rate (degrees per second, positive = turning right, the Decider's
 * yaw_rate_dps) from DeviceMotionEvent.rotationRate (deg/s around the device axes: alpha about
 * z out of the screen, beta about x to the screen's right, gamma about y up the screen;
 * right-handed). The phone is held upright, screen towards the user, so the world's vertical
 * is the device's y axis in portrait (screen angle 0), -y upside down (180), +x when the
 * device is turned a quarter counter-clockwise (90) and -x a quarter clockwise (270). Turning
 * right is a negative rotation about the upward axis. Null rates give 0.
 */
export function yawRateFromRotation(rotationRate, screenAngleDeg = 0) {
  const beta = rotationRate?.beta ?? 0;
  const gamma = rotationRate?.gamma ?? 0;
  const up = [['gamma', 1], ['beta', 1], ['gamma', -1], ['beta', -1]][((Math.round(screenAngleDeg / 90) % 4) + 4) % 4];
  return -up[1] * (up[0] === 'beta' ? beta : gamma) + 0; // + 0: no -0
}

/**
 * Integrates gyroscope samples into the turn made between two camera frames' capture times, so
 * that the Decider's psi = yaw_rate_dps * dt is the angle turned between the frame before and
 * this one, however the sensor's rate and the frame rate compare, and however long the model took
 * over the frame. Each sample's rate covers the time since the sample before (at most
 * MAX_SAMPLE_GAP_S: a longer gap is a paused sensor). Taken at the decision instead (after the
 * model run, ~0.15 s after capture in a browser), the turn ran ahead of the frame it was paired
 * with: on PTL val photos scanned at 30 deg/s, pairing each frame with the next one's turn (0.1 s
 * ahead) left 1.70 % of the goal-in-view frames confidently wrong against 0.40 % aligned
 * (docs/android.md, "The gyroscope's turn between captures").
 */
export const MAX_SAMPLE_GAP_S = 0.2;
const KEEP_S = 3; // samples kept: longer than any pair of frames the watchdog lets through

export class YawIntegrator {
  constructor() {
    this.samples = []; // [t (s, the frames' clock), rate (deg/s)], in time order
  }

  /** A sample: turn rate (deg/s, + right) at time t (s, the clock of the frames' capture times). */
  add(rateDps, t) {
    const last = this.samples.at(-1);
    if (!Number.isFinite(rateDps) || !Number.isFinite(t) || (last && !(t > last[0]))) return;
    this.samples.push([t, rateDps]);
    while (this.samples.length > 2 && this.samples[1][0] < t - KEEP_S) this.samples.shift();
  }

  /** Whether a sample came within MAX_SAMPLE_GAP_S before time t (a sensor still reporting). */
  reporting(t) {
    const last = this.samples.at(-1);
    return Boolean(last) && t - last[0] <= MAX_SAMPLE_GAP_S;
  }

  /** Mean turn rate (deg/s) over [t0, t1] (0 when t1 <= t0; a stretch no sample covers adds nothing). */
  between(t0, t1) {
    if (!(t1 > t0)) return 0;
    let angle = 0;
    // newest first: a sample at or before t0 covers nothing after it (called at every gyroscope
    // sample while a decision plays, so only the samples since its capture are visited)
    for (let i = this.samples.length - 1; i >= 1 && this.samples[i][0] > t0; i -= 1) {
      const [t, rate] = this.samples[i];
      const from = Math.max(this.samples[i - 1][0], t - MAX_SAMPLE_GAP_S);
      const overlap = Math.min(t, t1) - Math.max(from, t0);
      if (overlap > 0) angle += rate * overlap;
    }
    return angle / (t1 - t0);
  }
}

/**
 * The gyroscope checked against the camera picture. Its sign on a given phone rests on the W3C
 * axes and yawRateFromRotation's reading of the screen angle, which a browser or a phone may
 * break; a gyroscope that reads turns the wrong way moves the beacon away from the crossing as
 * the user turns toward it. So while both are on, every frame's turn from the gyroscope is
 * compared with the turn read from the picture (visualyaw.js).
 * Clear turns (a user scanning): only frames where both read |rate| >= `turn_dps` are voted on:
 * the same way confirms, the other way contradicts. A turn in the picture alone proves nothing (a
 * bus crossing a still phone's view, or a bar moving in the test clip, reads as a turn), nor does
 * a turn of the gyroscope alone (a blank wall). Of the last `window` voted frames, once at least
 * `least` were seen, `contradicted` or more contradicting makes the verdict 'wrong' for good (this
 * guidance): the gyroscope is no longer followed.
 * A walker's sway (its fastest turn ~14 deg/s) never reads that clear, so a walk begun facing the
 * crossing would never confirm the gyroscope. The sway confirms it too (never condemns it) once the
 * last `sway_window` frames on which either read a turn of `sway_dps` or more (the picture reading
 * one, both under `sway_max_dps`) agree in size: the cosine of the two rate series at least
 * `agree_cos`, the picture's turn within `agree_scale` times the gyroscope's either way (least
 * squares). The sway is compared with the gyroscope's turn over the frame's interval moved back by
 * each of `sway_lags_s` too (a window each; one agreeing confirms): a frame stamped 0.1 s late (a
 * browser without a capture time) already turns a 0.9 Hz sway's cosine to 0.84. Clear turns must
 * agree in size too: sign votes alone confirmed a gyroscope reading another axis. Python's runtime/gyro.py has the same rule and says why; tests/test_android_logic.py
 * checks they agree.
 */
export const GYRO_WRONG_TEXT = 'The gyroscope reads turns the wrong way: turns are followed from the camera picture.';
export const GYRO_CHECK = Object.freeze({
  turn_dps: 15, window: 12, least: 8, contradicted: 0.75, sway_dps: 5, sway_max_dps: 30, sway_window: 16,
  sway_lags_s: Object.freeze([0, 0.1, 0.2]), agree_cos: 0.85, agree_scale: 1.5,
});

/** (gyroscope, picture) turn-rate pairs agreeing in size: cosine and least-squares scale (GYRO_CHECK). */
function agree(pairs, c) {
  let gp = 0;
  let gg = 0;
  let pp = 0;
  for (const [g, p] of pairs) {
    gp += g * p;
    gg += g * g;
    pp += p * p;
  }
  return gp >= c.agree_cos * Math.sqrt(gg * pp) && gg / c.agree_scale <= gp && gp <= gg * c.agree_scale;
}

export class GyroCheck {
  constructor(cfg = GYRO_CHECK) {
    this.cfg = cfg;
    this.turns = []; // the last clear turns voted on: [gyroscope, picture] rates
    this.sway = cfg.sway_lags_s.map(() => []); // the last frames of a sway's turns, alike: a window a lag
    this.swayed = false; // a window of the sway has agreed: confirmed until found 'wrong'
    this.verdict = 'unchecked'; // 'unchecked' | 'ok' | 'wrong'
  }

  /**
   * One frame's turn rates (deg/s, + right): the gyroscope's and the picture's; returns the verdict.
   * `lagged`: the gyroscope's mean rate over the frame's interval moved back by each of
   * `sway_lags_s` after the first (YawIntegrator.between); without it the sway is compared at no lag only.
   */
  add(gyroDps, cameraDps, lagged = []) {
    const c = this.cfg;
    if (this.verdict === 'wrong' || !(Number.isFinite(gyroDps) && Number.isFinite(cameraDps))) return this.verdict;
    if (!this.swayed) [gyroDps, ...lagged].slice(0, this.sway.length).forEach((g, k) => { // once swayed, done
      if (cameraDps !== 0 && Math.max(Math.abs(g), Math.abs(cameraDps)) >= c.sway_dps
          && Math.abs(g) < c.sway_max_dps && Math.abs(cameraDps) < c.sway_max_dps) { // NaN fails the comparisons
        this.sway[k].push([g, cameraDps]);
        if (this.sway[k].length > c.sway_window) this.sway[k].shift();
        this.swayed ||= this.sway[k].length >= c.sway_window && agree(this.sway[k], c);
      }
    });
    if (!(Math.abs(cameraDps) >= c.turn_dps && Math.abs(gyroDps) >= c.turn_dps)) return this.verdict;
    this.turns.push([gyroDps, cameraDps]);
    if (this.turns.length > c.window) this.turns.shift();
    if (this.turns.length >= c.least) this.verdict = this.against() >= c.contradicted * this.turns.length ? 'wrong' : 'ok';
    return this.verdict;
  }

  against() {
    return this.turns.filter(([g, p]) => g * p < 0).length;
  }

  /** The picture vouches for the gyroscope (confirmation()). Then the app follows the gyroscope
   * even when it was not turned on (app.js gyroFollowed). */
  confirmed() {
    return this.confirmation() !== null;
  }

  /**
   * How the picture vouches for the gyroscope: 'clear turns' ('ok', with as large a share of them
   * agreeing as `contradicted` is of them contradicting for 'wrong', agreeing in size too); else, not
   * found 'wrong', 'sway' once a full window of a sway's turns agreed in size at one of the lags (it
   * stays so: the windows slide with every step, and a gyroscope followed now and then would switch
   * the rule); else null.
   */
  confirmation() {
    const c = this.cfg;
    if (this.verdict === 'wrong') return null;
    if (this.verdict === 'ok' && this.turns.length - this.against() >= c.contradicted * this.turns.length
      && agree(this.turns, c)) return 'clear turns';
    return this.swayed ? 'sway' : null;
  }
}

/**
 * How the phone may be tilted before the far kerb leaves the rows the model is shown. The view
 * crop keeps the training camera's vertical view, centred. PTL's photographers pointed their
 * phones a few degrees below the horizon (their far kerbs sit just above the middle of the
 * photo); pointed 15 deg further down than they did, 94 % of their far kerbs stay in view, 20 deg
 * only 70 % (scripts/pitch_tolerance.py, docs/android.md). So below `down_deg` (about 15-20 deg
 * further down than they held theirs) or above `up_deg` of camera elevation, a stop for "not
 * sure" says which way to tilt (TiltWatch). Guidance itself is never changed by the tilt.
 */
export const TILT = Object.freeze({ down_deg: -25, up_deg: 20, margin_deg: 5, fresh_s: 1.0, roll_fresh_s: 0.5 });

/**
 * The back camera's elevation (degrees above the horizon; -90 straight down) from
 * DeviceOrientationEvent's beta and gamma (the W3C Z-X'-Y'' angles): the camera looks along the
 * device's -z axis, whose vertical component is -cos(beta) cos(gamma), whatever the screen's
 * orientation. Null without both angles.
 */
export function cameraElevationDeg(beta, gamma) {
  if (!Number.isFinite(beta) || !Number.isFinite(gamma)) return null;
  const r = Math.PI / 180;
  const s = Math.max(-1, Math.min(1, -Math.cos(beta * r) * Math.cos(gamma * r)));
  return Math.asin(s) / r + 0; // + 0: no -0
}

/**
 * How far the scene is rolled counter-clockwise in the camera's frame (degrees; the phone turned
 * clockwise about the camera's axis, as its user sees the screen), from DeviceOrientationEvent's
 * beta and gamma and the screen's angle (screen.orientation.angle: the frame is upright for the
 * screen). Gravity in device axes is (sin g cos b, -sin b, -cos g cos b) for the W3C Z-X'-Y''
 * angles (alpha turns about the vertical and so never rolls the frame); the frame's right and
 * down are the device's x and -y turned by the screen angle. Null without both angles, or when
 * the camera points within 30 deg of straight down or up (gravity nearly along its axis: no
 * horizon to level; TiltWatch asks to raise or lower the phone long before).
 */
export function cameraRollDeg(beta, gamma, screenAngleDeg = 0) {
  if (!Number.isFinite(beta) || !Number.isFinite(gamma)) return null;
  const r = Math.PI / 180;
  const gx = Math.sin(gamma * r) * Math.cos(beta * r);
  const gy = -Math.sin(beta * r);
  const a = (Number.isFinite(screenAngleDeg) ? screenAngleDeg : 0) * r;
  const right = gx * Math.cos(a) - gy * Math.sin(a);
  const down = -(gx * Math.sin(a) + gy * Math.cos(a));
  if (Math.hypot(right, down) < 0.5) return null;
  return Math.atan2(right, down) / r + 0; // + 0: no -0
}

/**
 * Follows the phone's tilt (DeviceOrientationEvent samples) and names the stop reason it gives:
 * 'tilt_down' below cfg.down_deg of camera elevation, 'tilt_up' above cfg.up_deg, kept until
 * the camera comes back cfg.margin_deg inside the limit (a phone hovering at a limit does not
 * switch reasons, and so buzz, on every sample); null when held well enough, or when no sample
 * is fresher than cfg.fresh_s (the sensor stopped: no advice rather than stale advice).
 * The roll for levelling is held to a tighter cfg.roll_fresh_s: an older reading is no roll
 * known (rollDeg null: the frame is not turned, nor stopped for being rolled too far), since a
 * phone turned since then would be levelled by the wrong angle.
 */
export class TiltWatch {
  constructor(cfg = TILT) {
    this.cfg = { ...TILT, ...cfg };
    this.state = null;
    this.lastT = null;
    this.roll = null; // the camera's roll at the last sample (cameraRollDeg), for levelling
  }

  /** A sample at time t (s) with the screen at screenAngleDeg; samples without both angles are ignored. */
  add(beta, gamma, t, screenAngleDeg = 0) {
    const e = cameraElevationDeg(beta, gamma);
    if (e === null) return;
    this.roll = cameraRollDeg(beta, gamma, screenAngleDeg);
    const { down_deg: down, up_deg: up, margin_deg: margin } = this.cfg;
    if (e < (this.state === 'tilt_down' ? down + margin : down)) this.state = 'tilt_down';
    else if (e > (this.state === 'tilt_up' ? up - margin : up)) this.state = 'tilt_up';
    else this.state = null;
    this.lastT = t;
  }

  /** The reason at time `now` (s): 'tilt_down', 'tilt_up' or null. */
  reason(now) {
    return this.fresh(now) ? this.state : null;
  }

  /** The camera's roll at time `now` (s), degrees (cameraRollDeg), or null: none, or no sample fresher than cfg.roll_fresh_s. */
  rollDeg(now) {
    return this.fresh(now, this.cfg.roll_fresh_s) ? this.roll : null;
  }

  fresh(now, within_s = this.cfg.fresh_s) {
    return this.lastT !== null && now - this.lastT <= within_s;
  }
}

/** Said and shown once per guidance when the tilt sensor gives nothing (TiltSilence). */
export const NO_TILT_TEXT = 'No tilt sensor: hold the phone level.';

/**
 * Notices a tilt sensor that is missing, refused or silent, so that guidance without levelling is
 * never a silent failure: `due(t, lastSampleT)` is true once (per object: one per guidance) when
 * no sample came for `after_s` since guidance started or came back from the background
 * (`restart`), or since the last sample (a sensor that stopped). Pure; the clock is passed in.
 */
export class TiltSilence {
  constructor(t, after_s = 2.0) {
    this.after_s = after_s;
    this.from = t;
    this.told = false;
  }

  /** Guidance goes on again at t (back from the background: events stop there). */
  restart(t) {
    this.from = t;
  }

  due(t, lastSampleT = null) {
    if (this.told) return false;
    const since = lastSampleT === null || lastSampleT === undefined ? this.from : Math.max(this.from, lastSampleT);
    if (t - since < this.after_s) return false;
    this.told = true;
    return true;
  }
}

/**
 * When a phone held upright (portrait) has been unsure for a while, a "not sure" stop says to hold
 * it sideways. On the held-out PTL photographers, at the shipped gate, the beacon plays for 77.5 %
 * of landscape frames and for 38.9 % of portrait-phone views of the same photos, each at under
 * 0.5 % confidently wrong (README, "What the user hears"): sideways, the model is sure twice as
 * often. After `after_s` of one unbroken "not sure" stop in portrait the reason becomes
 * 'sideways' until the stop ends or the phone is turned; at most once every `every_s`, so a user
 * who keeps it upright on purpose is not told again and again. Only when the model placed a
 * crossing somewhere (`seeing`: its most probable action a strip) on at least half of that stop's
 * frames: unsure because nothing in view is a crossing, held sideways it stays so (crossing-demo's
 * summary gives the same advice by the same rule).
 */
export const SIDEWAYS = Object.freeze({ after_s: 5.0, every_s: 120.0, seeing_share: 0.5 });

export class SidewaysHint {
  constructor(cfg = SIDEWAYS) {
    this.cfg = { ...SIDEWAYS, ...cfg };
    this.since = null; // start of the current "not sure" stop in portrait
    this.frames = 0; // that stop's frames, and those on which the model placed a crossing
    this.seeing = 0;
    this.active = false;
    this.lastHint = -Infinity;
  }

  /** A decision at time t (s): `unsure` (a "not sure" stop), `portrait`, `seeing` (the frame's most
   * probable action is a strip; default true); returns 'sideways' or null. */
  update(t, unsure, portrait, seeing = true) {
    if (!unsure || !portrait) {
      this.since = null;
      this.frames = 0;
      this.seeing = 0;
      this.active = false;
      return null;
    }
    if (this.since === null) this.since = t;
    this.frames += 1;
    this.seeing += seeing ? 1 : 0;
    if (!this.active && t - this.since >= this.cfg.after_s && t - this.lastHint >= this.cfg.every_s
        && this.seeing >= this.cfg.seeing_share * this.frames) {
      this.active = true;
      this.lastHint = t;
    }
    return this.active ? 'sideways' : null;
  }
}

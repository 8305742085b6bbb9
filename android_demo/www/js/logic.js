// The decision logic shared with the Python runtime, ported line by line from
// crossing_assist/runtime/belief.py (temporal filter), gate.py (UPMS gate) and decide.py
// (freshness / watchdog and the Decider state machine). docs/runtime.md
// ("Decision logic") states every formula; android_demo/test_vectors.json (generated from the
// Python runtime) is reproduced by test/logic.test.mjs in Node and by the browser test.
//
// Pure: no DOM, no clocks, no randomness. Times in seconds, angles in degrees (negative =
// left), yaw rate in degrees per second (positive = the user turns right).

import { DEFAULT_FOV_DEG, N_BINS, headingToPan, spaceGroups, xToHeading } from './actions.js';
import { UNCERTAINTY_MEASURES } from './bundle.js';

export const N_STATES = N_BINS + 1;
export const SATURATION_HALF = Math.atanh(0.5); // alpha(threshold) = 1/2
export const GATE_LEARNER = 'learner';
export const GATE_HOLD = 'hold';
export const GATE_STOP = 'stop';
export const REASON_OK = 'ok';
export const REASON_UNCERTAIN = 'uncertain';
export const REASON_STALE = 'stale';
export const REASON_FAILED = 'failed';

export const DEFAULT_FILTER = Object.freeze({ tau_forget_s: 2.0, tau_diffuse_s: 2.0, tau_evidence_s: 0.1, eps: 0.01 });
export const DEFAULT_GATE = Object.freeze({
  saturation: SATURATION_HALF, alpha_min: 0.5, hold_time_s: 1.5, hold_turn_deg: 45.0, agree_deg: 15.0,
  belief_entropy_threshold: 1.2, contradict_strips: 1.5,
});
export const DEFAULT_DECISION = Object.freeze({
  n_actions: 13, fov_deg: DEFAULT_FOV_DEG, measure: 'entropy', threshold: 1.2, watchdog_s: 0.5,
  rate_min_hz: 2.0, rate_max_hz: 6.0,
});

// ----------------------------------------------------------------------------- pinhole helpers

function binCenterX(k) {
  return (k - 0.5) / N_BINS;
}

function headingToX(h, fovDeg) {
  const half = (fovDeg * Math.PI) / 360;
  return 0.5 + Math.tan((h * Math.PI) / 180) / (2 * Math.tan(half));
}

// ----------------------------------------------------------------------------- belief (filter)

/** The belief with no evidence: 1/13 everywhere. */
export function uniformBelief() {
  return new Array(N_STATES).fill(1.0 / N_STATES);
}

/** Move bin mass for a turn of psiDeg (positive = user turned right; goal moves left). */
export function yawShift(b, psiDeg, fovDeg) {
  if (psiDeg === 0) return b.slice();
  const out = new Array(N_STATES).fill(0);
  out[0] = b[0];
  for (let k = 1; k < N_STATES; k += 1) {
    const h = xToHeading(binCenterX(k), fovDeg) - psiDeg;
    if (!(h > -90 && h < 90)) {
      out[0] += b[k];
      continue;
    }
    const x = headingToX(h, fovDeg);
    if ((k === N_BINS && psiDeg > 0) || (k === 1 && psiDeg < 0)) {
      spreadEdge(out, k, N_BINS * x - 0.5, b[k]);
      continue;
    }
    if (x < 0 || x > 1) {
      out[0] += b[k];
      continue;
    }
    const z = Math.min(Math.max(N_BINS * x - 0.5, 0), N_BINS - 1);
    const i = Math.floor(z);
    const f = z - i;
    if (i >= N_BINS - 1) {
      out[N_BINS] += b[k];
    } else {
      out[i + 1] += (1 - f) * b[k];
      out[i + 2] += f * b[k];
    }
  }
  return out;
}

/**
 * An edge bin's mass after a turn moved its centre inward to z (0-based continuous bin index):
 * "at this edge or beyond", so spread evenly from z back out to the edge bin's own centre, each
 * bin taking its cell's share, the part beyond the frame's far edge to unknown.
 */
export function spreadEdge(out, k, z, mass) {
  const e = k - 1;
  const lo = Math.min(z, e);
  const hi = Math.max(z, e);
  const span = hi - lo;
  if (!(span > 1e-12)) {
    out[k] += mass;
    return;
  }
  let inside = 0;
  for (let i = 0; i < N_BINS; i += 1) {
    const share = Math.min(hi, i + 0.5) - Math.max(lo, i - 0.5);
    if (share > 0) {
      out[i + 1] += (mass * share) / span;
      inside += share;
    }
  }
  out[0] += (mass * Math.max(0, span - inside)) / span;
}

/** Spread bin mass to neighbours (reflecting edges); unknown untouched. */
export function diffuse(b, dt, tauS) {
  const d = 0.25 * (1 - Math.exp(-dt / tauS));
  const out = b.slice();
  for (let k = 1; k < N_STATES; k += 1) {
    const left = b[Math.max(1, k - 1)];
    const right = b[Math.min(N_BINS, k + 1)];
    out[k] = (1 - 2 * d) * b[k] + d * left + d * right;
  }
  return out;
}

/** Relax toward the uniform belief: lam b + (1 - lam) / 13, lam = exp(-dt / tau). */
export function forget(b, dt, tauS) {
  const lam = Math.exp(-dt / tauS);
  return b.map((v) => lam * v + (1 - lam) / N_STATES);
}

/** Per-state probabilities (13) from action probabilities (A): an action's mass is split over its bins. */
export function binLikelihood(probs, groups, lookup) {
  const q = new Array(N_STATES);
  q[0] = probs[0];
  for (let k = 1; k < N_STATES; k += 1) {
    const a = lookup[k];
    q[k] = probs[a] / groups[a].length;
  }
  return q;
}

/** Tempered Bayes update b * (q + eps)^w, normalised; w <= 0 returns b. */
export function update(b, q, weight, eps) {
  if (weight <= 0) return b.slice();
  const post = b.map((v, k) => v * (q[k] + eps) ** weight);
  const s = post.reduce((acc, v) => acc + v, 0);
  return post.map((v) => v / s);
}

/** Prediction half of a step: yaw shift by yawRate * dt, diffusion, forgetting. */
export function predict(b, dt, yawRateDps, fovDeg, cfg) {
  if (dt <= 0) return b.slice();
  let out = yawShift(b, yawRateDps * dt, fovDeg);
  out = diffuse(out, dt, cfg.tau_diffuse_s);
  return forget(out, dt, cfg.tau_forget_s);
}

/** Sum 13-way probabilities (unknown + bins) into the space's actions. */
export function binProbsToActionProbs(b, groups) {
  return groups.map((g, a) => (a === 0 ? b[0] : g.reduce((s, k) => s + b[k], 0)));
}

/** Entropy (nats) of a probability vector (0 log 0 = 0). */
export function entropy(probs) {
  let h = 0;
  for (const p of probs) if (p > 0) h -= p * Math.log(p);
  return h;
}

/**
 * Probability outside the most probable action and its neighbours (belief.far_mass): 1 - sum of
 * probs[a-1..a+1] over the strips (a = argmax, first on ties; never unknown), 1 - probs[0] when
 * a is unknown.
 */
export function farMass(probs) {
  const a = argmax(probs);
  if (a === 0) return 1 - probs[0];
  let near = 0;
  for (let k = Math.max(1, a - 1); k <= Math.min(probs.length - 1, a + 1); k += 1) near += probs[k];
  return Math.max(0, 1 - near);
}

/** The gate measures a probability vector gives, by name (belief.PROBS_MEASURES): the belief is gated with the frames' measure when it is one. */
export const PROBS_MEASURES = { entropy, far_mass: farMass };

/** The belief's uncertainty in the action space (DecisionConfig.learner_uncertainty). */
export function beliefUncertainty(b, groups, measure) {
  return (Object.hasOwn(PROBS_MEASURES, measure) ? PROBS_MEASURES[measure] : entropy)(binProbsToActionProbs(b, groups));
}

/** Index of the largest value (first on ties), as numpy's argmax. */
export function argmax(values) {
  let best = 0;
  for (let i = 1; i < values.length; i += 1) if (values[i] > values[best]) best = i;
  return best;
}

/** The belief's most probable action (first on ties) and its heading: [a, heading | null]. */
export function beliefHeading(b, groups, fovDeg) {
  const a = argmax(binProbsToActionProbs(b, groups));
  if (a === 0) return [0, null];
  const bins = groups[a];
  const lo = Math.max(1, bins[0] - 1);
  const hi = Math.min(N_BINS, bins[bins.length - 1] + 1);
  let sw = 0;
  let swx = 0;
  for (let k = lo; k <= hi; k += 1) {
    sw += b[k];
    swx += b[k] * binCenterX(k);
  }
  return [a, xToHeading(swx / sw, fovDeg)];
}

// ----------------------------------------------------------------------------- gate (UPMS)

/** UPMS coefficient 1 - tanh(c u) in [0, 1]; u = Infinity (or NaN) gives 0. */
export function alpha(u, c) {
  // crossing_assist/upms.py coefficient: 1 - tanh(c u) computed as 2 / (1 + exp(2 c u)) (the
  // same number, bit for bit with Python); non-finite u gives 0, negative u counts as 0.
  if (!Number.isFinite(u)) return 0;
  const x = 2 * c * Math.max(u, 0);
  if (x > 700) return 0;
  return 2 / (1 + Math.exp(x));
}

/** Rational mixing of the learner and the hold: {state, heading_deg, weight_learner, confidence}. */
export function mix(hLearner, aLearner, hHold, aHold, cfg) {
  const aL = hLearner !== null ? aLearner : 0;
  const aF = hHold !== null ? aHold : 0;
  const conf = Math.max(aL, aF);
  if (conf < cfg.alpha_min) return { state: GATE_STOP, heading_deg: null, weight_learner: 0, confidence: conf };
  const wL = aL / (aL + aF);
  const state = aL >= cfg.alpha_min ? GATE_LEARNER : GATE_HOLD;
  let heading;
  if (hLearner !== null && hHold !== null && Math.abs(hLearner - hHold) <= cfg.agree_deg) {
    heading = wL * hLearner + (1 - wL) * hHold;
  } else if (aL >= aF) {
    heading = hLearner;
  } else {
    heading = hHold;
  }
  return { state, heading_deg: heading, weight_learner: wL, confidence: conf };
}

// ----------------------------------------------------------------------------- decider

/**
 * Evidence weight of a frame before time scaling: alpha(U) = 1 - tanh(c U) when U < threshold
 * (so in (1/2, 1]), else 0: frames at or beyond the calibrated threshold, failed frames, frames
 * with non-finite uncertainty and frames whose argmax(probs) is unknown carry no evidence.
 */
export function frameWeight(obs, cFrame, threshold) {
  if (!obs.ok || !obs.probs || !Number.isFinite(obs.uncertainty)) return 0;
  if (argmax(obs.probs) === 0 || !(obs.uncertainty < threshold)) return 0;
  return alpha(obs.uncertainty, cFrame);
}

/**
 * Complete decision config: defaults overridden by `cfg` (same field names as the Python
 * DecisionConfig; `filter` and `gate` are nested objects). Throws RangeError when invalid.
 */
export function decisionConfig(cfg = {}) {
  const out = {
    ...DEFAULT_DECISION,
    ...cfg,
    filter: { ...DEFAULT_FILTER, ...(cfg.filter || {}) },
    gate: { ...DEFAULT_GATE, ...(cfg.gate || {}) },
  };
  spaceGroups(out.n_actions);
  if (!UNCERTAINTY_MEASURES.includes(out.measure)) {
    throw new RangeError(`Unknown uncertainty measure: ${JSON.stringify(out.measure)}; valid: ${UNCERTAINTY_MEASURES.join(', ')}`);
  }
  for (const [name, v] of Object.entries(out.filter)) if (!(v > 0)) throw new RangeError(`Invalid ${name}: ${v}; valid: > 0`);
  for (const name of ['saturation', 'hold_time_s', 'hold_turn_deg', 'agree_deg', 'belief_entropy_threshold', 'contradict_strips']) {
    if (!(out.gate[name] > 0)) throw new RangeError(`Invalid ${name}: ${out.gate[name]}; valid: > 0`);
  }
  if (!(out.gate.alpha_min > 0 && out.gate.alpha_min < 1)) throw new RangeError(`Invalid alpha_min: ${out.gate.alpha_min}; valid: 0 < alpha_min < 1`);
  if (!(out.threshold > 0)) throw new RangeError(`Invalid threshold: ${out.threshold}; valid: > 0`);
  if (!(out.watchdog_s > 0)) throw new RangeError(`Invalid watchdog_s: ${out.watchdog_s}; valid: > 0`);
  if (!(out.rate_min_hz > 0 && out.rate_min_hz <= out.rate_max_hz)) {
    throw new RangeError(`Invalid pulse rates: ${out.rate_min_hz}..${out.rate_max_hz} Hz; valid: 0 < min <= max`);
  }
  return out;
}

/** The decision config a bundle implies (its action space, FOV and calibrated threshold). */
export function configFromBundle(meta, overrides = {}) {
  return decisionConfig({
    n_actions: meta.actions.n,
    fov_deg: meta.fov_deg,
    measure: meta.calibration.uncertainty.measure,
    threshold: meta.calibration.uncertainty.threshold,
    ...overrides,
  });
}

/** The stateful decision step (port of decide.Decider). Call step() with non-decreasing t. */
export class Decider {
  constructor(cfg = {}) {
    this.cfg = decisionConfig(cfg);
    this.groups = spaceGroups(this.cfg.n_actions);
    this.lookup = new Array(N_STATES).fill(0);
    this.groups.forEach((g, a) => g.forEach((k) => { this.lookup[k] = a; }));
    const learnerThreshold = Object.hasOwn(PROBS_MEASURES, this.cfg.measure) ? this.cfg.threshold : this.cfg.gate.belief_entropy_threshold;
    this.cFrame = this.cfg.gate.saturation / this.cfg.threshold;
    this.cLearner = this.cfg.gate.saturation / learnerThreshold;
    this.reset();
  }

  /** Back to the start: uniform belief, no hold, no frame seen. */
  reset() {
    this.belief = uniformBelief();
    this.tPrev = null;
    this.tLastOk = null;
    this.holdHeading = null;
    this.holdT = 0;
    this.holdTurned = 0;
    this.holdEdge = 0;
  }

  /**
   * Step 4b: a frame whose most probable strip lies more than contradict_strips strip widths from
   * the hold drops it, however unsure the frame (a camera turned without a yaw input); a frame
   * that sees no goal leaves the hold.
   */
  contradict(obs) {
    if (this.holdHeading === null || !(Math.abs(this.holdHeading) < 90)) return;
    const a = argmax(obs.probs);
    if (a === 0) return;
    const bins = this.groups[a];
    const seen = (bins[0] - 1 + bins[bins.length - 1]) / (2 * N_BINS);
    if (Math.abs(headingToX(this.holdHeading, this.cfg.fov_deg) - seen) * N_BINS > this.cfg.gate.contradict_strips) {
      this.holdHeading = null;
    }
  }

  /**
   * Advance to time t (s) with this frame's outputs, obs = {probs: number[A], uncertainty,
   * ok} (null = no new frame: a tick). Returns the decision (same fields as the Python
   * Decision.to_json(); non-finite floats become null).
   */
  step(t, obs, yawRateDps = 0) {
    const { cfg } = this;
    const dt = this.tPrev === null ? 0 : Math.max(0, t - this.tPrev);
    this.tPrev = this.tPrev === null ? t : Math.max(t, this.tPrev);
    const psi = yawRateDps * dt;
    this.belief = predict(this.belief, dt, yawRateDps, cfg.fov_deg, cfg.filter);
    if (this.holdHeading !== null) {
      this.holdHeading -= psi;
      this.holdTurned += Math.abs(psi);
      // an edge hold ("at this edge or beyond") turned towards: where the goal is now is unknown
      if (turnedOutOfEdge(this.holdEdge, this.holdHeading, psi, cfg.fov_deg)) {
        this.holdHeading = null;
      }
    }
    if (obs && this.tLastOk !== null && t - this.tLastOk > cfg.watchdog_s) {
      // 4a: the first frame after a stall meets a fresh belief and no hold
      this.belief = uniformBelief();
      this.holdHeading = null;
    }
    let w = 0;
    if (obs && obs.ok) {
      w = frameWeight(obs, this.cFrame, cfg.threshold);
      const since = this.tLastOk === null ? cfg.filter.tau_evidence_s : t - this.tLastOk;
      w *= Math.min(1, Math.max(0, since) / cfg.filter.tau_evidence_s);
      if (w > 0) this.belief = update(this.belief, binLikelihood(obs.probs, this.groups, this.lookup), w, cfg.filter.eps);
      this.tLastOk = t;
      this.contradict(obs);
    }
    const [aL, hL] = beliefHeading(this.belief, this.groups, cfg.fov_deg);
    const uL = hL !== null ? beliefUncertainty(this.belief, this.groups, cfg.measure) : Infinity;
    const alL = alpha(uL, this.cLearner);
    const uF = this.holdHeading !== null && Math.abs(this.holdHeading) < 90
      ? (t - this.holdT) / cfg.gate.hold_time_s + this.holdTurned / cfg.gate.hold_turn_deg
      : Infinity;
    const alF = alpha(uF, cfg.gate.saturation);
    const hF = Number.isFinite(uF) ? this.holdHeading : null;
    const m = mix(hL, alL, hF, alF, cfg.gate);
    let reason;
    if (obs && !obs.ok) {
      reason = REASON_FAILED;
    } else if (this.tLastOk === null || t - this.tLastOk > cfg.watchdog_s) {
      reason = REASON_STALE;
    } else {
      reason = m.state === GATE_STOP ? REASON_UNCERTAIN : REASON_OK;
      if (hL !== null && alL >= cfg.gate.alpha_min) {
        this.holdHeading = hL;
        this.holdT = t;
        this.holdTurned = 0;
        this.holdEdge = edgeSide(hL, cfg.fov_deg);
      }
    }
    const stop = reason !== REASON_OK;
    const heading = stop ? null : m.heading_deg;
    const q = (m.confidence - cfg.gate.alpha_min) / (1 - cfg.gate.alpha_min);
    const rate = cfg.rate_min_hz + Math.min(1, Math.max(0, q)) * (cfg.rate_max_hz - cfg.rate_min_hz);
    const fin = (v) => (v === null || !Number.isFinite(v) ? null : v);
    return {
      t, gate: stop ? GATE_STOP : m.state, reason, stop,
      heading_deg: heading, pan: heading === null ? null : headingToPan(heading, cfg.fov_deg / 2),
      rate_hz: rate, frame_weight: w, learner_action: aL, learner_heading: hL, learner_u: fin(uL),
      alpha_learner: alL, hold_heading: hF, hold_u: fin(uF), alpha_hold: alF,
      weight_learner: m.weight_learner, belief: this.belief.slice(),
    };
  }
}

// ----------------------------------------------------------------------------- engine / beacon

/** The gate's frame uncertainty (engine.measure_value): entropy, mutual_info, variance[argmax probs] or farMass(probs). */
export function measureValue(measure, entropyNats, mutualInfo, variance, probs) {
  if (measure === 'entropy') return entropyNats;
  if (measure === 'mutual_info') return mutualInfo;
  if (measure === 'variance') return variance[argmax(probs)];
  if (measure === 'far_mass') return farMass(probs);
  throw new RangeError(`Unknown uncertainty measure: ${JSON.stringify(measure)}; valid: ${UNCERTAINTY_MEASURES.join(', ')}`);
}

/**
 * What the decision logic needs from one frame's model outputs ({probs, entropy, mutual_info,
 * variance, votes}): {probs, uncertainty, ok}. Non-finite probabilities or uncertainty make a
 * failed frame (ok = false), as in engine.Engine.predict.
 */
export function observationFromOutputs(outputs, measure) {
  const probs = Array.from(outputs.probs, Number);
  if (!probs.every(Number.isFinite)) return { probs: null, uncertainty: Infinity, ok: false };
  const u = Number(measureValue(measure, outputs.entropy, outputs.mutual_info, outputs.variance, probs));
  if (!Number.isFinite(u)) return { probs: null, uncertainty: Infinity, ok: false };
  return { probs, uncertainty: u, ok: true };
}

export const KIND_BEACON = 'beacon';
export const KIND_STOP = 'stop';
export const KIND_SILENCE = 'silence';

/** +1 / -1 when a heading lies in the right / left edge strip of a camera fovDeg across (or beyond it, short of 90 deg), else 0 (decide.edge_side). */
export function edgeSide(heading, fovDeg) {
  if (!(Math.abs(heading) < 90)) return 0;
  const x = headingToX(heading, fovDeg);
  if (x >= (N_BINS - 1) / N_BINS) return 1;
  return x <= 1 / N_BINS ? -1 : 0;
}

/**
 * A heading taken in edge strip `side` (+1 right, -1 left, 0 none), now at movedDeg after a turn of
 * turnDeg towards that edge, that has left the strip: where the goal is is then unknown (steps 3
 * and 10; decide.turned_out_of_edge).
 */
export function turnedOutOfEdge(side, movedDeg, turnDeg, fovDeg) {
  return side * turnDeg > 0 && edgeSide(movedDeg, fovDeg) !== side;
}

/**
 * Step 10 (decide.turned): the decision as it is played once the camera has turned turnDeg (the
 * gyroscope's, + = right) since its frame's capture. The heading moves by the turn (the goal stays
 * put in the world); a heading in an edge strip turned towards moves by half of it (the goal lies
 * anywhere from the moved heading back out to the edge), and once the turn has carried the moved
 * heading out of that strip, where the goal is is unknown (as for step 3's hold): a stop
 * ('uncertain') until the next decision. A stop stays a stop; a turn that is not a finite number
 * turns nothing.
 */
export function turnedDecision(decision, turnDeg, fovDeg) {
  if (decision.heading_deg === null || !Number.isFinite(turnDeg) || turnDeg === 0) return decision;
  const side = edgeSide(decision.heading_deg, fovDeg);
  if (turnedOutOfEdge(side, decision.heading_deg - turnDeg, turnDeg, fovDeg)) {
    return { ...decision, gate: GATE_STOP, reason: REASON_UNCERTAIN, stop: true, heading_deg: null, pan: null };
  }
  const h = decision.heading_deg - (side * turnDeg > 0 ? turnDeg / 2 : turnDeg);
  return { ...decision, heading_deg: h, pan: headingToPan(h, fovDeg / 2) };
}

/**
 * Step 10 without the turn's sign (decide.stale): a decision played while a gyroscope reports but
 * is not followed (the picture has not confirmed it yet, or found it turning the wrong way), so
 * the size of the turn since its frame's capture is known, not its way. Heard late, the decision
 * lags the user's facing by that turn and cannot be turned back, so it plays as decided while the
 * turn stays within half a strip (a twelfth of fovDeg), and as a stop (uncertain) beyond, until
 * the next decision. A turn that is not a finite number changes nothing; a stop stays a stop.
 */
export function staleDecision(decision, turnDeg, fovDeg) {
  if (decision.heading_deg === null || !Number.isFinite(turnDeg) || Math.abs(turnDeg) <= fovDeg / N_BINS / 2) {
    return decision;
  }
  return { ...decision, gate: GATE_STOP, reason: REASON_UNCERTAIN, stop: true, heading_deg: null, pan: null };
}

/** The cue of a decision (beacon.cue_for): {kind, pan, heading_deg, rate_hz}. */
export function cueFor(decision) {
  if (decision.stop || decision.heading_deg === null || decision.pan === null) {
    return { kind: KIND_STOP, pan: 0, heading_deg: 0, rate_hz: 1 };
  }
  return { kind: KIND_BEACON, pan: decision.pan, heading_deg: decision.heading_deg, rate_hz: decision.rate_hz };
}

export const HEAD_RADIUS_M = 0.0875;
export const SPEED_OF_SOUND_MS = 343.0;

/** Interaural time difference (s, > 0 = right ear leads) of a source at headingDeg (Woodworth). */
export function itdSeconds(headingDeg) {
  const phi = (Math.max(-90, Math.min(90, headingDeg)) * Math.PI) / 180;
  return (HEAD_RADIUS_M / SPEED_OF_SOUND_MS) * (phi + Math.sin(phi));
}

/** Constant-power gains [L, R] for pan in [-1, 1] (L^2 + R^2 = 1): what StereoPannerNode applies to mono. */
export function panGains(pan) {
  if (!(pan >= -1 && pan <= 1)) throw new RangeError(`Invalid pan: ${pan}; valid: -1 <= pan <= 1`);
  const theta = ((pan + 1) * Math.PI) / 4;
  return [Math.cos(theta), Math.sin(theta)];
}

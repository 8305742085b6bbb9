// The action vocabulary, ported from crossing_assist/actions.py (pure: no DOM, runs in Node
// and in the browser). 12 vertical strips ("bins") 1..12 left to right, 0 = unknown; the
// 4/8/13-action spaces group bins; headings come from a pinhole camera with horizontal field
// of view fov_deg: heading(x) = atan((2x - 1) tan(fov / 2)), degrees, negative = left.
// tests/test_android_logic.py checks every function here against the Python module.

export const N_BINS = 12;
export const UNKNOWN = 0;
export const DEFAULT_FOV_DEG = 90.0;

const GROUPS = {
  4: [[], [1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12]],
  8: [[], [1], [2, 3], [4, 5], [6, 7], [8, 9], [10, 11], [12]],
  13: [[], ...Array.from({ length: N_BINS }, (_, i) => [i + 1])],
};

/** Bins covered by each action of the n-action space (n in 4, 8, 13); groups[0] = [] (unknown). */
export function spaceGroups(n) {
  const g = GROUPS[n];
  if (!g) throw new RangeError(`Unknown action space: ${n}; valid: 4, 8, 13`);
  return g.map((bins) => bins.slice());
}

/** Names of the n-action space's actions, as in actions.py ("unknown", "left", "2-3", "7", ...). */
export function spaceNames(n) {
  const names = spaceGroups(n).map((g, a) =>
    a === 0 ? 'unknown' : g.length === 1 ? String(g[0]) : `${g[0]}-${g[g.length - 1]}`);
  if (n === 4) names.splice(1, 3, 'left', 'straight', 'right');
  return names;
}

function checkFov(fovDeg) {
  if (!(fovDeg > 0 && fovDeg < 180)) {
    throw new RangeError(`Invalid field of view: ${fovDeg} degrees; valid: 0 < fov < 180`);
  }
  return fovDeg;
}

/** Azimuth (degrees, negative = left) of image position x (fraction of width, 0..1). */
export function xToHeading(x, fovDeg = DEFAULT_FOV_DEG) {
  if (!(x >= 0 && x <= 1)) throw new RangeError(`Invalid goal position x: ${x}; valid: 0 <= x <= 1`);
  const half = (checkFov(fovDeg) * Math.PI) / 360;
  return (Math.atan((2 * x - 1) * Math.tan(half)) * 180) / Math.PI;
}

/** Centre of the strips of action a (fraction of width); throws for unknown (a = 0). */
export function actionCenterX(groups, a) {
  const bins = groups[a];
  if (!bins) throw new RangeError(`Invalid action: ${a}; valid: 0..${groups.length - 1}`);
  if (bins.length === 0) throw new RangeError('The unknown action has no position; check for action 0 first');
  return (bins[0] - 1 + bins[bins.length - 1]) / (2 * N_BINS);
}

/** Heading (degrees, negative = left) of the centre of action a's strips. */
export function actionHeading(groups, a, fovDeg = DEFAULT_FOV_DEG) {
  return xToHeading(actionCenterX(groups, a), fovDeg);
}

/** Stereo pan in [-1, 1] (-1 = hard left), saturating at +-fullScaleDeg (default fov / 2). */
export function headingToPan(headingDeg, fullScaleDeg = DEFAULT_FOV_DEG / 2) {
  if (!(fullScaleDeg > 0)) throw new RangeError(`Invalid full_scale_deg: ${fullScaleDeg}; valid: > 0`);
  if (Number.isNaN(headingDeg)) throw new RangeError('Invalid heading: nan');
  return Math.max(-1, Math.min(1, headingDeg / fullScaleDeg));
}

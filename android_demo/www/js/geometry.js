// The camera-geometry contract (bundle.json schemas 2 and 3, `geometry`; docs/contracts.md), the
// app's side: which horizontal field of view turns the 12 strips of THIS frame into headings,
// and which of its rows the graph sees. Pure (no DOM); the Python references are
// crossing_assist/runtime/camera.py (camera_fov) and crossing_assist/geometry.py (view_rows), and
// test_vectors.json's `geometry` section holds the cases both must agree on.
//
// * orientation of a frame: 'portrait' if height > width, else 'landscape';
// * FOV = the override for that orientation (the user's setting, or what the camera reports)
//   if there is one, else the bundle's geometry.camera_fov_deg[orientation]; with
//   geometry.sensor_aspect (long / short side of that sensor), a frame narrower than the sensor
//   in its orientation is a crop of it and gets the crop's FOV (defaultFov: 9:16 video ~41 deg);
// * a FOV outside 20..170 degrees is refused (FovError): the app then plays the stop cue;
// * a schema-1 bundle has one fov_deg for both orientations (parseGeometry in bundle.js);
// * the gate threshold is the orientation's too: calibration.uncertainty.portrait_threshold for
//   portrait frames when the bundle has one, else calibration.uncertainty.threshold (portrait
//   strips are narrower, so the same doubt in degrees reads as a higher entropy); with
//   calibration.uncertainty.wide_fov_deg the camera's width picks it instead (gateKind);
// * a new FOV or threshold (the phone turned) starts a fresh Decider.
//
// The model fits the frame onto its canvas inside the ONNX graph (letterbox or stretch), and
// the strips are strips of the frame (the camera's view): the app hands over raw frames, with
// one exception. The view crop (schema 3, geometry.view_crop, letterbox only): the app first
// keeps only the middle rows the canvas can show at the training camera's angular scale
// (viewRows), never columns. The FOV, orientation and gate threshold stay the whole frame's.
// And levelling: with the motion sensors on, a frame whose camera is rolled about its own axis is
// first turned back by that roll (levelAngle; camera.js FrameGrabber.level draws it), as
// crossing_assist/geometry.py level does for Engine.predict(..., roll_deg).

export const ORIENTATIONS = ['landscape', 'portrait'];
export const FOV_RANGE_DEG = [20, 170];
/** Levelling (geometry.MAX_LEVEL_DEG and level in Python): a roll is turned back by at most
 * max_deg; one under min_deg is left alone; beyond guided_max_deg (geometry.MAX_GUIDED_ROLL_DEG)
 * the frame gets no guidance (levelled, it stays rolled more than the training views were). */
export const LEVEL = Object.freeze({ max_deg: 45, min_deg: 0.5, guided_max_deg: 60 });
/** What fills what a camera did not see when the bundle names nothing (schema 1): geometry.PAD_RGB. */
export const PAD_RGB = Object.freeze([124, 116, 104]);

/** The roll (degrees, the scene's counter-clockwise roll in the frame) a frame is turned back
 * by: clamped to +-LEVEL.max_deg; 0 under LEVEL.min_deg or without a reading (null, NaN). */
export function levelAngle(rollDeg) {
  if (!Number.isFinite(rollDeg) || Math.abs(rollDeg) < LEVEL.min_deg) return 0;
  return Math.max(-LEVEL.max_deg, Math.min(LEVEL.max_deg, rollDeg));
}

/** True when a roll reading (degrees) is beyond LEVEL.guided_max_deg either way (geometry.rolled_too_far). */
export function rolledTooFar(rollDeg) {
  return Number.isFinite(rollDeg) && Math.abs(rollDeg) > LEVEL.guided_max_deg;
}

export class FovError extends RangeError {
  constructor(message) {
    super(message);
    this.name = 'FovError';
  }
}

/** 'portrait' when the frame is taller than wide, else 'landscape'. */
export function orientation(width, height) {
  return height > width ? 'portrait' : 'landscape';
}

/** A horizontal FOV in degrees inside 20..170, else FovError. */
export function checkFov(fov) {
  const [lo, hi] = FOV_RANGE_DEG;
  if (typeof fov !== 'number' || !Number.isFinite(fov) || fov < lo || fov > hi) {
    throw new FovError(`Invalid field of view: ${fov} degrees; valid: ${lo}..${hi}`);
  }
  return fov;
}

/**
 * Horizontal FOV (degrees) of a window covering `fraction` of the width of a frame whose
 * horizontal FOV is `fovDeg`: 2 atan(fraction tan(fov / 2)). Python: geometry.py window_fov.
 */
export function windowFov(fraction, fovDeg) {
  const rad = Math.PI / 180; // Python's math.radians / math.degrees: x * (pi / 180), x * (180 / pi)
  return 2 * Math.atan(fraction * Math.tan((fovDeg * rad) / 2)) * (180 / Math.PI);
}

/**
 * The default horizontal FOV (degrees, unchecked) of a width x height frame (Python: geometry.py
 * default_fov): geometry.camera_fov_deg[orientation]; with geometry.sensor_aspect s (not
 * null/undefined), full = s (landscape) or 1 / s (portrait), a = width / height, and a < full
 * (a crop narrower than the sensor) gives windowFov(a / full, that FOV).
 */
export function defaultFov(geometry, width, height) {
  const o = orientation(width, height);
  let fov = geometry.camera_fov_deg[o];
  const s = geometry.sensor_aspect;
  if (s != null) {
    const full = o === 'landscape' ? s : 1 / s;
    const a = width / height;
    if (a < full) fov = windowFov(a / full, fov);
  }
  return fov;
}

/** An aspect (long / short side) as a ratio of small integers ('4:3', '16:9'), else '1.41:1'. */
function ratioText(aspect) {
  for (let d = 1; d <= 20; d += 1) {
    const n = Math.round(aspect * d);
    if (Math.abs(n / d - aspect) < 1e-6) return `${n}:${d}`;
  }
  return `${aspect.toFixed(2)}:1`;
}

/**
 * The settings page's words for the bundle's default FOV of an orientation (what an empty FOV
 * field means): '53°', or with geometry.sensor_aspect '53° for 3:4 and wider frames, their
 * crop's for narrower ones (9:16: 41.0°)' (landscape's example: 1:1).
 */
export function defaultFovText(geometry, o) {
  const fov = `${geometry.camera_fov_deg[o]}°`;
  const s = geometry.sensor_aspect;
  if (s == null) return fov;
  const sensor = ratioText(s).split(':');
  const [w, h] = o === 'portrait' ? [9, 16] : [1, 1];
  const full = o === 'portrait' ? `${sensor[1]}:${sensor[0]}` : sensor.join(':');
  const narrower = w / h < (o === 'portrait' ? 1 / s : s); // the example is a crop of this sensor
  const example = narrower ? ` (${w}:${h}: ${defaultFov(geometry, w, h).toFixed(1)}°)` : '';
  return `${fov} for ${full} and wider frames, their crop’s for narrower ones${example}`;
}

/**
 * Horizontal FOV (degrees) for a width x height frame: `override` when not null/undefined (as
 * given), else defaultFov (the orientation's, a crop's with sensor_aspect). Throws FovError
 * outside 20..170.
 */
export function cameraFov(geometry, width, height, override = null) {
  return checkFov(override ?? defaultFov(geometry, width, height));
}

/**
 * Which gate threshold a width x height frame from a camera `fov` degrees across (its cameraFov)
 * takes (Python: bundle.py UncertaintySpec.which): 'narrow' (narrow_threshold, for portrait
 * frames at most narrow_fov_deg across, when the bundle has one), 'portrait'
 * (portrait_threshold, for other portrait frames, when it has one), else 'landscape' (threshold).
 * With wide_fov_deg and a known `fov` the camera's width decides, whatever the orientation:
 * at most narrow_fov_deg 'narrow', under wide_fov_deg 'portrait', else 'landscape'.
 * `uncertainty` is the bundle's calibration.uncertainty.
 */
export function gateKind(uncertainty, width, height, fov = null) {
  const { narrow_threshold: narrow, narrow_fov_deg: narrowFov, portrait_threshold: portrait, wide_fov_deg: wideFov } = uncertainty;
  const byWidth = wideFov != null && fov != null;
  if (!byWidth && orientation(width, height) !== 'portrait') return 'landscape';
  if (narrow != null && narrowFov != null && fov != null && fov <= narrowFov) return 'narrow';
  return portrait != null && (!byWidth || fov < wideFov) ? 'portrait' : 'landscape';
}

/** The gate threshold of that frame (Python: runtime/camera.py gate_threshold). */
export function gateThreshold(uncertainty, width, height, fov = null) {
  const kind = gateKind(uncertainty, width, height, fov);
  return { landscape: uncertainty.threshold, portrait: uncertainty.portrait_threshold, narrow: uncertainty.narrow_threshold }[kind];
}

/**
 * The zoom the camera reports (MediaStreamTrack getSettings().zoom against
 * getCapabilities().zoom.min): a zoom ratio r > 1 narrows the view to 2 atan(tan(fov/2) / r).
 * Browsers report no field of view itself; this is all they give that bears on it. Returns
 * `fov` unchanged when the track reports no zoom.
 */
export function zoomedFov(fov, settings = {}, capabilities = {}) {
  const zoom = settings?.zoom;
  const min = capabilities?.zoom?.min;
  if (!(typeof zoom === 'number' && typeof min === 'number' && min > 0 && zoom > min)) return fov;
  const half = (fov * Math.PI) / 360;
  return (360 / Math.PI) * Math.atan(Math.tan(half) / (zoom / min));
}

/**
 * The rows of a height x width frame (horizontal FOV `fovDeg`) that the canvas [H, W] (bundle.json
 * input.size) shows at the training camera's angular scale, or magnified by up to `zoom`
 * (geometry.view_zoom, schema 4): [top, rows], centred; rows > height (top < 0) means rows of
 * padding above and below (frameView). Python: crossing_assist/geometry.py view_rows, the same
 * integers (the shared test vectors check it):
 *   t = max(1, tan(train / 2) / tan(fov / 2) / zoom)
 *   rows = max(1, floor(width * H * t / W + 0.5)), at most height when t = 1 or when it is at
 *   most height + floor(height / 50); top = (height - rows) // 2
 * (a camera wider than the training one, t < 1, is fitted by its width: no further crop; a
 * narrower one's frame shorter than the view, a landscape camera zoomed in, is padded to it).
 */
export function viewRows(height, width, fovDeg, canvas, trainFovDeg, zoom = 1) {
  const [ch, cw] = canvas;
  const rad = Math.PI / 180; // as Python's math.radians: x * (pi / 180)
  const t = Math.max(1, Math.tan((trainFovDeg * rad) / 2) / Math.tan((fovDeg * rad) / 2) / zoom);
  const full = Math.max(1, Math.floor((width * ch * t) / cw + 0.5));
  // a frame the view's height but for rounding (a crop of the sensor) as it is (Python: PAD_SLACK)
  const rows = t === 1 || full <= height + Math.floor(height / 50) ? Math.min(height, full) : full;
  return [Math.floor((height - rows) / 2), rows];
}

/**
 * What of a frame ({rgb: row-major RGB bytes, width, height}) goes into the graph, for a frame
 * whose horizontal FOV is `fovDeg`: with geometry.view_crop, its viewRows (a subarray, no copy;
 * a padded copy when the frame is shorter than the view), else the whole frame. Returns {rgb,
 * width, height, top, rows}.
 */
export function frameView(frame, geometry, fovDeg, canvas) {
  const { rgb, width, height } = frame;
  if (!geometry.view_crop) return { rgb, width, height, top: 0, rows: height };
  const [top, rows] = viewRows(height, width, fovDeg, canvas, geometry.train_fov_deg, geometry.view_zoom ?? 1);
  if (top >= 0 && top + rows <= height) {
    return { rgb: rgb.subarray(top * width * 3, (top + rows) * width * 3), width, height: rows, top, rows };
  }
  // shorter than the view (Python: geometry.take_rows): padded above and below with pad_rgb
  const out = new Uint8Array(rows * width * 3);
  const pad = geometry.pad_rgb ?? PAD_RGB;
  const lo = Math.max(0, top);
  const hi = Math.min(height, top + rows);
  const [a, b] = [(lo - top) * width * 3, (hi - top) * width * 3]; // the frame's rows in `out`
  for (let i = 0; i < out.length; i += 3) {
    if (i === a) i = b; // only the padding is filled
    if (i >= out.length) break;
    out[i] = pad[0]; out[i + 1] = pad[1]; out[i + 2] = pad[2];
  }
  out.set(rgb.subarray(lo * width * 3, hi * width * 3), a);
  return { rgb: out, width, height: rows, top, rows };
}

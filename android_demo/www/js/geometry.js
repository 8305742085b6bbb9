// The camera-geometry contract (bundle.json schemas 2 and 3, `geometry`; docs/contracts.md), the
// app's side: which horizontal field of view turns the 12 strips of THIS frame into headings,
// and which of its rows the graph sees. Pure (no DOM); the Python references are
// crossing_assist/runtime/camera.py (camera_fov) and crossing_assist/geometry.py (view_rows), and
// test_vectors.json's `geometry` section holds the cases both must agree on.
//
// * orientation of a frame: 'portrait' if height > width, else 'landscape';
// * FOV = the override for that orientation (the user's setting, or what the camera reports)
//   if there is one, else the bundle's geometry.camera_fov_deg[orientation];
// * a FOV outside 20..170 degrees is refused (FovError): the app then plays the stop cue;
// * a schema-1 bundle has one fov_deg for both orientations (parseGeometry in bundle.js);
// * the gate threshold is the orientation's too: calibration.uncertainty.portrait_threshold for
//   portrait frames when the bundle has one, else calibration.uncertainty.threshold (portrait
//   strips are narrower, so the same doubt in degrees reads as a higher entropy);
// * a new FOV or threshold (the phone turned) starts a fresh Decider.
//
// The model fits the frame onto its canvas inside the ONNX graph (letterbox or stretch), and
// the strips are strips of the frame (the camera's view): the app hands over raw frames, with
// one exception. The view crop (schema 3, geometry.view_crop, letterbox only): the app first
// keeps only the middle rows the canvas can show at the training camera's angular scale
// (viewRows), never columns. The FOV, orientation and gate threshold stay the whole frame's.

export const ORIENTATIONS = ['landscape', 'portrait'];
export const FOV_RANGE_DEG = [20, 170];

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
 * Horizontal FOV (degrees) for a width x height frame: `override` when not null/undefined,
 * else geometry.camera_fov_deg[orientation]. Throws FovError outside 20..170.
 */
export function cameraFov(geometry, width, height, override = null) {
  const fov = override ?? geometry.camera_fov_deg[orientation(width, height)];
  return checkFov(fov);
}

/**
 * The gate threshold for a width x height frame (Python: runtime/camera.py gate_threshold):
 * `uncertainty` is the bundle's calibration.uncertainty.
 */
export function gateThreshold(uncertainty, width, height) {
  const portrait = uncertainty.portrait_threshold;
  return orientation(width, height) === 'portrait' && portrait != null ? portrait : uncertainty.threshold;
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
 * input.size) shows at the training camera's angular scale: [top, rows], centred. Python:
 * crossing_assist/geometry.py view_rows, the same integers (the shared test vectors check it):
 *   t = max(1, tan(train / 2) / tan(fov / 2))
 *   rows = min(height, max(1, floor(width * H * t / W + 0.5))), top = (height - rows) // 2
 * (a camera wider than the training one, t < 1, is fitted by its width: no further crop).
 */
export function viewRows(height, width, fovDeg, canvas, trainFovDeg) {
  const [ch, cw] = canvas;
  const rad = Math.PI / 180; // as Python's math.radians: x * (pi / 180)
  const t = Math.max(1, Math.tan((trainFovDeg * rad) / 2) / Math.tan((fovDeg * rad) / 2));
  const rows = Math.min(height, Math.max(1, Math.floor((width * ch * t) / cw + 0.5)));
  return [Math.floor((height - rows) / 2), rows];
}

/**
 * What of a frame ({rgb: row-major RGB bytes, width, height}) goes into the graph, for a frame
 * whose horizontal FOV is `fovDeg`: with geometry.view_crop, its viewRows (a subarray, no copy),
 * else the whole frame. Returns {rgb, width, height, top, rows}.
 */
export function frameView(frame, geometry, fovDeg, canvas) {
  const { rgb, width, height } = frame;
  if (!geometry.view_crop) return { rgb, width, height, top: 0, rows: height };
  const [top, rows] = viewRows(height, width, fovDeg, canvas, geometry.train_fov_deg);
  return { rgb: rgb.subarray(top * width * 3, (top + rows) * width * 3), width, height: rows, top, rows };
}

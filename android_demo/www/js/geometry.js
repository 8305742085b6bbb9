// The camera-geometry contract (bundle.json schema 2, `geometry`; docs/contracts.md), the
// app's side: which horizontal field of view turns the 12 strips of THIS frame into headings.
// Pure (no DOM); the Python reference is crossing_assist/runtime/camera.py (camera_fov), and
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
// the strips are strips of the frame (the camera's view): the app hands over raw frames.

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

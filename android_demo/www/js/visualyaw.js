// The camera's turn between two frames, read from the frames themselves (no gyroscope): a port
// of crossing_assist/runtime/visual_yaw.py, pinned by the shared test vectors (`visual_yaw`,
// version 12; the ambiguity check, version 18). A turn about the vertical axis slides the whole picture sideways, so:
//
// 1. each frame becomes a grey (mean of R, G, B) area-mean thumbnail THUMB_WIDTH wide, its
//    height from the frame's aspect (whole-number sums, one division: the Python values);
// 2. the middle of the new thumbnail (all but a quarter of its width at each side, DY rows) is
//    compared with the old one shifted by every whole dx up to a quarter of the width either way
//    and dy up to DY: the mean absolute difference, each less its own mean; the best dx (the
//    first minimum in [dy][dx] row-major order, numpy's argmin) is refined by the V through its
//    neighbours' scores;
// 3. the shift is trusted only with texture (population sd >= MIN_TEXTURE in the middle compared
//    and in the old thumbnail), a best score <= MAX_MATCH of the median score of all shifts, the
//    best dx inside the range searched, no other local minimum of the scores (each dx's best over
//    dy) 2 px or more away within AMBIGUOUS times the best (a repeating pattern, a zebra's stripes,
//    matched a period off as well) and no tile vetoing it (the middle cut into a TILES x
//    TILES grid; a tile with texture whose own best scores under 1 / TILE_VETO of its best within
//    a pixel of the chosen dx: part of the picture moved otherwise, a bus passing a still camera),
//    else the pair cannot tell (null): a blank wall, a passing bus, a brightness jump gives no
//    turn, never a guess; a shift under MIN_SHIFT is a still camera (0: a still scene's
//    neighbours never score quite alike);
// 4. dx pixels are atan(dx / f) degrees for the camera's horizontal FOV; the picture moving left
//    (dx > 0) is a turn to the right (+), the Decider's sign. A rate over MAX_TURN_DPS is 0.
//
// Thumbnails: {w, h, data: Float64Array(h * w), row-major}. Pure; VisualYaw keeps its scratch
// buffers, so a frame pair allocates only its thumbnail (~1.5 ms a 640 x 480 frame in Node).

export const THUMB_WIDTH = 64; // thumbnail width in pixels
export const DY = 2; // vertical shifts searched either way (thumbnail pixels)
export const MIN_TEXTURE = 2.0; // thumbnail sd (0..255 grey) below which a frame cannot show a turn
export const MAX_MATCH = 0.5; // the best shift must score at most this fraction of the median shift's score
export const MIN_SHIFT = 0.05; // a shift under this (thumbnail pixels) is a still camera
export const TILES = 3; // the middle is cut into TILES x TILES tiles, each able to veto a shift
export const TILE_VETO = 2.0; // ... when its score near the shift is over this many times its own best
export const AMBIGUOUS = 1.25; // another local minimum of the shifts' scores within this many times the best: cannot tell
export const MAX_TURN_DPS = 360.0; // a faster turn between two frames is not believed (a swap, a cut)

const DEG = Math.PI / 180; // CPython's math.radians / math.degrees factors
const RAD = 180 / Math.PI;

/** Python's round() of a non-negative float: halves go to the even integer. */
function roundHalfEven(x) {
  const r = Math.round(x);
  return r - x === 0.5 && r % 2 !== 0 ? r - 1 : r;
}

/**
 * The grey area-mean thumbnail of a frame: `rgb` flat row-major RGB bytes (Uint8Array,
 * Uint8ClampedArray or array) of `width` x `height`; `thumbWidth` wide (at most the frame's), its
 * height the frame's aspect (at least 8, at most the frame's). Cell (i, j) averages rows
 * floor(i H / h) .. floor((i + 1) H / h) and the columns alike, 0..255. RangeError on a bad frame.
 */
export function thumbnail(rgb, width, height, thumbWidth = THUMB_WIDTH) {
  if (!Number.isInteger(width) || !Number.isInteger(height) || width < 2 || height < 2) {
    throw new RangeError(`Invalid frame size: ${width} x ${height}; valid: whole numbers >= 2`);
  }
  if (!rgb || rgb.length !== width * height * 3) {
    throw new RangeError(`Invalid frame: ${rgb?.length} bytes for ${width} x ${height} RGB; valid: ${width * height * 3}`);
  }
  if (!Number.isInteger(thumbWidth) || thumbWidth < 1) throw new RangeError(`Invalid thumbnail width: ${thumbWidth}; valid: >= 1`);
  const w = Math.min(thumbWidth, width);
  const h = Math.min(height, Math.max(8, roundHalfEven((w * height) / width)));
  const xs = new Int32Array(w + 1);
  const ys = new Int32Array(h + 1);
  for (let j = 0; j <= w; j += 1) xs[j] = Math.floor((j * width) / w);
  for (let i = 0; i <= h; i += 1) ys[i] = Math.floor((i * height) / h);
  const data = new Float64Array(w * h); // whole-number sums of R + G + B (exact in float64)
  for (let i = 0; i < h; i += 1) {
    const row = i * w;
    for (let y = ys[i]; y < ys[i + 1]; y += 1) {
      let p = y * width * 3;
      for (let j = 0; j < w; j += 1) {
        let s = 0;
        for (let x = xs[j]; x < xs[j + 1]; x += 1, p += 3) s += rgb[p] + rgb[p + 1] + rgb[p + 2];
        data[row + j] += s;
      }
    }
  }
  for (let i = 0; i < h; i += 1) {
    for (let j = 0; j < w; j += 1) data[i * w + j] /= 3 * ((ys[i + 1] - ys[i]) * (xs[j + 1] - xs[j]));
  }
  return { w, h, data };
}

/** The part of `cur` compared: [m, dy, tw, th] (m columns and dy rows left out at each side). */
function middle(cur) {
  const m = Math.max(1, Math.floor(cur.w / 4));
  const dy = Math.min(DY, Math.floor(cur.h / 4));
  return [m, dy, Math.max(0, cur.w - 2 * m), Math.max(0, cur.h - 2 * dy)];
}

/** Population standard deviation (numpy's std, ddof 0) of rows y0..y0+th, columns x0..x0+tw of t. */
function stdOf(t, x0, y0, tw, th) {
  const n = tw * th;
  let s = 0;
  for (let y = 0; y < th; y += 1) for (let x = 0, p = (y0 + y) * t.w + x0; x < tw; x += 1, p += 1) s += t.data[p];
  const mean = s / n;
  let q = 0;
  for (let y = 0; y < th; y += 1) {
    for (let x = 0, p = (y0 + y) * t.w + x0; x < tw; x += 1, p += 1) {
      const d = t.data[p] - mean;
      q += d * d;
    }
  }
  return Math.sqrt(q / n);
}

/** First row (or column) of each of TILES tiles of `size` rows (numpy's (arange(TILES) * size) // TILES). */
function tileStarts(size) {
  const starts = new Int32Array(TILES + 1);
  for (let i = 0; i < TILES; i += 1) starts[i] = Math.floor((i * size) / TILES);
  starts[TILES] = size;
  return starts;
}

/** Fill `out` (Float64Array, rows x cols) with the scores and `tiles` (rows x cols x TILES x
 * TILES) with each tile's sum of absolute differences; `tplc` (tw * th) takes the middle less its
 * mean, `colsum` (prev.w) the window rows' column sums (each window's mean from tw of them). */
function scoresInto(prev, cur, out, tiles, tplc, colsum) {
  const [m, dy, tw, th] = middle(cur);
  const n = tw * th;
  const rows = cur.h - th + 1;
  const cols = cur.w - tw + 1;
  const ry = tileStarts(th);
  const rx = tileStarts(tw);
  const tt = TILES * TILES;
  let s = 0;
  for (let y = 0; y < th; y += 1) for (let x = 0, p = (dy + y) * cur.w + m; x < tw; x += 1, p += 1) s += cur.data[p];
  const tmean = s / n;
  for (let y = 0, k = 0; y < th; y += 1) {
    for (let x = 0, p = (dy + y) * cur.w + m; x < tw; x += 1, p += 1, k += 1) tplc[k] = cur.data[p] - tmean;
  }
  const a = prev.data;
  const pw = prev.w;
  for (let iy = 0; iy < rows; iy += 1) {
    colsum.fill(0, 0, pw);
    for (let y = 0; y < th; y += 1) for (let x = 0, p = (iy + y) * pw; x < pw; x += 1, p += 1) colsum[x] += a[p];
    for (let ix = 0; ix < cols; ix += 1) {
      let ws = 0;
      for (let x = 0; x < tw; x += 1) ws += colsum[ix + x];
      const wmean = ws / n;
      const t0 = (iy * cols + ix) * tt;
      let total = 0;
      for (let i = 0; i < TILES; i += 1) {
        for (let j = 0; j < TILES; j += 1) {
          let d = 0;
          for (let y = ry[i]; y < ry[i + 1]; y += 1) {
            for (let x = rx[j], p = (iy + y) * pw + ix + x, k = y * tw + x; x < rx[j + 1]; x += 1, p += 1, k += 1) {
              d += Math.abs(a[p] - wmean - tplc[k]);
            }
          }
          tiles[t0 + i * TILES + j] = d;
          total += d;
        }
      }
      out[iy * cols + ix] = total / n;
    }
  }
  return { rows, cols, ry, rx };
}

/**
 * Scores of every shift, {rows: 2 DY' + 1, cols: 2 M + 1, data: Float64Array} row-major by
 * [dy + DY'][dx + M]: the mean absolute difference between the middle of `cur` and the window of
 * `prev` shifted by (dx, dy), each less its own mean. Thumbnails of one size.
 */
export function shiftScores(prev, cur) {
  const [m, dy, tw, th] = middle(cur);
  const data = new Float64Array((2 * dy + 1) * (2 * m + 1));
  const tiles = new Float64Array(data.length * TILES * TILES);
  const { rows, cols } = scoresInto(prev, cur, data, tiles, new Float64Array(tw * th), new Float64Array(prev.w));
  return { rows, cols, data: data.subarray(0, rows * cols) };
}

/**
 * Horizontal shift in thumbnail pixels such that cur[x] ~ prev[x + shift] (+: the picture moved
 * left, the camera turned right; 0 under MIN_SHIFT); null when the pair cannot tell (different
 * sizes, too little texture, no shift clearly a match, the best at an end of the range searched,
 * another shift matching nearly as well, a tile of the middle vetoing it).
 * `scratch` ({scores, sorted, tiles, tplc, colsum, prof}: Float64Arrays, grown here): VisualYaw's, so that nothing is allocated.
 */
export function shiftBetween(prev, cur, scratch = {}) {
  if (prev.w !== cur.w || prev.h !== cur.h) return null;
  const [m, dy, tw, th] = middle(cur);
  if (stdOf(cur, m, dy, tw, th) < MIN_TEXTURE || stdOf(prev, 0, 0, prev.w, prev.h) < MIN_TEXTURE) return null;
  const size = (cur.h - th + 1) * (cur.w - tw + 1);
  if (!(scratch.scores?.length >= size)) {
    scratch.scores = new Float64Array(size);
    scratch.sorted = new Float64Array(size);
    scratch.tiles = new Float64Array(size * TILES * TILES);
  }
  if (!(scratch.tplc?.length >= tw * th)) scratch.tplc = new Float64Array(tw * th);
  if (!(scratch.colsum?.length >= prev.w)) scratch.colsum = new Float64Array(prev.w);
  const s = scratch.scores;
  const tiles = scratch.tiles;
  const { rows, cols, ry, rx } = scoresInto(prev, cur, s, tiles, scratch.tplc, scratch.colsum);
  const n = rows * cols; // odd (2 DY' + 1 rows, 2 M + 1 columns): the median is the middle score
  let k = 0; // numpy's argmin: the first minimum (or the first NaN) in row-major order
  for (let i = 1; i < n; i += 1) if (s[i] < s[k] || (s[i] !== s[i] && s[k] === s[k])) k = i;
  const sorted = scratch.sorted.subarray(0, n);
  sorted.set(s.subarray(0, n));
  sorted.sort();
  const ix = k % cols;
  const best = s[k];
  if (!(best <= MAX_MATCH * sorted[(n - 1) / 2]) || !(ix > 0 && ix < cols - 1)) return null;
  if (!(scratch.prof?.length >= cols)) scratch.prof = new Float64Array(cols);
  const prof = scratch.prof; // each column's best over dy
  for (let q = 0; q < cols; q += 1) {
    let v = s[q];
    for (let r = 1; r < rows; r += 1) v = Math.min(v, s[r * cols + q]);
    prof[q] = v;
  }
  for (let q = 1; q < cols - 1; q += 1) {
    const v = prof[q];
    if (Math.abs(q - ix) >= 2 && v < prof[q - 1] && v <= prof[q + 1] && v <= AMBIGUOUS * best) return null; // a repeating pattern
  }
  const tt = TILES * TILES;
  for (let i = 0; i < TILES; i += 1) {
    for (let j = 0; j < TILES; j += 1) {
      if (!(stdOf(cur, m + rx[j], dy + ry[i], rx[j + 1] - rx[j], ry[i + 1] - ry[i]) >= MIN_TEXTURE)) continue;
      let own = Infinity;
      let near = Infinity;
      for (let q = 0; q < n; q += 1) {
        const v = tiles[q * tt + i * TILES + j];
        own = Math.min(own, v);
        if (Math.abs((q % cols) - ix) <= 1) near = Math.min(near, v);
      }
      if (!(near <= TILE_VETO * own)) return null; // this part of the picture moved otherwise
    }
  }
  const a = s[k - 1]; // the V through the best and its neighbours
  const c = s[k + 1];
  const rise = Math.max(a, c) - best;
  const shift = ix - Math.floor(cols / 2) + (rise > 0 ? (0.5 * (a - c)) / rise : 0);
  return Math.abs(shift) >= MIN_SHIFT ? shift : 0;
}

/** A shift of `shiftPx` in an image `widthPx` wide seen `fovDeg` across, as the camera's turn in degrees (+ = right). */
export function shiftToDeg(shiftPx, widthPx, fovDeg) {
  const f = widthPx / 2 / Math.tan((fovDeg * DEG) / 2);
  return Math.atan(shiftPx / f) * RAD;
}

/** The camera's turn rate from consecutive frames: update() with each frame gives the yaw rate
 * (deg/s, + = right) since the previous one, 0 when it cannot tell. */
export class VisualYaw {
  constructor(width = THUMB_WIDTH) {
    if (!Number.isInteger(width) || width < 1) throw new RangeError(`Invalid thumbnail width: ${width}; valid: >= 1`);
    this.width = width;
    this.scratch = {};
    this.reset();
  }

  /** Start afresh: the next frame has nothing to be compared with. */
  reset() {
    this.prev = null;
    this.tPrev = null;
  }

  /**
   * The yaw rate between the last frame and `frame` ({rgb, width, height}, or null) taken at `t`
   * seconds, seen with a camera `fovDeg` across (null: unknown); a missing or unreadable frame or
   * FOV starts afresh (0).
   */
  update(frame, t, fovDeg) {
    let thumb = null;
    if (frame != null && fovDeg != null) {
      try {
        thumb = thumbnail(frame.rgb, frame.width, frame.height, this.width);
      } catch (err) {
        if (!(err instanceof RangeError)) throw err;
      }
    }
    const { prev, tPrev } = this;
    this.prev = thumb;
    this.tPrev = thumb !== null ? t : null;
    if (thumb === null || prev === null || tPrev === null || !(t > tPrev)) return 0;
    const shift = shiftBetween(prev, thumb, this.scratch);
    if (shift === null) return 0;
    const rate = shiftToDeg(shift, thumb.w, fovDeg) / (t - tPrev);
    return Math.abs(rate) <= MAX_TURN_DPS ? rate : 0;
  }
}

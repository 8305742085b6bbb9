// The rear camera: getUserMedia into a <video>, and a grabber that hands out each NEW camera
// frame once as RGB bytes, with the time the camera captured it. A camera that stops delivering
// frames (frozen, unplugged, taken by another app) yields nothing, so no fresh decision arrives
// and the watchdog stops the beacon.
//
// A frame's time (performance.now() ms) is its own: requestVideoFrameCallback's captureTime,
// else its presentationTime, else expectedDisplayTime (never later than when the callback ran).
// A frame that arrived during a model run waits for the next grab, so the grab's time would
// make it look younger than it is. Without the API: the time the poll first saw the frame.

import { levelAngle } from './geometry.js';
import { rgbaToRgb } from './model.js';

export const MAX_WIDTH = 640; // frames wider than this are downscaled (aspect kept), as the Python runtime does

export class CameraError extends Error {
  constructor(message) {
    super(message);
    this.name = 'CameraError';
  }
}

/** Open the rear camera into `video`; resolves with the MediaStream once frames flow. */
export async function openCamera(video) {
  if (!navigator.mediaDevices?.getUserMedia) {
    throw new CameraError('This browser gives no camera access here: open the app over https:// or http://localhost');
  }
  let stream;
  try {
    stream = await navigator.mediaDevices.getUserMedia({
      audio: false,
      video: { facingMode: { ideal: 'environment' }, width: { ideal: 640 }, height: { ideal: 480 } },
    });
  } catch (err) {
    const why = err?.name === 'NotAllowedError' ? 'permission was refused: allow the camera in the browser settings' : `${err?.name || 'error'}: ${err?.message || err}`;
    throw new CameraError(`Cannot open the camera (${why})`);
  }
  video.muted = true;
  video.playsInline = true;
  video.srcObject = stream;
  await video.play();
  return stream;
}

/** Hands out each new video frame once, as {rgb, width, height, seq, timeMs} (timeMs: captured, performance.now() clock). */
export class FrameGrabber {
  constructor(video, maxWidth = MAX_WIDTH) {
    this.video = video;
    this.maxWidth = maxWidth;
    this.canvas = document.createElement('canvas');
    this.ctx = this.canvas.getContext('2d', { willReadFrequently: true });
    this.presented = 0; // frames the browser presented so far
    this.taken = 0; // the `presented` count at the last grab
    this.waiters = [];
    this.lastTime = -1;
    this.frameMs = null; // capture time of the newest frame presented (performance.now() ms)
    this.closed = false;
    if ('requestVideoFrameCallback' in HTMLVideoElement.prototype) {
      const onFrame = (nowMs, meta) => {
        if (this.closed) return;
        const t = meta?.captureTime ?? meta?.presentationTime ?? meta?.expectedDisplayTime;
        this.frameMs = Number.isFinite(t) ? Math.min(t, performance.now()) : performance.now();
        this.presented += 1;
        this.wake();
        this.handle = video.requestVideoFrameCallback(onFrame);
      };
      this.handle = video.requestVideoFrameCallback(onFrame);
    } else {
      // Fallback: a frame is new when the video's clock moved.
      this.poll = setInterval(() => {
        if (video.currentTime !== this.lastTime) {
          this.lastTime = video.currentTime;
          this.frameMs = performance.now();
          this.presented += 1;
          this.wake();
        }
      }, 15);
    }
  }

  wake() {
    const waiters = this.waiters;
    this.waiters = [];
    for (const resolve of waiters) resolve(true);
  }

  /** Resolves true when a frame newer than the last grab is there, false after timeoutMs. */
  waitForNewFrame(timeoutMs) {
    if (this.presented > this.taken) return Promise.resolve(true);
    return new Promise((resolve) => {
      const timer = setTimeout(() => {
        this.waiters = this.waiters.filter((w) => w !== done);
        resolve(false);
      }, timeoutMs);
      const done = (v) => {
        clearTimeout(timer);
        resolve(v);
      };
      this.waiters.push(done);
    });
  }

  /**
   * The current frame as RGB, {rgb, width, height, seq, timeMs} (downscaled to width <= maxWidth),
   * or null. timeMs: when the camera captured it (performance.now() clock; the grab's own time
   * when no frame was seen presented yet).
   */
  grab() {
    const { videoWidth: vw, videoHeight: vh } = this.video;
    if (!vw || !vh) return null;
    const scale = Math.min(1, this.maxWidth / vw);
    const width = Math.max(1, Math.round(vw * scale));
    const height = Math.max(1, Math.round(vh * scale));
    if (this.canvas.width !== width || this.canvas.height !== height) {
      this.canvas.width = width;
      this.canvas.height = height;
      this.rgb = new Uint8Array(width * height * 3);
    }
    this.ctx.drawImage(this.video, 0, 0, width, height);
    const rgba = this.ctx.getImageData(0, 0, width, height).data;
    this.taken = this.presented;
    return { rgb: rgbaToRgb(rgba, this.rgb), width, height, seq: this.taken, timeMs: this.frameMs ?? performance.now() };
  }

  /**
   * The last grabbed frame turned level (geometry.js levelAngle of rollDeg, the camera's roll from
   * the orientation sensor), the corners the camera did not see filled with padRgb (the bundle's
   * geometry.pad_rgb), as crossing_assist/geometry.py level: {rgb, width, height, seq, timeMs, roll_deg}.
   * The frame itself (same object) when there is nothing to turn. Call right after grab(): it
   * draws from the grab's canvas.
   */
  level(frame, rollDeg, padRgb) {
    const angle = levelAngle(rollDeg);
    if (angle === 0) return frame;
    const { width, height } = frame;
    if (!this.levelCtx) this.levelCtx = document.createElement('canvas').getContext('2d', { willReadFrequently: true });
    const ctx = this.levelCtx;
    if (!this.levelRgb || ctx.canvas.width !== width || ctx.canvas.height !== height) {
      ctx.canvas.width = width;
      ctx.canvas.height = height;
      this.levelRgb = new Uint8Array(width * height * 3);
    }
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = `rgb(${padRgb[0]}, ${padRgb[1]}, ${padRgb[2]})`;
    ctx.fillRect(0, 0, width, height);
    // canvas y points down, so a positive angle turns the picture clockwise: back by the roll
    ctx.setTransform(1, 0, 0, 1, width / 2, height / 2);
    ctx.rotate((angle * Math.PI) / 180);
    ctx.drawImage(this.canvas, -width / 2, -height / 2);
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    const rgba = ctx.getImageData(0, 0, width, height).data;
    return { rgb: rgbaToRgb(rgba, this.levelRgb), width, height, seq: frame.seq, timeMs: frame.timeMs, roll_deg: angle };
  }

  close() {
    this.closed = true;
    if (this.handle !== undefined) this.video.cancelVideoFrameCallback(this.handle);
    if (this.poll) clearInterval(this.poll);
    this.wake();
  }
}

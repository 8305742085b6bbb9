// Field recordings for researchers (?record=1, this visit only): while guidance runs, the camera's
// video as the camera gives it (before levelling or any crop) and the motion sensors' log, each
// gyroscope sample's turn rate with the roll known then. After guidance ends the helper view
// offers both as downloads, to be replayed on a computer as the app heard them:
//
//   crossing-demo walk.webm --imu walk.imu.csv
//
// The log is crossing_assist/runtime/imu.py's CSV: t (s, from the recording's start, the video's
// first frame at t = 0 up to the recorder's start-up), yaw_dps (+ = turning right, the Decider's
// yaw rate: live.js yawRateFromRotation) and roll_deg (+ = the phone turned clockwise, as
// geometry.level takes it; empty while no roll is known). Nothing leaves the phone by itself.

/** The log's header: crossing_assist/runtime/imu.py's column names. */
export const IMU_HEADER = 't,yaw_dps,roll_deg';

/** The longest recording (s): its video is kept in the phone's memory until it is downloaded
 * (about 20 MB a minute at a browser's default bit rate), so a walk left recording stops here. */
export const MAX_RECORD_S = 15 * 60;

/** How long stop() waits for the recorder's last chunk (ms): ending guidance never hangs on it. */
export const STOP_WAIT_MS = 2000;

/** Video types tried in order: WebM (Chromium, Firefox), then MP4 (Safari). */
export const VIDEO_TYPES = ['video/webm;codecs=vp8', 'video/webm', 'video/mp4'];

const num = (v, digits) => (v === null || v === undefined || !Number.isFinite(v) ? '' : String(Number(v.toFixed(digits))));

/**
 * The log as CSV text: rows of [t (s), yaw rate (deg/s), roll (deg) or null], kept in time order
 * (a row not after the one before is dropped, as YawIntegrator drops it) and without rows whose
 * time or rate is not a finite number.
 */
export function imuCsv(rows) {
  const lines = [IMU_HEADER];
  let last = -Infinity;
  for (const [t, yaw, roll] of rows) {
    if (!Number.isFinite(t) || !Number.isFinite(yaw)) continue;
    const tt = Number(t.toFixed(4));
    if (!(tt > last)) continue;
    last = tt;
    lines.push(`${tt},${num(yaw, 4)},${num(roll, 3)}`);
  }
  return `${lines.join('\n')}\n`;
}

/** The first of VIDEO_TYPES the browser's MediaRecorder can write ('' when none is named). */
export function videoType(isSupported = (t) => globalThis.MediaRecorder?.isTypeSupported?.(t) ?? false) {
  return VIDEO_TYPES.find((t) => isSupported(t)) ?? '';
}

/**
 * One recording: `new FieldRecorder(stream, clock)` starts it; `motion(t, yawDps, rollDeg)` adds a
 * gyroscope sample at `t` on `clock`'s time (s); `stop()` resolves to { video: Blob, type,
 * extension, csv, samples, seconds, capped }. At `maxSeconds` it stops by itself (`capped`: the
 * video and the log end there). Throws at once where the browser cannot record video.
 */
export class FieldRecorder {
  constructor(stream, clock, { maxSeconds = MAX_RECORD_S } = {}) {
    if (typeof globalThis.MediaRecorder !== 'function') throw new Error('This browser cannot record video.');
    this.clock = clock;
    const type = videoType();
    this.recorder = new MediaRecorder(stream, type ? { mimeType: type } : undefined);
    this.chunks = [];
    this.rows = [];
    this.capped = false;
    this.t0 = clock(); // replaced by the recorder's own start, when it comes
    this.recorder.addEventListener('start', () => { this.t0 = clock(); });
    this.recorder.addEventListener('dataavailable', (e) => { if (e.data?.size) this.chunks.push(e.data); });
    // its last chunk comes before 'stop', however it was stopped (here at the cap, or by stop())
    this.stopped = new Promise((resolve) => this.recorder.addEventListener('stop', resolve, { once: true }));
    this.recorder.start(1000); // a chunk a second: a recording cut short still holds what came before
    this.cap = setTimeout(() => {
      this.capped = true;
      this.seconds = this.clock() - this.t0;
      this.recorder.stop();
    }, maxSeconds * 1000);
  }

  motion(t, yawDps, rollDeg) {
    if (this.recorder.state === 'recording') this.rows.push([t - this.t0, yawDps, rollDeg]);
  }

  stop() {
    clearTimeout(this.cap);
    const seconds = this.seconds ?? this.clock() - this.t0;
    if (this.recorder.state !== 'inactive') this.recorder.stop();
    const late = new Promise((resolve) => { setTimeout(resolve, STOP_WAIT_MS); });
    return Promise.race([this.stopped, late]).then(() => {
      const type = this.recorder.mimeType || this.chunks[0]?.type || 'video/webm';
      const csv = imuCsv(this.rows);
      return { video: new Blob(this.chunks, { type }), type, extension: type.includes('mp4') ? 'mp4' : 'webm',
        csv, samples: csv.split('\n').length - 2, seconds, capped: this.capped }; // rows: not the header nor the last newline
    });
  }
}

// Settings kept on this phone (localStorage), read at load and written on every change:
// tutorialDone (the first-run headphone check and sound tutorial was played), speech,
// hapticDirections, tilt, gyro, visualYaw, and the per-orientation camera field of view the user
// set (null = the bundle's default for that orientation).
//
// The motion sensors are two settings:
// * `tilt` (DeviceOrientationEvent only): a rolled camera's frame is turned level before the
//   model sees it, a phone rolled beyond levelling stops ("hold it level"), and a phone pointed
//   far down or up is told which way to tilt. ON by default: a blind user will not tick a box,
//   and unlevelled a camera rolled 35-45 deg was confidently wrong on 9.5 % of 200 real photos
//   (0.5 % levelled). Its sign rests on the W3C angles alone; a missing or silent sensor is said
//   aloud (app.js), never a silent failure.
// * `gyro` (DeviceMotionEvent): turns followed with the gyroscope (the Decider's yaw rate). OFF
//   by default: its sign on a given phone needs a sighted check ("turning right must read right");
//   the camera picture checks it as well, and one found turning the wrong way is left (live.js
//   GyroCheck). Off, the gyroscope is still listened to while `tilt` is on, and followed (the
//   Decider's yaw rate, the beacon turned between decisions: decision step 10) once the picture
//   has confirmed it (GyroCheck.confirmed, app.js gyroFollowed).
// Without the gyroscope, `visualYaw` (ON by default) follows turns read from the camera picture
// itself (visualyaw.js: consecutive frames' sideways shift; no sensor, no sign to check). In a
// 30 deg/s scan (scripts/pan_probe.py) the beacon was 2 strips or more off on 0.68 % of the
// goal-in-view frames with it, 3.4 % with neither, 0.6 % with the gyroscope.

import { checkFov } from './geometry.js';

export const SETTINGS_KEY = 'crossing-assist-settings';
export const DEFAULT_SETTINGS = Object.freeze({
  tutorialDone: false, speech: true, hapticDirections: false, tilt: true, gyro: false, visualYaw: true,
  fov: { landscape: null, portrait: null },
});

/**
 * The stored settings merged over the defaults; a damaged entry gives the defaults (and a bad FOV:
 * null, a flag that is not true or false: its default).
 *
 * Migration from the single "Use the motion sensors" setting (`gyro`, which turned on the
 * gyroscope, the tilt advice and levelling together): a stored `gyro: true` keeps its meaning, both
 * on (`tilt` was never stored then, so it takes its default, on). A stored `gyro: false` is not
 * read as "no tilt sensor": false was the default, stored by every phone whose settings were
 * written at all, so it says nothing about levelling; `tilt` is then on too, and only an explicit
 * `tilt: false`, written under the new key by its checkbox, turns it off.
 */
export function loadSettings(storage = globalThis.localStorage) {
  let stored = {};
  try {
    stored = JSON.parse(storage?.getItem(SETTINGS_KEY) || '{}') || {};
  } catch {
    stored = {};
  }
  if (typeof stored !== 'object' || Array.isArray(stored)) stored = {};
  const out = { ...DEFAULT_SETTINGS, ...stored, fov: { ...DEFAULT_SETTINGS.fov, ...(stored.fov || {}) } };
  for (const key of ['tutorialDone', 'speech', 'hapticDirections', 'tilt', 'gyro', 'visualYaw']) {
    if (typeof out[key] !== 'boolean') out[key] = DEFAULT_SETTINGS[key];
  }
  for (const o of ['landscape', 'portrait']) {
    if (out.fov[o] !== null) {
      try {
        checkFov(out.fov[o]);
      } catch {
        out.fov[o] = null;
      }
    }
  }
  return out;
}

/**
 * The URL flags' settings for this visit only (never saved, so a test link cannot leave a phone
 * without levelling): ?gyro=1 keeps its old meaning, all the motion sensors (gyroscope and tilt);
 * ?tilt=0 turns the tilt sensor (levelling, roll limit, tilt advice) off, ?tilt=1 on; ?tilt is
 * read after ?gyro; ?visualyaw=0 turns off following turns from the camera picture, ?visualyaw=1
 * on. {} without flags.
 */
export function urlOverrides(params) {
  const out = {};
  if (params.get('gyro') === '1') Object.assign(out, { gyro: true, tilt: true });
  if (params.get('tilt') === '0') out.tilt = false;
  else if (params.get('tilt') === '1') out.tilt = true;
  if (params.get('visualyaw') === '0') out.visualYaw = false;
  else if (params.get('visualyaw') === '1') out.visualYaw = true;
  return out;
}

export function saveSettings(settings, storage = globalThis.localStorage) {
  try {
    storage?.setItem(SETTINGS_KEY, JSON.stringify(settings));
    return true;
  } catch {
    return false; // private mode or full: the settings last for this visit
  }
}

// Settings kept on this phone (localStorage), read at load and written on every change:
// tutorialDone (the first-run headphone check and sound tutorial was played), speech,
// hapticDirections, gyro, and the per-orientation camera field of view the user set (null =
// the bundle's default for that orientation).

import { checkFov } from './geometry.js';

export const SETTINGS_KEY = 'crossing-assist-settings';
export const DEFAULT_SETTINGS = Object.freeze({
  tutorialDone: false, speech: true, hapticDirections: false, gyro: false, fov: { landscape: null, portrait: null },
});

/** The stored settings merged over the defaults; a damaged entry gives the defaults (and a bad FOV: null). */
export function loadSettings(storage = globalThis.localStorage) {
  let stored = {};
  try {
    stored = JSON.parse(storage?.getItem(SETTINGS_KEY) || '{}') || {};
  } catch {
    stored = {};
  }
  const out = { ...DEFAULT_SETTINGS, ...stored, fov: { ...DEFAULT_SETTINGS.fov, ...(stored.fov || {}) } };
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

export function saveSettings(settings, storage = globalThis.localStorage) {
  try {
    storage?.setItem(SETTINGS_KEY, JSON.stringify(settings));
    return true;
  } catch {
    return false; // private mode or full: the settings last for this visit
  }
}

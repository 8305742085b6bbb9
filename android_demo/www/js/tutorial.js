// The first-run headphone check and sound tutorial: a beep left, right and centre, each named
// aloud (swapped ears are caught before they matter), then the beacon sweeping left to right
// and the stop cue with its vibration, how to hold the phone (sideways guides best: live.js,
// SidewaysHint), and how to end guidance. `playTutorial` plays it
// through the app's audio and speaker; `skipped()` is polled between steps (a tap skips).

import { STOP_PATTERNS } from './haptics.js';
import { KIND_BEACON, KIND_SILENCE, KIND_STOP } from './logic.js';

/** What is said, what plays, for how long (s); `sweep`: the beacon pans from left to right. */
export const TUTORIAL = Object.freeze([
  { say: 'Sound check. A beep in your left ear.', cue: { kind: KIND_BEACON, pan: -1, heading_deg: -45, rate_hz: 3 }, s: 3 },
  { say: 'Right ear.', cue: { kind: KIND_BEACON, pan: 1, heading_deg: 45, rate_hz: 3 }, s: 2 },
  { say: 'Centre.', cue: { kind: KIND_BEACON, pan: 0, heading_deg: 0, rate_hz: 3 }, s: 2 },
  { say: 'If left and right were swapped, turn your headphones round.', cue: { kind: KIND_SILENCE }, s: 3 },
  { say: 'This is the beacon. It comes from where to head, and beeps faster the surer the app is.', sweep: true, s: 6 },
  { say: 'This is the stop cue, two falling beeps, with a vibration. Stop and scan slowly.', cue: { kind: KIND_STOP }, s: 4 },
  { say: 'Hold the phone at chest height, camera ahead. Held sideways, it guides best.', cue: { kind: KIND_SILENCE }, s: 4 },
  { say: 'Double tap or hold the screen to end guidance. Guidance starts now.', cue: { kind: KIND_SILENCE }, s: 3 },
]);

const SWEEP_STEPS = 12;
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/**
 * Play the tutorial. `audio`: a BeaconAudio; `say(text)`: speak and show; `vibrate(pattern)`;
 * `onStep({part, text, cue})`: a record hook; `speed`: > 1 plays faster (tests); `skipped()`.
 * Resolves true when it played to the end, false when skipped.
 */
export async function playTutorial({ audio, say, vibrate, onStep = () => {}, speed = 1, skipped = () => false }) {
  for (const [i, part] of TUTORIAL.entries()) {
    if (skipped()) break;
    say(part.say);
    const steps = part.sweep ? SWEEP_STEPS : 1;
    for (let k = 0; k < steps && !skipped(); k += 1) {
      const pan = part.sweep ? -1 + (2 * k) / (steps - 1) : 0;
      const cue = part.sweep ? { kind: KIND_BEACON, pan, heading_deg: 45 * pan, rate_hz: 2 + (2 * k) / (steps - 1) } : part.cue;
      audio.render(cue);
      if (cue.kind === KIND_STOP) vibrate(STOP_PATTERNS.uncertain);
      onStep({ part: i, text: part.say, cue: { ...cue } });
      await sleep((1000 * part.s) / steps / speed);
    }
  }
  audio.render({ kind: KIND_SILENCE });
  return !skipped();
}

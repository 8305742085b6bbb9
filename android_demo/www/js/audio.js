// The beacon in Web Audio, with the Python runtime's sound design (runtime/beacon.py,
// BeaconConfig defaults):
//
// * beacon: a pulsed 1000 Hz sine (60 ms pulses, 5 ms ramps, peak 0.5) through a
//   StereoPannerNode (constant-power: L = cos theta, R = sin theta, theta = (pan + 1) pi / 4,
//   exactly beacon.pan_gains) and an interaural time difference (Woodworth; the far ear is
//   delayed). The pulse rate (rate_hz, 2..6 Hz) says how sure the guidance is.
// * stop/scan cue: centred, two descending beeps (440 Hz then 330 Hz, 120 ms each) once a
//   second (the vibration that goes with it: haptics.js).
// * silence before Start.
//
// The AudioContext can be suspended or interrupted under the app (a phone call, another app
// taking the audio, the OS): `onStateChange(state)` is called on every change, and
// `playing()` says whether sound can come out at all. The app treats a context that is not
// 'running' as failed guidance.
//
// Graph:  beaconOsc -> pulseGain -> panner -> splitter -> delayL/delayR -> merger --\
//         stopOsc   -> stopGain --------------------------------------------------- master -> speakers
//                                                   master -> splitter -> analyser L / R (levels)
//
// A look-ahead scheduler (every 25 ms, 150 ms ahead) writes each pulse's gain envelope on the
// audio clock, so the rhythm stays regular while the main thread runs the model.

import { itdSeconds, KIND_BEACON, KIND_SILENCE, KIND_STOP } from './logic.js';

export const SOUND = Object.freeze({
  tone_hz: 1000, pulse_s: 0.06, ramp_s: 0.005, amplitude: 0.5, itd: true,
  stop_hz: 440, stop_beep_s: 0.12, stop_period_s: 1.0,
});
const LOOKAHEAD_S = 0.15;
const TICK_MS = 25;
const GLIDE_S = 0.02; // time constant of pan / ITD changes (no zipper noise)

export class BeaconAudio {
  /** `ctx`: an AudioContext created or resumed in a user gesture (autoplay rules). */
  constructor(ctx, sound = SOUND) {
    this.ctx = ctx;
    this.sound = { ...SOUND, ...sound };
    this.cue = { kind: KIND_SILENCE, pan: 0, heading_deg: 0, rate_hz: 1 };
    this.nextPulse = 0;
    this.nextStop = 0;
    this.onStateChange = null;
    ctx.addEventListener('statechange', () => this.onStateChange?.(ctx.state));

    this.master = new GainNode(ctx, { gain: 1 });
    this.master.connect(ctx.destination);
    this.panner = new StereoPannerNode(ctx, { pan: 0 });
    const split = new ChannelSplitterNode(ctx, { numberOfOutputs: 2 });
    const merge = new ChannelMergerNode(ctx, { numberOfInputs: 2 });
    this.delays = [0, 1].map((ch) => {
      const d = new DelayNode(ctx, { maxDelayTime: 0.01, delayTime: 0 });
      split.connect(d, ch);
      d.connect(merge, 0, ch);
      return d;
    });
    this.panner.connect(split);
    merge.connect(this.master);
    this.pulseGain = new GainNode(ctx, { gain: 0 });
    this.pulseGain.connect(this.panner);
    this.beaconOsc = new OscillatorNode(ctx, { type: 'sine', frequency: this.sound.tone_hz });
    this.beaconOsc.connect(this.pulseGain);
    this.stopGain = new GainNode(ctx, { gain: 0 });
    this.stopGain.connect(this.master);
    this.stopOsc = new OscillatorNode(ctx, { type: 'sine', frequency: this.sound.stop_hz });
    this.stopOsc.connect(this.stopGain);

    const tap = new ChannelSplitterNode(ctx, { numberOfOutputs: 2 });
    this.master.connect(tap);
    this.analysers = [0, 1].map((ch) => {
      const a = new AnalyserNode(ctx, { fftSize: 32768 });
      tap.connect(a, ch);
      return a;
    });
    this.buf = new Float32Array(32768);

    this.beaconOsc.start();
    this.stopOsc.start();
    this.timer = setInterval(() => this.schedule(), TICK_MS);
  }

  /**
   * Play a cue ({kind: 'beacon' | 'stop' | 'silence', pan, heading_deg, rate_hz}, as made by
   * logic.cueFor). A beacon keeps its rhythm while pan and rate change; a change of kind cuts
   * what was sounding at once (a stale beacon must not keep pulsing) and starts the new cue.
   */
  render(cue) {
    const now = this.ctx.currentTime;
    const prev = this.cue.kind;
    this.cue = { ...this.cue, ...cue };
    if (this.cue.kind === KIND_BEACON) {
      this.panner.pan.setTargetAtTime(this.cue.pan, now, GLIDE_S);
      const lag = this.sound.itd ? Math.abs(itdSeconds(this.cue.heading_deg)) : 0;
      const right = this.cue.heading_deg > 0; // source on the right: the left ear hears it later
      this.delays[0].delayTime.setTargetAtTime(right ? lag : 0, now, GLIDE_S);
      this.delays[1].delayTime.setTargetAtTime(right ? 0 : lag, now, GLIDE_S);
    }
    if (this.cue.kind !== prev) {
      for (const g of [this.pulseGain.gain, this.stopGain.gain]) {
        g.cancelScheduledValues(now);
        g.setTargetAtTime(0, now, this.sound.ramp_s / 3);
      }
      this.nextPulse = now + 0.02;
      this.nextStop = now + 0.02;
    }
    this.schedule();
  }

  schedule() {
    const s = this.sound;
    const horizon = this.ctx.currentTime + LOOKAHEAD_S;
    if (this.cue.kind === KIND_BEACON && this.cue.rate_hz > 0) {
      const period = Math.max(1 / this.cue.rate_hz, 2 * s.pulse_s);
      while (this.nextPulse < horizon) {
        this.envelope(this.pulseGain.gain, this.nextPulse, s.pulse_s, s.amplitude);
        this.nextPulse += period;
      }
    } else if (this.cue.kind === KIND_STOP) {
      const level = s.amplitude * Math.SQRT1_2;
      while (this.nextStop < horizon) {
        const t1 = this.nextStop;
        const t2 = t1 + 1.5 * s.stop_beep_s;
        this.stopOsc.frequency.setValueAtTime(s.stop_hz, t1);
        this.envelope(this.stopGain.gain, t1, s.stop_beep_s, level);
        this.stopOsc.frequency.setValueAtTime(0.75 * s.stop_hz, t2);
        this.envelope(this.stopGain.gain, t2, s.stop_beep_s, level);
        this.nextStop += s.stop_period_s;
      }
    }
  }

  envelope(param, t, dur, level) {
    const r = this.sound.ramp_s;
    param.setValueAtTime(0, t);
    param.linearRampToValueAtTime(level, t + r);
    param.setValueAtTime(level, t + dur - r);
    param.linearRampToValueAtTime(0, t + dur);
  }

  /** Peak absolute sample of the left and right output over the last ~0.7 s (at 48 kHz): [left, right]. */
  levels() {
    return this.analysers.map((a) => {
      a.getFloatTimeDomainData(this.buf);
      let peak = 0;
      for (const v of this.buf) peak = Math.max(peak, Math.abs(v));
      return peak;
    });
  }

  /** Whether sound can come out: the context is 'running' (not suspended, interrupted or closed). */
  playing() {
    return this.ctx.state === 'running';
  }

  /** What is playing now: {kind, pan (the panner's current value), rate_hz, levels, contextState}. */
  state() {
    return { kind: this.cue.kind, pan: this.panner.pan.value, rate_hz: this.cue.rate_hz, levels: this.levels(),
      contextState: this.ctx.state };
  }

  close() {
    clearInterval(this.timer);
    this.render({ kind: KIND_SILENCE });
    return this.ctx.close();
  }
}

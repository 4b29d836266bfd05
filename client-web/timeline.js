// Time controls: a scrubber over the scene's time (seconds for the built-in demos, which are
// functions of time; the stored steps for pushed scenes), play and pause, speed, loop, and
// live-follow (`time: null`: the server shows the newest state, for scenes a simulation is
// still pushing or a demo it animates). Playback pins each time in turn, and sends the next
// only once a frame has shown the previous one, so it runs as fast as frames come and never
// queues inputs in front of a slow server.
import { $, fillSelect } from './ui.js';
import { apiFetch } from './api.js';

/** Span of the scrubber for demo scenes, seconds (a demo is defined for every time). */
export const DEMO_SPAN_SECS = 60;
const DEMO_STEP_SECS = 0.05;
const DEMO_SPEEDS = [0.25, 0.5, 1, 2, 4];
const STEP_SPEEDS = [1, 2, 5, 10, 25];
const POLL_STEPS_MS = 2000;

export class Timeline {
  /**
   * `settings` is the viewer's settings object (reads and writes `time`, `speed`, `loop`);
   * `sendTime(time | null)` sends a time input and returns its input id (null when offline);
   * `saved()` persists the settings; `online()` says whether the server is reachable now.
   */
  constructor(settings, { sendTime, saved, online }) {
    this.settings = settings;
    this.online = online;
    this.sendTime = sendTime;
    this.saved = saved;
    this.steps = null; // stored scenes: [{ index, time }], oldest first; null for demos
    this.playing = false;
    this.position = 0; // playback position: seconds (demo) or fractional step index (stored)
    this.awaitedInput = null; // input id of the last time sent by playback, until a frame shows it
    this.lastTick = null;
    this.shownTime = null; // scene time of the last frame shown
    this.pollTimer = null;
    this.scene = null;
    this.el = { slider: $('time'), out: $('time-out'), play: $('play'), live: $('live'), loop: $('loop'), speed: $('speed'), speedOut: $('speed-out') };
    this.el.slider.addEventListener('input', () => this.#scrub());
    this.el.play.addEventListener('click', () => (this.playing ? this.pause() : this.play()));
    this.el.live.addEventListener('click', () => this.follow());
    this.el.loop.addEventListener('change', () => { settings.loop = this.el.loop.checked; this.saved(); });
    this.el.speed.addEventListener('change', () => {
      settings.speed = Number(this.el.speed.value);
      this.#render();
      this.saved();
    });
    requestAnimationFrame((t) => this.#tick(t));
  }

  /** Sets the scene: `steps` lists a stored scene's steps (null for a demo). */
  setScene(sceneInfo, steps) {
    this.scene = sceneInfo;
    this.steps = steps;
    this.pause();
    clearInterval(this.pollTimer);
    if (steps) this.pollTimer = setInterval(() => this.#pollSteps(), POLL_STEPS_MS);
    const speeds = steps ? STEP_SPEEDS : DEMO_SPEEDS;
    const options = [...new Set([...speeds, this.settings.speed])].sort((a, b) => a - b);
    fillSelect(this.el.speed, options.map((v) => [String(v), steps ? `${v} steps/s` : `${v}×`]), String(this.settings.speed));
    this.el.loop.checked = this.settings.loop;
    this.#render();
  }

  /** The inputs that restore the time after (re)connecting. */
  restore() {
    if (this.settings.time !== null) this.sendTime(this.settings.time);
  }

  /** Called for every frame shown. */
  frameShown(header) {
    this.shownTime = header.sceneTime;
    if (this.awaitedInput !== null && header.inputId >= this.awaitedInput) this.awaitedInput = null;
    if (this.settings.time === null) this.#render();
  }

  play() {
    if (!this.#count()) return;
    this.playing = true;
    this.position = this.#positionOf(this.settings.time ?? this.shownTime ?? 0);
    if (this.position >= this.#last()) this.position = 0;
    this.lastTick = null;
    this.awaitedInput = null;
    this.#render();
  }

  pause() {
    this.playing = false;
    this.#render();
  }

  /** Shows scene time `time` (stopping playback); returns the time input's id. */
  pinAt(time) {
    this.playing = false;
    this.settings.time = time;
    const id = this.sendTime(time);
    this.awaitedInput = id;
    this.saved();
    this.#render();
    return id;
  }

  /** Follows the newest state (live), stopping playback. */
  follow() {
    this.pause();
    this.settings.time = null;
    this.sendTime(null);
    this.saved();
    this.#render();
  }

  #count() {
    return this.steps ? this.steps.length : DEMO_SPAN_SECS / DEMO_STEP_SECS;
  }

  #last() {
    return this.steps ? this.steps.length - 1 : DEMO_SPAN_SECS;
  }

  /** Scrubber position of scene time `t`: itself for demos, the step shown at `t` for stored scenes. */
  #positionOf(t) {
    if (!this.steps) return Math.max(0, Math.min(DEMO_SPAN_SECS, t));
    let i = 0;
    while (i + 1 < this.steps.length && this.steps[i + 1].time <= t) i += 1;
    return i;
  }

  #timeAt(position) {
    if (!this.steps) return Math.round(position / DEMO_STEP_SECS) * DEMO_STEP_SECS;
    return this.steps[Math.max(0, Math.min(this.steps.length - 1, Math.floor(position)))].time;
  }

  #pin(time) {
    if (time === this.settings.time) return;
    this.settings.time = time;
    this.awaitedInput = this.sendTime(time);
    this.saved();
  }

  #scrub() {
    const position = Number(this.el.slider.value);
    this.playing = false;
    this.#pin(this.#timeAt(position));
    this.#render();
  }

  #tick(now) {
    requestAnimationFrame((t) => this.#tick(t));
    if (!this.playing) return;
    const dt = this.lastTick === null ? 0 : Math.min(0.25, (now - this.lastTick) / 1000);
    this.lastTick = now;
    if (this.awaitedInput !== null) return; // the previous time is not on screen yet
    this.position += dt * this.settings.speed;
    const last = this.#last();
    if (this.position > last + (this.steps ? 1 : 0) - 1e-9) {
      if (this.settings.loop) this.position = 0;
      else { this.position = last; this.pause(); }
    }
    this.#pin(this.#timeAt(this.position));
    this.#render();
  }

  async #pollSteps() {
    if (!this.scene || !this.steps || document.hidden || !this.online()) return;
    try {
      const response = await apiFetch(`/api/v1/scenes/${encodeURIComponent(this.scene.id)}/steps`);
      if (!response.ok) return;
      const { steps } = await response.json();
      if (Array.isArray(steps)) {
        this.steps = steps.map((s) => ({ index: s.index, time: s.time }));
        this.#render();
      }
    } catch {
      // The connection's own reconnect reports an unreachable server; polling just waits.
    }
  }

  #render() {
    const { slider, out, play, live, speedOut } = this.el;
    const isLive = this.settings.time === null;
    const count = this.steps ? this.steps.length : null;
    if (this.steps) {
      slider.min = '0';
      slider.max = String(Math.max(0, count - 1));
      slider.step = '1';
    } else {
      slider.min = '0';
      slider.max = String(DEMO_SPAN_SECS);
      slider.step = String(DEMO_STEP_SECS);
    }
    slider.disabled = this.steps !== null && count === 0;
    const t = isLive ? this.shownTime : this.settings.time;
    if (t !== null) slider.value = String(this.#positionOf(t));
    if (isLive && this.steps) slider.value = slider.max;
    const at = Number(slider.value);
    const label = this.steps
      // The step's own index as pushed (a simulation may number them 0, 10, 20, …) and where it
      // stands among the stored steps.
      ? (count ? `step ${this.steps[at]?.index ?? '–'} (${at + 1} of ${count}, t = ${fmt(this.#timeAt(at))})` : 'no steps yet')
      : `${fmt(t ?? 0)} s`;
    out.textContent = isLive ? `live · ${label}` : label;
    slider.setAttribute('aria-valuetext', out.textContent);
    play.textContent = this.playing ? 'Pause' : 'Play';
    play.setAttribute('aria-pressed', String(this.playing));
    play.disabled = this.steps !== null && count < 2;
    live.setAttribute('aria-pressed', String(isLive));
    speedOut.textContent = this.steps ? `${this.settings.speed} steps/s` : `${this.settings.speed}×`;
  }
}

function fmt(t) {
  return Number.isInteger(t) ? String(t) : t.toFixed(2);
}

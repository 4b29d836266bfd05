// The statistics overlay: frames per second, input-to-frame latency, bandwidth and the
// server's stage timings (update, build, trace, encode, from each frame's header), as numbers
// and as a live plot of the last 30 seconds. Every number is measured from the frames this
// page received; nothing is estimated.

import { codecLabel, FLAG_STILL, FLAG_FINAL } from './protocol.js';

const WINDOW_MS = 1000; // frames and bytes per second are counted over the last second
const HISTORY_MS = 30000; // span of the plot
const SAMPLE_MS = 250;
// A still frame says whether the server is still refining the resting view or is done.
function stillLabel(flags) {
  if (!(flags & FLAG_STILL)) return '';
  return flags & FLAG_FINAL ? ' still, final' : ' still, refining';
}

const STAGES = [['update', 'updateUs', '#c9a227'], ['build', 'buildUs', '#d9682b'], ['trace', 'traceUs', '#4f9de0'], ['encode', 'encodeUs', '#8f6fd8']];

export class Stats {
  constructor(panel, text, plot) {
    this.panel = panel;
    this.text = text;
    this.plot = plot;
    this.arrivals = []; // [performance.now(), bytes]
    this.latencies = []; // [performance.now(), ms]
    this.samples = []; // { t, fps, latencyMs, mbps, stages: [ms × 4] }
    this.last = null; // header of the last frame
    this.framesTotal = 0;
    this.fps = 0;
    setInterval(() => this.#sample(), SAMPLE_MS);
  }

  get shown() {
    return !this.panel.hidden;
  }

  set shown(on) {
    this.panel.hidden = !on;
    if (on) this.#render();
  }

  /** Records a frame as it is shown: its size on the wire and, if it answers an input, the latency. */
  frame(header, bytes, latencyMs) {
    const now = performance.now();
    this.arrivals.push([now, bytes]);
    if (latencyMs !== null) this.latencies.push([now, latencyMs]);
    this.last = header;
    this.framesTotal += 1;
  }

  #sample() {
    const now = performance.now();
    while (this.arrivals.length && this.arrivals[0][0] <= now - WINDOW_MS) this.arrivals.shift();
    while (this.latencies.length && this.latencies[0][0] <= now - 5000) this.latencies.shift();
    while (this.samples.length && this.samples[0].t <= now - HISTORY_MS) this.samples.shift();
    this.fps = this.arrivals.length;
    const lat = this.latencies.length ? this.latencies[this.latencies.length - 1][1] : null;
    const mbps = (this.arrivals.reduce((sum, [, b]) => sum + b, 0) * 8) / 1e6 / (WINDOW_MS / 1000);
    const h = this.last;
    this.samples.push({ t: now, fps: this.fps, latencyMs: lat, mbps, stages: STAGES.map(([, key]) => (h ? h[key] / 1000 : 0)) });
    if (this.shown) this.#render();
  }

  #render() {
    const s = this.samples[this.samples.length - 1];
    const h = this.last;
    const ms = (v) => `${v.toFixed(1)} ms`;
    const lines = [
      `fps      ${this.fps}`,
      `latency  ${s && s.latencyMs !== null ? ms(s.latencyMs) : '–'}`,
      `bitrate  ${s ? s.mbps.toFixed(2) : '0.00'} Mbit/s`,
    ];
    if (h) {
      lines.push(`size     ${h.width}×${h.height} ${codecLabel(h.codec)}${stillLabel(h.flags)}`);
      for (const [name, key] of STAGES) lines.push(`${name.padEnd(8)} ${ms(h[key] / 1000)}`);
    }
    this.text.textContent = lines.join('\n');
    this.text.dataset.sample = String(this.samples.length ? Math.round(s.t) : 0);
    this.#plot();
  }

  #plot() {
    const c = this.plot;
    const dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth, h = c.clientHeight;
    if (!w || !h) return;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr);
      c.height = Math.round(h * dpr);
    }
    const g = c.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, h);
    g.font = '10px ui-monospace, monospace';
    const now = performance.now();
    const x = (t) => w - ((now - t) / HISTORY_MS) * w;
    const rows = [
      ['fps', (s) => s.fps, '#7bd88f'],
      ['ms latency', (s) => s.latencyMs, '#f2c14e'],
      ['Mbit/s', (s) => s.mbps, '#5bc0eb'],
    ];
    const rowH = h / 4;
    rows.forEach(([label, value, colour], i) => {
      const top = i * rowH;
      const max = Math.max(1e-9, ...this.samples.map(value).filter((v) => v !== null));
      g.strokeStyle = colour;
      g.beginPath();
      let started = false;
      for (const s of this.samples) {
        const v = value(s);
        if (v === null) { started = false; continue; }
        const y = top + rowH - 2 - (v / max) * (rowH - 12);
        if (started) g.lineTo(x(s.t), y); else g.moveTo(x(s.t), y);
        started = true;
      }
      g.stroke();
      g.fillStyle = colour;
      g.fillText(`${label} (max ${max < 10 ? max.toFixed(1) : Math.round(max)})`, 2, top + 9);
    });
    // Stage timings of the latest frame at each sample, stacked.
    const top = 3 * rowH;
    const total = (s) => s.stages.reduce((a, b) => a + b, 0);
    const max = Math.max(1e-9, ...this.samples.map(total));
    const barW = Math.max(1, (w * SAMPLE_MS) / HISTORY_MS);
    for (const s of this.samples) {
      let y = top + rowH - 2;
      s.stages.forEach((v, k) => {
        const bh = (v / max) * (rowH - 12);
        g.fillStyle = STAGES[k][2];
        g.fillRect(x(s.t) - barW, y - bh, barW, bh);
        y -= bh;
      });
    }
    let lx = 2;
    for (const [name, , colour] of STAGES) {
      g.fillStyle = colour;
      g.fillText(name, lx, top + 9);
      lx += g.measureText(name).width + 6;
    }
    g.fillStyle = '#aaa';
    g.fillText(`${max < 10 ? max.toFixed(1) : Math.round(max)} ms`, lx, top + 9);
  }
}

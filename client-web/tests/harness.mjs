// Shared helpers of the browser tests: the real server binary, Debian's chromium through
// playwright-core, frames counted on the wire, image comparison of the canvas, and failure
// screenshots. Every page records console errors, page errors and unhandled promise
// rejections; a test fails on any of them.
import { spawn } from 'node:child_process';
import { mkdirSync, mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = dirname(fileURLToPath(import.meta.url));
export const repoRoot = resolve(here, '..', '..');
export const screenshotDir = join(repoRoot, 'tests', 'browser', 'screenshots');

/**
 * Starts `isoray` on 127.0.0.1 (an ephemeral port unless `port` is given) with its own empty
 * data directory; resolves once it prints its address.
 */
export async function startServer({ args = [], port = 0, dataDir = null } = {}) {
  const bin = process.env.ISORAY_BIN || join(repoRoot, 'target', 'debug', 'isoray');
  const ownDir = dataDir === null;
  const dir = dataDir ?? mkdtempSync(join(tmpdir(), 'isoray-browser-'));
  const child = spawn(bin, ['--listen', `127.0.0.1:${port}`, '--log', 'warn', '--data-dir', dir, ...args],
    { stdio: ['ignore', 'pipe', 'pipe'] });
  let stderr = '';
  child.stderr.on('data', (d) => { stderr += d; });
  const url = await new Promise((resolveUrl, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error(`server did not start: ${stderr}`)), 20000);
    child.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/open (http:\/\/[^/\s]+\/)/);
      if (m) { clearTimeout(timer); resolveUrl(m[1]); }
    });
    child.on('exit', (code) => { clearTimeout(timer); reject(new Error(`server exited with ${code}: ${stderr}`)); });
  });
  return {
    url,
    port: Number(new URL(url).port),
    dataDir: dir,
    async stop({ keepData = false } = {}) {
      if (child.exitCode === null && child.signalCode === null) {
        const exited = new Promise((r) => child.once('exit', r));
        child.kill('SIGTERM');
        await exited;
      }
      if (ownDir && !keepData) rmSync(dir, { recursive: true, force: true });
    },
  };
}

/** Launches headless chromium and a page that records every console error and page error. */
export async function openBrowser() {
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--headless', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  const context = await browser.newContext({ viewport: { width: 720, height: 480 }, acceptDownloads: true, hasTouch: true });
  const page = await context.newPage();
  const problems = [];
  // Network errors the test provokes on purpose (a stopped server) are allowed only while
  // `expectNetworkErrors` is set, and only the browser's own connection-refused messages.
  // A test that provokes another browser-logged HTTP failure names it in `expectStatus`.
  const state = { expectNetworkErrors: false, expectStatus: null, expected: [] };
  page.on('console', (msg) => {
    if (msg.type() !== 'error') return;
    const text = msg.text();
    if (state.expectNetworkErrors && /ERR_CONNECTION_REFUSED|WebSocket connection to .* failed/.test(text)) {
      state.expected.push(text);
      return;
    }
    if (state.expectStatus !== null && text.includes(`the server responded with a status of ${state.expectStatus}`)) {
      state.expected.push(text);
      return;
    }
    problems.push(`console error: ${text}`);
  });
  page.on('pageerror', (err) => problems.push(`page error: ${err.message}`));
  await page.addInitScript(() => {
    window.addEventListener('unhandledrejection', (e) => console.error(`unhandled rejection: ${e.reason && e.reason.stack || e.reason}`));
  });
  return { browser, context, page, problems, network: state };
}

/**
 * Counts binary websocket messages (frames) the page receives, independently of the app: when
 * each arrived, its bytes and the codec byte of its header.
 */
export function countWireFrames(page) {
  const counter = { frames: 0, times: [], bytes: [], codecs: [] };
  page.on('websocket', (ws) => {
    ws.on('framereceived', ({ payload }) => {
      if (typeof payload !== 'string') {
        counter.frames += 1;
        counter.times.push(Date.now());
        counter.bytes.push(payload.length);
        counter.codecs.push(payload[32]); // the header's codec byte
      }
    });
  });
  return counter;
}

/** Frames the page has drawn so far. */
export async function frameCount(page) {
  return Number(await page.locator('#view').getAttribute('data-frames') || 0);
}

/** Waits until the page has drawn `n` more frames than `from` (default: now). */
export async function waitForFrames(page, n = 1, { from = null, timeout = 20000 } = {}) {
  const start = from ?? await frameCount(page);
  await page.waitForFunction((target) => Number(document.getElementById('view').dataset.frames || 0) >= target,
    start + n, { timeout });
}

/**
 * Waits for the view to settle after an action — a new frame since `from` frames, the last
 * one the server's lossless still frame, then `quietMs` with no frame — and returns the pixels.
 */
export async function settledPixels(page, { from = 0, quietMs = 400, timeout = 30000 } = {}) {
  const deadline = Date.now() + timeout;
  // A still frame of the size the viewer asks for now: on a busy machine the page's layout
  // (and so the size it asks for) can settle after the first still frame arrived.
  const stillAtSize = (n) => {
    const v = window.isoray && window.isoray.view;
    if (!(v && v.framesShown > n && v.lastHeader && (v.lastHeader.flags & 1) === 1)) return false;
    const [w, h] = window.isoray.quality.size();
    return v.lastHeader.width === w && v.lastHeader.height === h;
  };
  await page.waitForFunction(stillAtSize, from, { timeout });
  let last = await frameCount(page);
  let since = Date.now();
  while (Date.now() < deadline) {
    await page.waitForTimeout(100);
    const now = await frameCount(page);
    if (now !== last) { last = now; since = Date.now(); } else if (Date.now() - since >= quietMs) {
      if (await page.evaluate(stillAtSize, from)) break;
      since = Date.now();
    }
  }
  return canvasPixels(page);
}

/**
 * The canvas as { width, height, data: Buffer } (RGBA), moved out of the page as base64;
 * resampled to `size` ([w, h]) when given, to compare frames of different resolutions.
 */
export async function canvasPixels(page, size = null) {
  const { width, height, base64 } = await page.evaluate((size) => {
    let c = document.getElementById('view');
    if (size) {
      const r = document.createElement('canvas');
      [r.width, r.height] = size;
      r.getContext('2d').drawImage(c, 0, 0, r.width, r.height);
      c = r;
    }
    const bytes = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let binary = '';
    for (let i = 0; i < bytes.length; i += 0x8000) binary += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
    return { width: c.width, height: c.height, base64: btoa(binary) };
  }, size);
  return { width, height, data: Buffer.from(base64, 'base64') };
}

/** Mean absolute difference per colour channel, 0–255; Infinity if sizes differ. */
export function meanAbsDiff(a, b) {
  if (a.width !== b.width || a.height !== b.height) return Infinity;
  let sum = 0, n = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    for (let c = 0; c < 3; c++) sum += Math.abs(a.data[i + c] - b.data[i + c]);
    n += 3;
  }
  return sum / n;
}

/** Standard deviation of the grey level: a flat canvas has none. */
export function stddev(img) {
  const g = [];
  for (let i = 0; i < img.data.length; i += 4) g.push((img.data[i] + img.data[i + 1] + img.data[i + 2]) / 3);
  const mean = g.reduce((s, v) => s + v, 0) / g.length;
  return Math.sqrt(g.reduce((s, v) => s + (v - mean) ** 2, 0) / g.length);
}

/** Drags the mouse across the canvas from its centre by (dx, dy) pixels. */
export async function drag(page, dx, dy, { button = 'left', shift = false } = {}) {
  await page.locator('#view').scrollIntoViewIfNeeded();
  const box = await page.locator('#view').boundingBox();
  const x = box.x + box.width / 2, y = box.y + box.height / 2;
  if (shift) await page.keyboard.down('Shift');
  await page.mouse.move(x, y);
  await page.mouse.down({ button });
  await page.mouse.move(x + dx, y + dy, { steps: 6 });
  await page.mouse.up({ button });
  if (shift) await page.keyboard.up('Shift');
}

/**
 * Runs `body` with a server, a browser and a page; saves a screenshot on failure; fails on
 * any console error, page error or unhandled rejection.
 */
export async function withPage(name, body, { serverArgs = [] } = {}) {
  const servers = [await startServer({ args: serverArgs })];
  const { browser, page, problems, network } = await openBrowser();
  const ctx = {
    server: servers[0],
    page,
    network,
    /** Starts another server (e.g. on the same port and data directory after a stop). */
    async startServer(options) {
      const s = await startServer(options);
      servers.push(s);
      return s;
    },
  };
  try {
    await body(ctx);
    if (problems.length) throw new Error(problems.join('\n'));
  } catch (err) {
    mkdirSync(screenshotDir, { recursive: true });
    const file = join(screenshotDir, `${name}.png`);
    await page.screenshot({ path: file }).catch(() => {});
    err.message += `\n(screenshot: ${file})`;
    if (problems.length && !err.message.includes(problems[0])) err.message += `\n${problems.join('\n')}`;
    throw err;
  } finally {
    await browser.close();
    for (const s of servers.reverse()) await s.stop();
  }
}

/** JSON request to the server's REST API. */
export async function api(server, method, path, body, token) {
  const headers = {};
  if (body !== undefined) headers['content-type'] = 'application/json';
  if (token) headers.authorization = `Bearer ${token}`;
  const response = await fetch(new URL(path, server.url), { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  const text = await response.text();
  if (!response.ok) throw new Error(`${method} ${path}: ${response.status} ${text}`);
  return text ? JSON.parse(text) : null;
}

// Shared helpers of the browser tests: the real server binary, Debian's chromium through
// playwright-core, image comparison of the canvas, and failure screenshots.
import { spawn } from 'node:child_process';
import { mkdirSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = dirname(fileURLToPath(import.meta.url));
export const repoRoot = resolve(here, '..', '..');
export const screenshotDir = join(repoRoot, 'tests', 'browser', 'screenshots');

/** Starts `isoray` on an ephemeral loopback port; resolves once it prints its address. */
export async function startServer(args = []) {
  const bin = process.env.ISORAY_BIN || join(repoRoot, 'target', 'debug', 'isoray');
  const child = spawn(bin, ['--listen', '127.0.0.1:0', '--log', 'warn', ...args], { stdio: ['ignore', 'pipe', 'pipe'] });
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
    child,
    async stop() {
      if (child.exitCode !== null) return;
      const exited = new Promise((r) => child.once('exit', r));
      child.kill('SIGTERM');
      await exited;
    },
  };
}

/** Launches headless chromium and a page that records console errors and page errors. */
export async function openBrowser() {
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--headless', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  const context = await browser.newContext({ viewport: { width: 800, height: 600 } });
  const page = await context.newPage();
  const problems = [];
  page.on('console', (msg) => { if (msg.type() === 'error') problems.push(`console error: ${msg.text()}`); });
  page.on('pageerror', (err) => problems.push(`page error: ${err.message}`));
  return { browser, page, problems };
}

/** Frames the page has drawn so far. */
export async function frameCount(page) {
  return Number(await page.locator('#view').getAttribute('data-frames') || 0);
}

/** Waits until the page has drawn `n` more frames than it had. */
export async function waitForFrames(page, n = 1, timeout = 20000) {
  const start = await frameCount(page);
  await page.waitForFunction((target) => Number(document.getElementById('view').dataset.frames || 0) >= target,
    start + n, { timeout });
}

/** Waits until no frame has arrived for `quietMs` (a still view), then returns the pixels. */
export async function settledPixels(page, quietMs = 600, timeout = 20000) {
  const deadline = Date.now() + timeout;
  let last = await frameCount(page);
  let since = Date.now();
  while (Date.now() < deadline) {
    await page.waitForTimeout(100);
    const now = await frameCount(page);
    if (now !== last) { last = now; since = Date.now(); } else if (Date.now() - since >= quietMs && now > 0) break;
  }
  return canvasPixels(page);
}

/** The canvas as { width, height, data: number[] } (RGBA). */
export async function canvasPixels(page) {
  return page.evaluate(() => {
    const c = document.getElementById('view');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height);
    return { width: c.width, height: c.height, data: Array.from(d.data) };
  });
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

/** Runs `body` with a server, a browser and a page; screenshots on failure; fails on console errors. */
export async function withPage(name, body, { serverArgs = [] } = {}) {
  const server = await startServer(serverArgs);
  const { browser, page, problems } = await openBrowser();
  try {
    await body({ server, page });
    if (problems.length) throw new Error(problems.join('\n'));
  } catch (err) {
    mkdirSync(screenshotDir, { recursive: true });
    const file = join(screenshotDir, `${name}.png`);
    await page.screenshot({ path: file }).catch(() => {});
    err.message += `\n(screenshot: ${file})`;
    throw err;
  } finally {
    await browser.close();
    await server.stop();
  }
}

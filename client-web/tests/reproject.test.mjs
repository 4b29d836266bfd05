// Latency hiding: with depth reprojection on, the canvas answers a camera drag in the first
// display frame after the input, before the server's frame for that input arrives; with it
// off, the canvas changes only when the server's frame arrives (the server's latency).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, settledPixels } from './harness.mjs';

// The 1,000-ball scene at a pinned time, full resolution while moving (a debug server takes
// far longer than a display frame to trace it), and a long rest before the still frame.
const SERVER = ['--min-scale', '1', '--still-after-ms', '3000'];
const PAGE = '?scene=scattered-1k&t=3';
// A short drag, as between two display frames of a real one: about 5° of orbit here.
const DRAG_PX = 8;

/**
 * In the page: drags the canvas by `dx` pixels with pointer events, then records the canvas
 * in the first animation frame after the input and when the server's frame for the camera
 * input arrives. Returns times (ms from the input) and how much the canvas changed.
 */
async function dragAndWatch(page, dx) {
  return page.evaluate(async (dx) => {
    const { view, connection } = window.isoray;
    const canvas = document.getElementById('view');
    const grab = () => {
      const c = document.createElement('canvas');
      [c.width, c.height] = [160, 120];
      c.getContext('2d').drawImage(canvas, 0, 0, c.width, c.height);
      return c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    };
    const diff = (a, b) => {
      let sum = 0;
      for (let i = 0; i < a.length; i += 4) for (let k = 0; k < 3; k++) sum += Math.abs(a[i + k] - b[i + k]);
      return sum / (a.length * 0.75);
    };
    const before = grab();
    const framesBefore = view.framesShown;
    const rect = canvas.getBoundingClientRect();
    const at = (x) => ({ pointerId: 1, isPrimary: true, button: 0, buttons: 1, bubbles: true,
      clientX: rect.left + rect.width / 2 + x, clientY: rect.top + rect.height / 2 });
    const t0 = performance.now();
    const firstInput = connection.nextInputId; // the camera input this drag sends
    canvas.dispatchEvent(new PointerEvent('pointerdown', at(0)));
    canvas.dispatchEvent(new PointerEvent('pointermove', at(dx)));
    // The app sends the camera (and reprojects) in its requestAnimationFrame callback, which
    // runs before this one in the same display frame.
    await new Promise((r) => requestAnimationFrame(() => r()));
    const firstFrameMs = performance.now() - t0;
    const inFirstFrame = grab();
    const serverFrameByFirstFrame = view.framesShown > framesBefore;
    canvas.dispatchEvent(new PointerEvent('pointerup', at(dx)));
    // Now wait for the server's frame that answers the camera input.
    const deadline = performance.now() + 20000;
    while (!(view.lastHeader && view.lastHeader.inputId >= firstInput) && performance.now() < deadline) {
      await new Promise((r) => requestAnimationFrame(() => r()));
    }
    const serverMs = performance.now() - t0;
    const answered = view.lastHeader.inputId >= firstInput;
    const fromServer = grab();
    return {
      firstFrameMs,
      serverMs,
      answered,
      serverFrameByFirstFrame,
      changedInFirstFrame: diff(before, inFirstFrame),
      changedByServer: diff(before, fromServer),
      warpVsServer: diff(inFirstFrame, fromServer),
      warps: window.isoray.reproject.warps,
    };
  }, dx);
}

/** Opens the page and waits for a settled view whose last interactive frame carried depth. */
async function ready(page, url) {
  await page.goto(url);
  await waitForFrames(page, 1);
  // Nudge the camera once so an interactive frame (with its depth block) arrives, then rest.
  await page.keyboard.press('Tab');
  await page.locator('#view').focus();
  await page.keyboard.press('ArrowLeft');
  await settledPixels(page, { quietMs: 300 });
}

test('with reprojection on, a drag moves the picture in the first display frame', async () => {
  await withPage('reproject-on', async ({ page, server }) => {
    await ready(page, server.url + PAGE);
    assert.equal(await page.evaluate(() => window.isoray.reproject.ready), true, 'a frame with depth is loaded');
    const r = await dragAndWatch(page, DRAG_PX);
    console.log('reprojection on:', JSON.stringify(r));
    assert.equal(r.answered, true, 'the server answered the drag');
    assert.equal(r.serverFrameByFirstFrame, false, 'the server frame had not arrived yet');
    // An 8-pixel orbit of the 1,000 balls changes the canvas by about 16 grey levels on
    // average (measured 15.8); an unchanged canvas differs by 0.
    assert.ok(r.changedInFirstFrame > 2, `the canvas changed in the first display frame (${r.changedInFirstFrame.toFixed(2)})`);
    assert.ok(r.firstFrameMs < r.serverMs, `reprojected after ${r.firstFrameMs.toFixed(1)} ms, server frame after ${r.serverMs.toFixed(1)} ms`);
    // The reprojected picture is close to the true one: measured at half the distance of the
    // picture before the drag (7.7 against 15.8); holes and quantised depth keep it above 0.
    assert.ok(r.warpVsServer < 0.7 * r.changedByServer,
      `reprojection ${r.warpVsServer.toFixed(2)} from the true frame, the old view ${r.changedByServer.toFixed(2)}`);
  }, { serverArgs: SERVER });
});

test('with reprojection off, the canvas waits for the server frame', async () => {
  await withPage('reproject-off', async ({ page, server }) => {
    await ready(page, server.url + PAGE + '&reproject=off');
    assert.equal(await page.evaluate(() => window.isoray.reproject.ready), false);
    const r = await dragAndWatch(page, DRAG_PX);
    console.log('reprojection off:', JSON.stringify(r));
    assert.equal(r.answered, true);
    assert.equal(r.serverFrameByFirstFrame, false);
    assert.equal(r.changedInFirstFrame, 0, 'nothing moves before the server frame');
    assert.ok(r.changedByServer > 2, `the server frame moves the picture (${r.changedByServer.toFixed(2)})`);
    assert.equal(r.warps, 0);
  }, { serverArgs: SERVER });
});

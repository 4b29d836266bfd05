// The statistics overlay shows real numbers: its frame rate matches the frames the test
// itself counts on the websocket (not the app's own counter), and it is toggled with a key.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, countWireFrames } from './harness.mjs';

const overlayFps = async (page) => {
  const m = /fps\s+(\d+)/.exec(await page.locator('#stats-text').textContent());
  assert.ok(m, 'the overlay shows a frame rate');
  return Number(m[1]);
};

test('the stats overlay shows the frame rate the page really receives', async (t) => {
  await withPage('stats-fps', async ({ server, page }) => {
    const wire = countWireFrames(page);
    // A live (unpinned) demo animates, so frames keep coming at the server's pace.
    await page.goto(server.url + '?scene=blobs');
    await waitForFrames(page, 3);
    assert.equal(await page.locator('#stats').isHidden(), true, 'the overlay starts hidden');
    await page.locator('#view').focus();
    await page.keyboard.press('s');
    assert.equal(await page.locator('#stats').isVisible(), true, 'the s key shows the overlay');
    await page.waitForURL(/stats=1/);

    // Each reading is the number of frames of the last second; compare it with the frames
    // that crossed the wire in the second before the reading.
    const pairs = [];
    const rates = [];
    const codecs = []; // [codec the overlay names, codec numbers on the wire in the second before]
    for (let i = 0; i < 8; i++) {
      // Read each new sample as soon as the overlay shows it, so it and the wire count cover
      // the same second.
      await page.waitForTimeout(300);
      const sample = await page.locator('#stats-text').getAttribute('data-sample');
      await page.waitForFunction((prev) => document.getElementById('stats-text').dataset.sample !== prev, sample);
      const text = await page.locator('#stats-text').textContent();
      const now = Date.now();
      const recent = wire.times.map((t, k) => [t, wire.bytes[k]]).filter(([t]) => t > now - 1000);
      pairs.push([Number(/fps\s+(\d+)/.exec(text)[1]), recent.length]);
      rates.push([Number(/bitrate\s+([\d.]+)/.exec(text)[1]), recent.reduce((a, [, b]) => a + b, 0) * 8 / 1e6]);
      const shown = /^size\s+\d+×\d+ (.+?)( still, (?:refining|final))?$/m.exec(text);
      assert.ok(shown, `the overlay shows the frame's size and codec (${text})`);
      codecs.push([shown[1], [...new Set(wire.codecs.filter((_, k) => wire.times[k] > now - 1000))]]);
    }
    const meanShown = pairs.slice(2).reduce((a, [s]) => a + s, 0) / (pairs.length - 2);
    const meanWire = pairs.slice(2).reduce((a, [, w]) => a + w, 0) / (pairs.length - 2);
    t.diagnostic(`overlay fps vs wire frames in the last second: ${JSON.stringify(pairs)}; Mbit/s overlay vs wire: ${JSON.stringify(rates.map((r) => r.map((v) => +v.toFixed(2))))}`);
    assert.ok(meanWire >= 2, `frames arrive while the scene animates (${meanWire.toFixed(1)} per second on the wire)`);
    // The overlay counts frames once drawn, the test once the browser reports them, so a
    // frame near the edge of the second can fall on either side; averaged, within 20% or 2 fps.
    assert.ok(Math.abs(meanShown - meanWire) <= Math.max(2, 0.2 * meanWire),
      `overlay fps ${meanShown.toFixed(1)} vs ${meanWire.toFixed(1)} frames per second on the wire (${JSON.stringify(pairs)})`);

    // The codec by its name, one that crossed the wire in the second before (an animated demo
    // goes from JPEG to H.264 once its motion is sustained, where the browser decodes H.264).
    const names = { 1: 'JPEG', 2: 'PNG', 3: 'H.264' };
    t.diagnostic(`overlay codec vs codecs on the wire: ${JSON.stringify(codecs)}`);
    for (const [shown, onWire] of codecs) {
      assert.ok(onWire.map((c) => names[c]).includes(shown), `the overlay names "${shown}", the wire carried codecs ${JSON.stringify(onWire)}`);
    }

    // The other figures are there and plausible: latency in ms, bit rate from the bytes.
    const text = await page.locator('#stats-text').textContent();
    for (const label of ['latency', 'bitrate', 'update', 'build', 'trace', 'encode']) assert.match(text, new RegExp(label));
    const meanRate = (k) => rates.slice(2).reduce((a, r) => a + r[k], 0) / (rates.length - 2);
    assert.ok(meanRate(1) > 0, 'bytes arrive');
    assert.ok(Math.abs(meanRate(0) - meanRate(1)) <= 0.25 * meanRate(1),
      `overlay bit rate ${meanRate(0).toFixed(2)} vs ${meanRate(1).toFixed(2)} Mbit/s on the wire`);

    await page.keyboard.press('s');
    assert.equal(await page.locator('#stats').isHidden(), true, 'the s key hides the overlay again');
  });
});

test('the stats overlay tells a resting view still refining from a finished one', async () => {
  await withPage('stats-final', async ({ server, page }) => {
    // A pinned time: the view rests, its still frames refine (the antialiasing positions),
    // and the last of them carries the final flag, which the overlay names.
    await page.goto(server.url + '?scene=blobs&t=3&stats=1');
    await waitForFrames(page, 1);
    await page.waitForFunction(
      () => /^size\s+\d+×\d+ PNG still, final$/m.test(document.getElementById('stats-text').textContent),
      null,
      { timeout: 60000 },
    );
    const text = await page.locator('#stats-text').textContent();
    assert.match(text, /still, final/, text);
  });
});

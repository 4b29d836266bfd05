// Codecs in the browser: the page tells the server what it decodes; sustained motion then
// arrives as H.264, which WebCodecs decodes onto the canvas, and a page that turns H.264 off
// gets JPEG only.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, canvasPixels, stddev } from './harness.mjs';

/** Waits until `n` frames of codec `codec` have been shown; returns the codecs seen. */
async function framesOf(page, codec, n) {
  return page.evaluate(async ({ codec, n }) => {
    const { view } = window.isoray;
    const seen = [];
    let count = 0, last = view.framesShown;
    const deadline = performance.now() + 20000;
    while (count < n && performance.now() < deadline) {
      await new Promise((r) => requestAnimationFrame(() => r()));
      if (view.framesShown !== last) {
        last = view.framesShown;
        seen.push(view.lastHeader.codec);
        if (view.lastHeader.codec === codec) count += 1;
      }
    }
    return seen;
  }, { codec, n });
}

test('sustained motion streams H.264 that the page decodes', async () => {
  await withPage('h264', async ({ page, server }) => {
    // The live animation is sustained motion.
    await page.goto(server.url + '?scene=blobs');
    const seen = await framesOf(page, 3, 10);
    console.log('codecs shown:', seen.join(','));
    assert.ok(seen.filter((c) => c === 3).length >= 10, `ten H.264 frames shown: ${seen.join(',')}`);
    const img = await canvasPixels(page);
    assert.ok(stddev(img) > 10, `the decoded frames show the scene (stddev ${stddev(img).toFixed(1)})`);
  }, { serverArgs: ['--max-fps', '20'] });
});

test('a page without H.264 gets JPEG for the same motion', async () => {
  await withPage('no-h264', async ({ page, server }) => {
    await page.goto(server.url + '?scene=blobs&h264=off');
    const seen = await framesOf(page, 1, 25);
    assert.ok(seen.every((c) => c === 1), `JPEG only: ${seen.join(',')}`);
  }, { serverArgs: ['--max-fps', '20'] });
});

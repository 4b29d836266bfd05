// Quality settings reach the server: the codec preference decides what arrives on the wire,
// and the target frame rate caps how many frames come. Both are kept in the URL.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withPage, waitForFrames, countWireFrames, canvasPixels, stddev } from './harness.mjs';

const CODEC = { jpeg: 1, png: 2, h264: 3 };

/** Records the codec byte of every frame header the page receives. */
function recordCodecs(page) {
  const codecs = [];
  page.on('websocket', (ws) => ws.on('framereceived', ({ payload }) => {
    if (typeof payload !== 'string') codecs.push(payload[32]);
  }));
  return codecs;
}

/** The codecs of the frames that arrive over the next `n` frames the page shows. */
async function nextCodecs(page, wire, n) {
  await page.waitForTimeout(500); // frames already on their way under the old preference
  const from = wire.length;
  await waitForFrames(page, n);
  return wire.slice(from);
}

test('the codec menu offers what both ends decode, and the choice is what arrives', async () => {
  await withPage('codec-choice', async ({ server, page }) => {
    const wire = recordCodecs(page);
    await page.goto(`${server.url}?scene=blobs`);
    await waitForFrames(page, 2);
    assert.ok(await page.locator('#codec').isVisible(), 'the codec menu shows once the server lists codecs');
    const offered = await page.locator('#codec option').evaluateAll((els) => els.map((e) => e.value));
    const { decodable, serverCodecs } = await page.evaluate(() => ({
      decodable: window.isoray.quality.decodable, serverCodecs: window.isoray.quality.info.codecs,
    }));
    assert.deepEqual(offered, ['auto', ...decodable.filter((c) => serverCodecs.includes(c))],
      `the menu (${offered}) is the browser's codecs (${decodable}) the server sends (${serverCodecs})`);
    assert.ok(offered.includes('jpeg') && offered.includes('png'));

    // PNG only: every frame of the animating demo is lossless, and shows the scene.
    await page.selectOption('#codec', 'png');
    await page.waitForURL(/codec=png/);
    const png = await nextCodecs(page, wire, 3);
    assert.deepEqual([...new Set(png)], [CODEC.png], `PNG frames only: ${png}`);
    assert.equal(await page.evaluate(() => window.isoray.view.lastHeader.codec), CODEC.png, 'the page shows PNG frames');
    const img = await canvasPixels(page);
    assert.ok(stddev(img) > 10, `the PNG frames show the scene (stddev ${stddev(img).toFixed(1)})`);

    // JPEG: the moving view comes as JPEG, never as video.
    await page.selectOption('#codec', 'jpeg');
    await page.waitForURL(/codec=jpeg/);
    const jpeg = await nextCodecs(page, wire, 3);
    assert.ok(jpeg.includes(CODEC.jpeg), `JPEG frames arrive: ${jpeg}`);
    assert.ok(!jpeg.includes(CODEC.h264) && !jpeg.includes(CODEC.png), `and nothing else while moving: ${jpeg}`);

    // The preference survives a reload, and the new session honours it.
    await page.reload();
    await waitForFrames(page, 1);
    assert.equal(await page.locator('#codec').inputValue(), 'jpeg', 'the menu shows the kept preference');
    const reloaded = await nextCodecs(page, wire, 3);
    assert.ok(reloaded.length > 0 && reloaded.every((c) => c === CODEC.jpeg), `JPEG after the reload: ${reloaded}`);
  });
});

/** Frames per second on the wire over `ms` milliseconds. */
async function wireRate(page, wire, ms) {
  const before = wire.frames;
  const start = Date.now();
  await page.waitForTimeout(ms);
  return (wire.frames - before) / ((Date.now() - start) / 1000);
}

test('the target frame rate caps the frames that arrive, and is kept in the URL', async (t) => {
  await withPage('target-fps', async ({ server, page }) => {
    const wire = countWireFrames(page);
    // A small window keeps frames cheap, so the server's cap is what limits the rate.
    await page.setViewportSize({ width: 480, height: 360 });
    await page.goto(`${server.url}?scene=blobs&scale=0.25`);
    await waitForFrames(page, 3);
    assert.equal(await page.locator('#fps').getAttribute('max'), '20', 'the slider runs up to the server\'s --max-fps');
    const full = await wireRate(page, wire, 3000);
    t.diagnostic(`frames per second on the wire at the server's maximum (20): ${full.toFixed(2)}`);

    await page.locator('#fps').fill('3');
    await page.waitForURL(/fps=3/);
    await page.waitForTimeout(1000);
    const capped = await wireRate(page, wire, 4000);
    t.diagnostic(`frames per second on the wire at a target of 3: ${capped.toFixed(2)}`);
    assert.ok(capped > 0.5, `frames still come (${capped.toFixed(2)} per second)`);
    assert.ok(capped <= 3.75, `at most the target, give or take a frame in the window (${capped.toFixed(2)} per second)`);
    assert.ok(full > 2 * capped, `the target is what slowed them (${full.toFixed(2)} before)`);

    await page.reload();
    await waitForFrames(page, 1);
    assert.equal(await page.locator('#fps').inputValue(), '3', 'the target survives a reload');
    await page.waitForTimeout(1000);
    const reloaded = await wireRate(page, wire, 3000);
    assert.ok(reloaded <= 3.75, `the new session honours it (${reloaded.toFixed(2)} per second)`);

    // Back to the top: the server is told its maximum again (the URL forgets the target).
    await page.locator('#fps').fill('20');
    await page.waitForURL((url) => !url.searchParams.has('fps'));
    await page.waitForTimeout(1000);
    const again = await wireRate(page, wire, 3000);
    t.diagnostic(`frames per second on the wire back at the maximum: ${again.toFixed(2)}`);
    assert.ok(again > 2 * capped, `frames come faster again (${again.toFixed(2)} per second)`);
  }, { serverArgs: ['--max-fps', '20'] });
});

// The rest of the viewer: the lossless screenshot, the waiting state before the first frame,
// dismissible server errors, the scene picker, labels and keyboard focus order, and a render
// size that follows the canvas and devicePixelRatio within the server's limit.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFile } from 'node:fs/promises';
import { withPage, waitForFrames, settledPixels, frameCount } from './harness.mjs';

test('the screenshot button downloads the still frame as a lossless PNG', async () => {
  await withPage('screenshot', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    const shown = await settledPixels(page);
    const [download] = await Promise.all([page.waitForEvent('download'), page.click('#screenshot')]);
    assert.match(download.suggestedFilename(), /^isoray-blobs-t3-\d+x\d+\.png$/);
    const png = await readFile(await download.path());
    assert.deepEqual([...png.subarray(0, 8)], [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a], 'a PNG file');
    assert.equal(png.readUInt32BE(16), shown.width, 'the width of the frame shown');
    assert.equal(png.readUInt32BE(20), shown.height, 'the height of the frame shown');
    // Decoded, the file has exactly the pixels on the canvas.
    const same = await page.evaluate(async (b64) => {
      const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
      const bitmap = await createImageBitmap(new Blob([bytes], { type: 'image/png' }));
      const c = new OffscreenCanvas(bitmap.width, bitmap.height);
      c.getContext('2d').drawImage(bitmap, 0, 0);
      const a = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      const v = document.getElementById('view');
      const b = v.getContext('2d').getImageData(0, 0, v.width, v.height).data;
      return a.length === b.length && a.every((x, i) => x === b[i]);
    }, png.toString('base64'));
    assert.ok(same, 'the PNG holds the pixels shown');
  });
});

test('before the first frame the page says it is waiting; server errors show until dismissed', async () => {
  await withPage('waiting-and-errors', async ({ server, page }) => {
    // Hold every frame back: the page must show that it waits.
    let hold = true;
    await page.routeWebSocket(/\/stream$/, (ws) => {
      const upstream = ws.connectToServer();
      upstream.onMessage((m) => { if (!hold || typeof m === 'string') ws.send(m); });
      ws.onMessage((m) => upstream.send(m));
    });
    await page.goto(`${server.url}?scene=blobs&t=3`);
    await page.waitForFunction(() => /Waiting for the first frame/.test(document.getElementById('status-text').textContent));
    await page.waitForTimeout(1000);
    assert.equal(await frameCount(page), 0);
    assert.equal(await page.locator('#status').isVisible(), true, 'the waiting banner is visible');
    hold = false;
    // Frames come again once the client moves the view (the held ones were never acknowledged,
    // so the server waits; a new connection starts afresh).
    await page.reload();
    await waitForFrames(page, 1);
    assert.equal(await page.locator('#status').isHidden(), true);

    // An input the server rejects: its message shows, and stays until dismissed.
    await page.evaluate(() => window.isoray.connection.send({ type: 'isovalue', value: 1e9 }));
    const error = page.locator('#errors .error');
    await error.first().waitFor();
    assert.match(await error.first().textContent(), /isovalue .* outside .*\(invalid_value\)/);
    await page.waitForTimeout(500);
    assert.equal(await error.count(), 1);
    await page.getByRole('button', { name: /^Dismiss/ }).click();
    assert.equal(await error.count(), 0, 'the dismiss button removes the message');
  });
});

test('the scene picker lists every scene with kind and size, and switches scenes', async () => {
  await withPage('scene-picker', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    await settledPixels(page);
    const { scenes } = await (await fetch(`${server.url}api/v1/scenes`)).json();
    const options = await page.locator('#scene option').allTextContents();
    assert.equal(options.length, scenes.length, 'one option per scene');
    for (const s of scenes) {
      // A name that ends in its kind ("Gyroid (tets)") is listed without it: the kind is said once.
      const name = s.name.replace(` (${s.kind})`, '');
      const line = options.find((o) => o.startsWith(`${name} (`));
      assert.ok(line && line.includes(s.kind) && line.includes(s.primitives.toLocaleString('en')),
        `${s.id} is listed with kind and size: ${options}`);
      assert.equal(line.split(s.kind).length, 2, `"${line}" names the kind once`);
    }
    // A scene pushed after the page loaded shows up when the picker gets focus.
    const created = await (await fetch(`${server.url}api/v1/scenes`, {
      method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify({ kind: 'metaballs', name: 'Late arrival' }),
    })).json();
    await page.locator('#scene').focus();
    await page.waitForFunction((id) => !!document.querySelector(`#scene option[value="${id}"]`), created.scene.id);
    assert.match(await page.locator(`#scene option[value="${created.scene.id}"]`).textContent(), /Late arrival \(metaballs · 0 balls · 0 time steps\)/);

    const before = await frameCount(page);
    await page.selectOption('#scene', 'molecule');
    await page.waitForURL(/scene=molecule/);
    await waitForFrames(page, 1, { from: before });
    assert.match(await page.locator('#scene-details').textContent(), /molecule/i);
    assert.doesNotMatch(page.url(), /[?&]t=/, 'a new scene starts live, from its own view');
  });
});

test('controls are labelled and reachable by keyboard; render size follows canvas × devicePixelRatio', async () => {
  await withPage('a11y-and-size', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3`);
    await waitForFrames(page, 1);
    // Every form control has an accessible name.
    const unnamed = await page.evaluate(() => [...document.querySelectorAll('input, select, button, canvas#view')]
      .filter((el) => !el.closest('[hidden]'))
      .filter((el) => !(el.labels && el.labels.length) && !el.getAttribute('aria-label') && !el.textContent.trim())
      .map((el) => el.id || el.outerHTML.slice(0, 60)));
    assert.deepEqual(unnamed, [], 'controls without a label');
    // Tab walks the header, then the view, then the panel.
    const order = [];
    await page.locator('body').focus();
    for (let i = 0; i < 12; i++) {
      await page.keyboard.press('Tab');
      order.push(await page.evaluate(() => document.activeElement.id));
    }
    const at = (id) => order.indexOf(id);
    assert.ok(at('scene') >= 0 && at('scene') < at('view') && at('view') < at('isovalue'), `focus order ${order}`);

    // Render size: canvas CSS size × devicePixelRatio × scale, capped by the server's limit.
    const size = () => page.evaluate(() => {
      const r = document.getElementById('view').getBoundingClientRect();
      return { css: [r.width, r.height], dpr: devicePixelRatio, sent: window.isoray.quality.size() };
    });
    const s1 = await size();
    assert.deepEqual(s1.sent, s1.css.map((v) => Math.round(v * s1.dpr)));
    let before = await frameCount(page);
    await page.locator('#scale').fill('0.5');
    await settledPixels(page, { from: before });
    const half = await page.evaluate(() => [document.getElementById('view').width, document.getElementById('view').height]);
    assert.deepEqual(half, s1.css.map((v) => Math.round(v * s1.dpr * 0.5)), 'the still frame has the scaled size');
    await page.setViewportSize({ width: 1000, height: 700 });
    before = await frameCount(page);
    await settledPixels(page, { from: before });
    const s2 = await size();
    const bigger = await page.evaluate(() => [document.getElementById('view').width, document.getElementById('view').height]);
    assert.deepEqual(bigger, s2.css.map((v) => Math.round(v * s2.dpr * 0.5)), 'a resized window gets frames of its new size');

    // A phone-sized window: the panel goes below the view and nothing scrolls sideways.
    await page.setViewportSize({ width: 390, height: 800 });
    await page.waitForTimeout(200);
    const layout = await page.evaluate(() => ({
      scrollWidth: document.documentElement.scrollWidth,
      width: innerWidth,
      panelTop: document.getElementById('panel').getBoundingClientRect().top,
      viewBottom: document.getElementById('view').getBoundingClientRect().bottom,
    }));
    assert.ok(layout.scrollWidth <= layout.width, `no sideways scrolling (${layout.scrollWidth} > ${layout.width})`);
    assert.ok(layout.panelTop >= layout.viewBottom - 1, 'the controls sit below the view');
    // With the controls hidden the view fills the window below the header (no empty page under
    // it), and frames follow its new size.
    before = await frameCount(page);
    await page.locator('#panel-toggle').click();
    await page.waitForFunction(() => {
      const r = document.getElementById('view').getBoundingClientRect();
      return Math.abs(r.bottom - innerHeight) <= 1 && document.documentElement.scrollHeight <= innerHeight;
    });
    await settledPixels(page, { from: before });
    const s3 = await size();
    const full = await page.evaluate(() => [document.getElementById('view').width, document.getElementById('view').height]);
    assert.deepEqual(full, s3.css.map((v) => Math.round(v * s3.dpr * 0.5)), 'the view without the controls gets frames of its size');
  });
});

test('the header keeps its buttons together on the right at every width', async () => {
  await withPage('header', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3&scale=0.25`);
    await waitForFrames(page, 1, { from: 0 });
    for (const width of [1600, 1280, 1000, 720, 390]) {
      await page.setViewportSize({ width, height: 700 });
      await page.waitForFunction((w) => innerWidth === w, width);
      const layout = await page.evaluate(() => {
        const rect = (id) => document.getElementById(id).getBoundingClientRect();
        const header = document.querySelector('header');
        const details = document.getElementById('scene-details');
        return {
          tops: ['screenshot', 'stats-toggle', 'panel-toggle'].map((id) => Math.round(rect(id).top)),
          right: rect('panel-toggle').right,
          headerRight: header.getBoundingClientRect().right - parseFloat(getComputedStyle(header).paddingRight),
          cut: details.scrollWidth > details.clientWidth,
          title: details.title,
          text: details.textContent,
        };
      });
      assert.equal(new Set(layout.tops).size, 1, `${width} px: the three buttons on one row (${layout.tops})`);
      assert.ok(Math.abs(layout.right - layout.headerRight) <= 1, `${width} px: the buttons end at the header's right (${layout.right} vs ${layout.headerRight})`);
      assert.equal(layout.title, layout.text, `${width} px: the description's tooltip holds all of it`);
      assert.ok(layout.text.length > 0, 'the scene is described');
    }
  });
});

test('the render size is capped by the server limit', async () => {
  await withPage('size-cap', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs&t=3&scale=2`);
    const still = await settledPixels(page);
    assert.ok(still.width <= 200 && still.height <= 200, `frames within --max-size 200 (${still.width}×${still.height})`);
    assert.ok(still.width === 200 || still.height === 200, 'as large as the limit allows');
  }, { serverArgs: ['--max-size', '200', '--default-width', '160', '--default-height', '90'] });
});

test('with --view-token the page says it needs the token, and with ?token= it streams', async () => {
  await withPage('view-token', async ({ server, page, network }) => {
    // Without the token: the scene list is refused (the browser logs the 401 itself).
    network.expectStatus = 401;
    await page.goto(`${server.url}?scene=blobs&t=3`);
    await page.waitForFunction(() => /needs a view token/.test(document.getElementById('status-text').textContent));
    assert.equal(await frameCount(page), 0);
    assert.ok(network.expected.length >= 1, 'the 401 happened');
    network.expectStatus = null;

    // With it: the list, the stream (token in the websocket's query), the histogram.
    await page.goto(`${server.url}?scene=blobs&t=3&token=peek-0123456789abcdef`);
    await settledPixels(page);
    await page.waitForFunction(() => window.isoray.surfaces.histogram !== null);
    await page.waitForURL(/token=peek-0123456789abcdef/);
  }, { serverArgs: ['--view-token', 'peek-0123456789abcdef'] });
});

test('the scene picker says when a server of the deployment does not answer', async () => {
  // The server lists its peers' scenes with its own (--peers); nothing listens on the peer's
  // port, so its scenes are missing, and the picker says so while still offering the rest.
  await withPage('shards-down', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs`);
    await page.waitForFunction(() => document.getElementById('scene').options.length > 0);
    await page.waitForSelector('#shards-down', { state: 'visible' });
    assert.match(await page.textContent('#shards-down'), /^1 server not answering: its scenes are missing/);
    assert.equal(await page.getAttribute('#shards-down', 'title'), 'http://127.0.0.1:9');
    const ids = await page.$$eval('#scene option', (os) => os.map((o) => o.value));
    assert.ok(ids.includes('blobs'), `this server's scenes are listed: ${ids}`);
  }, { serverArgs: ['--peers', 'http://127.0.0.1:9', '--peer-timeout-ms', '500'] });
  // Without peers (or with every peer answering) there is no note.
  await withPage('shards-up', async ({ server, page }) => {
    await page.goto(`${server.url}?scene=blobs`);
    await page.waitForFunction(() => document.getElementById('scene').options.length > 0);
    assert.equal(await page.isHidden('#shards-down'), true);
  });
});

test('a portrait view sees across what a square view sees, and turned to landscape the scene\'s own view', async () => {
  await withPage('portrait', async ({ server, page }) => {
    const sent = [];
    let info = null;
    page.on('websocket', (ws) => {
      ws.on('framesent', ({ payload }) => { if (typeof payload === 'string') sent.push(JSON.parse(payload)); });
      ws.on('framereceived', ({ payload }) => {
        if (typeof payload === 'string' && payload.includes('"type":"info"')) info = JSON.parse(payload);
      });
    });
    // Waits on the wire, not on a guess of how long the page takes.
    const until = async (cond, what) => {
      const end = Date.now() + 20000;
      while (!cond()) {
        assert.ok(Date.now() < end, `timed out waiting for ${what}: ${JSON.stringify(sent.slice(-4))}`);
        await new Promise((r) => setTimeout(r, 25));
      }
    };
    const last = (type) => sent.filter((m) => m.type === type).at(-1);
    // The camera that goes with the size asked last: its vertical field of view keeps the
    // scene's horizontal one, 2·atan(tan(fov/2) / aspect), in a portrait view.
    const expected = () => {
      const { width, height } = last('resize');
      const fov = info.camera.fov_y_deg;
      const aspect = width / height;
      return aspect >= 1 ? fov : (360 / Math.PI) * Math.atan(Math.tan((fov * Math.PI) / 360) / aspect);
    };
    const matches = () => info && last('resize') && last('camera') && Math.abs(last('camera').fov_y_deg - expected()) < 1e-6;

    await page.setViewportSize({ width: 390, height: 760 });
    await page.goto(`${server.url}?scene=blobs&t=3`);
    await waitForFrames(page, 1);
    await until(() => matches() && last('resize').width < last('resize').height, 'a portrait camera');
    const portrait = last('camera').fov_y_deg;
    assert.ok(portrait > info.camera.fov_y_deg + 1, `portrait sees wider: ${portrait}° for the scene's ${info.camera.fov_y_deg}°`);
    // The link keeps the scene's field of view, not the portrait one.
    const cam = new URL(page.url()).searchParams.get('cam');
    assert.ok(cam === null || Number(cam.split(',')[6]) === info.camera.fov_y_deg, `the link's camera: ${cam}`);

    await page.setViewportSize({ width: 900, height: 560 });
    await until(() => matches() && last('resize').width > last('resize').height, 'the landscape camera');
    assert.equal(last('camera').fov_y_deg, info.camera.fov_y_deg);
  });
});

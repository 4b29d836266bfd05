// The client's pure modules in Node, without a browser: camera maths and the URL settings.
import { test } from 'node:test';
import assert from 'node:assert/strict';

globalThis.location = { pathname: '/', search: '' };
const { basis, orbitFromPose, poseFromOrbit, pan, rotate, zoom, viewFov } = await import('../camera.js');
const { defaults, parseSettings, serializeSettings, UP_AXES } = await import('../settings.js');
const { renderSize } = await import('../quality.js');

const close = (a, b, eps = 1e-9) => a.every((v, i) => Math.abs(v - b[i]) < eps);

test('every view-up axis gives a right-handed basis with that axis up', () => {
  for (const up of UP_AXES) {
    const { a, u, b } = basis(up);
    const cross = [a[1] * u[2] - a[2] * u[1], a[2] * u[0] - a[0] * u[2], a[0] * u[1] - a[1] * u[0]];
    assert.ok(close(cross, b), `${up}: a × u = b`);
    const axis = { x: 0, y: 1, z: 2 }[up[1]];
    assert.equal(u[axis], up[0] === '-' ? -1 : 1, `${up}: u is the axis`);
  }
});

test('orbit and pose convert both ways, around every up axis', () => {
  for (const up of UP_AXES) {
    const orbit = { yaw: 0.7, pitch: -0.4, distance: 5.5, target: [1, -2, 0.5], fov: 40 };
    const pose = poseFromOrbit(orbit, up);
    assert.ok(Math.abs(Math.hypot(...pose.eye.map((e, i) => e - pose.target[i])) - 5.5) < 1e-9, 'eye at the distance');
    const back = orbitFromPose(pose, up);
    assert.ok(close([back.yaw, back.pitch, back.distance, ...back.target], [0.7, -0.4, 5.5, 1, -2, 0.5]), `${up}: ${JSON.stringify(back)}`);
  }
});

test('pan moves the target across the view, zoom and rotate keep it', () => {
  const o = { yaw: 0.3, pitch: 0.2, distance: 4, target: [0, 0, 0], fov: 45 };
  const pose0 = poseFromOrbit(o, '+y');
  pan(o, '+y', 0.1, 0);
  const forward = pose0.target.map((t, i) => t - pose0.eye[i]);
  const moved = o.target;
  assert.ok(Math.abs(moved.reduce((s, v, i) => s + v * forward[i], 0)) < 1e-9, 'pan is perpendicular to the view direction');
  assert.ok(Math.hypot(...moved) > 0.1, 'and moves the target');
  assert.equal(o.distance, 4);
  const target = [...o.target];
  zoom(o, 0.5);
  rotate(o, 1, 10);
  assert.deepEqual(o.target, target);
  assert.equal(o.distance, 2);
  assert.ok(o.pitch < Math.PI / 2, 'pitch stays short of the up axis');
});

test('settings survive the URL, and malformed values fall back to defaults', () => {
  const s = parseSettings('?scene=blobs&cam=1,0.2,3,0,1,0,45&up=-z&iso=0.5&t=3&speed=2&loop=0&fx=shadows,-ambient_occlusion,depth:3&scale=0.5&fps=20&stats=1&token=abc&reproject=off');
  assert.deepEqual(parseSettings(serializeSettings(s)), s);
  assert.deepEqual(s.fx, { shadows: true, ambient_occlusion: false, depth: 3 });
  assert.deepEqual(s.extra, [['reproject', 'off']], 'other modules\' switches are kept');
  const bad = parseSettings('?cam=1,2,-3,0,0,0,45&up=sideways&iso=x&t=-1&speed=0&scale=9&fps=1e9&fx=rm%20-rf');
  assert.equal(bad.cam, null, 'a negative distance is refused');
  assert.equal(bad.up, '+y');
  assert.equal(bad.iso, null);
  assert.equal(bad.time, null);
  assert.equal(bad.speed, 1);
  assert.equal(bad.scale, 1);
  assert.equal(bad.fps, null);
  assert.deepEqual(bad.fx, {});
});

test('render size follows CSS size × devicePixelRatio × scale, capped keeping the aspect ratio', () => {
  assert.deepEqual(renderSize(400, 300, 2, 1, 4096, 4096), [800, 600]);
  assert.deepEqual(renderSize(400, 300, 2, 0.5, 4096, 4096), [400, 300]);
  assert.deepEqual(renderSize(1000, 500, 2, 1, 1000, 1000), [1000, 500]);
  assert.deepEqual(renderSize(0, 0, 1, 1, 100, 100), [1, 1]);
});

test('codec preference picks the stream codecs the server chooses from', async () => {
  const { codecOrder, offeredCodecs } = await import('../quality.js');
  const all = ['h264', 'jpeg', 'png'];
  assert.deepEqual(codecOrder('auto', all), all);
  assert.deepEqual(codecOrder('jpeg', all), ['jpeg', 'png'], 'images only: no video');
  assert.deepEqual(codecOrder('h264', all), ['h264', 'png'], 'no JPEG: video from the first moving frame');
  assert.deepEqual(codecOrder('png', all), ['png']);
  assert.deepEqual(codecOrder('h264', ['jpeg', 'png']), ['jpeg', 'png'], 'a codec not offered falls back to auto');
  assert.deepEqual(codecOrder('vp9', all), all, 'an unknown preference (from a URL) falls back to auto');
  assert.deepEqual(offeredCodecs(all, ['jpeg', 'png']), ['jpeg', 'png'], 'a server without H.264');
  assert.deepEqual(offeredCodecs(['jpeg', 'png'], ['jpeg', 'png', 'h264']), ['jpeg', 'png'], 'a browser without H.264');
  assert.deepEqual(offeredCodecs(all, undefined), all, 'before the server says');
});

test('the stream message carries the codecs and the target frame rate, capped by the server', async () => {
  const { streamFields } = await import('../quality.js');
  const info = { codecs: ['jpeg', 'png', 'h264'], max_fps: 30 };
  const decodable = ['h264', 'jpeg', 'png'];
  assert.deepEqual(streamFields({ codec: 'png', fps: 12 }, info, decodable), { codecs: ['png'], fps: 12 });
  assert.deepEqual(streamFields({ codec: 'auto', fps: null }, info, decodable), { codecs: decodable, fps: 30 },
    'back at the maximum the server is told so (an absent fps would keep the old target)');
  assert.deepEqual(streamFields({ codec: 'auto', fps: 120 }, info, decodable).fps, 30, 'a URL asking for more gets the cap');
  assert.deepEqual(streamFields({ codec: 'jpeg', fps: null }, null, ['jpeg', 'png']), { codecs: ['jpeg', 'png'] },
    'before info: no frame rate');
});

test('codec and target frame rate are kept in the URL and checked when read', () => {
  const s = { ...defaults(), codec: 'png', fps: 12 };
  const q = serializeSettings(s);
  assert.match(q, /codec=png/);
  assert.match(q, /fps=12/);
  const back = parseSettings(q);
  assert.equal(back.codec, 'png');
  assert.equal(back.fps, 12);
  assert.equal(serializeSettings(defaults()).includes('codec'), false, 'the default is not written');
  assert.equal(parseSettings('?codec=<script>').codec, 'auto', 'a malformed codec name is ignored');
  assert.equal(parseSettings('?fps=0').fps, null, 'a frame rate under 1 is ignored');
  assert.equal(parseSettings('?fps=abc').fps, null);
});

test('a portrait view keeps the orbit\'s horizontal field of view; others keep its vertical one', () => {
  const o = orbitFromPose({ eye: [0, 1, 6], target: [0, 0, 0], fov_y_deg: 45 }, '+Y');
  for (const aspect of [1, 1.5, 3, 0, NaN]) assert.equal(poseFromOrbit(o, '+Y', aspect).fov_y_deg, 45, `aspect ${aspect}`);
  for (const aspect of [0.9, 0.5, 0.25]) {
    const fov = poseFromOrbit(o, '+Y', aspect).fov_y_deg;
    // Horizontal half-angle of the portrait view: atan(aspect · tan(fov/2)) = 22.5°.
    const across = (360 / Math.PI) * Math.atan(aspect * Math.tan((fov * Math.PI) / 360));
    assert.ok(Math.abs(across - 45) < 1e-9, `aspect ${aspect}: ${fov}° sees ${across}° across`);
  }
  // A very tall view stops widening at 150°.
  assert.equal(viewFov(45, 0.01), 150);
  // The orbit itself is not changed: a link keeps the scene's field of view.
  assert.equal(o.fov, 45);
});

// Latency hiding: when the camera moves, the last frame is reprojected to the new camera at
// once (WebGL2), while the server's frame for that camera is on its way.
//
// How it works: interactive frames carry a depth block (protocol/PROTOCOL.md): the camera the
// frame was traced with and 16-bit inverse depth at a quarter of the frame's size. Each depth
// texel is a vertex of a grid mesh; the vertex shader puts it back in the world (the pixel's
// ray of the old camera, at its depth) and projects it with the new camera; the fragment
// shader samples the old frame's colour there. Background texels (no hit) are directions and
// only turn with the camera. A depth test keeps near surfaces in front. Where the new camera
// sees what the old one did not (disocclusion), the mesh stretches a triangle from a
// silhouette to what lay behind it; the fragment shader measures each triangle's
// magnification (new pixels per old pixel, from the screen-space derivatives of the old
// image coordinates) and drops triangles grown more than MAX_MAGNIFICATION times, so the
// hole shows the old frame's mean colour: a plain fill that the true frame replaces a moment
// later.

/** A triangle drawn this many times larger than it was in the old frame was torn open by a
 * disocclusion, not seen closer: it is dropped. */
const MAX_MAGNIFICATION = 3;

const VERTEX_SHADER = `#version 300 es
precision highp float;
uniform highp sampler2D u_depth;
uniform ivec2 u_grid;
uniform float u_near;
uniform vec3 u_eye0, u_f0, u_r0, u_u0;
uniform vec2 u_half0;
uniform vec3 u_eye1, u_f1, u_r1, u_u1;
uniform vec2 u_half1;
uniform vec2 u_clip;
out vec2 v_uv;
void main() {
  int i = gl_VertexID % u_grid.x;
  int j = gl_VertexID / u_grid.x;
  vec2 uv = vec2(float(i) / float(max(u_grid.x - 1, 1)), float(j) / float(max(u_grid.y - 1, 1)));
  vec4 t = texelFetch(u_depth, ivec2(i, j), 0);
  float q = (floor(t.r * 255.0 + 0.5) * 256.0 + floor(t.g * 255.0 + 0.5)) / 65535.0;
  vec3 dir = u_f0 + u_r0 * ((2.0 * uv.x - 1.0) * u_half0.x) + u_u0 * ((1.0 - 2.0 * uv.y) * u_half0.y);
  v_uv = uv;
  if (q <= 0.0) {
    // A direction: it turns with the camera and lies on the far plane.
    float x = dot(dir, u_r1), y = dot(dir, u_u1), z = dot(dir, u_f1);
    gl_Position = vec4(x / u_half1.x, y / u_half1.y, 0.99999 * z, z);
    return;
  }
  vec3 rel = u_eye0 + dir * (u_near / q) - u_eye1;
  float x = dot(rel, u_r1), y = dot(rel, u_u1), z = dot(rel, u_f1);
  float n = u_clip.x, f = u_clip.y;
  gl_Position = vec4(x / u_half1.x, y / u_half1.y, z * (f + n) / (f - n) - 2.0 * f * n / (f - n), z);
}`;

const FRAGMENT_SHADER = `#version 300 es
precision highp float;
uniform sampler2D u_color;
uniform vec2 u_frame;
in vec2 v_uv;
out vec4 color;
void main() {
  // Old pixels per new pixel: the Jacobian of the old image coordinates over the screen.
  vec2 dx = dFdx(v_uv) * u_frame, dy = dFdy(v_uv) * u_frame;
  float oldPerNew = abs(dx.x * dy.y - dx.y * dy.x);
  if (oldPerNew * ${MAX_MAGNIFICATION.toFixed(1)} < 1.0) discard;
  color = vec4(texture(u_color, v_uv).rgb, 1.0);
}`;

const sub = (p, q) => p.map((v, i) => v - q[i]);
const cross = (p, q) => [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]];
const normalize = (p) => { const n = Math.hypot(...p) || 1; return p.map((v) => v / n); };

/** The renderer's camera frame (render/src/camera.rs): forward, right, up and half extents. */
export function cameraFrame(pose, aspect) {
  const f = normalize(sub(pose.target, pose.eye));
  const r = normalize(cross(f, pose.up));
  const u = cross(r, f);
  const halfH = Math.tan((pose.fov_y_deg * Math.PI) / 360);
  return { eye: pose.eye, f, r, u, half: [halfH * aspect, halfH] };
}

/**
 * The colour of disoccluded holes: the mean of the frame's background (the pixels whose depth
 * texel says the ray missed), or of the whole frame when it has no background. Most holes
 * open onto the background, which this renderer shades by direction alone.
 */
function holeColor(image, depthBitmap, [w, h]) {
  const canvas = (holeColor.canvas ||= new OffscreenCanvas(1, 1));
  [canvas.width, canvas.height] = [w, 2 * h];
  const ctx = canvas.getContext('2d', { willReadFrequently: true });
  ctx.imageSmoothingQuality = 'high';
  ctx.drawImage(image, 0, 0, w, h);
  if (depthBitmap) ctx.drawImage(depthBitmap, 0, h, w, h);
  const px = ctx.getImageData(0, 0, w, 2 * h).data;
  const sum = [0, 0, 0, 0], all = [0, 0, 0, 0];
  for (let i = 0; i < w * h * 4; i += 4) {
    const missed = depthBitmap && px[w * h * 4 + i] === 0 && px[w * h * 4 + i + 1] === 0;
    for (const acc of missed ? [sum, all] : [all]) {
      acc[0] += px[i]; acc[1] += px[i + 1]; acc[2] += px[i + 2]; acc[3] += 1;
    }
  }
  const mean = sum[3] > 0 ? sum : all;
  return [0, 1, 2].map((k) => mean[k] / Math.max(1, mean[3]) / 255);
}

export class Reprojector {
  /** `enabled`: whether the session asks for depth and the view is reprojected. */
  constructor({ enabled = true } = {}) {
    this.enabled = enabled;
    this.canvas = document.createElement('canvas');
    this.gl = null;
    this.frame = null; // { near, camera, grid: [w, h], aspect, inputId }
    this.colorSize = [1, 1]; // size of the colour image loaded
    this.fill = [0, 0, 0]; // colour of disoccluded holes
    this.warps = 0; // reprojected images drawn, for tests and the overlay
    this.failed = null; // why WebGL2 is unavailable, if it is
  }

  /** Whether a frame with depth is loaded, so `render` can answer a camera change. */
  get ready() {
    return this.enabled && this.frame !== null && this.gl !== null;
  }

  #init() {
    if (this.gl || this.failed) return this.gl;
    const gl = this.canvas.getContext('webgl2', { antialias: false, depth: true, premultipliedAlpha: false, preserveDrawingBuffer: false });
    if (!gl) {
      this.failed = 'WebGL2 is not available';
      return null;
    }
    const shader = (type, source) => {
      const s = gl.createShader(type);
      gl.shaderSource(s, source);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    };
    const program = gl.createProgram();
    gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX_SHADER));
    gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    this.program = program;
    this.uniforms = {};
    for (const name of ['u_depth', 'u_color', 'u_frame', 'u_grid', 'u_near', 'u_eye0', 'u_f0', 'u_r0', 'u_u0', 'u_half0',
      'u_eye1', 'u_f1', 'u_r1', 'u_u1', 'u_half1', 'u_clip']) {
      this.uniforms[name] = gl.getUniformLocation(program, name);
    }
    this.colorTexture = gl.createTexture();
    this.depthTexture = gl.createTexture();
    this.indexBuffer = gl.createBuffer();
    this.vao = gl.createVertexArray();
    this.indexGrid = null;
    this.indexCount = 0;
    this.gl = gl;
    return gl;
  }

  #upload(texture, image, filter) {
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, image);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, filter);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, filter);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
  }

  /**
   * Takes a decoded frame (`decode.js`). A frame with depth becomes the one reprojected; a
   * frame without (the still frame) replaces only the colour when it shows the same input,
   * so the sharper picture is reprojected next time.
   */
  setFrame({ header, image, depth }) {
    if (!this.enabled) return;
    if (!depth && !(this.frame && this.frame.inputId === header.inputId)) return;
    const gl = this.#init();
    if (!gl) return;
    this.#upload(this.colorTexture, image, gl.LINEAR);
    this.colorSize = [header.width, header.height];
    if (depth) {
      this.#upload(this.depthTexture, depth.bitmap, gl.NEAREST);
      this.frame = {
        near: depth.near,
        camera: depth.camera,
        grid: [depth.width, depth.height],
        aspect: header.width / header.height,
        inputId: header.inputId,
      };
      this.fill = holeColor(image, depth.bitmap, this.frame.grid);
    }
  }

  /**
   * Draws the loaded frame as the camera `pose` sees it, `width` × `height` pixels; returns
   * the canvas to draw from, or null when nothing can be reprojected.
   */
  render(pose, width, height) {
    if (!this.ready) return null;
    const gl = this.gl;
    const { grid, camera, near, aspect } = this.frame;
    if (this.canvas.width !== width || this.canvas.height !== height) {
      this.canvas.width = width;
      this.canvas.height = height;
    }
    if (!this.indexGrid || this.indexGrid[0] !== grid[0] || this.indexGrid[1] !== grid[1]) this.#buildIndices(grid);
    const from = cameraFrame(camera, aspect);
    const to = cameraFrame(pose, width / height);
    gl.viewport(0, 0, width, height);
    const [r, g, b] = this.fill;
    gl.clearColor(r, g, b, 1);
    gl.clearDepth(1);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LEQUAL);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.useProgram(this.program);
    const u = this.uniforms;
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.depthTexture);
    gl.uniform1i(u.u_depth, 0);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, this.colorTexture);
    gl.uniform1i(u.u_color, 1);
    gl.uniform2f(u.u_frame, this.colorSize[0], this.colorSize[1]);
    gl.uniform2i(u.u_grid, grid[0], grid[1]);
    gl.uniform1f(u.u_near, near);
    gl.uniform3fv(u.u_eye0, from.eye);
    gl.uniform3fv(u.u_f0, from.f);
    gl.uniform3fv(u.u_r0, from.r);
    gl.uniform3fv(u.u_u0, from.u);
    gl.uniform2fv(u.u_half0, from.half);
    gl.uniform3fv(u.u_eye1, to.eye);
    gl.uniform3fv(u.u_f1, to.f);
    gl.uniform3fv(u.u_r1, to.r);
    gl.uniform3fv(u.u_u1, to.u);
    gl.uniform2fv(u.u_half1, to.half);
    gl.uniform2f(u.u_clip, Math.max(1e-4, near * 0.05), near * 1e4);
    gl.bindVertexArray(this.vao);
    gl.drawElements(gl.TRIANGLES, this.indexCount, gl.UNSIGNED_INT, 0);
    gl.bindVertexArray(null);
    this.warps += 1;
    return this.canvas;
  }

  #buildIndices([w, h]) {
    const gl = this.gl;
    const indices = new Uint32Array(Math.max(0, (w - 1) * (h - 1) * 6));
    let k = 0;
    for (let j = 0; j + 1 < h; j++) {
      for (let i = 0; i + 1 < w; i++) {
        const a = j * w + i, b = a + 1, c = a + w, d = c + 1;
        indices.set([a, c, b, b, c, d], k);
        k += 6;
      }
    }
    gl.bindVertexArray(this.vao);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.indexBuffer);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    this.indexGrid = [w, h];
    this.indexCount = indices.length;
  }
}

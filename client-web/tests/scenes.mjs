// Small scenes the browser tests create through the REST API, so they do not wait on a large
// demo's first build on a busy machine.
import { api } from './harness.mjs';

/**
 * A tet scene over [-1, 1]³ (an n³ grid of cubes, six tets each) with one step of the field
 * 3 - |p|²: isosurfaces are spheres, larger for lower values. Returns the scene id.
 */
export async function createTetBall(server, n = 8) {
  const vertices = [];
  for (let k = 0; k <= n; k++) for (let j = 0; j <= n; j++) for (let i = 0; i <= n; i++) {
    vertices.push([i, j, k].map((c) => -1 + (2 * c) / n));
  }
  const at = (i, j, k) => i + (n + 1) * (j + (n + 1) * k);
  const volume = (t) => {
    const [a, b, c, d] = t.map((v) => vertices[v]);
    const u = b.map((x, q) => x - a[q]), v = c.map((x, q) => x - a[q]), w = d.map((x, q) => x - a[q]);
    return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0]);
  };
  const cells = [];
  for (let k = 0; k < n; k++) for (let j = 0; j < n; j++) for (let i = 0; i < n; i++) {
    // The six tets of a cube around its main diagonal (corner 0 to corner 7).
    const c = [0, 1, 2, 3, 4, 5, 6, 7].map((m) => at(i + (m & 1), j + ((m >> 1) & 1), k + ((m >> 2) & 1)));
    for (const [p, q] of [[1, 3], [3, 2], [2, 6], [6, 4], [4, 5], [5, 1]]) {
      let t = [c[0], c[p], c[q], c[7]];
      // VTK's order: a positive volume.
      if (volume(t) < 0) t = [t[1], t[0], t[2], t[3]];
      cells.push(t);
    }
  }
  const created = await api(server, 'POST', '/api/v1/scenes', {
    kind: 'tets',
    name: 'Tet ball',
    camera: { eye: [0, 0.9, 3.4], target: [0, 0, 0] },
    isovalue: 2.5,
    tets: { mesh: { vertices, cells } },
  });
  const { id } = created.scene;
  const scalars = vertices.map((p) => 3 - (p[0] ** 2 + p[1] ** 2 + p[2] ** 2));
  await api(server, 'PUT', `/api/v1/scenes/${id}/steps/0`, { scalars }, created.write_token);
  return id;
}

"""Seed inputs for the fuzz targets, written by the real tools (NumPy, meshio): a few valid
files per target, so libFuzzer starts from inputs that reach deep into each parser.

    python3 fuzz/seeds.py fuzz/corpus    # run.sh does this; needs numpy and meshio
Each target's input starts with one selector byte (see fuzz_targets/*.rs)."""
import io
import json
import os
import struct
import sys
import tempfile

import meshio
import numpy as np

out = sys.argv[1] if len(sys.argv) > 1 else "fuzz/corpus"


def put(target, name, data):
    d = os.path.join(out, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def npy(a):
    b = io.BytesIO()
    np.save(b, a)
    return b.getvalue()


def raw(a, code):
    a = np.ascontiguousarray(a)
    return b"ISRA" + struct.pack("<BBHQ", 1, code, a.shape[1], a.shape[0]) + a.tobytes()


rng = np.random.default_rng(7)
balls = rng.random((6, 7)).astype(np.float32)
scalars = rng.random((8, 1))
for sel, layout in ((0, "balls"), (17, "tets8")):
    a = balls if sel == 0 else scalars
    put("npy_step", f"{layout}-f4", bytes([sel]) + npy(a.astype("<f4")))
    put("npy_step", f"{layout}-f8", bytes([sel]) + npy(a.astype("<f8")))
    put("raw_step", f"{layout}-f4", bytes([sel]) + raw(a.astype("<f4"), 1))
    put("raw_step", f"{layout}-f8", bytes([sel]) + raw(a.astype("<f8"), 2))

# Two tets sharing a face.
verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype="<f4")
cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
put("tet_mesh", "npy-i8", bytes([0]) + npy(verts) + npy(cells.astype("<i8")))
put("tet_mesh", "npy-u4", bytes([0]) + npy(verts.astype("<f8")) + npy(cells.astype("<u4")))
put("tet_mesh", "raw-u4", bytes([1]) + raw(verts, 1) + raw(cells.astype("<u4"), 3))

with tempfile.TemporaryDirectory() as tmp:
    pts = rng.random((40, 3))
    tets = np.array([rng.choice(40, 4, replace=False) for _ in range(30)])
    mesh = meshio.Mesh(pts, [("tetra", tets)], point_data={"u": rng.random(40)})
    for name, kw in (
        ("zlib", {}),
        ("lzma", {"compression": "lzma"}),
        ("raw", {"compression": None}),
        ("ascii", {"binary": False}),
    ):
        p = os.path.join(tmp, f"{name}.vtu")
        meshio.write(p, mesh, file_format="vtu", **kw)
        put("vtk_file", f"vtu-{name}", b"\x00" + open(p, "rb").read())
    for name, binary in (("ascii", False), ("binary", True)):
        p = os.path.join(tmp, f"{name}.vtk")
        meshio.write(p, mesh, file_format="vtk", binary=binary)
        put("vtk_file", f"legacy-{name}", b"\x01" + open(p, "rb").read())

# Surfel scenes: an icosphere (subdivided once: 42 vertices, 80 faces) as meshio writes it
# to PLY (binary and ASCII), OBJ and OFF; its vertices as an oriented point cloud (ASCII PLY
# with nx ny nz, meshio) and as `.xyz` with normals (NumPy's savetxt). The selector's low two
# bits pick the file type (xyz, ply, obj, off), the next two how far the nodes move.
t = (1 + 5 ** 0.5) / 2
ico = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]])
ico /= np.linalg.norm(ico, axis=1)[:, None]
faces = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
verts, mids, tris = list(ico), {}, []
for f in faces:
    m = []
    for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
        key = (min(a, b), max(a, b))
        if key not in mids:
            v = verts[a] + verts[b]
            verts.append(v / np.linalg.norm(v))
            mids[key] = len(verts) - 1
        m.append(mids[key])
    tris += [[f[0], m[0], m[2]], [f[1], m[1], m[0]], [f[2], m[2], m[1]], m]
verts, tris = np.array(verts), np.array(tris, dtype=np.int32)
with tempfile.TemporaryDirectory() as tmp:
    sphere = meshio.Mesh(verts, [("triangle", tris)])
    cloud = meshio.Mesh(verts, [],
                        point_data={"nx": verts[:, 0], "ny": verts[:, 1], "nz": verts[:, 2]})
    for sel, name, mesh, kw in (
        (1, "mesh-binary.ply", sphere, {}),
        (5, "mesh-ascii.ply", sphere, {"binary": False}),
        (2, "mesh.obj", sphere, {}),
        (3, "mesh.off", sphere, {}),
        (9, "cloud-ascii.ply", cloud, {"binary": False}),
        (13, "cloud-binary.ply", cloud, {}),
    ):
        p = os.path.join(tmp, name)
        meshio.write(p, mesh, **kw)
        put("surfel_file", name, bytes([sel]) + open(p, "rb").read())
    p = os.path.join(tmp, "cloud.xyz")
    np.savetxt(p, np.hstack([verts, verts]))
    put("surfel_file", "cloud.xyz", bytes([4]) + open(p, "rb").read())

# The same objects as a client posts them (`surfels` of a scene), and explicit surfels with
# clipping between two groups.
nodes = (verts * 1.1)[::3].tolist()
for sel, name, spec in (
    (1, "points", {"points": {"positions": verts.tolist(), "normals": verts.tolist()},
                   "nodes": nodes}),
    (2, "mesh", {"mesh": {"vertices": verts.tolist(), "triangles": tris.tolist(), "count": 200},
                 "nodes": nodes, "update": "lazy"}),
    (3, "surfels", {"surfels": [{"centre": list(v), "t1": [0, 0.1, 0], "t2": [0.1, 0, 0],
                                 "radius": 1.5, "group": int(v[2] > 0)} for v in verts.tolist()],
                    "nodes": nodes, "node_mass": [1.0] * len(nodes), "clip": [[0, 1], [1, 0]],
                    "update": "eager"}),
):
    put("surfel_scene", name, bytes([sel]) + json.dumps(spec).encode())

# Surfel steps: 14 nodes' positions (selector 28: .npy, 29: raw).
pos = rng.random((14, 3))
put("surfel_step", "npy-f4", bytes([28]) + npy(pos.astype("<f4")))
put("surfel_step", "npy-f8", bytes([28]) + npy(pos.astype("<f8")))
put("surfel_step", "raw-f4", bytes([29]) + raw(pos.astype("<f4"), 1))

for i, m in enumerate([
    {"type": "camera", "input_id": 7, "eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]},
    {"type": "isovalue", "input_id": 1, "value": 0.5},
    {"type": "resize", "input_id": 2, "width": 640, "height": 480},
    {"type": "time", "input_id": 3, "time": 1.5},
    {"type": "ack", "sequence": 3},
    {"type": "stream", "input_id": 4, "codecs": ["h264", "jpeg", "png"], "depth": True},
    {"type": "effects", "input_id": 5, "effects": {"shadows": True, "depth": 3}},
]):
    put("ws_message", f"msg{i}", json.dumps(m).encode())
print("seeds written to", out)

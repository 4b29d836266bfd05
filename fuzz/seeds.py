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

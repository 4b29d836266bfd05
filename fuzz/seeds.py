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

# Particle files of `isoray push` for metaball scenes, as NumPy writes them: a CSV with a
# header (first byte 0), XYZ frames (1) and NPZ archives, stored and deflated (2).
parts = rng.random((40, 3))
with tempfile.TemporaryDirectory() as tmp:
    p = os.path.join(tmp, "p.csv")
    np.savetxt(p, np.hstack([parts, rng.random((40, 2))]), delimiter=",",
               header="x,y,z,radius,strength", comments="")
    put("points_file", "particles.csv", bytes([0]) + open(p, "rb").read())
    frames = "".join(f"{len(parts)}\nframe {k}\n" +
                     "".join(f"C {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in parts + k)
                     for k in range(3))
    put("points_file", "frames.xyz", bytes([1]) + frames.encode())
    for name, save in (("stored.npz", np.savez), ("deflated.npz", np.savez_compressed)):
        p = os.path.join(tmp, name)
        save(p, positions=np.stack([parts, parts + 1]), radius=rng.random((2, 40)),
             strength=rng.random(40), color=rng.random((40, 3)).astype(np.float32))
        put("points_file", name, bytes([2]) + open(p, "rb").read())

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

# Scene descriptions (`POST /v1/scenes`) of every kind: the README's lighting example (every
# light kind, transparent, refractive and reflective materials, groups, floor, clip box, an
# extra isosurface, every effect), a volume with occlusion, and a tet and a surfel scene.
lighting = {
    "lights": [{"kind": "sphere", "position": [3, 6, 4], "radius": 1.2, "intensity": 60},
               {"kind": "point", "position": [-3, 4, 2], "color": [1, 0.9, 0.8], "intensity": 10},
               {"to_light": [0.4, 0.8, 0.45], "intensity": 0.3}],
    "materials": [{"diffuse": [1, 1, 1]},
                  {"opacity": 0.1, "ior": 1.5, "specular": 0.8, "shininess": 200},
                  {"reflectivity": 0.85}, {"emission": [2, 2, 2]}],
    "groups": [{"first": 0, "count": 3, "material": 1}, {"first": 3, "count": 2, "material": 2}],
    "floor": {"height": -1.5, "checker": 1.0},
    "clip_box": {"min": [0, -10, 0], "max": [10, 10, 10]},
    "isosurfaces": [{"isovalue": 0.2, "material": 1}],
    "effects": {"shadows": True, "soft_shadows": True, "reflections": True, "refraction": True,
                "transparency": True, "depth": 3, "light_samples": 4},
}
camera = {"eye": [0, 1.5, 7.5], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 45}
for name, spec in (
    ("metaballs-all", {"kind": "metaballs", "camera": camera, "isovalue": 0.5,
                       "isovalue_slider": [0.1, 1.5], "lighting": lighting,
                       "metaballs": {"radius": 1.0, "strength": 1.0}}),
    ("metaballs-volume", {"kind": "metaballs", "lighting": {
        "volume": {"density": 0.5}, "occlusion_distance": 2,
        "effects": {"transparency": True, "ambient_occlusion": True, "ao_samples": 4}}}),
    ("tets", {"kind": "tets", "isovalue": 0.0, "isovalue_slider": [-1, 1], "lighting": lighting}),
    ("surfels", {"kind": "surfels", "camera": camera, "lighting": lighting,
                 "surfels": {"points": {"positions": verts.tolist()}, "nodes": nodes}}),
):
    put("scene_spec", name, json.dumps(spec).encode())

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

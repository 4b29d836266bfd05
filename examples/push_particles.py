"""Toy particle simulation that pushes every step to an isoray server.

Creates a metaball scene, runs N particles under gravity in a box with NumPy, and pushes each
step as a .npy array (PUT /api/v1/scenes/{id}/steps/{index}). Open the printed URL in a browser
to watch the animation advance while it runs. Needs only NumPy and the standard library.

    python3 examples/push_particles.py --server http://127.0.0.1:8080 --particles 50000 --steps 100
"""
import argparse
import io
import json
import time
import urllib.request

import numpy as np


def request(method, url, body=None, headers=None):
    req = urllib.request.Request(url, data=body, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(req) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--server", default="http://127.0.0.1:8080")
    ap.add_argument("--particles", type=int, default=50_000)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--radius", type=float, default=0.08)
    args = ap.parse_args()
    api = args.server.rstrip("/") + "/api/v1"

    spec = {"kind": "metaballs", "name": "particles in a box",
            "metaballs": {"radius": args.radius, "strength": 1.0}}
    status, body = request("POST", api + "/scenes", json.dumps(spec).encode(),
                           {"Content-Type": "application/json"})
    if status != 201:
        raise SystemExit(f"create failed: {status} {body.decode()}")
    created = json.loads(body)
    scene, token = created["scene"]["id"], created["write_token"]
    print(f"scene {scene}: watch it at {args.server}/#{scene}")

    rng = np.random.default_rng(1)
    pos = rng.uniform(-1.5, 1.5, (args.particles, 3)).astype(np.float32)
    vel = rng.normal(0, 0.5, (args.particles, 3)).astype(np.float32)
    dt = 0.02
    headers = {"Content-Type": "application/x-npy", "Authorization": f"Bearer {token}"}
    t0 = time.time()
    sent = 0
    for step in range(args.steps):
        vel[:, 1] -= 9.81 * dt
        pos += vel * dt
        for axis in range(3):  # bounce off the walls of a box of half-size 2
            out = np.abs(pos[:, axis]) > 2.0
            vel[out, axis] *= -0.9
            pos[out, axis] = np.clip(pos[out, axis], -2.0, 2.0)
        buf = io.BytesIO()
        np.save(buf, pos)
        data = buf.getvalue()
        status, body = request("PUT", f"{api}/scenes/{scene}/steps/{step}?time={step * dt}",
                               data, headers)
        if status not in (200, 201):
            raise SystemExit(f"step {step} failed: {status} {body.decode()}")
        sent += len(data)
    secs = time.time() - t0
    print(f"pushed {args.steps} steps of {args.particles} particles, "
          f"{sent / 1e6:.1f} MB in {secs:.1f} s ({sent / 1e6 / secs:.1f} MB/s)")


if __name__ == "__main__":
    main()

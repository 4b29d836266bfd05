"""Toy particle simulation that pushes every step to an isoray server.

Creates a metaball scene, runs N particles under gravity in a box with NumPy (a block of
fluid-like particles dropped into one corner, bouncing off the walls), and pushes each step
as a .npy array (PUT /api/v1/scenes/{id}/steps/{index}?time=...). Open the printed URL in a
browser to watch the animation advance while it runs. Needs NumPy and the standard library.

    python3 examples/push_particles.py --server http://127.0.0.1:8080 --particles 50000 --steps 100
"""
import argparse
import io
import json
import sys
import time
import urllib.error
import urllib.request

import numpy as np


def request(method, url, body=None, headers=None):
    """One HTTP request; returns (status, body bytes), also for 4xx/5xx answers."""
    req = urllib.request.Request(url, data=body, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=300) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--server", default="http://127.0.0.1:8080")
    ap.add_argument("--particles", type=int, default=50_000)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--radius", type=float, default=0.12, help="ball radius (scene default)")
    ap.add_argument("--dt", type=float, default=0.02, help="simulation time per step, seconds")
    ap.add_argument("--interval", type=float, default=0.0,
                    help="seconds between pushes, like a simulation that takes that long per step "
                         "(0: push as fast as possible)")
    ap.add_argument("--token", help="admin token, if the server needs one to create scenes")
    args = ap.parse_args()
    api = args.server.rstrip("/") + "/api/v1"

    spec = {
        "kind": "metaballs",
        "name": f"{args.particles} particles in a box",
        "description": "examples/push_particles.py: a block of particles dropped into a box",
        "metaballs": {"radius": args.radius, "strength": 1.0, "color": [0.2, 0.45, 0.9]},
        "camera": {"eye": [0.0, 2.5, 8.0], "target": [0.0, -0.5, 0.0]},
        "isovalue": 0.5,
    }
    headers = {"Content-Type": "application/json"}
    if args.token:
        headers["Authorization"] = f"Bearer {args.token}"
    status, body = request("POST", api + "/scenes", json.dumps(spec).encode(), headers)
    if status != 201:
        sys.exit(f"creating the scene failed: {status} {body.decode(errors='replace')}")
    created = json.loads(body)
    scene, token = created["scene"]["id"], created["write_token"]
    # Flushed at once: a test (and a person) reads the id while the run goes on.
    print(f"scene {scene}: watch it at {args.server.rstrip('/')}/?scene={scene}", flush=True)

    rng = np.random.default_rng(1)
    n = args.particles
    # A block in the upper left corner of a box of half-size 2, falling and spreading out.
    pos = rng.uniform([-2.0, -0.5, -2.0], [-0.2, 2.0, 2.0], (n, 3)).astype(np.float32)
    vel = rng.normal(0.0, 0.3, (n, 3)).astype(np.float32)
    vel[:, 0] += 1.5
    dt = np.float32(args.dt)
    headers = {"Content-Type": "application/x-npy", "Authorization": f"Bearer {token}"}
    t0 = time.time()
    sent = 0
    for step in range(args.steps):
        if args.interval > 0:
            time.sleep(max(0.0, t0 + step * args.interval - time.time()))
        vel[:, 1] -= np.float32(9.81) * dt
        pos += vel * dt
        for axis in range(3):  # bounce off the walls, losing a little energy
            out = np.abs(pos[:, axis]) > 2.0
            vel[out, axis] *= -0.8
            np.clip(pos[:, axis], -2.0, 2.0, out=pos[:, axis])
        buf = io.BytesIO()
        np.save(buf, pos)
        data = buf.getvalue()
        url = f"{api}/scenes/{scene}/steps/{step}?time={step * args.dt:.6f}"
        status, body = request("PUT", url, data, headers)
        if status not in (200, 201):
            sys.exit(f"step {step} failed: {status} {body.decode(errors='replace')}")
        sent += len(data)
    secs = max(time.time() - t0, 1e-9)
    print(
        f"pushed {args.steps} steps of {n} particles: {sent / 1e6:.1f} MB in {secs:.1f} s "
        f"({sent / 1e6 / secs:.1f} MB/s)",
        flush=True,
    )


if __name__ == "__main__":
    main()

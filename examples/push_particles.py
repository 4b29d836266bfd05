"""Toy particle simulation that pushes every step to an isoray server.

Creates a metaball scene, runs N particles under gravity in a box with NumPy (a block of
fluid-like particles dropped into one corner, bouncing off the walls), and pushes each step
as a .npy array through the Python client (clients/python: `Scene.push`, which PUTs
/api/v1/scenes/{id}/steps/{index}?time=...). Open the printed URL in a browser to watch the
animation advance while it runs. Needs NumPy and requests (`pip install ./clients/python`).

    python3 examples/push_particles.py --server http://127.0.0.1:8080 --particles 50000 --steps 100
"""
import argparse
import os
import sys
import time

import numpy as np

try:
    import isoray_client as iso
except ImportError:  # run from a checkout without `pip install ./clients/python`
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "clients", "python"))
    import isoray_client as iso


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

    try:
        scene = iso.Scene.create(
            args.server,
            kind="metaballs",
            name=f"{args.particles} particles in a box",
            admin_token=args.token,
            description="examples/push_particles.py: a block of particles dropped into a box",
            metaballs={"radius": args.radius, "strength": 1.0, "color": [0.2, 0.45, 0.9]},
            camera={"eye": [0.0, 2.5, 8.0], "target": [0.0, -0.5, 0.0]},
            isovalue=0.5,
        )
    except iso.IsorayError as e:
        sys.exit(f"creating the scene failed: {e}")
    # Flushed at once: a test (and a person) reads the id while the run goes on.
    print(f"scene {scene.id}: watch it at {scene.viewer_url}", flush=True)

    rng = np.random.default_rng(1)
    n = args.particles
    # A block in the upper left corner of a box of half-size 2, falling and spreading out.
    pos = rng.uniform([-2.0, -0.5, -2.0], [-0.2, 2.0, 2.0], (n, 3)).astype(np.float32)
    vel = rng.normal(0.0, 0.3, (n, 3)).astype(np.float32)
    vel[:, 0] += 1.5
    dt = np.float32(args.dt)
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
        try:
            scene.push(step, pos, time=step * args.dt)
        except iso.IsorayError as e:
            sys.exit(f"step {step} failed: {e}")
        sent += pos.nbytes
    secs = max(time.time() - t0, 1e-9)
    print(
        f"pushed {args.steps} steps of {n} particles: {sent / 1e6:.1f} MB in {secs:.1f} s "
        f"({sent / 1e6 / secs:.1f} MB/s)",
        flush=True,
    )


if __name__ == "__main__":
    main()

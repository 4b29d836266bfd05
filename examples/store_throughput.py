"""Store ingest throughput: pushes 100 steps of 1M particles (.npy, little-endian f32, 4 columns)
to a running server and prints MB/s. Usage: python3 examples/store_throughput.py http://127.0.0.1:8080"""
import io, json, time, urllib.request, numpy as np, sys
api = sys.argv[1] + "/api/v1"
def req(m, u, d=None, h={}):
    r = urllib.request.Request(u, data=d, method=m, headers=h)
    with urllib.request.urlopen(r) as f: return f.status, f.read()
s, b = req("POST", api + "/scenes", b'{"kind":"metaballs"}', {"Content-Type": "application/json"})
c = json.loads(b); sid, tok = c["scene"]["id"], c["write_token"]
bufs = []
for k in range(2):
    a = np.random.default_rng(k).uniform(-2, 2, (1_000_000, 4)).astype(np.float32); a[:, 3] = 0.05
    x = io.BytesIO(); np.save(x, a); bufs.append(x.getvalue())
H = {"Content-Type": "application/x-npy", "Authorization": "Bearer " + tok}
t0 = time.time(); sent = 0
for i in range(100):
    d = bufs[i % 2]; st, _ = req("PUT", f"{api}/scenes/{sid}/steps/{i}", d, H); assert st == 201, st; sent += len(d)
dt = time.time() - t0
print(f"100 steps x 1M particles (.npy <f4, 4 columns, {len(bufs[0])} bytes each): {sent/1e6:.0f} MB in {dt:.2f} s = {sent/1e6/dt:.0f} MB/s")

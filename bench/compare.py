#!/usr/bin/env python3
"""POST /v1/compare as a job (issue 15, item 5): N stored ellipsoids (an icosphere of 2,562 vertices stretched
along x by 1.0 … 2.9), shape-DNA with k = 50 and area normalization. Times (a) the first comparison (every
eigensolve), (b) the same request again (the same job: its stored result), (c) the same shapes with another
metric (a new job whose eigenpairs all come from the cache), each as the whole synchronous request
(?wait=600) over loopback, with the default worker count. Prints one JSON line. Standard library only.

Usage: python3 bench/compare.py [--n 20]
"""
import argparse, json, os, subprocess, tempfile, time
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402

def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=20)
    a = ap.parse_args()
    kac = release_kac()
    work = tempfile.mkdtemp()
    mesh = os.path.join(work, "sphere.off")
    subprocess.run([kac, "generate", "icosphere", "--level", "4", "--out", mesh], check=True, stdout=subprocess.DEVNULL)
    lines = open(mesh).read().split("\n")
    nv = int(lines[1].split()[0])
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=os.path.join(work, "data"), KAC_MAX_WAIT_S="900",
               RUST_LOG="error")
    p = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        base = "http://" + json.loads(p.stdout.readline())["listening"]
        ids = []
        for i in range(a.n):
            s = 1.0 + 0.1 * i
            out = lines[:2]
            for l in lines[2:2 + nv]:
                x, y, z = map(float, l.split())
                out.append("%r %r %r" % (s * x, y, z))
            out += lines[2 + nv:]
            _, shape = call(base, "POST", "/v1/shapes?format=off", "\n".join(out).encode(), "application/octet-stream")
            ids.append(shape["id"])
        req = {"shape_ids": ids, "k": 50, "normalization": "area"}
        times = {}
        for name, body in [("first", req), ("same request again", req),
                           ("other metric, eigenpairs cached", dict(req, metric="canberra"))]:
            t = time.perf_counter()
            st, r = call(base, "POST", "/v1/compare?wait=600", body, timeout=900)
            times[name] = round(time.perf_counter() - t, 3)
            assert st == 200 and len(r["shape_ids"]) == a.n and not r["failures"], (st, r)
        print(json.dumps({"shapes": a.n, "vertices_each": nv, "k": 50, "seconds": times}))
    finally:
        p.terminate()
        p.wait()

if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Search latency over many stored fingerprints (issue 15, item 5).

Starts a release `kac serve` on a throwaway data directory, stores one real fingerprint (a shape-DNA job on a
generated icosphere, k = 50, area normalization) to learn its family, stops the server, adds N synthetic
fingerprints of that family straight into the store's SQLite table (ascending positive values like real
shape-DNA; their shapes are not stored, which a search by fingerprint does not need), starts the server again
(it loads the index), and times POST /v1/search over loopback: by fingerprint and by the stored shape's id,
10 neighbours, sequentially. Prints one JSON line per N. Standard library only.

Usage: python3 bench/search.py [--n 1000,10000,100000] [--queries 200]
"""
import argparse, json, os, random, sqlite3, struct, subprocess, tempfile, time
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402

def start(kac, data):
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=data, RUST_LOG="error")
    t = time.perf_counter()
    p = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    base = "http://" + json.loads(p.stdout.readline())["listening"]
    return p, base, time.perf_counter() - t

def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]

def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", default="1000,10000,100000")
    ap.add_argument("--queries", type=int, default=200)
    a = ap.parse_args()
    kac = release_kac()
    rng = random.Random(7)
    for n in (int(x) for x in a.n.split(",")):
        work = tempfile.mkdtemp()
        data = os.path.join(work, "data")
        mesh = os.path.join(work, "sphere.off")
        subprocess.run([kac, "generate", "icosphere", "--level", "3", "--out", mesh], check=True, stdout=subprocess.DEVNULL)
        p, base, _ = start(kac, data)
        _, shape = call(base, "POST", "/v1/shapes?format=off", open(mesh, "rb").read(), "application/octet-stream")
        q = {"k": 50, "normalization": "area"}
        st, first = call(base, "POST", "/v1/search?wait=60", dict(q, shape_id=shape["id"]))
        assert st == 200, (st, first)
        family = first["family"]
        p.terminate(); p.wait()
        db = sqlite3.connect(os.path.join(data, "kac.sqlite3"))
        rows = []
        for i in range(n - 1):
            v = sorted(rng.uniform(0.5, 200.0) for _ in range(50))
            rows.append((family, "%064x" % rng.getrandbits(256), struct.pack("<50d", *v)))
        db.executemany("INSERT INTO fingerprints (family, shape_id, fingerprint) VALUES (?, ?, ?)", rows)
        db.commit(); db.close()
        p, base, startup = start(kac, data)
        try:
            by_fp, by_id = [], []
            for i in range(a.queries):
                fp = sorted(rng.uniform(0.5, 200.0) for _ in range(50))
                t = time.perf_counter()
                st, r = call(base, "POST", "/v1/search", dict(q, fingerprint=fp, neighbours=10))
                by_fp.append(time.perf_counter() - t)
                assert st == 200 and r["searched"] == n, (st, r.get("searched"))
                t = time.perf_counter()
                st, r = call(base, "POST", "/v1/search", dict(q, shape_id=shape["id"], neighbours=10))
                by_id.append(time.perf_counter() - t)
                assert st == 200 and len(r["neighbours"]) == 10
            ms = lambda x: round(1000 * x, 2)
            print(json.dumps({"fingerprints": n, "k": 50, "neighbours": 10, "queries": a.queries,
                              "startup_with_index_s": round(startup, 3),
                              "by_fingerprint_ms": {"p50": ms(pct(by_fp, 0.5)), "p99": ms(pct(by_fp, 0.99))},
                              "by_shape_id_ms": {"p50": ms(pct(by_id, 0.5)), "p99": ms(pct(by_id, 0.99))}}), flush=True)
        finally:
            p.terminate(); p.wait()

if __name__ == "__main__":
    main()

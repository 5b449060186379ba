#!/usr/bin/env python3
"""One large-k job across replicas (issue 31, item 1): its spectrum slices solved as slice jobs by another replica
sharing the PostgreSQL queue, against the same job on one replica alone, in the same run on this machine.

Mesh: the 163,842-vertex unit icosphere (bench/out/ico7.off), K pairs (default 1000). Every replica runs one worker
with one solver thread (two replicas on a 2-core machine: one core each), and the default limits (before 994cc2b the
default --max-output-values refused this job, counting the basis of one run). Each configuration gets a database of
its own, so no slice
job of one is found done by another. For each: wall seconds from submission to the job's end, the slices solved on
the other replica, and the peak RSS (VmHWM) of each replica.

Needs Debian's postgresql (a throwaway cluster under target/ is started and removed).
Usage: python3 bench/slice_jobs.py [--k 1000]
"""
import argparse, json, os, subprocess, sys, tempfile, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import ROOT, call, release_kac  # noqa: E402
from pg_cluster import Cluster  # noqa: E402


def serve(kac, store, work):
    args = [kac, "serve", "--addr", "127.0.0.1:0", "--data-dir", work, "--workers", "1", "--solver-threads", "1",
            "--store", store]
    p = subprocess.Popen(args, env=dict(os.environ, RUST_LOG="error"), stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL)
    return p, "http://" + json.loads(p.stdout.readline())["listening"]


def peak_gb(p):
    with open(f"/proc/{p.pid}/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmHWM")) / 1e6


def run(kac, store, mesh, k, replicas):
    procs = []
    with tempfile.TemporaryDirectory() as work:
        try:
            for i in range(replicas):
                procs.append(serve(kac, store, os.path.join(work, str(i))))
            base = procs[0][1]
            st, shape = call(base, "POST", "/v1/shapes?format=off", open(mesh, "rb").read(), "application/octet-stream")
            assert st in (200, 201), shape
            t0 = time.monotonic()
            st, job = call(base, "POST", "/v1/jobs", {"shape_id": shape["id"], "analysis": "spectrum", "k": k})
            assert st == 202, job
            while True:
                st, v = call(base, "GET", f"/v1/jobs/{job['id']}")
                if v["status"] not in ("enqueued", "processing"):
                    break
                time.sleep(0.05)
            wall = time.monotonic() - t0
            assert v["status"] == "succeeded", v
            st, res = call(base, "GET", v["result"] + "?values=false", timeout=600)
            slices = res["solver"]["slices"]
            elsewhere = sum(1 for s in slices if s.get("solved_by"))
            assert res["solver"]["completeness"]["complete"], res["solver"]
            peaks = [round(peak_gb(p), 2) for p, _ in procs]
            # Each slice: who solved it (null: the job's own replica), its pairs and seconds (elsewhere: from the
            # claim of its slice job to its pairs stored, the operator built again included).
            each = [[s.get("solved_by"), s["pairs"], round(s["seconds"], 2)] for s in slices]
            return {"seconds": round(wall, 2), "slices": len(slices), "solved_on_another_replica": elsewhere,
                    "each_slice": each, "peak_gb": peaks, "eigenvalues": res["eigenvalues"]}
        finally:
            for p, _ in procs:
                p.kill()
                p.wait()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--k", type=int, default=1000)
    args = ap.parse_args()
    kac = release_kac()
    out_dir = os.path.join(ROOT, "bench", "out")
    os.makedirs(out_dir, exist_ok=True)
    mesh = os.path.join(out_dir, "ico7.off")
    if not os.path.exists(mesh):
        subprocess.run([kac, "generate", "icosphere", "--level", "7", "--out", mesh], check=True,
                       stdout=subprocess.DEVNULL)
    with Cluster("pg-slices") as pg:
        one = run(kac, pg.database("one"), mesh, args.k, 1)
        two = run(kac, pg.database("two"), mesh, args.k, 2)
    worst = max(abs(a - b) / max(abs(b), 1.0) for a, b in zip(two.pop("eigenvalues"), one.pop("eigenvalues")))
    print(json.dumps({"k": args.k, "vertices": 163842, "one_replica": one, "two_replicas": two,
                      "two_over_one": round(one["seconds"] / two["seconds"], 2),
                      "eigenvalues_max_relative_difference": worst}))


if __name__ == "__main__":
    main()

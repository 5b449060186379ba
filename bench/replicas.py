#!/usr/bin/env python3
"""The shared backend against the embedded one (issue 17, item 5), in one run on this machine:

1. jobs/s of shape-DNA (k = 50, area-normalized) on 10k-vertex shapes (an icosphere of 10,242 vertices stretched
   along x, a different stretch per job, so nothing is cached): the embedded SQLite store with one replica, and
   PostgreSQL with one and with two replicas, one worker each; jobs submitted round-robin, timed from the first
   submission to the last success;
2. p50/p99 of GET /v1/results/{id} through each backend, on a replica whose in-memory result cache is off
   (--store-cache-bytes 0), so every read goes to the store; one keep-alive connection, every stored result in
   turn;
3. the queue's claim latency with 10,000 jobs queued (examples/queue_claims.rs), for each backend.

Prints one JSON line. Needs Debian's postgresql (a throwaway cluster under target/ is started and removed).
Usage: python3 bench/replicas.py [--jobs 16]
"""
import argparse, http.client, json, os, subprocess, sys, tempfile, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import ROOT, call, release_kac  # noqa: E402
from pg_cluster import Cluster  # noqa: E402


def serve(kac, store, work, *extra):
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=os.path.join(work, "data"), RUST_LOG="error",
               KAC_MAX_WAIT_S="900")
    args = [kac, "serve", "--workers", "1", "--solver-threads", "1"] + (["--store", store] if store else []) + list(extra)
    p = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    return p, "http://" + json.loads(p.stdout.readline())["listening"]


def shapes(kac, work, n):
    mesh = os.path.join(work, "sphere.off")
    subprocess.run([kac, "generate", "icosphere", "--level", "5", "--out", mesh], check=True, stdout=subprocess.DEVNULL)
    lines = open(mesh).read().split("\n")
    nv = int(lines[1].split()[0])
    out = []
    for i in range(n):
        s = 1.0 + 0.05 * (i + 1)
        body = lines[:2] + ["%r %r %r" % (s * x, y, z) for x, y, z in
                            (map(float, l.split()) for l in lines[2:2 + nv])] + lines[2 + nv:]
        out.append("\n".join(body).encode())
    return nv, out


def follow(base, job):
    """Reads the job's server-sent events until it ends; its last status."""
    conn = http.client.HTTPConnection(base[len("http://"):], timeout=900)
    conn.request("GET", "/v1/jobs/%s/events" % job)
    r = conn.getresponse()
    status = None
    for line in r:
        if line.startswith(b"data: "):
            status = json.loads(line[6:])["status"]
            if status in ("succeeded", "failed", "canceled"):
                break
    conn.close()
    return status


def throughput(kac, store, work, bodies, replicas, warm=False):
    """Jobs per second; `warm`: every replica has read every shape before the clock starts (a collection analysed
    again), else the shapes were uploaded through the first replica only and the others read them from the store
    when their jobs need them."""
    procs = [serve(kac, store, os.path.join(work, "r%d" % i)) for i in range(replicas)]
    try:
        bases = [b for _, b in procs]
        ids = []
        for body in bodies:
            st, s = call(bases[0], "POST", "/v1/shapes?format=off", body, "application/octet-stream")
            assert st in (200, 201), (st, s)
            ids.append(s["id"])
        if warm:
            for b in bases:
                for sid in ids:
                    assert call(b, "GET", "/v1/shapes/" + sid)[0] == 200
        t = time.perf_counter()
        jobs = []
        for i, sid in enumerate(ids):
            st, j = call(bases[i % replicas], "POST", "/v1/jobs",
                         {"shape_id": sid, "analysis": "shape-dna", "options": {"k": 50, "normalization": "area"}})
            assert st == 202, (st, j)
            jobs.append(j["id"])
        # Each job followed by its event stream (no polling: the client must not take the replicas' CPU).
        for i, j in enumerate(jobs):
            assert follow(bases[i % replicas], j) == "succeeded", j
        return len(jobs) / (time.perf_counter() - t), jobs
    finally:
        for p, _ in procs:
            p.terminate()
            p.wait()


def reads(kac, store, work, jobs, rounds=5):
    p, base = serve(kac, store, work, "--store-cache-bytes", "0")
    try:
        conn = http.client.HTTPConnection(base[len("http://"):])
        ms = []
        for _ in range(rounds):
            for j in jobs:
                t = time.perf_counter()
                conn.request("GET", "/v1/results/" + j)
                r = conn.getresponse()
                r.read()
                assert r.status == 200
                ms.append((time.perf_counter() - t) * 1e3)
        ms.sort()
        return {"p50_ms": round(ms[len(ms) // 2], 3), "p99_ms": round(ms[int(0.99 * (len(ms) - 1))], 3),
                "reads": len(ms)}
    finally:
        p.terminate()
        p.wait()


def claims(store):
    subprocess.run(["cargo", "build", "--release", "--locked", "--example", "queue_claims"], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    out = subprocess.run([os.path.join(ROOT, "target", "release", "examples", "queue_claims"), "--store", store],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--jobs", type=int, default=16)
    a = ap.parse_args()
    kac = release_kac()
    work = tempfile.mkdtemp()
    nv, bodies = shapes(kac, work, a.jobs)
    out = {"vertices": nv, "jobs": a.jobs, "analysis": "shape-dna k=50", "cores": os.cpu_count()}
    with Cluster() as pg:
        sq = "sqlite:" + os.path.join(work, "embedded")
        out["jobs_per_s"] = {}
        out["jobs_per_s"]["sqlite, 1 replica"], sq_jobs = throughput(kac, sq, work, bodies, 1)
        url1 = pg.database("one")
        out["jobs_per_s"]["postgres, 1 replica"], pg_jobs = throughput(kac, url1, work, bodies, 1)
        url2 = pg.database("two")
        out["jobs_per_s"]["postgres, 2 replicas"], _ = throughput(kac, url2, work, bodies, 2)
        url3 = pg.database("three")
        out["jobs_per_s"]["postgres, 2 replicas, shapes read by both"], _ = throughput(kac, url3, work, bodies, 2,
                                                                                      warm=True)
        r = out["jobs_per_s"]
        out["two_replicas_over_one"] = round(r["postgres, 2 replicas"] / r["postgres, 1 replica"], 3)
        out["two_replicas_over_one, shapes read by both"] = round(
            r["postgres, 2 replicas, shapes read by both"] / r["postgres, 1 replica"], 3)
        out["postgres_cost_per_job"] = round(r["sqlite, 1 replica"] / r["postgres, 1 replica"] - 1, 4)
        for k in r:
            r[k] = round(r[k], 3)
        out["get_result"] = {"sqlite": reads(kac, sq, work, sq_jobs), "postgres": reads(kac, url1, work, pg_jobs)}
        out["claim_10k_queued"] = {"sqlite": claims("sqlite:" + os.path.join(work, "claims")),
                                   "postgres": claims(pg.database("claims"))}
    print(json.dumps(out))


if __name__ == "__main__":
    main()

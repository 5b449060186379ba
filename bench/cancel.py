#!/usr/bin/env python3
"""Cancel latency of a running job in each of its phases (issue 15, item 4).

Starts a release `kac serve` on a free loopback port, uploads a generated icosphere (level 7: 163,842 vertices),
and for each delay submits a fresh `spectrum` job (k = 500, a distinct `solver.tol` so no job is reused), cancels
it after the delay, and measures the time from the cancel request to the job's terminal status, with the phase
the job was in. Prints one JSON line per trial and a summary line. Standard library only.

Usage: python3 bench/cancel.py [--k 500] [--level 7] [--delays 0.05,0.3,1,2,4,8,16]
"""
import argparse, json, os, subprocess, sys, tempfile, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402

def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--k", type=int, default=500)
    ap.add_argument("--level", type=int, default=7)
    ap.add_argument("--delays", default="0.05,0.3,1,2,4,8,16")
    ap.add_argument("--analysis", default="spectrum")
    a = ap.parse_args()
    kac = release_kac()
    work = tempfile.mkdtemp()
    mesh = os.path.join(work, "sphere.off")
    subprocess.run([kac, "generate", "icosphere", "--level", str(a.level), "--out", mesh], check=True,
                   stdout=subprocess.DEVNULL)
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=os.path.join(work, "data"), KAC_WORKERS="1",
               KAC_MAX_K="2000", RUST_LOG="error")
    srv = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        base = "http://" + json.loads(srv.stdout.readline())["listening"]
        _, shape = call(base, "POST", "/v1/shapes?format=off", open(mesh, "rb").read(), "application/octet-stream")
        worst = 0.0
        for i, delay in enumerate(float(d) for d in a.delays.split(",")):
            req = {"shape_id": shape["id"], "analysis": a.analysis, "k": a.k, "solver": {"tol": 1e-10 * (1 + i * 1e-6)}}
            st, job = call(base, "POST", "/v1/jobs", req)
            assert st == 202, (st, job)
            time.sleep(delay)
            _, before = call(base, "GET", "/v1/jobs/" + job["id"])
            t0 = time.perf_counter()
            call(base, "POST", "/v1/jobs/%s/cancel" % job["id"])
            while True:
                _, v = call(base, "GET", "/v1/jobs/" + job["id"])
                if v["status"] in ("succeeded", "failed", "canceled"):
                    break
                time.sleep(0.005)
            dt = time.perf_counter() - t0
            if v["status"] == "canceled":
                worst = max(worst, dt)
            print(json.dumps({"delay_s": delay, "phase_at_cancel": before["progress"]["phase"],
                              "status_before": before["status"], "final": v["status"],
                              "cancel_to_terminal_s": round(dt, 3)}), flush=True)
        print(json.dumps({"vertices": shape["summary"].get("vertices"), "k": a.k, "analysis": a.analysis,
                          "worst_cancel_s": round(worst, 3)}))
    finally:
        srv.terminate()
        srv.wait()

if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Cancel and timeout latency of running jobs in each of their phases (issue 15 item 4, issue 28 item 3).

Starts a release `kac serve` on a free loopback port and, for each case (a generated shape, an analysis and its
parameters), submits a fresh job (a distinct `solver.tol`, so no job or cached spectrum is reused) per delay, cancels
it after the delay, and measures the time from the cancel request to the job's terminal status, with the phase the
job was in. Then, with `--job-timeout-s 2` on a second server, the time from the timeout to the terminal status.
One JSON line per trial and a summary per case. Standard library only.

Cases (default all):
  spectrum    icosphere level 7 (163,842 vertices), spectrum k = 500: assembly, null space, symbolic, a factor of
              15M values (in pieces), iterating, Ritz vectors, verifying
  tets-p2     unit cube of tets n = 15 with quadratic elements (29,791 unknowns, a factor of 20M values with wide
              supernodes, in pieces), spectrum k = 100
  hks         icosphere level 7, hks k = 300 with 200 times (descriptor chunks after the solve)
  extrapolate the unit square, 32 × 32, spectrum k = 20 with extrapolation over 3 refinements
  geodesic    icosphere level 7, the heat method from one vertex with Varadhan's cross-check (no eigensolve)

Usage: python3 bench/cancel.py [--cases spectrum,tets-p2] [--delays 0.05,0.3,1,2,4,8]
"""
import argparse, json, os, subprocess, sys, tempfile, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402

CASES = {
    "spectrum": (["icosphere", "--level", "7"], {"analysis": "spectrum", "k": 500}),
    "tets-p2": (["cube-tets", "--n", "15"], {"analysis": "spectrum", "k": 100, "operator": {"order": 2}}),
    "hks": (["icosphere", "--level", "7"], {"analysis": "hks", "k": 300, "options": {"count": 200}}),
    "extrapolate": (["square", "--n", "32"],
                    {"analysis": "spectrum", "k": 20, "extrapolate": True, "refinements": 3}),
    # No eigensolve: factorizations and assembly in single calls, run where a stop can leave them.
    "geodesic": (["icosphere", "--level", "7"], {"analysis": "geodesic", "sources": [0]}),
}


def distinct(request, trial):
    """The request made unique (no job or cached result reused): the solver's tolerance, or for the heat method
    its time factor."""
    if request["analysis"] == "geodesic":
        return dict(request, options={"time_factor": 1.0 + trial * 1e-6})
    return dict(request, solver={"tol": 1e-10 * (1 + trial * 1e-6)})


def serve(kac, work, name, extra_env):
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=os.path.join(work, name), KAC_WORKERS="1",
               KAC_MAX_K="2000", RUST_LOG="error", **extra_env)
    srv = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    return srv, "http://" + json.loads(srv.stdout.readline())["listening"]


def upload(kac, work, base, gen):
    fmt = "off" if gen[0] in ("icosphere", "square") else "json"
    mesh = os.path.join(work, "-".join(gen) + "." + fmt)
    subprocess.run([kac, "generate", *gen, "--out", mesh], check=True, stdout=subprocess.DEVNULL)
    st, shape = call(base, "POST", "/v1/shapes?format=" + fmt, open(mesh, "rb").read(), "application/octet-stream")
    assert st in (200, 201), (st, shape)
    return shape


def until_terminal(base, job_id):
    while True:
        _, v = call(base, "GET", "/v1/jobs/" + job_id)
        if v["status"] in ("succeeded", "failed", "canceled"):
            return v
        time.sleep(0.005)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--delays", default="0.05,0.3,1,2,4,8")
    a = ap.parse_args()
    kac = release_kac()
    work = tempfile.mkdtemp()
    srv, base = serve(kac, work, "cancel", {})
    tsrv, tbase = serve(kac, work, "timeout", {"KAC_JOB_TIMEOUT_S": "2"})
    trial = 0
    try:
        for case in a.cases.split(","):
            gen, request = CASES[case]
            shape = upload(kac, work, base, gen)
            tshape = upload(kac, work, tbase, gen)
            worst, phases = 0.0, set()
            for delay in (float(d) for d in a.delays.split(",")):
                trial += 1
                req = dict(distinct(request, trial), shape_id=shape["id"])
                st, job = call(base, "POST", "/v1/jobs", req)
                assert st == 202, (st, job)
                time.sleep(delay)
                _, before = call(base, "GET", "/v1/jobs/" + job["id"])
                t0 = time.perf_counter()
                call(base, "POST", "/v1/jobs/%s/cancel" % job["id"])
                v = until_terminal(base, job["id"])
                dt = time.perf_counter() - t0
                if v["status"] == "canceled":
                    worst = max(worst, dt)
                    phases.add(before["progress"]["phase"])
                print(json.dumps({"case": case, "delay_s": delay, "phase_at_cancel": before["progress"]["phase"],
                                  "final": v["status"], "cancel_to_terminal_s": round(dt, 3)}), flush=True)
            # The timeout: the job is stopped 2 s after it started running; measured from then.
            trial += 1
            req = dict(distinct(request, trial), shape_id=tshape["id"])
            st, job = call(tbase, "POST", "/v1/jobs", req)
            v = until_terminal(tbase, job["id"])
            late = None
            if v["status"] == "failed" and v["error"]["code"] == "job-timeout":
                started = v["started_at"]
                finished = v["finished_at"]
                parse = lambda s: time.mktime(time.strptime(s[:19], "%Y-%m-%dT%H:%M:%S")) + float("0" + s[19:-1])
                late = round(parse(finished) - parse(started) - 2.0, 3)
            print(json.dumps({"case": case, "vertices": shape["summary"].get("vertices"), "worst_cancel_s": round(worst, 3),
                              "phases_canceled": sorted(phases), "timeout_final": v["status"],
                              "timeout_late_s": late}), flush=True)
    finally:
        for s in (srv, tsrv):
            s.terminate()
            s.wait()


if __name__ == "__main__":
    main()

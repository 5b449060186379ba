#!/usr/bin/env python3
"""Bulk ingest: shapes ingested per second (upload + shape-DNA k = 50 + indexed) against the eigensolver-bound
rate, with the server's default worker count (one per core: 2 on the 2-core machine the target is stated for).

Meshes. `kac generate icosphere --level 5` (10,242 vertices, 20,480 triangles, closed) once, then N distinct
variants: each vertex moved radially by 1 + Σ of three Gaussian bumps (random centres on the sphere, amplitude
±0.15, width 0.35 to 0.7: smooth, low frequency), then each axis scaled by 1 + U(−0.15, 0.15); written as OFF
(%.10g) into a throwaway directory before anything is timed.

Eigensolver-bound rate, two ways:
  (a) `cli_rate`: the first --cli-sample meshes through `kac shape-dna FILE --k 50 --normalization area
      --threads 1`, as many processes at once as the server has workers; sample / wall seconds (each process
      also starts, reads and validates its file). Run before the server starts.
  (b) `solve_only_rate`: the service's own solves during the ingest. A shape-DNA result holds no timings, so for
      --solve-sample shapes spread evenly over the ingest order the script submits, after the ingest, a
      `spectrum` job with k = 50 + the result's `shape_dna.zero_modes_dropped` (the pairs the shape-DNA job
      solved for, same default solver settings): it is answered from the eigenpair cache (`eigenpairs_reused`:
      true; the cache holds about 250 of these shapes with the default --cache-bytes) and its `timings` are the
      solver's report of the solve the ingest's job ran. eigensolve seconds = `timings.total_s` −
      `timings.assembly_s` (symbolic + numeric factorization, Lanczos iteration, Sylvester verification);
      solve_only_rate = workers / mean(eigensolve seconds). Only reused samples count (a sample evicted from the
      cache is solved again, after the ingest, and is left out; `solve_sample.reused` says how many counted).
  `job_worker_s` is the mean time a bulk upload's fingerprint job spent on a worker (the server's
  kac_job_duration_seconds{analysis="fingerprint"} sum / count): the solve plus loading the shape, assembling,
  the descriptors and storing the result.

Ingest. A fresh `kac serve` (throwaway data directory, default settings unless --workers / --queue-capacity);
--uploaders threads send POST /v1/shapes/bulk with --batch files each plus the `options` part
{"tags": ["ingest-bench"], "fingerprint": {"k": 50, "normalization": "area"}}. The bulk route starts one
fingerprint job per file in the queue's backlog lane, which --queue-capacity does not bound (since issue 50 no job
is left unstarted for capacity); the uploaders still pace themselves as they did when a full queue refused jobs
(a batch is sent only when the jobs submitted and not yet finished plus the batch fit --queue-capacity, or none
are outstanding), so that the figures stay comparable with the earlier runs; a file whose job did not start would
be submitted again with POST /v1/jobs (`queue_full_retries`, now always 0). Progress is read from GET /metrics (kac_jobs{status}) every 0.2 s.
  * upload_s: the bulk requests' own seconds, summed; upload_wall_s: the first request's start to the last
    answer (includes waiting for room in the queue);
  * ingest_s: the first request's start to the latest `finished_at` of the jobs (GET /v1/jobs/{id} of each,
    after the run; ms resolution); ingest_rate = N / ingest_s; ratio = ingest_rate / solve_only_rate (the target:
    ≥ 0.8);
  * indexed: POST /v1/search {"k": 50, "normalization": "area", "shape_id": the first, "neighbours": 5}
    answers `searched` (the fingerprints of the family held), which must equal N;
  * peak_mb: the server's VmHWM (/proc/PID/status) after the ingest and the search (before the samples of (b)).
Prints one JSON line on stdout (progress on stderr). Standard library and numpy.

Usage: bench/.venv/bin/python bench/ingest.py [--n 200] [--batch 25] [--uploaders 1] [--kac target/release/kac]
"""
import argparse, datetime, json, os, shutil, subprocess, sys, tempfile, threading, time, urllib.request, uuid
from concurrent.futures import ThreadPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402
from search import peak_mb, stop  # noqa: E402

FP = {"k": 50, "normalization": "area"}
TAG = "ingest-bench"
TERMINAL = ("succeeded", "failed", "canceled")


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def meshes(kac, work, n, seed):
    """N distinct deformed level-5 icospheres as OFF files; (paths, vertices)."""
    src = os.path.join(work, "ico5.off")
    subprocess.run([kac, "generate", "icosphere", "--level", "5", "--out", src], check=True,
                   stdout=subprocess.DEVNULL)
    lines = open(src).read().split("\n")
    nv, nf = map(int, lines[1].split()[:2])
    v = np.array([l.split() for l in lines[2:2 + nv]], float)
    faces = "\n".join(lines[2 + nv:2 + nv + nf]) + "\n"
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    rng = np.random.default_rng(seed)
    out = os.path.join(work, "meshes")
    os.makedirs(out)
    paths = []
    for i in range(n):
        c = rng.normal(size=(3, 3))
        c /= np.linalg.norm(c, axis=1, keepdims=True)
        amp, width = rng.uniform(-0.15, 0.15, 3), rng.uniform(0.35, 0.7, 3)
        d2 = ((u[:, None, :] - c[None]) ** 2).sum(-1)
        r = 1.0 + (amp * np.exp(-d2 / (2 * width ** 2))).sum(1)
        x = v * r[:, None] * (1.0 + rng.uniform(-0.15, 0.15, 3))
        p = os.path.join(out, "m%05d.off" % i)
        with open(p, "w") as f:
            f.write("OFF\n%d %d 0\n" % (nv, nf))
            f.write(("%.10g %.10g %.10g\n" * nv) % tuple(x.ravel()))
            f.write(faces)
        paths.append(p)
    return paths, nv


def cli_rate(kac, paths, parallel):
    """(a): the sample through `kac shape-dna --threads 1`, `parallel` processes at once."""
    def one(p):
        t = time.perf_counter()
        subprocess.run([kac, "shape-dna", p, "--k", str(FP["k"]), "--normalization", FP["normalization"],
                        "--threads", "1"], check=True, stdout=subprocess.DEVNULL)
        return time.perf_counter() - t
    t0 = time.perf_counter()
    with ThreadPoolExecutor(parallel) as ex:
        each = list(ex.map(one, paths))
    wall = time.perf_counter() - t0
    return {"sample": len(paths), "parallel": parallel, "wall_s": round(wall, 3),
            "mean_process_s": round(float(np.mean(each)), 4), "rate": round(len(paths) / wall, 3)}


def serve(kac, data, logfile, workers, capacity):
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=data, RUST_LOG="error")
    if workers is not None:
        env["KAC_WORKERS"] = str(workers)
    if capacity is not None:
        env["KAC_QUEUE_CAPACITY"] = str(capacity)
    with open(logfile, "ab") as err:
        p = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=err)
    line = p.stdout.readline()
    if not line:
        raise RuntimeError("kac serve exited (%s) before listening" % p.wait())
    threading.Thread(target=lambda: [None for _ in p.stdout], daemon=True).start()
    return p, "http://" + json.loads(line)["listening"]


def metrics(base):
    """GET /metrics as {name{labels}: value}."""
    with urllib.request.urlopen(base + "/metrics", timeout=30) as r:
        text = r.read().decode()
    out = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            name, _, value = line.rpartition(" ")
            try:
                out[name] = float(value)
            except ValueError:
                pass
    return out


def finished(m):
    return sum(m.get('kac_jobs{status="%s"}' % s, 0) for s in TERMINAL)


def multipart(paths, options):
    """A multipart/form-data body: the options part, then one file part per path; (body, content type)."""
    b = uuid.uuid4().hex
    chunks = [("--%s\r\nContent-Disposition: form-data; name=\"options\"\r\nContent-Type: application/json\r\n\r\n"
               % b).encode(), json.dumps(options).encode(), b"\r\n"]
    for p in paths:
        chunks.append(("--%s\r\nContent-Disposition: form-data; name=\"file\"; filename=\"%s\"\r\n"
                       "Content-Type: application/octet-stream\r\n\r\n" % (b, os.path.basename(p))).encode())
        with open(p, "rb") as f:
            chunks.append(f.read())
        chunks.append(b"\r\n")
    chunks.append(("--%s--\r\n" % b).encode())
    return b"".join(chunks), "multipart/form-data; boundary=" + b


class Queue:
    """The client's view of the server's queue: jobs it submitted (reserved before sending) and jobs finished
    (from /metrics, polled)."""

    def __init__(self, base, capacity):
        self.base, self.capacity = base, capacity
        self.cv = threading.Condition()
        self.reserved = 0
        self.done = 0
        self.stopped = False
        self.thread = threading.Thread(target=self.poll, daemon=True)
        self.thread.start()

    def poll(self):
        while not self.stopped:
            try:
                done = finished(metrics(self.base))
            except OSError as e:
                log("  GET /metrics: %s" % e)
                with self.cv:
                    self.stopped = True
                    self.cv.notify_all()
                return
            with self.cv:
                self.done = done
                self.cv.notify_all()
            time.sleep(0.2)

    def reserve(self, n):
        """Waits until n more jobs fit (or none are outstanding), then counts them as submitted."""
        with self.cv:
            self.cv.wait_for(lambda: self.reserved - self.done + n <= self.capacity or self.reserved <= self.done
                             or self.stopped)
            self.reserved += n

    def release(self, n):
        with self.cv:
            self.reserved -= n
            self.cv.notify_all()

    def wait_all(self, total):
        with self.cv:
            self.cv.wait_for(lambda: self.done >= total or self.stopped)
        if self.done < total:
            raise RuntimeError("the server stopped answering before every job finished")


def ingest(base, paths, batch, uploaders, capacity):
    """Uploads every path in bulk requests; the files' entries (in order), request seconds, the first request's
    start (perf counter and wall clock), the last answer (perf counter), and the queue-full retries."""
    q = Queue(base, capacity)
    batches = [list(range(i, min(i + batch, len(paths)))) for i in range(0, len(paths), batch)]
    entries = [None] * len(paths)
    request_s, retries, lock = [], [0], threading.Lock()
    first, last = [], [0.0]
    options = {"tags": [TAG], "fingerprint": FP}

    def retry(i, shape_id):
        while True:
            q.reserve(1)
            st, job = call(base, "POST", "/v1/jobs", {"shape_id": shape_id, "analysis": "shape-dna", "options": FP})
            if st in (200, 202):
                return job
            q.release(1)
            if st != 503:
                raise RuntimeError("POST /v1/jobs for %s: %s %s" % (paths[i], st, job))
            time.sleep(0.5)

    def uploader():
        while True:
            with lock:
                if not batches:
                    return
                idx = batches.pop(0)
            body, ctype = multipart([paths[i] for i in idx], options)
            q.reserve(len(idx))
            t = time.perf_counter()
            with lock:
                if not first:
                    first.extend([t, time.time()])
            st, r = call(base, "POST", "/v1/shapes/bulk", body, ctype, timeout=600)
            t1 = time.perf_counter()
            if st != 200:
                raise RuntimeError("POST /v1/shapes/bulk: %s %s" % (st, r))
            assert len(r["files"]) == len(idx), (len(r["files"]), len(idx))
            no_job = [(i, f) for i, f in zip(idx, r["files"]) if f.get("job") is None]
            q.release(len(no_job))
            with lock:
                request_s.append(t1 - t)
                last[0] = max(last[0], t1)
            for i, f in zip(idx, r["files"]):
                entries[i] = f
            for i, f in no_job:
                p = f.get("problem") or {}
                if f.get("shape") and "queue-full" in str(p.get("type", "")):
                    f["job"] = retry(i, f["shape"]["id"])
                    f["retried"] = True
                    with lock:
                        retries[0] += 1
            log("  sent %d / %d files (%.1f s)" % (sum(e is not None for e in entries), len(paths),
                                                   time.perf_counter() - first[0]))

    errors = []

    def guarded():
        try:
            uploader()
        except Exception as e:  # noqa: BLE001 (reported after the join)
            errors.append(e)

    threads = [threading.Thread(target=guarded) for _ in range(uploaders)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    if errors:
        q.stopped = True
        raise errors[0]
    jobs = sum(1 for e in entries if e.get("job"))
    q.wait_all(jobs)
    q.stopped = True
    return entries, request_s, first, last[0], retries[0]


def iso(s):
    return datetime.datetime.strptime(s, "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=datetime.timezone.utc).timestamp()


def solve_sample(base, job_ids, count):
    """(b): the eigensolve seconds of the ingest's jobs, from `spectrum` jobs answered by the eigenpair cache."""
    if count and count < len(job_ids):
        pick = [job_ids[int(round(j))] for j in np.linspace(0, len(job_ids) - 1, count)]
    else:
        pick = list(job_ids)
    pending = []
    for jid in pick:
        st, job = call(base, "GET", "/v1/jobs/" + jid)
        st, res = call(base, "GET", job["result"])
        k = FP["k"] + res["shape_dna"]["zero_modes_dropped"]
        while True:
            st, sj = call(base, "POST", "/v1/jobs", {"shape_id": job["shape_id"], "analysis": "spectrum", "k": k})
            if st in (200, 202):
                break
            if st != 503:
                raise RuntimeError("spectrum job: %s %s" % (st, sj))
            time.sleep(0.5)
        pending.append(sj["id"])
    solve, assembly, fresh = [], [], 0
    for jid in wait_jobs(base, pending):
        st, job = call(base, "GET", "/v1/jobs/" + jid)
        if job["status"] != "succeeded":
            raise RuntimeError("spectrum job %s: %s" % (jid, job.get("error")))
        st, res = call(base, "GET", job["result"])
        if not res.get("eigenpairs_reused"):
            fresh += 1
            continue
        t = res["timings"]
        solve.append(t["total_s"] - t["assembly_s"])
        assembly.append(t["assembly_s"])
    return solve, assembly, len(pick), fresh


def wait_jobs(base, ids):
    for jid in ids:
        while call(base, "GET", "/v1/jobs/" + jid)[1]["status"] not in TERMINAL:
            time.sleep(0.1)
    return ids


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=200, help="meshes ingested")
    ap.add_argument("--batch", type=int, default=25, help="files per bulk request")
    ap.add_argument("--uploaders", type=int, default=1, help="bulk requests in flight at once")
    ap.add_argument("--workers", type=int, default=None,
                    help="the server's --workers (default: its own, one per core)")
    ap.add_argument("--queue-capacity", type=int, default=None,
                    help="the server's --queue-capacity (default: its own, 64)")
    ap.add_argument("--cli-sample", type=int, default=8, help="meshes for (a), the CLI's rate")
    ap.add_argument("--solve-sample", type=int, default=40,
                    help="shapes whose solve seconds are read back for (b) (0: all)")
    ap.add_argument("--kac", default=None, help="the binary (default: cargo build --release)")
    ap.add_argument("--workdir", default=None,
                    help="where the throwaway meshes and data directory go (default: TMPDIR)")
    ap.add_argument("--keep", action="store_true", help="keep the meshes and the data directory")
    ap.add_argument("--seed", type=int, default=11)
    a = ap.parse_args()
    kac = os.path.abspath(a.kac) if a.kac else release_kac()
    workers = a.workers or len(os.sched_getaffinity(0))

    work = tempfile.mkdtemp(prefix="kac-ingest-", dir=a.workdir)
    p = None
    try:
        t = time.perf_counter()
        paths, nv = meshes(kac, work, a.n, a.seed)
        log("%d meshes of %d vertices written in %.1f s (%s)" % (a.n, nv, time.perf_counter() - t, work))

        log("(a) kac shape-dna on %d meshes, %d at a time" % (min(a.cli_sample, a.n), workers))
        cli = cli_rate(kac, paths[:a.cli_sample], workers)

        p, base = serve(kac, os.path.join(work, "data"), os.path.join(work, "serve.log"), a.workers, a.queue_capacity)
        m0 = metrics(base)
        capacity = int(m0["kac_queue_capacity"])
        log("ingest: %d files in batches of %d, %d uploader(s), %d workers, queue capacity %d"
            % (a.n, a.batch, a.uploaders, workers, capacity))
        entries, request_s, (t0, t0_wall), t_last, retries = ingest(base, paths, a.batch, a.uploaders, capacity)
        polled_s = time.perf_counter() - t0

        jobs = [e["job"]["id"] for e in entries if e.get("job")]
        views = [call(base, "GET", "/v1/jobs/" + j)[1] for j in jobs]
        statuses = {}
        for v in views:
            statuses[v["status"]] = statuses.get(v["status"], 0) + 1
        ends = [iso(v["finished_at"]) for v in views if v.get("finished_at")]
        ingest_s = max(ends) - t0_wall if ends else None
        m1 = metrics(base)
        key = '{analysis="fingerprint",status="succeeded"}'
        n_done = m1.get("kac_job_duration_seconds_count" + key, 0)
        job_worker_s = m1.get("kac_job_duration_seconds_sum" + key, 0) / n_done if n_done else None

        first_shape = next((e["shape"]["id"] for e in entries if e.get("shape")), None)
        st, s = call(base, "POST", "/v1/search", dict(FP, shape_id=first_shape, neighbours=5, tags=[TAG]))
        searched = s.get("searched") if st == 200 else None
        if st != 200:
            log("  search: %s %s" % (st, s))
        mem = peak_mb(p)

        succeeded = [j for j, v in zip(jobs, views) if v["status"] == "succeeded"]
        log("(b) solve seconds of %d of the ingest's solves" % min(a.solve_sample or len(succeeded), len(succeeded)))
        solve, assembly, sampled, fresh = solve_sample(base, succeeded, a.solve_sample)

        problems = {}
        for e in entries:
            pr = e.get("problem")
            if pr and not e.get("retried"):
                k = pr.get("type", "?")
                problems[k] = problems.get(k, 0) + 1
        solve_mean = float(np.mean(solve)) if solve else None
        solve_rate = workers / solve_mean if solve_mean else None
        ingest_rate = a.n / ingest_s if ingest_s else None
        r3 = lambda x: None if x is None else round(x, 3)
        print(json.dumps({
            "meshes": a.n, "vertices": nv, "batch": a.batch, "uploaders": a.uploaders, "workers": workers,
            "queue_capacity": capacity,
            "upload_s": r3(sum(request_s)), "upload_wall_s": r3(t_last - t0),
            "upload_per_file_ms": round(1000 * sum(request_s) / a.n, 1),
            "ingest_s": r3(ingest_s), "ingest_polled_s": r3(polled_s),
            "ingest_rate": r3(ingest_rate), "solve_only_rate": r3(solve_rate), "cli_rate": cli["rate"],
            "ratio": r3(ingest_rate / solve_rate) if ingest_rate and solve_rate else None,
            "created": sum(e["status"] == 201 for e in entries), "existing": sum(e["status"] == 200 for e in entries),
            "failed": sum(e.get("shape") is None for e in entries), "problems": problems,
            "queue_full_retries": retries, "jobs": statuses, "indexed": searched,
            "all_indexed": searched == a.n,
            "solve_sample": {"sampled": sampled, "reused": len(solve), "solved_again": fresh,
                             "eigensolve_s": r3(solve_mean),
                             "eigensolve_median_s": r3(float(np.median(solve))) if solve else None,
                             "eigensolve_max_s": r3(max(solve)) if solve else None,
                             "assembly_s": round(float(np.mean(assembly)), 4) if assembly else None},
            "job_worker_s": r3(job_worker_s),
            "peak_mb": mem, "cli": cli}), flush=True)
    finally:
        if p is not None:
            stop(p)
        if a.keep:
            log("kept %s" % work)
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Search over many stored fingerprints of one family: the index against the exact scan, on real distributions.

Families (--descriptor). `shape-dna` (default): k = 50, area normalization, not reweighted (the options of the
earlier figures in BENCHMARKS.md, given explicitly: retrieval's defaults are now `geometry` and `index`);
`heat-distribution` (96 values: 6 blocks of 16 quantiles of log(h/Z)) and `gps-d2` (32 quantiles of GPS
distances), each with retrieval's defaults and k = 50.

Data, as bench/dna_corpus.py builds it: a real set of a few hundred fingerprints, computed on the shared meshes
(/work/shared/data) and on generated shapes at several resolutions, each also under vertex noise and uniform
scaling — shape-DNA by `kac shape-dna` (cached in bench/out/real_dna.json), the other families by
`kac fingerprint -k 50` (cached in bench/out/real_families.json); and, for collections larger than that,
synthetic rows that follow it: a point on the path between a real fingerprint and one of its 10 nearest, with
small noise (white and low-frequency) — for shape-DNA log-linear with multiplicative noise, sorted; for the
quantile families linear with additive noise scaled by each component's standard deviation over the real set,
sorted within each block of quantiles. A fifth of the real set is held out of every collection; the rest is
stored as it is.

Queries. Mostly held-out real fingerprints (not in the collection; their near-duplicates under other noise,
scale or resolution may be), each slightly perturbed (0.1 % white and 0.2 % smooth noise: multiplicative for
shape-DNA, of each component's spread for the others), and some stored synthetic rows perturbed the same way;
shuffled together. Recall is reported for the two kinds apart.

Data model (as crates/kac-engine/src/store/sqlite/ creates it): DATA_DIR/kac.sqlite3 holds
`fingerprints (family TEXT, shape_id TEXT, fingerprint BLOB, PRIMARY KEY (family, shape_id))`, the BLOB being
the values as little-endian float64. A family is the hash of the descriptor, its options and the operator; this
script learns it from one real search (a generated icosphere uploaded and searched by its id with
{"descriptor": <family>, "k": 50, ...the options}, which runs a `fingerprint` job and stores one fingerprint per
family), stops the server and inserts the other N − 1 rows of the family straight into the table (one
transaction, executemany in chunks; shape ids are 64 lowercase hex digits, increasing in insertion order so the
primary key's B-tree is appended to). Their shapes are not stored: a search by fingerprint does not need them.
For the quantile families the family learned is checked against those `kac fingerprint` gave the real set.

Per N, in one run:
  * index build: DATA_DIR/search-index.bin (the index snapshot) is deleted, the server is started; it builds
    the index from the table and writes the snapshot. `index_build_s` is the time until it prints its
    {"listening": ...} line; the script then waits for the snapshot file to exist and stop growing, reads the
    process's peak resident memory (VmHWM in /proc/PID/status) and stops it (SIGTERM);
  * start-up: the server is started again and reads the snapshot: `startup_s`, the time to {"listening": ...};
    `server_load_report` is the server's own "search index loaded" log line of each start (where it read the
    index from, how many fingerprints, its seconds, why a snapshot was refused), null where it logs none;
  * queries: POST /v1/search {"descriptor": <family>, "k": 50, ...the options, "fingerprint": [...],
    "neighbours": 10}, sequentially over loopback, each timed as the whole request (3 untimed warm-up requests
    first). First every query through the index, then the first --exact-queries of them (a random mix of both
    kinds) again with "exact": true (the exact scan); the two passes are apart so that neither's latency
    includes the other's effect on the caches; recall@10 = |indexed ids ∩ exact ids| / 10, averaged;
    `exact_fraction`: indexed answers marked "exact": true (proven exact); `mean_probed`: fingerprints the index
    computed a distance to; the same again within the tag "one-percent" (every hundredth row);
  * the serving process's VmHWM after all queries.
Prints one JSON line per N on stdout, with its "descriptor" (progress on stderr). The data directory is removed
after each N unless --keep; 10^7 shape-DNA fingerprints take about 6 GB of table (measured: 590 MB per 10^6
rows; the 96 values of the heat distribution about twice that) plus the snapshot on disk (--workdir to choose
where). Inserting them takes about 9 s per 10^6 rows here.

Usage: bench/.venv/bin/python bench/search.py [--descriptor shape-dna|heat-distribution|gps-d2]
           [--n 100000,1000000,10000000] [--queries 200] [--exact-queries 50] [--kac target/release/kac]
"""
import argparse, itertools, json, os, shutil, signal, sqlite3, subprocess, sys, tempfile, threading, time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402
import dna_corpus  # noqa: E402

# Each family's request options (with the fingerprint or shape id, they make the search's body).
OPTIONS = {"shape-dna": {"descriptor": "shape-dna", "k": 50, "normalization": "area", "reweighting": "none"},
           "heat-distribution": {"descriptor": "heat-distribution", "k": 50},
           "gps-d2": {"descriptor": "gps-d2", "k": 50}}
SNAPSHOT = "search-index.bin"


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def start(kac, data, logfile=os.devnull):
    """A `kac serve` on data; (process, base URL, seconds until it printed its listening line). Its log (errors,
    and the service's and the engine's own info lines such as "search index loaded", not one per request) goes
    to `logfile`."""
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=data,
               RUST_LOG="error,kac::service=info,kac::service::ops=error,kac_engine=info")
    t = time.perf_counter()
    with open(logfile, "ab") as err:
        p = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=err)
    line = p.stdout.readline()
    secs = time.perf_counter() - t
    if not line:
        raise RuntimeError("kac serve exited (%s) before listening" % p.wait())
    base = "http://" + json.loads(line)["listening"]
    # whatever else it prints must not fill the pipe
    threading.Thread(target=lambda: [None for _ in p.stdout], daemon=True).start()
    return p, base, secs


def log_fields(logfile, message):
    """The fields of the last log line with this message (the server logs JSON lines), if any."""
    found = None
    for line in open(logfile, errors="replace"):
        try:
            fields = json.loads(line).get("fields", {})
        except ValueError:
            continue
        if fields.get("message") == message:
            found = {k: v for k, v in fields.items() if k != "message"}
    return found


def load_report(logfile):
    """The fields of the last "search index loaded" log line (from, fingerprints, seconds, refused), if any."""
    return log_fields(logfile, "search index loaded")


def stop(p):
    p.send_signal(signal.SIGTERM)
    try:
        p.wait(timeout=120)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


def peak_mb(p):
    """The process's peak resident set (VmHWM), MB."""
    for line in open("/proc/%d/status" % p.pid):
        if line.startswith("VmHWM:"):
            return round(int(line.split()[1]) / 1024)
    return None


def wait_snapshot(path, limit):
    """Seconds until `path` exists and its size holds still for a second; None if not within `limit`."""
    t0, last = time.perf_counter(), None
    while time.perf_counter() - t0 < limit:
        size = os.path.getsize(path) if os.path.exists(path) else None
        if size is not None and size == last:
            return time.perf_counter() - t0 - 1.0
        last = size
        time.sleep(1.0)
    return None


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


def learn_family(kac, data, work, q):
    """The family of fingerprints with options `q`, from one real search; it stores one fingerprint per family."""
    mesh = os.path.join(work, "sphere.off")
    subprocess.run([kac, "generate", "icosphere", "--level", "3", "--out", mesh], check=True,
                   stdout=subprocess.DEVNULL)
    p, base, _ = start(kac, data)
    try:
        _, shape = call(base, "POST", "/v1/shapes?format=off", open(mesh, "rb").read(), "application/octet-stream")
        st, first = call(base, "POST", "/v1/search?wait=60", dict(q, shape_id=shape["id"]))
        assert st == 200, (st, first)
        return first["family"]
    finally:
        stop(p)


def fill(data, family, base, rows, seed, pick, synthetic):
    """Inserts `rows` rows: the real fingerprints `base`, spread at random through the table, and synthetic
    ones following them (`synthetic(base, n, seed, chunk)` yields them in chunks). Returns the synthetic rows
    numbered `pick` (in the order they were generated) and the seconds it took."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed + 1)
    n_syn = max(0, rows - len(base))
    head = base[:rows]
    # shape ids: a prefix increasing with the row, then random digits
    def ids(start, m):
        tail = rng.bytes(24 * m).hex()
        return ["%016x%s" % ((start + i) * (2 ** 64 - 1) // max(rows, 1), tail[48 * i:48 * (i + 1)])
                for i in range(m)]

    def blobs(x):
        b = np.ascontiguousarray(x, "<f8").tobytes()
        w = 8 * x.shape[1]
        return [b[i * w:(i + 1) * w] for i in range(len(x))]

    db = sqlite3.connect(os.path.join(data, "kac.sqlite3"))
    db.execute("PRAGMA journal_mode = DELETE")  # the server sets WAL again when it opens the file
    db.execute("PRAGMA synchronous = OFF")
    db.execute("PRAGMA cache_size = -262144")  # 256 MB
    sql = "INSERT INTO fingerprints (family, shape_id, fingerprint) VALUES (?, ?, ?)"
    picked = {}
    # the real rows go to random places among the synthetic ones (table order is load order)
    chunk = 250_000
    share = rng.multinomial(len(head), np.diff(np.r_[0:n_syn:chunk, n_syn]) / n_syn) if n_syn else [len(head)]
    at, done, real_at = 0, 0, np.cumsum(np.r_[0, share])
    with db:  # one transaction
        for c, chunk_rows in enumerate(itertools.chain(synthetic(base, n_syn, seed, chunk),
                                                       [np.empty((0, base.shape[1]))] if not n_syn else [])):
            for j in (j for j in pick if done <= j < done + len(chunk_rows)):
                picked[j] = chunk_rows[j - done].copy()
            x = np.concatenate([head[real_at[c]:real_at[c + 1]], chunk_rows])
            x = x[rng.permutation(len(x))]
            idx = ids(at, len(x))
            db.executemany(sql, zip(itertools.repeat(family), idx, blobs(x)))
            # every hundredth shape carries the tag "one-percent" (for the filtered searches)
            db.executemany("INSERT INTO shape_tags (shape_id, tag) VALUES (?, 'one-percent')",
                           [(idx[i],) for i in range(len(idx)) if (at + i) % 100 == 0])
            done += len(chunk_rows)
            at += len(x)
            if at // 1_000_000 > (at - len(x)) // 1_000_000:
                log("  inserted %d / %d" % (at, rows))
    assert at == rows, (at, rows)
    db.close()
    return [picked[j] for j in pick], time.perf_counter() - t0


def queries(real_held, synthetic_rows, count, n_synthetic, rng, perturb):
    """[(kind, fingerprint)]: held-out real fingerprints (cycled) and stored synthetic rows, perturbed
    (`perturb(rows, rng)`), shuffled."""
    n_real = count - len(synthetic_rows[:n_synthetic])
    order = np.concatenate([rng.permutation(len(real_held)) for _ in range(n_real // max(1, len(real_held)) + 1)])
    real = perturb(real_held[order[:n_real]], rng)
    syn = perturb(np.array(synthetic_rows[:n_synthetic]).reshape(-1, real_held.shape[1]), rng)
    qs = [("real", q.tolist()) for q in real] + [("synthetic", q.tolist()) for q in syn]
    return [qs[i] for i in rng.permutation(len(qs))]


def expansion(descriptor, real):
    """(synthetic(base, n, seed, chunk), perturb(rows, rng)) of a family: shape-DNA's log-linear blends and
    multiplicative noise, or the quantile families' linear blends and additive noise in units of each
    component's standard deviation over `real` (the whole real set), sorted within blocks."""
    if descriptor == "shape-dna":
        return (lambda base, n, seed, chunk: dna_corpus.synthetic(base, n, seed=seed, chunk=chunk),
                lambda x, rng: dna_corpus.perturb(x, rng, sigma=0.001, smooth=0.002))
    block, spread = dna_corpus.FAMILIES[descriptor][1], np.asarray(real, float).std(axis=0)
    return (lambda base, n, seed, chunk: dna_corpus.synthetic_linear(base, n, block, spread, seed=seed, chunk=chunk),
            lambda x, rng: dna_corpus.perturb_linear(x, rng, spread, block, sigma=0.001, smooth=0.002))


def search(base, q, fp, n, exact=False, tags=None):
    body = dict(q, fingerprint=fp, neighbours=10)
    if exact:
        body["exact"] = True
    if tags:
        body["tags"] = tags
    t = time.perf_counter()
    st, r = call(base, "POST", "/v1/search", body, timeout=600)
    secs = time.perf_counter() - t
    assert st == 200 and (n is None or r["searched"] == n), (st, r if st != 200 else r.get("searched"))
    return secs, r


def run(a, kac, n, base_real, held, model, cli_families):
    """One collection of n fingerprints of the family a.descriptor; `model`: its expansion(); `cli_families`: the
    family ids `kac fingerprint` gave the real set (None: not checked)."""
    rng = np.random.default_rng(a.seed + n)
    q = OPTIONS[a.descriptor]
    synthetic, perturb = model
    work = tempfile.mkdtemp(prefix="kac-search-", dir=a.workdir)
    data = os.path.join(work, "data")
    try:
        family = learn_family(kac, data, work, q)
        if cli_families is not None and family not in cli_families:
            log("  the family searched (%s) is none of those `kac fingerprint` gave the real set (%s)"
                % (family, ", ".join(cli_families)))
        rows = n - 1  # the learning search stored one
        n_syn_q = min(a.synthetic_queries, a.queries, max(0, rows - len(base_real)))
        pick = sorted(rng.choice(max(0, rows - len(base_real)), n_syn_q, replace=False).tolist()) if n_syn_q else []
        log("N = %d: inserting %d rows (%d real) into family %s" % (n, rows, min(rows, len(base_real)), family))
        syn_rows, insert_s = fill(data, family, base_real, rows, a.seed + n, pick, synthetic)
        qs = queries(held, syn_rows, a.queries, n_syn_q, rng, perturb)
        snap = os.path.join(data, SNAPSHOT)
        if os.path.exists(snap):
            os.remove(snap)

        log("  building the index (first start)")
        build_log, serve_log = os.path.join(work, "build.log"), os.path.join(work, "serve.log")
        p, base, build_s = start(kac, data, build_log)
        try:
            snap_wait = wait_snapshot(snap, a.snapshot_wait)
            build_mb = peak_mb(p)
        finally:
            stop(p)
        build_report = load_report(build_log)
        snap_written = "while running" if snap_wait is not None else ("at stop" if os.path.exists(snap) else None)
        snap_mb = round(os.path.getsize(snap) / 2 ** 20) if os.path.exists(snap) else None

        log("  start from the snapshot, %d queries" % len(qs))
        p, base, startup_s = start(kac, data, serve_log)
        serve_report = load_report(serve_log)
        if serve_report and serve_report.get("from") != "snapshot":
            log("  the second start did not read the snapshot: %s" % serve_report)
        try:
            for _, fp in qs[:3]:
                search(base, q, fp, n)
            indexed = [search(base, q, fp, n) for _, fp in qs]
            n_exact = len(qs) if a.exact_queries is None else min(a.exact_queries, len(qs))
            exact = [search(base, q, fp, n, exact=True) for _, fp in qs[:n_exact]]
            one = ["one-percent"]
            tagged = [search(base, q, fp, n, tags=one) for _, fp in qs]
            tagged_exact = [search(base, q, fp, n, exact=True, tags=one) for _, fp in qs[:n_exact]]
            serve_mb = peak_mb(p)
        finally:
            stop(p)

        recall = {"real": [], "synthetic": []}
        for (kind, _), (_, ri), (_, re) in zip(qs, indexed, exact):
            got = {x["shape_id"] for x in ri["neighbours"]}
            want = {x["shape_id"] for x in re["neighbours"]}
            recall[kind].append(len(got & want) / max(1, len(want)))
        tagged_recall = [len({x["shape_id"] for x in ri["neighbours"]} & {x["shape_id"] for x in re["neighbours"]})
                         / max(1, len(re["neighbours"])) for (_, ri), (_, re) in zip(tagged, tagged_exact)]
        marked = [r["exact"] for _, r in indexed if "exact" in r]
        probed = [r["probed"] for _, r in indexed if "probed" in r]
        ms = lambda xs: {"p50": round(1000 * pct(xs, 0.5), 2), "p99": round(1000 * pct(xs, 0.99), 2)}
        mean = lambda xs: round(float(np.mean(xs)), 4) if xs else None
        return {"descriptor": a.descriptor, "fingerprints": n, "real_in_collection": min(rows, len(base_real)),
                "k": 50, "neighbours": 10,
                "queries": len(qs), "real_queries": sum(k == "real" for k, _ in qs), "exact_queries": len(exact),
                "insert_s": round(insert_s, 1),
                "db_mb": round(os.path.getsize(os.path.join(data, "kac.sqlite3")) / 2 ** 20),
                "index_build_s": round(build_s, 3),
                "snapshot": {"written": snap_written, "mb": snap_mb,
                             "after_listening_s": None if snap_wait is None else round(snap_wait, 1)},
                "startup_s": round(startup_s, 3),
                "server_load_report": {"build": build_report, "serve": serve_report},
                "peak_mb": {"build": build_mb, "serve": serve_mb},
                "indexed_ms": ms([s for s, _ in indexed]), "exact_scan_ms": ms([s for s, _ in exact]),
                "recall_at_10": {"real": mean(recall["real"]), "synthetic": mean(recall["synthetic"]),
                                 "min": min(recall["real"] + recall["synthetic"], default=None)},
                "exact_fraction": mean(marked), "mean_probed": mean(probed),
                "tag_1_percent": {"ms": ms([s for s, _ in tagged]), "exact_scan_ms": ms([s for s, _ in tagged_exact]),
                                  "recall_at_10": mean(tagged_recall),
                                  "method": sorted({r.get("method") for _, r in tagged} - {None})}}
    finally:
        if a.keep:
            log("  kept " + work)
        else:
            shutil.rmtree(work, ignore_errors=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--descriptor", default="shape-dna", choices=list(OPTIONS), help="the family searched")
    ap.add_argument("--n", default="100000,1000000,10000000", help="collection sizes, comma-separated")
    ap.add_argument("--queries", type=int, default=200)
    ap.add_argument("--exact-queries", type=int, default=None,
                    help="queries also run with the exact scan, for recall (default: all; 50 is enough at 10^7)")
    ap.add_argument("--synthetic-queries", type=int, default=50, help="of --queries, from stored synthetic rows")
    ap.add_argument("--holdout", type=float, default=0.2, help="share of the real set kept out of the collection")
    ap.add_argument("--kac", default=None, help="the binary (default: cargo build --release)")
    ap.add_argument("--rebuild-real", action="store_true",
                    help="recompute the real set (bench/out/real_dna.json or real_families.json)")
    ap.add_argument("--workdir", default=None, help="where the throwaway data directories go (default: TMPDIR)")
    ap.add_argument("--keep", action="store_true", help="keep the data directories")
    ap.add_argument("--snapshot-wait", type=float, default=120, help="seconds to wait for the snapshot file")
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    kac = os.path.abspath(a.kac) if a.kac else release_kac()
    if a.workdir:
        os.makedirs(a.workdir, exist_ok=True)

    if a.descriptor == "shape-dna":
        real, cli_families = dna_corpus.real_fingerprints(kac, rebuild=a.rebuild_real, log=log), None
        ends = ("lambda1", "lambda50")
    else:
        shapes = dna_corpus.real_families(kac, rebuild=a.rebuild_real, log=log)
        (real, cli_families), ends = dna_corpus.family_rows(shapes, a.descriptor), ("first", "last")
    values = np.array([v for _, v in real], float)
    model = expansion(a.descriptor, values)
    rng = np.random.default_rng(a.seed)
    perm = rng.permutation(len(values))
    n_held = max(1, int(round(a.holdout * len(values))))
    held, base_real = values[np.sort(perm[:n_held])], values[np.sort(perm[n_held:])]
    log("real set (%s): %d fingerprints, %d held out as queries; %s" % (
        a.descriptor, len(values), n_held, json.dumps(dna_corpus.summary(values, ends))))
    for n in (int(float(x)) for x in a.n.split(",")):
        print(json.dumps(run(a, kac, n, base_real, held, model, cli_families)), flush=True)


if __name__ == "__main__":
    main()

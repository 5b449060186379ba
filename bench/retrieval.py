#!/usr/bin/env python3
"""Retrieval through the service, scored as a back end would score it, against lapy's shape-DNA recipe.

Collections. Labelled public mesh collections assembled by hand (see docs/retrieval.md for their origin and
licence; their licences forbid redistribution, so they are not in the repository): a directory (--data, default
$KAC_RETRIEVAL_DATA or ../retrieval-data beside the repository) holding manifest.json
{"collections": {name: [{"file": relative path, "class": label, ...}, ...]}} and the files.

Per collection, in one run:
  * a fresh `kac serve` (release build, embedded store in a temporary directory, default limits except the body
    size) takes every file through `POST /v1/shapes/bulk` (requests of at most 48 MB; the default options: a
    `fingerprint` job per file), and the script waits for the bulk uploads' progress (`GET /v1/shapes/bulk/{id}`)
    to report every job done: `ingest_s`, and shapes fingerprinted per second;
  * every shape is searched with `POST /v1/search` (shape_id, neighbours = all others) by each descriptor:
    `fused` (the default), `shape-dna`, `heat-distribution`, `gps-d2`, and shape-DNA under the earlier default
    options (`normalization: none`, `reweighting: none`, computed on demand by the search); the ranking is scored
    leave-one-out (the query is never among its neighbours) by the SHREC measures: nearest neighbour (NN), first
    tier (FT), second tier (ST), E-measure over the first 32, discounted cumulative gain (DCG, normalized by the
    ideal), mean average precision (mAP);
  * lapy's recipe (lapy.shapedna: k = 50 eigenvalues of the cotangent Laplacian with consistent mass, `geometry`
    normalization, reweighting, Euclidean distance), each mesh read with lapy's own TriaMesh.read_off and solved
    single-threaded: the same measures, and lapy's total solve time;
  * the fused distance's weights on a grid (steps of 0.05), recomputed from the families' distances the fused search
    returned and their spreads: the best weights for mAP on each collection, and, with both collections, the
    default weights' rule (the best class-level mAP among the weights whose non-rigid mAP reaches 0.99).

A file whose bytes repeat an earlier file's is left out (the service stores it once; `duplicates_dropped`).

Prints progress on stderr and one JSON object per collection on stdout; --out writes them all to a file.

Usage: bench/.venv/bin/python bench/retrieval.py [--data DIR] [--collections classlevel,nonrigid]
           [--kac target/release/kac] [--no-lapy] [--out bench/out/retrieval.json]
"""
import argparse, hashlib, json, os, shutil, subprocess, sys, tempfile, threading, time, uuid

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import ROOT, call, release_kac  # noqa: E402

DESCRIPTORS = ["fused", "shape-dna", "heat-distribution", "gps-d2"]
FAMILIES = ["shape-dna", "heat-distribution", "gps-d2"]
OLD_DEFAULT = {"descriptor": "shape-dna", "normalization": "none", "reweighting": "none"}
REQUEST_BYTES = 48 << 20


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def start(kac, data):
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=data, RUST_LOG="error",
               KAC_MAX_BODY_BYTES=str(64 << 20), KAC_MAX_BODY_MEMORY_BYTES=str(256 << 20))
    p = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    line = p.stdout.readline()
    if not line:
        raise RuntimeError("kac serve exited (%s) before listening" % p.wait())
    threading.Thread(target=lambda: [None for _ in p.stdout], daemon=True).start()
    return p, "http://" + json.loads(line)["listening"]


def multipart(files):
    """A multipart/form-data body of (name, bytes) file parts; (body, content type)."""
    boundary = uuid.uuid4().hex
    out = []
    for name, data in files:
        out.append(("--%s\r\nContent-Disposition: form-data; name=\"file\"; filename=\"%s\"\r\n"
                    "Content-Type: application/octet-stream\r\n\r\n" % (boundary, name)).encode())
        out.append(data)
        out.append(b"\r\n")
    out.append(("--%s--\r\n" % boundary).encode())
    return b"".join(out), "multipart/form-data; boundary=" + boundary


def scores(ranked, labels):
    """SHREC measures of leave-one-out rankings: ranked[i] lists the other items, nearest first."""
    n = len(labels)
    acc = dict(NN=0.0, FT=0.0, ST=0.0, E=0.0, DCG=0.0, mAP=0.0)
    counted = 0
    for i, order in enumerate(ranked):
        rel = np.array([labels[j] == labels[i] for j in order], float)
        c = int(sum(1 for j in range(n) if j != i and labels[j] == labels[i]))
        if c == 0:
            continue
        counted += 1
        acc["NN"] += rel[0]
        acc["FT"] += rel[:c].sum() / c
        acc["ST"] += rel[:2 * c].sum() / c
        r32 = rel[:32].sum()
        p, r = r32 / 32, r32 / c
        acc["E"] += 2 * p * r / (p + r) if p + r > 0 else 0.0
        disc = np.concatenate([[1.0], 1.0 / np.log2(np.arange(2, len(rel) + 1))])
        acc["DCG"] += (rel * disc).sum() / disc[:c].sum()
        hits = np.cumsum(rel)
        acc["mAP"] += (hits / np.arange(1, len(rel) + 1) * rel).sum() / c
    return {k: round(v / max(counted, 1), 4) for k, v in acc.items()}


def rank_matrix(d):
    n = len(d)
    return [[j for j in np.argsort(d[i], kind="stable") if j != i] for i in range(n)]


def ingest(base, root, entries):
    """Bulk-uploads the files; their shape ids, and seconds until every fingerprint job is done."""
    t0 = time.perf_counter()
    ids, batches, jobs, chunk, size = [None] * len(entries), [], [], [], 0
    def send(chunk):
        body, ctype = multipart([(os.path.basename(e["file"]), data) for _, e, data in chunk])
        st, r = call(base, "POST", "/v1/shapes/bulk", body, ctype, timeout=600)
        if st != 200:
            raise RuntimeError("bulk upload: %s %s" % (st, r))
        if r.get("unstarted") or r.get("failed"):
            raise RuntimeError("bulk upload left files without a job: %s" % r)
        for (i, _, _), f in zip(chunk, r["files"]):
            ids[i] = f["shape"]["id"]
            jobs.append(f["job"]["id"])
        batches.append(r.get("batch"))
    for i, e in enumerate(entries):
        data = open(os.path.join(root, e["file"]), "rb").read()
        if chunk and size + len(data) > REQUEST_BYTES:
            send(chunk)
            chunk, size = [], 0
        chunk.append((i, e, data))
        size += len(data)
    if chunk:
        send(chunk)
    while True:
        if None in batches:
            # A service without bulk progress: each job.
            views = [call(base, "GET", "/v1/jobs/" + j)[1] for j in jobs]
            progress = [{"done": all(v["status"] in ("succeeded", "failed", "canceled") for v in views),
                         "failed": sum(v["status"] == "failed" for v in views),
                         "canceled": sum(v["status"] == "canceled" for v in views)}]
        else:
            progress = [call(base, "GET", "/v1/shapes/bulk/" + b)[1] for b in batches]
        if all(p["done"] for p in progress):
            break
        time.sleep(0.2)
    failed = sum(p["failed"] + p["canceled"] for p in progress)
    if failed:
        raise RuntimeError("%d fingerprint jobs failed: %s" % (failed, progress))
    return ids, time.perf_counter() - t0


def search_all(base, ids, request, check=True):
    """Each shape's ranking of all others by a search; (rankings, the families' distance matrices when fused,
    the spreads, seconds per search)."""
    n = len(ids)
    index = {s: i for i, s in enumerate(ids)}
    ranked, fam = [], {f: np.zeros((n, n)) for f in FAMILIES}
    spreads, secs = {}, []
    for i, s in enumerate(ids):
        t = time.perf_counter()
        st, r = call(base, "POST", "/v1/search?wait=120", dict(request, shape_id=s, neighbours=n - 1), timeout=600)
        secs.append(time.perf_counter() - t)
        if st != 200:
            raise RuntimeError("search %s: %s %s" % (request, st, r))
        order = [index[x["shape_id"]] for x in r["neighbours"]]
        if check and len(order) != n - 1:
            raise RuntimeError("search %s answered %d of %d neighbours" % (request, len(order), n - 1))
        ranked.append(order)
        for x in r["neighbours"]:
            for f, d in (x.get("distances") or {}).items():
                fam[f][i, index[x["shape_id"]]] = d
        spreads = {f["descriptor"]: f["spread"] for f in r["families"]}
    return ranked, fam, spreads, float(np.median(secs))


def grid(step=0.05):
    n = int(round(1 / step))
    return [(i * step, j * step, (n - i - j) * step) for i in range(n + 1) for j in range(n + 1 - i)]


def grid_scores(fam, spreads, labels):
    """Each grid point's scores: the fused distance recomputed from the families' distances and spreads."""
    out = []
    for w in grid():
        d = sum(wi * fam[f] / spreads[f] for wi, f in zip(w, FAMILIES))
        out.append(([round(x, 2) for x in w], scores(rank_matrix(d), labels)))
    return out


def best_weights(points):
    w, s = max(points, key=lambda p: p[1]["mAP"])
    return {"weights": dict(zip(FAMILIES, w)), "scores": s}


def weights_rule(by_collection):
    """The default weights' rule: on the grid, the best class-level mAP among the weights whose non-rigid mAP
    reaches 0.99."""
    cl, nr = by_collection["classlevel"], by_collection["nonrigid"]
    ok = [(w, s, t) for (w, s), (_, t) in zip(cl, nr) if t["mAP"] >= 0.99]
    if not ok:
        return None
    w, s, t = max(ok, key=lambda p: p[1]["mAP"])
    return {"weights": dict(zip(FAMILIES, w)), "classlevel": s, "nonrigid": t}


def lapy_recipe(root, entries, labels):
    from lapy import TriaMesh
    from lapy import shapedna
    t_solve, rows = 0.0, []
    for e in entries:
        tria = TriaMesh.read_off(os.path.join(root, e["file"]))
        t = time.perf_counter()
        ev = shapedna.compute_shapedna(tria, k=50)
        t_solve += time.perf_counter() - t
        v = shapedna.normalize_ev(tria, ev["Eigenvalues"], method="geometry")
        rows.append(shapedna.reweight_ev(v))
    x = np.array(rows)[:, 1:]  # lapy's recipe keeps the zero eigenvalue first: it is 0 for every shape
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(-1))
    return scores(rank_matrix(d), labels), t_solve


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.environ.get("KAC_RETRIEVAL_DATA",
                                                    os.path.join(os.path.dirname(ROOT), "retrieval-data")))
    ap.add_argument("--collections", default="classlevel,nonrigid")
    ap.add_argument("--kac")
    ap.add_argument("--no-lapy", action="store_true")
    ap.add_argument("--out")
    a = ap.parse_args()
    kac = a.kac or release_kac()
    manifest = json.load(open(os.path.join(a.data, "manifest.json")))["collections"]
    results, by_collection = [], {}
    for name in a.collections.split(","):
        entries, seen, duplicates = [], {}, []
        for e in manifest[name]:
            # The service stores a shape once per content: a file repeated is one shape (SHREC'07 holds one).
            h = hashlib.sha256(open(os.path.join(a.data, e["file"]), "rb").read()).hexdigest()
            if h in seen:
                duplicates.append([seen[h], e["file"]])
                continue
            seen[h] = e["file"]
            entries.append(e)
        labels = [e["class"] for e in entries]
        log("%s: %d meshes, %d classes" % (name, len(entries), len(set(labels))))
        data = tempfile.mkdtemp(prefix="kac-retrieval-")
        p, base = start(kac, data)
        try:
            ids, ingest_s = ingest(base, a.data, entries)
            log("  ingest %.1f s (%.2f shapes/s)" % (ingest_s, len(ids) / ingest_s))
            out = {"collection": name, "meshes": len(entries), "classes": len(set(labels)),
                   "ingest_s": round(ingest_s, 2), "shapes_per_s": round(len(ids) / ingest_s, 3),
                   "workers": os.cpu_count(), "duplicates_dropped": duplicates, "kac": {}}
            for d in DESCRIPTORS:
                ranked, fam, spreads, med = search_all(base, ids, {"descriptor": d})
                out["kac"][d] = dict(scores(ranked, labels), search_median_s=round(med, 4))
                log("  %-18s %s" % (d, out["kac"][d]))
                if d == "fused":
                    out["spreads"] = spreads
                    points = grid_scores(fam, spreads, labels)
                    by_collection[name] = points
                    out["weights_grid"] = best_weights(points)
                    log("  best weights here %s" % out["weights_grid"])
            # The earlier default's fingerprints are computed by a first search of each shape (each such search sees
            # only the shapes fingerprinted before it), then every shape is searched again.
            search_all(base, ids, OLD_DEFAULT, check=False)
            ranked, _, _, med = search_all(base, ids, OLD_DEFAULT)
            out["kac"]["shape-dna (none, none)"] = dict(scores(ranked, labels), search_median_s=round(med, 4))
            log("  %-18s %s" % ("old default", out["kac"]["shape-dna (none, none)"]))
        finally:
            p.terminate()
            p.wait()
            shutil.rmtree(data, ignore_errors=True)
        if not a.no_lapy:
            s, t_solve = lapy_recipe(a.data, entries, labels)
            out["lapy"] = dict(s, solve_s=round(t_solve, 2))
            out["throughput_ratio"] = round(t_solve / ingest_s, 2)
            log("  lapy %s; solve %.1f s; kac ingest is %.1fx faster" % (s, t_solve, t_solve / ingest_s))
        print(json.dumps(out), flush=True)
        results.append(out)
    if {"classlevel", "nonrigid"} <= set(by_collection):
        rule = weights_rule(by_collection)
        log("weights by the rule (best class-level mAP with non-rigid mAP >= 0.99): %s" % rule)
        print(json.dumps({"weights_rule": rule}), flush=True)
        results.append({"weights_rule": rule})
    if a.out:
        with open(a.out, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()

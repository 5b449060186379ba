#!/usr/bin/env python3
"""Searches while a family's index cells are trained again (issue 33: an index built incrementally).

A family of N fingerprints (real shape-DNA distributions, as bench/search.py makes them) is loaded by a release
`kac serve`, which trains its cells for N rows. While it runs, 3N more rows are written to the store's table and its
change log (as other replicas' jobs would), so the next search applies them: the family has grown fourfold and its
cells are trained again on a thread of their own (families above 131,072 rows) while searches go on. Sequential
searches (10 neighbours, by fingerprint) are timed before the growth, while the changes are applied and the cells
trained, and after; the training's own time is read from the server's log line. Prints one JSON line.

Usage: bench/.venv/bin/python bench/search_growth.py [--n 150000] [--kac target/release/kac]
"""
import argparse, json, os, shutil, sqlite3, sys, tempfile, time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import dna_corpus  # noqa: E402
import search as S  # noqa: E402
from kac_http import call, release_kac  # noqa: E402


def trained(logfile):
    """The seconds of the last "cells trained again" log line, if any."""
    fields = S.log_fields(logfile, "search index cells trained again")
    return fields and fields.get("seconds")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=150_000)
    ap.add_argument("--kac")
    ap.add_argument("--seed", type=int, default=5)
    a = ap.parse_args()
    kac = a.kac or release_kac()
    base_real = np.array([v for _, v in dna_corpus.real_fingerprints(kac, log=lambda *x: None)])
    work = tempfile.mkdtemp(prefix="kac-growth-")
    data = os.path.join(work, "data")
    try:
        family = S.learn_family(kac, data, work)
        S.fill(data, family, base_real, a.n - 1, a.seed, [])
        snap = os.path.join(data, S.SNAPSHOT)
        if os.path.exists(snap):
            os.remove(snap)
        logfile = os.path.join(work, "serve.log")
        p, base, _ = S.start(kac, data, logfile)
        rng = np.random.default_rng(a.seed)
        qs = [q.tolist() for q in dna_corpus.perturb(base_real[rng.integers(0, len(base_real), 400)], rng,
                                                     sigma=0.001, smooth=0.002)]
        timed = lambda q: S.search(base, q, None)[0]
        try:
            before = [timed(q) for q in qs[:100]]
            # 3N rows more, in the table and the log (what other replicas' jobs write).
            extra = next(dna_corpus.synthetic(base_real, 3 * a.n, seed=a.seed + 1, chunk=3 * a.n))
            db = sqlite3.connect(os.path.join(data, "kac.sqlite3"), timeout=60)
            ids = ["%064x" % int(x) for x in rng.integers(1, 2 ** 62, len(extra))]
            blobs = [np.ascontiguousarray(r, "<f8").tobytes() for r in extra]
            with db:
                db.executemany("INSERT INTO fingerprints (family, shape_id, fingerprint) VALUES (?, ?, ?)",
                               [(family, i, b) for i, b in zip(ids, blobs)])
                db.executemany("INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES (?, ?, ?)",
                               [(family, i, b) for i, b in zip(ids, blobs)])
            db.close()
            t0 = time.perf_counter()
            first = timed(qs[100])  # applies the 3N changes
            during, t_train, i = [], None, 0
            while t_train is None and time.perf_counter() - t0 < 300:
                during.append(timed(qs[101 + i % 299]))
                i += 1
                if i % 20 == 0:
                    t_train = trained(logfile)
            after = [timed(q) for q in qs[:100]]
        finally:
            S.stop(p)
        ms = lambda xs: {"p50": round(1000 * S.pct(xs, 0.5), 2), "p99": round(1000 * S.pct(xs, 0.99), 2),
                         "max": round(1000 * max(xs), 2)} if xs else None
        print(json.dumps({"rows_before": a.n, "rows_after": 4 * a.n, "before_ms": ms(before),
                          "applying_changes_s": round(first, 2),
                          "while_training_ms": ms(during), "searches_while_training": len(during),
                          "training_s": t_train, "after_ms": ms(after),
                          "wall_s": round(time.perf_counter() - t0, 1)}), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

"""Peer check of the `operator` analysis over HTTP: SciPy reads the matrices kac serves and agrees with kac.

- scipy.sparse.load_npz reads L.npz and M.npz; scipy.io.mmread reads L.mtx and M.mtx; both give the same
  matrices, equal to the triplets in the result JSON;
- SciPy's ARPACK (eigsh, shift-invert) on those matrices gives the eigenvalues kac's `spectrum` returns for the
  same shape and operator (relative 1e-8), under Neumann and Dirichlet conditions; a Dirichlet matrix's rows are
  the unknowns, mapped to vertices by `unknown_vertices`.

Usage: python operator_scipy.py HOST:PORT   (a running kac server)
"""
import io
import json
import math
import sys
import urllib.parse
import urllib.request

import numpy as np
import scipy.io
import scipy.sparse
import scipy.sparse.linalg

ADDR = sys.argv[1]


def torus_off(n=40, m=20, R=1.0, r=0.4):
    """A torus, triangulated: n × m vertices."""
    v = [((R + r * math.cos(2 * math.pi * j / m)) * math.cos(2 * math.pi * i / n),
          (R + r * math.cos(2 * math.pi * j / m)) * math.sin(2 * math.pi * i / n),
          r * math.sin(2 * math.pi * j / m)) for i in range(n) for j in range(m)]
    f = []
    for i in range(n):
        for j in range(m):
            a, b = i * m + j, ((i + 1) % n) * m + j
            c, d = ((i + 1) % n) * m + (j + 1) % m, i * m + (j + 1) % m
            f += [(a, b, c), (a, c, d)]
    return "OFF\n%d %d 0\n" % (len(v), len(f)) + "".join("%r %r %r\n" % p for p in v) + "".join("3 %d %d %d\n" % t for t in f)


def disk_off(rings=12):
    """A disk of radius 1 in rings (the boundary for Dirichlet)."""
    v, f = [(0.0, 0.0, 0.0)], []
    prev = [0]
    for k in range(1, rings + 1):
        cnt = 6 * k
        ring = list(range(len(v), len(v) + cnt))
        v += [(k / rings * math.cos(2 * math.pi * i / cnt), k / rings * math.sin(2 * math.pi * i / cnt), 0.0) for i in range(cnt)]
        # Join ring k−1 to ring k by walking both in angle order.
        i = j = 0
        pc = len(prev)
        while i < cnt or j < (pc if k > 1 else 0):
            a_next = (i + 1) / cnt
            b_next = (j + 1) / pc if k > 1 else 2.0
            if k == 1 or a_next <= b_next:
                f.append((prev[j % pc], ring[i % cnt], ring[(i + 1) % cnt]))
                i += 1
            else:
                f.append((prev[j % pc], ring[i % cnt], prev[(j + 1) % pc]))
                j += 1
        prev = ring
    return "OFF\n%d %d 0\n" % (len(v), len(f)) + "".join("%r %r %r\n" % p for p in v) + "".join("3 %d %d %d\n" % t for t in f)


def analyze(off, request):
    q = urllib.parse.urlencode({"format": "off", "wait": "120", "analysis": json.dumps(request)})
    req = urllib.request.Request("http://%s/v1/analyze?%s" % (ADDR, q), data=off.encode(), method="POST")
    with urllib.request.urlopen(req) as r:
        return json.load(r)


def get(path):
    with urllib.request.urlopen("http://%s%s" % (ADDR, path)) as r:
        return r.read()


def check(name, off, operator, k=20):
    r = analyze(off, {"analysis": "operator", "operator": operator})
    n = r["unknowns"]
    mats = {}
    for key in ("stiffness", "mass"):
        links = r["arrays"][key]
        a = scipy.sparse.load_npz(io.BytesIO(get(links["npz"])))
        b = scipy.sparse.csr_matrix(scipy.io.mmread(io.BytesIO(get(links["mtx"]))))
        t = np.array(r["arrays"][key]["values"])
        c = scipy.sparse.coo_matrix((t[:, 2], (t[:, 0].astype(int), t[:, 1].astype(int))), shape=(n, n)).tocsr()
        c = c + scipy.sparse.triu(c, 1).T
        assert a.shape == (n, n) and a.format == "csr", (name, key, a.shape, a.format)
        for other, what in ((b, "mtx"), (c, "triplets")):
            diff = abs(a - other).max()
            assert diff == 0, "%s %s: npz and %s differ by %g" % (name, key, what, diff)
        assert abs(a - a.T).max() == 0, (name, key, "not symmetric")
        mats[key] = a
    unknown = np.array(r["arrays"]["unknown_vertices"]["values"])[:, 0]
    assert len(unknown) == n
    s = analyze(off, {"analysis": "spectrum", "k": k, "operator": operator})
    kac = np.array(s["eigenvalues"])
    peer = np.sort(scipy.sparse.linalg.eigsh(mats["stiffness"], k=k, M=mats["mass"], sigma=-0.01, which="LM",
                                             tol=1e-12, return_eigenvectors=False))
    rel = np.max(np.abs(kac - peer) / np.maximum(np.abs(peer), 1.0))
    assert rel < 1e-8, "%s: kac and ARPACK differ by %g\n%s\n%s" % (name, rel, kac, peer)
    print("%s: %d unknowns, L %d and M %d non-zeros read by SciPy (npz = mtx = triplets); "
          "λ₁..λ%d agree with ARPACK to %.1e" % (name, n, mats["stiffness"].nnz, mats["mass"].nnz, k, rel))


check("torus, Neumann, consistent mass", torus_off(), {})
check("torus, lumped mass", torus_off(), {"mass": "lumped"})
check("disk, Dirichlet", disk_off(), {"boundary": "dirichlet"})
print("peers: ok")

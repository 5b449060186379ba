"""Real fingerprints of every retrieval family, and synthetic collections of any size that follow their
distributions (for bench/search.py). Needs numpy.

Shapes. The real sets are computed on
  * every file under /work/shared/data (see its README.md) that the CLI accepts: triangle and polygon meshes
    (OFF, OBJ, PLY, STL, glTF/GLB), the two point clouds and the two tet meshes; files it refuses (fewer than
    51 eigenpairs on a tiny mesh) or that take over 20 s are skipped;
  * the shapes `kac generate` writes (icosphere, torus, disk, square and the isospectral drums gww1/gww2),
    each at three resolutions (remeshing: the same surface at another level or cell count);
and, for every one of those whose vertices this module can read (OFF, OBJ, PLY, STL, XYZ; not glTF or tets),
the same shape again under
  * vertex noise: every coordinate plus Gaussian noise of 0.2 %, 0.5 % and 1 % of the bounding-box diagonal,
    two seeds each;
  * uniform scaling by 0.5 and 3 (area normalization makes these near-duplicates of the original: a real
    collection holds such duplicates);
  * for the generated shapes only, a stretch of one axis by 1.25 and 2 (other shapes between the few kinds).
The variants are written to a temporary directory, never into the repository.

Real shape-DNA (`real_fingerprints`): `kac shape-dna FILE --k 50 --normalization area --reweighting none` (the
JSON's `shape_dna.values`: the 50 smallest non-zero eigenvalues times the surface area), cached in
bench/out/real_dna.json. Real families (`real_families`): `kac fingerprint FILE -k 50` (retrieval's defaults;
without `-k` where the CLI has no such flag, its default being 50), once per shape and variant, every family it
reports kept (`shape-dna`: 50 values, `heat-distribution`: 96, 6 blocks of 16 quantiles, `gps-d2`: 32
quantiles; `FAMILIES`), with the family id the CLI gives each, cached in bench/out/real_families.json;
`family_rows` picks one family's rows out of it. Each cache (ignored by git) holds its recipe's version; a rerun
reuses it.

Synthetic expansion of shape-DNA (`synthetic`): each row is exp((1 − t)·log a + t·log b) for a real fingerprint a
drawn uniformly and b one of a's 10 nearest real fingerprints (Euclidean, the service's default metric), t uniform
in [0, 1]; times a per-component multiplicative noise exp(ε_j + s(j)), ε_j ~ N(0, 0.3 %) independent and s a
smooth low-frequency term (Legendre degrees 1 and 2 over the index, coefficients ~ N(0, 0.5 %)); sorted
ascending, as eigenvalues are.

Synthetic expansion of the quantile families (`synthetic_linear`; their values may be negative, so no logarithm):
each row is (1 − t)·a + t·b for a and b drawn as above, plus a per-component additive noise σ_j·(ε_j + s(j)),
σ_j the component's standard deviation over the real set, ε_j ~ N(0, 0.3 %) and s the same smooth term
(coefficients ~ N(0, 0.5 %)) taken over the index within each block of quantiles; then sorted within each block
(heat distribution: 6 blocks of 16, one per time; GPS D2: one block of 32), as quantile functions are ascending.

Both are produced in chunks, so 10^7 rows never need more than a chunk in memory.
"""
import json, math, os, subprocess, tempfile, time, zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = "/work/shared/data"
CACHE = os.path.join(HERE, "out", "real_dna.json")
FAMILIES_CACHE = os.path.join(HERE, "out", "real_families.json")
K = 50
RECIPE = 1  # bump when the list of shapes or variants changes: the caches are then rebuilt
FAMILIES_RECIPE = 1  # bump as RECIPE, or when `kac fingerprint`'s call changes
# Each family `kac fingerprint -k 50` reports: its values per fingerprint, as blocks of ascending quantiles (None:
# shape-DNA, eigenvalues).
FAMILIES = {"shape-dna": (K, None), "heat-distribution": (96, 16), "gps-d2": (32, 32)}

GENERATED = [("icosphere", "--level", [2, 3, 4]), ("torus", "--n", [8, 16, 32]), ("disk", "--n", [8, 16, 32]),
             ("square", "--n", [8, 16, 32]), ("gww1", "--n", [4, 8, 16]), ("gww2", "--n", [4, 8, 16])]
NOISE = [0.002, 0.005, 0.01]  # of the bounding-box diagonal
NOISE_SEEDS = [1, 2]
SCALES = [0.5, 3.0]
STRETCHES = [1.25, 2.0]


# ---- reading and writing vertices ------------------------------------------------------------------------------

def _off(path):
    toks = []
    for line in open(path):
        line = line.split("#", 1)[0].split()
        toks.extend(line)
    head = toks[0]
    if not head.endswith("OFF"):
        raise ValueError("not OFF")
    nv, nf = int(toks[1]), int(toks[2])
    p = 4
    v = np.array(toks[p:p + 3 * nv], float).reshape(nv, 3)
    p += 3 * nv
    faces = []
    for _ in range(nf):
        c = int(toks[p])
        faces.append([int(x) for x in toks[p + 1:p + 1 + c]])
        p += 1 + c
        # colours after the indices are not supported (none of the shared or generated files has them)
    return v, faces


def _obj(path):
    v, faces = [], []
    for line in open(path):
        t = line.split()
        if not t:
            continue
        if t[0] == "v":
            v.append([float(x) for x in t[1:4]])
        elif t[0] == "f":
            idx = [int(x.split("/")[0]) for x in t[1:]]
            faces.append([i - 1 if i > 0 else len(v) + i for i in idx])
    return np.array(v, float), faces


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _ply(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    fmt, elements = None, []
    for line in data[:end].decode("ascii", "replace").splitlines():
        t = line.split()
        if not t:
            continue
        if t[0] == "format":
            fmt = t[1]
        elif t[0] == "element":
            elements.append((t[1], int(t[2]), []))
        elif t[0] == "property":
            elements[-1][2].append(t[1:])
    v, faces = None, None
    if fmt == "ascii":
        lines = iter(data[end:].decode().split("\n"))
        for name, count, props in elements:
            rows = [next(lines).split() for _ in range(count)]
            if name == "vertex":
                names = [p[-1] for p in props]
                cols = [names.index(c) for c in "xyz"]
                v = np.array([[float(r[c]) for c in cols] for r in rows], float)
            elif name == "face":
                faces = [[int(x) for x in r[1:1 + int(r[0])]] for r in rows]
    elif fmt == "binary_little_endian":
        p = end
        for name, count, props in elements:
            if any(q[0] == "list" for q in props):
                if name != "face" or len(props) != 1:
                    raise ValueError("unsupported PLY list element")
                ct, it = np.dtype("<" + _PLY_TYPES[props[0][1]]), np.dtype("<" + _PLY_TYPES[props[0][2]])
                faces = []
                for _ in range(count):
                    c = int(np.frombuffer(data, ct, 1, p)[0])
                    p += ct.itemsize
                    faces.append(np.frombuffer(data, it, c, p).astype(int).tolist())
                    p += c * it.itemsize
            else:
                dt = np.dtype([(q[-1], "<" + _PLY_TYPES[q[0]]) for q in props])
                rec = np.frombuffer(data, dt, count, p)
                p += count * dt.itemsize
                if name == "vertex":
                    # a point cloud's normals ride along (the point-cloud operator uses them)
                    cols = ["x", "y", "z"] + (["nx", "ny", "nz"] if {"nx", "ny", "nz"} <= set(dt.names) else [])
                    v = np.stack([rec[c].astype(float) for c in cols], axis=1)
    else:
        raise ValueError("unsupported PLY format %s" % fmt)
    return v, faces


def _stl(path):
    data = open(path, "rb").read()
    n = int.from_bytes(data[80:84], "little") if len(data) >= 84 else 0
    if n > 0 and len(data) >= 84 + 50 * n:  # binary (even when the header starts with "solid")
        rec = np.frombuffer(data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), n, 84)
        tri = rec["v"].astype(float)
    else:
        vs = [[float(x) for x in line.split()[1:4]] for line in data.decode().splitlines()
              if line.strip().startswith("vertex")]
        tri = np.array(vs, float).reshape(-1, 3, 3)
    # weld exactly equal positions, as kac does by default
    v, inv = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)
    return v, inv.reshape(-1, 3).tolist()


def _xyz(path):
    v = np.loadtxt(path, ndmin=2)
    return v[:, :6 if v.shape[1] >= 6 else 3], None


def read_vertices(path):
    """(vertices (n, 3), faces as index lists) or, for a point cloud, (points (n, 3 or 6: with normals), None)."""
    ext = os.path.splitext(path)[1].lower()
    return {".off": _off, ".obj": _obj, ".ply": _ply, ".stl": _stl, ".xyz": _xyz}[ext](path)


def write_shape(path, v, faces):
    """An OFF (polygons as they are) or, for a point cloud, an XYZ file."""
    with open(path, "w") as f:
        if faces is None:
            np.savetxt(f, v, fmt="%.17g")
            return
        f.write("OFF\n%d %d 0\n" % (len(v), len(faces)))
        np.savetxt(f, v, fmt="%.17g")
        f.write("".join("%d %s\n" % (len(q), " ".join(map(str, q))) for q in faces))


# ---- fingerprints -----------------------------------------------------------------------------------------------

def shape_dna(kac, path, timeout=20):
    """The CLI's shape-DNA values (k = 50, area normalization), or None where it refuses or takes too long."""
    try:
        r = subprocess.run([kac, "shape-dna", path, "--k", str(K), "--normalization", "area", "--reweighting", "none",
                            "--threads", "1"], capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    if r.returncode != 0:
        return None
    v = json.loads(r.stdout)["shape_dna"]["values"]
    return v if len(v) == K and all(math.isfinite(x) and x > 0 for x in v) else None


_K_FLAG = {}


def fingerprint_command(kac):
    """`kac fingerprint`'s arguments before the file: with `-k 50` where its help lists the flag (without it,
    the CLI's default k, 50, which `fingerprint` checks in the answer's options)."""
    if kac not in _K_FLAG:
        h = subprocess.run([kac, "fingerprint", "--help"], capture_output=True, text=True).stdout
        _K_FLAG[kac] = any(t.strip(",") == "-k" for t in h.split())
    return [kac, "fingerprint", "--threads", "1"] + (["-k", str(K)] if _K_FLAG[kac] else [])


def fingerprint(kac, path, timeout=20):
    """The CLI's retrieval fingerprint (k = 50, its defaults): {descriptor: {"family", "eigenpairs", "values"}}
    of the families in FAMILIES with their full length of finite values; None where it refuses, takes too long
    or gives none of them."""
    try:
        r = subprocess.run(fingerprint_command(kac) + [path], capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    if r.returncode != 0:
        return None
    answer = json.loads(r.stdout)
    if answer.get("options", {}).get("k", K) != K:
        return None
    out = {}
    for f in answer.get("families", []):
        v = f.get("values") or []
        if f.get("descriptor") in FAMILIES and len(v) == FAMILIES[f["descriptor"]][0] \
                and all(math.isfinite(x) for x in v):
            out[f["descriptor"]] = {"family": f.get("family"), "eigenpairs": f.get("eigenpairs"), "values": v}
    return out or None


def _variants(name, v, faces, generated):
    """(label, vertices) of the noisy, scaled (and, for generated shapes, stretched) copies."""
    xyz = v[:, :3]  # a point cloud's normals (columns 3..5) are kept as they are
    diag = float(np.linalg.norm(xyz.max(0) - xyz.min(0)))

    def moved(w):
        return np.hstack([w, v[:, 3:]])
    for level in NOISE:
        for seed in NOISE_SEEDS:
            rng = np.random.default_rng(zlib.crc32(("%s|%g|%d" % (name, level, seed)).encode()))
            yield "noise%g%%#%d" % (100 * level, seed), moved(xyz + rng.normal(0.0, level * diag, xyz.shape))
    for s in SCALES:
        yield "scale%g" % s, moved(xyz * s)
    if generated:
        for s in STRETCHES:
            yield "stretch-x%g" % s, moved(xyz * np.array([s, 1.0, 1.0]))


def _real_set(kac, compute):
    """(name, result, skipped, seconds): `compute(kac, path)` (None: skipped) on every shape and variant above."""
    t0 = time.perf_counter()
    out, skipped = [], []
    with tempfile.TemporaryDirectory(prefix="kac-dna-") as tmp:
        sources = []  # (name, path, generated)
        for d in sorted(os.listdir(SHARED)):
            if os.path.isdir(os.path.join(SHARED, d)) and d != "reference":
                for f in sorted(os.listdir(os.path.join(SHARED, d))):
                    sources.append(("shared/%s/%s" % (d, f), os.path.join(SHARED, d, f), False))
        for shape, flag, values in GENERATED:
            for x in values:
                p = os.path.join(tmp, "%s-%d.off" % (shape, x))
                subprocess.run([kac, "generate", shape, flag, str(x), "--out", p], check=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                sources.append(("generate/%s%s%d" % (shape, flag[1:], x), p, True))
        for name, path, generated in sources:
            base = compute(kac, path)
            if base is None:
                skipped.append(name)
                continue
            out.append((name, base))
            try:
                v, faces = read_vertices(path)
            except (KeyError, ValueError, IndexError):
                continue  # glTF, tets: the original only
            ext = ".xyz" if faces is None else ".off"
            for label, w in _variants(name, v, faces, generated):
                p = os.path.join(tmp, "variant" + ext)
                write_shape(p, w, faces)
                r = compute(kac, p)
                if r is None:
                    skipped.append(name + "+" + label)
                else:
                    out.append((name + "+" + label, r))
    return out, skipped, time.perf_counter() - t0


def real_fingerprints(kac, cache=CACHE, rebuild=False, log=print):
    """[(name, values)] of the real shape-DNA set described above; from the cache where it holds this recipe."""
    if not rebuild and os.path.exists(cache):
        c = json.load(open(cache))
        if c.get("recipe") == RECIPE and c.get("k") == K:
            return [(r["name"], r["values"]) for r in c["fingerprints"]]
    out, skipped, secs = _real_set(kac, shape_dna)
    log("real shape-DNA: %d fingerprints in %.1f s; skipped %d: %s" % (len(out), secs, len(skipped),
                                                                         ", ".join(skipped)))
    os.makedirs(os.path.dirname(cache), exist_ok=True)
    with open(cache, "w") as f:
        json.dump({"recipe": RECIPE, "k": K, "normalization": "area", "reweighting": "none",
                   "seconds": round(secs, 1), "skipped": skipped,
                   "fingerprints": [{"name": n, "values": v} for n, v in out]}, f)
    return out


def real_families(kac, cache=FAMILIES_CACHE, rebuild=False, log=print):
    """[(name, {descriptor: {"family", "eigenpairs", "values"}})] of every shape and variant above, by
    `kac fingerprint -k 50`; from the cache where it holds this recipe."""
    if not rebuild and os.path.exists(cache):
        c = json.load(open(cache))
        if c.get("recipe") == RECIPE and c.get("families_recipe") == FAMILIES_RECIPE and c.get("k") == K:
            return [(r["name"], r["families"]) for r in c["shapes"]]
    out, skipped, secs = _real_set(kac, fingerprint)
    counts = {d: sum(d in fs for _, fs in out) for d in FAMILIES}
    log("real families: %d shapes in %.1f s (%s); skipped %d: %s" % (
        len(out), secs, ", ".join("%s %d" % kv for kv in counts.items()), len(skipped), ", ".join(skipped)))
    os.makedirs(os.path.dirname(cache), exist_ok=True)
    with open(cache, "w") as f:
        json.dump({"recipe": RECIPE, "families_recipe": FAMILIES_RECIPE, "k": K,
                   "command": " ".join(["kac"] + fingerprint_command(kac)[1:] + ["FILE"]),
                   "seconds": round(secs, 1), "skipped": skipped,
                   "shapes": [{"name": n, "families": fs} for n, fs in out]}, f)
    return out


def family_rows(shapes, descriptor):
    """[(name, values)] of one family out of `real_families`' answer, and the family ids the CLI gave them."""
    rows = [(n, fs[descriptor]["values"]) for n, fs in shapes if descriptor in fs]
    ids = sorted({fs[descriptor]["family"] for _, fs in shapes if descriptor in fs})
    return rows, ids


# ---- synthetic expansion ----------------------------------------------------------------------------------------

def sq_distances(x):
    """Squared Euclidean distances between the rows of x (without an (n, n, k) temporary)."""
    s = (x * x).sum(1)
    return np.maximum(s[:, None] + s[None, :] - 2.0 * (x @ x.T), 0.0)


def neighbours(real, count=10):
    """Each real fingerprint's `count` nearest others (Euclidean), as row indices."""
    d = sq_distances(real)
    np.fill_diagonal(d, np.inf)
    return np.argsort(d, axis=1)[:, :min(count, len(real) - 1)]


def perturb(x, rng, sigma=0.003, smooth=0.005):
    """x (rows, k) times exp(ε_j + s(j)): white lognormal noise and a smooth low-frequency term; re-sorted."""
    m, k = x.shape
    u = np.linspace(-1.0, 1.0, k)
    basis = np.stack([u, 1.5 * u * u - 0.5])  # Legendre P1, P2
    s = rng.normal(0.0, smooth, (m, 2)) @ basis
    y = x * np.exp(rng.normal(0.0, sigma, (m, k)) + s)
    y.sort(axis=1)
    return y


def synthetic(real, n, seed=0, chunk=250_000, near=10, sigma=0.003, smooth=0.005):
    """Yields float64 chunks (rows, k), n rows in all, that follow the real fingerprints' distribution."""
    real = np.asarray(real, float)
    nb = neighbours(real, near)
    logs = np.log(real)
    rng = np.random.default_rng(seed)
    done = 0
    while done < n:
        m = min(chunk, n - done)
        a = rng.integers(0, len(real), m)
        b = nb[a, rng.integers(0, nb.shape[1], m)]
        t = rng.random((m, 1))
        x = logs[a]
        x *= 1.0 - t
        x += t * logs[b]
        np.exp(x, out=x)
        yield perturb(x, rng, sigma, smooth)
        done += m


def _smooth(rng, m, width, smooth):
    """(m, width) low-frequency terms: Legendre P1 and P2 over the index, coefficients ~ N(0, smooth)."""
    u = np.linspace(-1.0, 1.0, width)
    return rng.normal(0.0, smooth, (m, 2)) @ np.stack([u, 1.5 * u * u - 0.5])


def perturb_linear(x, rng, spread, block, sigma=0.003, smooth=0.005):
    """x (rows, k) plus spread_j·(ε_j + s(j)): white Gaussian noise and, per block of `block` quantiles, a smooth
    low-frequency term; re-sorted within each block."""
    m, k = x.shape
    noise = rng.normal(0.0, sigma, (m, k))
    for b in range(0, k, block):
        noise[:, b:b + block] += _smooth(rng, m, block, smooth)
    y = x + noise * spread
    y.reshape(m, k // block, block).sort(axis=2)
    return y


def synthetic_linear(real, n, block, spread=None, seed=0, chunk=250_000, near=10, sigma=0.003, smooth=0.005):
    """Yields float64 chunks (rows, k), n rows in all, that follow the real rows of a quantile family (blocks of
    `block` ascending values); `spread`: each component's standard deviation over the real set (default: over
    `real`)."""
    real = np.asarray(real, float)
    if real.shape[1] % block:
        raise ValueError("%d values are not blocks of %d" % (real.shape[1], block))
    spread = real.std(axis=0) if spread is None else np.asarray(spread, float)
    nb = neighbours(real, near)
    rng = np.random.default_rng(seed)
    done = 0
    while done < n:
        m = min(chunk, n - done)
        a = rng.integers(0, len(real), m)
        b = nb[a, rng.integers(0, nb.shape[1], m)]
        t = rng.random((m, 1))
        x = real[a]
        x *= 1.0 - t
        x += t * real[b]
        yield perturb_linear(x, rng, spread, block, sigma, smooth)
        done += m


def summary(values, ends=("lambda1", "lambda50")):
    """A few numbers on the spread of a set of fingerprints (rows); `ends` names the first and last component."""
    x = np.asarray(values, float)
    nb = neighbours(x, 1)[:, 0]
    nn = np.linalg.norm(x - x[nb], axis=1)
    d = np.sqrt(sq_distances(x)[np.triu_indices(len(x), 1)])
    q = lambda a, p: float(np.round(np.percentile(a, p), 4))
    return {"count": len(x),
            ends[0]: [q(x[:, 0], p) for p in (0, 50, 100)],
            ends[1]: [q(x[:, -1], p) for p in (0, 50, 100)],
            "nearest_distance_p10_p50_p90": [q(nn, p) for p in (10, 50, 90)],
            "nearest_relative_p50": q(nn / np.linalg.norm(x, axis=1), 50),
            "pair_distance_p10_p50_p90": [q(d, p) for p in (10, 50, 90)]}


if __name__ == "__main__":
    import argparse, resource, sys
    ap = argparse.ArgumentParser(description="Build (or read) a real set and time a synthetic expansion.")
    ap.add_argument("--kac", default=os.path.join(os.path.dirname(HERE), "target", "release", "kac"))
    ap.add_argument("--rebuild", action="store_true")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--descriptor", default="shape-dna", choices=list(FAMILIES),
                    help="shape-dna: `kac shape-dna` (area); the others: `kac fingerprint`")
    a = ap.parse_args()
    err = lambda s: print(s, file=sys.stderr)
    if a.descriptor == "shape-dna":
        r = np.array([v for _, v in real_fingerprints(a.kac, rebuild=a.rebuild, log=err)])
        expand, ends = lambda: synthetic(r, a.n), ("lambda1", "lambda50")
    else:
        r = np.array([v for _, v in family_rows(real_families(a.kac, rebuild=a.rebuild, log=err), a.descriptor)[0]])
        expand, ends = lambda: synthetic_linear(r, a.n, FAMILIES[a.descriptor][1]), ("first", "last")
    print(json.dumps({"descriptor": a.descriptor, "real": summary(r, ends)}))
    t = time.perf_counter()
    rows = 0
    sample = None
    for c in expand():
        rows += len(c)
        if sample is None:
            sample = c[:2000].copy()
    print(json.dumps({"synthetic_rows": rows, "seconds": round(time.perf_counter() - t, 2),
                      "max_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
                      "sample": summary(sample, ends)}))

"""Real shape-DNA fingerprints, and synthetic collections of any size that follow their distribution
(for bench/search.py). Needs numpy.

Real set (`real_fingerprints`): `kac shape-dna FILE --k 50 --normalization area` (the JSON's
`shape_dna.values`: the 50 smallest non-zero eigenvalues times the surface area) on
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
The variants are written to a temporary directory, never into the repository. The result is cached in
bench/out/real_dna.json (ignored by git) with the recipe's version; a rerun reuses it.

Synthetic expansion (`synthetic`): each row is exp((1 − t)·log a + t·log b) for a real fingerprint a drawn
uniformly and b one of a's 10 nearest real fingerprints (Euclidean, the service's default metric), t uniform in
[0, 1]; times a per-component multiplicative noise exp(ε_j + s(j)), ε_j ~ N(0, 0.3 %) independent and s a smooth
low-frequency term (Legendre degrees 1 and 2 over the index, coefficients ~ N(0, 0.5 %)); sorted ascending, as
eigenvalues are. It is produced in chunks, so 10^7 × 50 never needs more than a chunk in memory.
"""
import json, math, os, subprocess, tempfile, time, zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = "/work/shared/data"
CACHE = os.path.join(HERE, "out", "real_dna.json")
K = 50
RECIPE = 1  # bump when the list of shapes or variants changes: the cache is then rebuilt

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
        r = subprocess.run([kac, "shape-dna", path, "--k", str(K), "--normalization", "area", "--threads", "1"],
                           capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    if r.returncode != 0:
        return None
    v = json.loads(r.stdout)["shape_dna"]["values"]
    return v if len(v) == K and all(math.isfinite(x) and x > 0 for x in v) else None


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


def real_fingerprints(kac, cache=CACHE, rebuild=False, log=print):
    """[(name, values)] of the real set described above; from the cache where it holds this recipe."""
    if not rebuild and os.path.exists(cache):
        c = json.load(open(cache))
        if c.get("recipe") == RECIPE and c.get("k") == K:
            return [(r["name"], r["values"]) for r in c["fingerprints"]]
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
            base = shape_dna(kac, path)
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
                dna = shape_dna(kac, p)
                if dna is None:
                    skipped.append(name + "+" + label)
                else:
                    out.append((name + "+" + label, dna))
    secs = time.perf_counter() - t0
    log("real shape-DNA: %d fingerprints in %.1f s; skipped %d: %s" % (len(out), secs, len(skipped),
                                                                         ", ".join(skipped)))
    os.makedirs(os.path.dirname(cache), exist_ok=True)
    with open(cache, "w") as f:
        json.dump({"recipe": RECIPE, "k": K, "normalization": "area", "seconds": round(secs, 1),
                   "skipped": skipped, "fingerprints": [{"name": n, "values": v} for n, v in out]}, f)
    return out


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


def summary(values):
    """A few numbers on the spread of a set of fingerprints (rows)."""
    x = np.asarray(values, float)
    nb = neighbours(x, 1)[:, 0]
    nn = np.linalg.norm(x - x[nb], axis=1)
    d = np.sqrt(sq_distances(x)[np.triu_indices(len(x), 1)])
    q = lambda a, p: float(np.round(np.percentile(a, p), 4))
    return {"count": len(x),
            "lambda1": [q(x[:, 0], p) for p in (0, 50, 100)],
            "lambda50": [q(x[:, -1], p) for p in (0, 50, 100)],
            "nearest_distance_p10_p50_p90": [q(nn, p) for p in (10, 50, 90)],
            "nearest_relative_p50": q(nn / np.linalg.norm(x, axis=1), 50),
            "pair_distance_p10_p50_p90": [q(d, p) for p in (10, 50, 90)]}


if __name__ == "__main__":
    import argparse, resource, sys
    ap = argparse.ArgumentParser(description="Build (or read) the real set and time a synthetic expansion.")
    ap.add_argument("--kac", default=os.path.join(os.path.dirname(HERE), "target", "release", "kac"))
    ap.add_argument("--rebuild", action="store_true")
    ap.add_argument("--n", type=int, default=100_000)
    a = ap.parse_args()
    real = real_fingerprints(a.kac, rebuild=a.rebuild, log=lambda s: print(s, file=sys.stderr))
    r = np.array([v for _, v in real])
    print(json.dumps({"real": summary(r)}))
    t = time.perf_counter()
    rows = 0
    sample = None
    for c in synthetic(r, a.n):
        rows += len(c)
        if sample is None:
            sample = c[:2000].copy()
    print(json.dumps({"synthetic_rows": rows, "seconds": round(time.perf_counter() - t, 2),
                      "max_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
                      "sample": summary(sample)}))

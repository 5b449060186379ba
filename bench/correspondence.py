#!/usr/bin/env python3
"""Correspondence against pyFM (issue 32, item 5), in one run on the same pairs with the same settings: WKS
descriptors (100 energies, every 5th kept), a first map in K = 30 eigenfunctions (descriptor weight 1, Laplacian
0.01 on the squared eigenvalue differences, not pyFM's default resolvent mask; descriptor commutativity 0.1,
orientation 0.1: each program's orientation-preserving term, Ren et al. 2018), ZoomOut to 100 in steps of 5, the final
map over every vertex. kac matches ZoomOut's steps on
3,000 pseudo-random vertices per shape (its default); pyFM runs twice: its default (every vertex) and sampled
like kac (3,000 by farthest points). Each side's seconds are the
whole computation from the files: both spectra from cold, the map, the refinement, the vertex map.

Pairs whose vertices correspond (so the true map is known), generated here: an asymmetric lumpy sphere (10,242
vertices) against a rotated copy and against a twisted copy; a lumpy sphere with a mirror symmetry (x → −x, whose
mirror map fits every intrinsic descriptor as well as the true one) against a rotated copy; one of Gordon, Webb & Wolpert's drums (6,481 and
25,561 vertices) against a copy bent onto a cylinder and stretched 15 % across; each copy's vertices shuffled.

Error: the mean geodesic distance on the source (heat method, `kac geodesic`) between each sampled target vertex's
match and its true match, over √area; 100 target vertices sampled evenly.

Public pose pairs (`--pose-pairs DIR`): near-isometric poses of one body whose vertices correspond by index, as
their datasets define ground truth; the target's vertices are shuffled too. DIR holds `faust/tr_reg_00{0,1}.off`
(MPI-FAUST registrations, 6,890 vertices; Bogo et al. 2014) and `tosca/{cat,dog}{0,1}.off` (TOSCA high-resolution,
27,894 and 25,290 vertices, with small holes; Bronstein et al. 2008), the pairs missing from it skipped. The files are
not in the repository (their licences allow research use, not redistribution): BENCHMARKS.md says where the copies
measured came from.

Usage: python3 bench/correspondence.py [--pyfm-python /path/to/venv/bin/python] [--pose-pairs DIR]
(pyFM: `pip install pyfmaps`; by default the running interpreter must import pyFM.)
"""
import argparse, json, math, os, subprocess, sys, tempfile, time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import release_kac  # noqa: E402

PYFM = r"""
import sys, time, json, numpy as np
from pyFM.mesh import TriMesh
from pyFM.functional import FunctionalMapping
a, b, out, sub = sys.argv[1:5]
t = time.perf_counter()
m = FunctionalMapping(TriMesh(a), TriMesh(b))
m.preprocess(n_descr=100, descr_type="WKS", subsample_step=5, k_process=100, k_descr=100)
m.fit(K=(30, 30), w_descr=1e0, w_lap=1e-2, w_dcomm=1e-1, w_orient=1e-1, orient_reversing=False,
      use_resolvent_laplacian=False)
fm = m.zoomout_refine(nit=14, step=5, subsample=int(sub) or None)
p2p = m.get_p2p(FM=fm)
s = time.perf_counter() - t
np.save(out, np.asarray(p2p, dtype=np.float64))
print(json.dumps({"seconds": s}))
"""


def read_off(path):
    lines = [l for l in open(path).read().split("\n") if l.strip() and not l.startswith("#")]
    nv, nf = map(int, lines[1].split()[:2])
    v = np.array([list(map(float, l.split()[:3])) for l in lines[2:2 + nv]])
    f = np.array([list(map(int, l.split()[1:4])) for l in lines[2 + nv:2 + nv + nf]])
    return v, f


def write_off(path, v, f):
    with open(path, "w") as o:
        o.write("OFF\n%d %d 0\n" % (len(v), len(f)))
        o.writelines("%.17g %.17g %.17g\n" % tuple(p) for p in v)
        o.writelines("3 %d %d %d\n" % tuple(t) for t in f)


def lumpy(v):
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    r = 1.0 + 0.3 * x + 0.2 * y * y - 0.25 * z ** 3 + 0.15 * x * y + 0.1 * np.sin(3 * z)
    return np.stack([x * r, 1.3 * y * r, 0.8 * z * r], axis=1)


def symmetric_lumpy(v):
    """Lumpy, but even in x: the mirror x → −x is an isometry (the icosphere's vertices are mirror-symmetric)."""
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    r = 1.0 + 0.3 * y + 0.2 * x * x - 0.25 * z ** 3 + 0.1 * np.sin(3 * z)
    return np.stack([x * r, 1.3 * y * r, 0.8 * z * r], axis=1)


def shuffled(v, f, motion, seed):
    """The copy whose vertex y is the source's perm[y], moved; and perm (the true target → source map)."""
    perm = np.random.default_rng(seed).permutation(len(v))
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(v))
    return motion(v[perm]), inverse[f], perm


def area(v, f):
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()


def geodesic_error(kac, src, v, f, found, truth, samples, work):
    ys = np.linspace(0, len(truth) - 1, samples).astype(int)
    total = {k: 0.0 for k in found}
    for y in ys:
        d_path = os.path.join(work, "d.npy")
        subprocess.run([kac, "geodesic", src, "--source", str(int(truth[y])), "--varadhan-factor", "0", "--out", d_path],
                       check=True, stdout=subprocess.DEVNULL)
        d = np.load(d_path)[:, 0]
        for k, m in found.items():
            total[k] += d[int(m[y])]
    return {k: t / len(ys) / math.sqrt(area(v, f)) for k, t in total.items()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pyfm-python", default=sys.executable)
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--pose-pairs", default=None, help="a directory of public pose pairs (see the docstring)")
    ap.add_argument("--only-pose-pairs", action="store_true", help="skip the generated pairs")
    ap.add_argument("--kac-flags", default="", help="more flags for kac correspondence (e.g. --bijective)")
    ap.add_argument("--skip-pyfm", action="store_true", help="kac alone (its columns only)")
    a = ap.parse_args()
    kac = release_kac()
    work = tempfile.mkdtemp()
    pairs = []
    sphere = os.path.join(work, "sphere.off")
    subprocess.run([kac, "generate", "icosphere", "--level", "5", "--out", sphere], check=True, stdout=subprocess.DEVNULL)
    v, f = read_off(sphere)
    v = lumpy(v)
    c, s = math.cos(0.6), math.sin(0.6)
    rot = lambda p: np.stack([c * p[:, 0] - s * p[:, 1] + 3, s * p[:, 0] + c * p[:, 1] - 1, p[:, 2] + 0.5], axis=1)

    def twist(p):
        th = 0.5 * p[:, 2]
        return np.stack([np.cos(th) * p[:, 0] - np.sin(th) * p[:, 1], np.sin(th) * p[:, 0] + np.cos(th) * p[:, 1],
                         p[:, 2]], axis=1)

    pairs.append(("lumpy sphere, rotated", v, f, rot, 1))
    pairs.append(("lumpy sphere, twisted", v, f, twist, 2))
    sv, _ = read_off(sphere)
    pairs.append(("mirror-symmetric lumpy sphere, rotated", symmetric_lumpy(sv), f, rot, 4))
    for n in (30, 60):
        drum = os.path.join(work, "drum%d.off" % n)
        subprocess.run([kac, "generate", "gww1", "--n", str(n), "--out", drum], check=True, stdout=subprocess.DEVNULL)
        dv, df = read_off(drum)

        def bend(p, r0=0.6):
            x, y = p[:, 0], p[:, 1] * (1 + 0.15 * p[:, 0] / 3)
            return np.stack([r0 * np.sin(x / r0), y, r0 * (1 - np.cos(x / r0))], axis=1)

        pairs.append(("drum, bent and stretched", dv, df, bend, 3))
    # Each entry: name, source vertices and faces, the target's vertices and faces (vertex i of the target is
    # vertex i of the source), the shuffle's seed.
    pairs = [(name, v, f, motion(v), f, seed) for name, v, f, motion, seed in pairs]
    if a.only_pose_pairs:
        pairs = []
    if a.pose_pairs:
        for name, x, y, seed in (("FAUST, subject 0, poses 0 and 1", "faust/tr_reg_000.off", "faust/tr_reg_001.off", 5),
                                 ("TOSCA cat, poses 0 and 1", "tosca/cat0.off", "tosca/cat1.off", 6),
                                 ("TOSCA dog, poses 0 and 1", "tosca/dog0.off", "tosca/dog1.off", 7)):
            x, y = os.path.join(a.pose_pairs, x), os.path.join(a.pose_pairs, y)
            if not (os.path.exists(x) and os.path.exists(y)):
                print("skipped (not in %s): %s" % (a.pose_pairs, name), file=sys.stderr)
                continue
            (v, f), (w, g) = read_off(x), read_off(y)
            if len(v) != len(w) or not np.array_equal(f, g):
                sys.exit("%s and %s do not correspond vertex by vertex" % (x, y))
            pairs.append((name, v, f, w, g, seed))
    rows = []
    for name, v, f, moved, moved_f, seed in pairs:
        src, tgt = os.path.join(work, "a.off"), os.path.join(work, "b.off")
        tv, tf, perm = shuffled(moved, moved_f, lambda p: p, seed)
        write_off(src, v, f)
        write_off(tgt, tv, tf)
        m_path = os.path.join(work, "map.npy")
        t = time.perf_counter()
        subprocess.run([kac, "correspondence", src, tgt, "--fit-k", "30", "--refine-k", "100", "--refine-step", "5",
                        "--map", m_path] + a.kac_flags.split(), check=True, stdout=subprocess.DEVNULL)
        kac_s = time.perf_counter() - t
        kac_map = np.load(os.path.join(work, "map.target_to_source.npy"))[:, 0]
        # pyFM twice: its own default (ZoomOut over every vertex), and sampled like kac (3,000 by farthest points).
        maps, seconds = {"kac": kac_map}, {"kac": kac_s}
        for label, sub in () if a.skip_pyfm else (("pyFM", "0"), ("pyFM sampled", "3000")):
            p_path = os.path.join(work, "pyfm.npy")
            r = subprocess.run([a.pyfm_python, "-c", PYFM, src, tgt, p_path, sub], check=True, capture_output=True,
                               text=True)
            seconds[label] = json.loads(r.stdout.strip().split("\n")[-1])["seconds"]
            maps[label] = np.load(p_path)
        err = geodesic_error(kac, src, v, f, maps, perm, a.samples, work)
        nan = float("nan")
        rows.append({"pair": name, "vertices": len(v), "kac_s": round(kac_s, 2),
                     "pyfm_s": round(seconds.get("pyFM", nan), 2),
                     "pyfm_sampled_s": round(seconds.get("pyFM sampled", nan), 2),
                     "speedup": round(seconds.get("pyFM", nan) / kac_s, 1), "kac_error": round(err["kac"], 4),
                     "pyfm_error": round(err.get("pyFM", nan), 4),
                     "pyfm_sampled_error": round(err.get("pyFM sampled", nan), 4)})
        print(json.dumps(rows[-1]), flush=True)
    print("| pair | vertices | kac s | pyFM s | pyFM / kac | pyFM sampled s | kac error | pyFM error | "
          "pyFM sampled error |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print("| %s | %d | %.2f | %.2f | %.1f× | %.2f | %.4f | %.4f | %.4f |" % (
            r["pair"], r["vertices"], r["kac_s"], r["pyfm_s"], r["speedup"], r["pyfm_sampled_s"], r["kac_error"],
            r["pyfm_error"], r["pyfm_sampled_error"]))

if __name__ == "__main__":
    main()

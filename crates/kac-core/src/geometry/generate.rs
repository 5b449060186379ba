//! Shapes with known spectra, generated in code: icospheres (sphere: λ = l(l+1), multiplicity 2l+1), unit
//! square grids (π²(m²+n²)), disks (squares of Bessel zeros), tori, tetrahedral cubes, segments ((πk/ℓ)²)
//! and the graphs whose spectra and spanning-tree counts are classical (paths, cycles, complete graphs,
//! the Petersen graph).

use super::{Graph, Point, Polyline, TetMesh, TriangleMesh};
use std::collections::HashMap;

/// The unit icosphere: a regular icosahedron subdivided `level` times, vertices projected to the sphere.
/// Level k has 10·4ᵏ + 2 vertices (level 5: 10,242; 6: 40,962; 7: 163,842) and 20·4ᵏ faces, counter-clockwise
/// seen from outside.
pub fn icosphere(level: u32) -> TriangleMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<Point> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let normalize = |p: Point| {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / n, p[1] / n, p[2] / n]
    };
    for p in v.iter_mut() {
        *p = normalize(*p);
    }
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(f.len() * 3 / 2);
        let mut nf = Vec::with_capacity(f.len() * 4);
        let mut midpoint = |a: u32, b: u32, v: &mut Vec<Point>| -> u32 {
            let key = if a < b { (a, b) } else { (b, a) };
            *mid.entry(key).or_insert_with(|| {
                let (pa, pb) = (v[a as usize], v[b as usize]);
                v.push(normalize([(pa[0] + pb[0]) / 2.0, (pa[1] + pb[1]) / 2.0, (pa[2] + pb[2]) / 2.0]));
                (v.len() - 1) as u32
            })
        };
        for [a, b, c] in f {
            let ab = midpoint(a, b, &mut v);
            let bc = midpoint(b, c, &mut v);
            let ca = midpoint(c, a, &mut v);
            nf.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    TriangleMesh { vertices: v, faces: f }
}

/// The rectangle [0, w] × [0, h] at z = 0 as an n × m grid of squares, each split along alternating
/// diagonals (a "criss-cross-free" pattern that keeps the mesh symmetric).
pub fn grid(n: usize, m: usize, w: f64, h: f64) -> TriangleMesh {
    let mut vertices = Vec::with_capacity((n + 1) * (m + 1));
    for j in 0..=m {
        for i in 0..=n {
            vertices.push([w * i as f64 / n as f64, h * j as f64 / m as f64, 0.0]);
        }
    }
    let idx = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut faces = Vec::with_capacity(2 * n * m);
    for j in 0..m {
        for i in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            if (i + j) % 2 == 0 {
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            } else {
                faces.push([a, b, d]);
                faces.push([b, c, d]);
            }
        }
    }
    TriangleMesh { vertices, faces }
}

/// The unit square [0, 1]² with n × n squares.
pub fn unit_square(n: usize) -> TriangleMesh {
    grid(n, n, 1.0, 1.0)
}

/// The boundary of the Gordon–Webb–Wolpert isospectral drums (Gordon, Webb & Wolpert 1992) in the coordinates
/// of Moler's "Can one hear the shape of a drum?" (2012): eight-sided polygons of area 7/2, each a union of seven
/// half unit squares, non-congruent and with the same Dirichlet spectrum.
pub const GWW_DRUMS: [[[f64; 2]; 8]; 2] = [
    [[0.0, 0.0], [0.0, 1.0], [2.0, 3.0], [2.0, 2.0], [3.0, 2.0], [2.0, 1.0], [1.0, 1.0], [1.0, 0.0]],
    [[1.0, 0.0], [0.0, 1.0], [0.0, 2.0], [2.0, 2.0], [2.0, 3.0], [3.0, 2.0], [2.0, 1.0], [1.0, 1.0]],
];

/// Gordon–Webb–Wolpert drum `which` (1 or 2), meshed conformingly: every unit square of [0, 3]² is cut by its two
/// diagonals into four triangles, those inside the drum (the drum's edges run along grid lines and diagonals, so
/// each such triangle is wholly inside or outside) are each split uniformly into n² triangles, and shared
/// vertices are merged. Mesh size 1/(2n) along the axes.
pub fn gww_drum(which: usize, n: usize) -> TriangleMesh {
    let poly = GWW_DRUMS[(which.clamp(1, 2)) - 1];
    let n = n.max(1);
    let inside = |x: f64, y: f64| {
        // Even–odd rule.
        let mut c = false;
        for k in 0..8 {
            let (a, b) = (poly[k], poly[(k + 1) % 8]);
            if (a[1] > y) != (b[1] > y) && x < a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]) {
                c = !c;
            }
        }
        c
    };
    let scale = (2 * n) as f64;
    let mut index: std::collections::HashMap<(i64, i64), u32> = std::collections::HashMap::new();
    let mut vertices: Vec<Point> = vec![];
    let mut faces = vec![];
    let mut vertex = |p: [f64; 2], vertices: &mut Vec<Point>| -> u32 {
        let key = ((p[0] * scale).round() as i64, (p[1] * scale).round() as i64);
        *index.entry(key).or_insert_with(|| {
            vertices.push([key.0 as f64 / scale, key.1 as f64 / scale, 0.0]);
            (vertices.len() - 1) as u32
        })
    };
    for i in 0..3 {
        for j in 0..3 {
            let (x, y) = (i as f64, j as f64);
            let c = [x + 0.5, y + 0.5];
            let corners = [[x, y], [x + 1.0, y], [x + 1.0, y + 1.0], [x, y + 1.0]];
            for k in 0..4 {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                let centroid = [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0];
                if !inside(centroid[0], centroid[1]) {
                    continue;
                }
                // Uniform subdivision of the triangle (a, b, c): points a + (u/n)(b − a) + (v/n)(c − a).
                let at = |u: usize, v: usize| {
                    let (s, t) = (u as f64 / n as f64, v as f64 / n as f64);
                    [a[0] + s * (b[0] - a[0]) + t * (c[0] - a[0]), a[1] + s * (b[1] - a[1]) + t * (c[1] - a[1])]
                };
                for u in 0..n {
                    for v in 0..n - u {
                        let (p0, p1, p2) = (at(u, v), at(u + 1, v), at(u, v + 1));
                        let f = [vertex(p0, &mut vertices), vertex(p1, &mut vertices), vertex(p2, &mut vertices)];
                        faces.push(f);
                        if u + v + 1 < n {
                            let p3 = at(u + 1, v + 1);
                            faces.push([f[1], vertex(p3, &mut vertices), f[2]]);
                        }
                    }
                }
            }
        }
    }
    TriangleMesh { vertices, faces }
}

/// The unit disk: `rings` concentric rings, ring k with 6k vertices, boundary vertices exactly on the circle.
pub fn unit_disk(rings: usize) -> TriangleMesh {
    let mut vertices: Vec<Point> = vec![[0.0, 0.0, 0.0]];
    let mut start = vec![0usize];
    for k in 1..=rings {
        start.push(vertices.len());
        let r = k as f64 / rings as f64;
        for j in 0..6 * k {
            let a = 2.0 * std::f64::consts::PI * j as f64 / (6 * k) as f64;
            vertices.push([r * a.cos(), r * a.sin(), 0.0]);
        }
    }
    let mut faces = Vec::new();
    for k in 1..=rings {
        let outer = |j: usize| (start[k] + j % (6 * k)) as u32;
        let inner = |j: usize| if k == 1 { 0 } else { (start[k - 1] + j % (6 * (k - 1))) as u32 };
        // Walk the six sectors: each has k outer and k−1 inner steps.
        for s in 0..6 {
            for j in 0..k {
                let o = s * k + j;
                let i = s * (k - 1) + j;
                faces.push([inner(i), outer(o), outer(o + 1)]);
                if j + 1 < k {
                    faces.push([inner(i), outer(o + 1), inner(i + 1)]);
                }
            }
        }
    }
    TriangleMesh { vertices, faces }
}

/// A torus of major radius `r_major` and minor radius `r_minor`, n × m quads split in two.
pub fn torus(r_major: f64, r_minor: f64, n: usize, m: usize) -> TriangleMesh {
    let mut vertices = Vec::with_capacity(n * m);
    for i in 0..n {
        let u = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
        for j in 0..m {
            let w = 2.0 * std::f64::consts::PI * j as f64 / m as f64;
            let rr = r_major + r_minor * w.cos();
            vertices.push([rr * u.cos(), rr * u.sin(), r_minor * w.sin()]);
        }
    }
    let idx = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let mut faces = Vec::with_capacity(2 * n * m);
    for i in 0..n {
        for j in 0..m {
            faces.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            faces.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    TriangleMesh { vertices, faces }
}

/// The unit cube [0, 1]³ as n³ small cubes, each split into six tetrahedra around its main diagonal
/// (Kuhn/Freudenthal subdivision: conforming across cubes), all positively oriented.
pub fn unit_cube_tets(n: usize) -> TetMesh {
    let idx = |i: usize, j: usize, k: usize| (k * (n + 1) * (n + 1) + j * (n + 1) + i) as u32;
    let mut vertices = Vec::with_capacity((n + 1).pow(3));
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                vertices.push([i as f64 / n as f64, j as f64 / n as f64, k as f64 / n as f64]);
            }
        }
    }
    let mut tets = Vec::with_capacity(6 * n * n * n);
    // Paths from corner 000 to 111 along the permutations of the axes.
    let perms = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                for p in perms {
                    let mut c = [0usize; 3];
                    let mut t = [idx(i, j, k); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] = 1;
                        t[s + 1] = idx(i + c[0], j + c[1], k + c[2]);
                    }
                    let pts = t.map(|v| vertices[v as usize]);
                    if super::vec3::volume6(pts[0], pts[1], pts[2], pts[3]) < 0.0 {
                        t.swap(2, 3);
                    }
                    tets.push(t);
                }
            }
        }
    }
    TetMesh { vertices, tets }
}

/// The segment [0, ℓ] with n equal pieces.
pub fn segment(n: usize, length: f64) -> Polyline {
    Polyline {
        vertices: (0..=n).map(|i| [length * i as f64 / n as f64, 0.0, 0.0]).collect(),
        segments: (0..n as u32).map(|i| [i, i + 1]).collect(),
    }
}

/// The path graph P_n.
pub fn path_graph(n: usize) -> Graph {
    let edges: Vec<[u32; 2]> = (0..n.saturating_sub(1) as u32).map(|i| [i, i + 1]).collect();
    Graph { vertex_count: n, positions: None, weights: vec![1.0; edges.len()], edges }
}

/// A pair of connected graphs on 6 vertices and 7 edges with the same combinatorial Laplacian spectrum that are
/// not isomorphic (their degree sequences differ: 4,2,2,2,2,2 and 3,3,3,2,2,1): the discrete "can you hear the
/// shape" counterexample. Found by an exhaustive search of the connected graphs on 6 vertices, comparing exact
/// characteristic polynomials of their Laplacians; `which` is 1 or 2.
pub fn cospectral_graph(which: usize) -> Graph {
    let edges: Vec<[u32; 2]> = if which == 2 {
        vec![[0, 2], [0, 4], [0, 5], [1, 2], [1, 4], [1, 5], [2, 3]]
    } else {
        vec![[0, 2], [0, 3], [0, 4], [0, 5], [1, 4], [1, 5], [2, 3]]
    };
    Graph { vertex_count: 6, positions: None, weights: vec![1.0; edges.len()], edges }
}

/// The cycle graph C_n.
pub fn cycle_graph(n: usize) -> Graph {
    let edges: Vec<[u32; 2]> = (0..n as u32).map(|i| [i.min((i + 1) % n as u32), i.max((i + 1) % n as u32)]).collect();
    Graph { vertex_count: n, positions: None, weights: vec![1.0; edges.len()], edges }
}

/// The complete graph K_n.
pub fn complete_graph(n: usize) -> Graph {
    let edges: Vec<[u32; 2]> = (0..n as u32).flat_map(|i| (i + 1..n as u32).map(move |j| [i, j])).collect();
    Graph { vertex_count: n, positions: None, weights: vec![1.0; edges.len()], edges }
}

/// The Petersen graph (10 vertices, 15 edges, 2000 spanning trees, Laplacian spectrum 0, 2⁵, 5⁴).
pub fn petersen_graph() -> Graph {
    let mut edges = Vec::new();
    for i in 0..5u32 {
        edges.push([i, (i + 1) % 5]);
        edges.push([i, i + 5]);
        edges.push([5 + i, 5 + (i + 2) % 5]);
    }
    let edges: Vec<[u32; 2]> = edges.into_iter().map(|[a, b]| [a.min(b), a.max(b)]).collect();
    Graph { vertex_count: 10, positions: None, weights: vec![1.0; edges.len()], edges }
}

/// `n` points uniformly at random on the unit sphere (deterministic for a seed; SplitMix64): a randomly, not
/// evenly, sampled cloud with known spectrum l(l+1) and area 4π.
/// A uniform random number generator on [0, 1) (splitmix64), deterministic per seed.
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// n points drawn uniformly at random on the flat torus (cos u, sin u, cos v, sin v) ⊂ R⁴ (u, v uniform in
/// [0, 2π)), row-major with 4 coordinates each: a flat 2-manifold of area 4π², whose Laplace–Beltrami eigenvalues
/// are a² + b² (a, b integers): 0, 1 (×4), 2 (×4), 4 (×4), 5 (×8), …
pub fn random_flat_torus_r4(n: usize, seed: u64) -> Vec<f64> {
    let mut next = uniform(seed);
    (0..n)
        .flat_map(|_| {
            let (u, v) = (2.0 * std::f64::consts::PI * next(), 2.0 * std::f64::consts::PI * next());
            [u.cos(), u.sin(), v.cos(), v.sin()]
        })
        .collect()
}

pub fn random_sphere_points(n: usize, seed: u64) -> Vec<Point> {
    let mut next = uniform(seed);
    (0..n)
        .map(|_| {
            let z = 2.0 * next() - 1.0;
            let phi = 2.0 * std::f64::consts::PI * next();
            let r = (1.0 - z * z).sqrt();
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect()
}

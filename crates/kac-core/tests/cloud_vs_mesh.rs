//! A scan finds its mesh (issue 21, item 3): point clouds sampled area-uniformly from the shared meshes (in code,
//! 10,000 points each), clean and with Gaussian noise of 1 % of the shape's size (σ = 0.01·√(A/4π)) along the
//! face normals, give a shape-DNA (the first 50 non-zero eigenvalues times the area) within 5 % (median over the
//! 50) of the mesh's own, and the mesh nearest to each cloud by that shape-DNA, among every closed manifold mesh
//! of the shared data with enough vertices, is its own (the two tori and the two spheres of the data count as one
//! class each).
//!
//! The mesh's own shape-DNA is that of its polyhedron, which is what the cloud samples: quadratic elements
//! (`order: 2`) on the mesh refined (flat, the same polyhedron) to at least 2,000 vertices. These meshes are coarse
//! (60 to 2,304 vertices), and P1's own error at λ₅₀ would be as large as what is measured (the 576-vertex torus:
//! P1 and the cloud differ by 9.6 % at the median, P2 and the cloud by 0.8 %). Measured medians: 0.55 % to 3.2 %.
//!
//! The penguin's control mesh is a candidate but is not sampled: its flippers nearly touch its body (vertices
//! 0.013 apart whose geodesic distance is 1.86; the spacing of 10,000 samples is 0.041), and no cloud of that
//! density can tell surfaces that close apart: its cloud hears flippers joined to the body (shape-DNA 27 % off,
//! nearest to the genus-2 `eight`), a limit of every mesh-free operator, not a noise effect.

mod common;

use kac_core::geometry::{PointCloud, Shape};
use kac_core::operators::{self, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};
use kac_core::{load, ReadOptions, ValidateOptions};

const ORDER: u8 = 2;

/// Closed manifold meshes of the shared data with enough vertices for 50 eigenvalues with quadratic elements (the
/// icosahedron's 12 have too few); clouds are sampled from all but the last (see the module documentation).
const MESHES: &[&str] = &[
    "obj/torus.obj",
    "obj/fish_low_resolution.obj",
    "off/torus.off",
    "off/eight.off",
    "ply/nut_binary.ply",
    "ply/sphere_binary.ply",
    "stl/sphere_binary.stl",
    "stl/HalfDonut_binary.stl",
    "stl/Moon_binary.stl",
    "obj/penguin_control_mesh.obj",
];
const SAMPLED: usize = MESHES.len() - 1;

fn shape_dna(shape: &Shape, order: u8) -> Vec<f64> {
    let o = operators::build(shape, &OperatorOptions { order, ..Default::default() }).unwrap_or_else(|e| panic!("{e}"));
    let area: f64 = o.pair.mass.iter().sum();
    let e = eigs(&o.pair, &EigenOptions { k: 51, ..Default::default() }, None, Control::default()).unwrap();
    e.values[1..].iter().map(|l| l * area).collect()
}

fn median_relative(a: &[f64], b: &[f64]) -> f64 {
    let mut d: Vec<f64> = a.iter().zip(b).map(|(x, y)| (x - y).abs() / y).collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| ((x - y) / y).powi(2)).sum::<f64>().sqrt()
}

/// n points area-uniform on a triangle mesh, with Gaussian noise of `sigma` along the face normal.
fn sample(m: &kac_core::geometry::TriangleMesh, n: usize, sigma: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut state = seed;
    let mut uniform = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let mut cumulative = vec![];
    let mut total = 0.0;
    for f in &m.faces {
        let [a, b, c] = f.map(|i| m.vertices[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        total += 0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        cumulative.push(total);
    }
    (0..n)
        .map(|_| {
            let t = uniform() * total;
            let f = m.faces[cumulative.partition_point(|&c| c < t).min(m.faces.len() - 1)];
            let [a, b, c] = f.map(|i| m.vertices[i as usize]);
            let (r1, r2) = (uniform().sqrt(), uniform());
            let (wa, wb, wc) = (1.0 - r1, r1 * (1.0 - r2), r1 * r2);
            let p: [f64; 3] = std::array::from_fn(|k| wa * a[k] + wb * b[k] + wc * c[k]);
            let nrm = cross(sub(b, a), sub(c, a));
            let l = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
            let g = (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
            std::array::from_fn(|k| p[k] + sigma * g * nrm[k] / l)
        })
        .collect()
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn clouds_sampled_from_the_shared_meshes_find_their_mesh() {
    let dir = common::shared_data("clouds_sampled_from_the_shared_meshes_find_their_mesh");
    let meshes: Vec<kac_core::geometry::TriangleMesh> = MESHES
        .iter()
        .map(|f| {
            let (v, _) = load(&dir.join(f), None, &ReadOptions::default(), &ValidateOptions::default()).unwrap();
            match v.shape {
                Shape::TriangleMesh(m) => m,
                _ => panic!("{f}: not a triangle mesh"),
            }
        })
        .collect();
    let dna: Vec<Vec<f64>> = meshes
        .iter()
        .map(|m| {
            let mut fine = m.clone();
            while fine.vertices.len() < 2000 {
                fine = kac_core::geometry::refine::refine_triangles(&fine);
            }
            shape_dna(&Shape::TriangleMesh(fine), ORDER)
        })
        .collect();
    for (i, m) in meshes.iter().enumerate().take(SAMPLED) {
        let a: f64 = {
            let o = operators::build(&Shape::TriangleMesh(m.clone()), &OperatorOptions::default()).unwrap();
            o.pair.mass.iter().sum()
        };
        let size = (a / (4.0 * std::f64::consts::PI)).sqrt();
        for sigma in [0.0, 0.01 * size] {
            let cloud =
                Shape::PointCloud(PointCloud { points: sample(m, 10_000, sigma, 5 + i as u64), ..Default::default() });
            let c = shape_dna(&cloud, 1);
            let own = median_relative(&c, &dna[i]);
            let nearest =
                (0..meshes.len()).min_by(|&p, &q| distance(&c, &dna[p]).total_cmp(&distance(&c, &dna[q]))).unwrap();
            eprintln!("{} σ = {sigma:.4}: median {own:.4}, nearest {}", MESHES[i], MESHES[nearest]);
            assert!(own < 0.05, "{} σ = {sigma}: the cloud's shape-DNA is {own} from the mesh's", MESHES[i]);
            // The two tori of the shared data are one shape class, the two spheres another.
            let class = |p: usize| ["torus", "sphere"].into_iter().find(|c| MESHES[p].contains(c));
            let same = |p: usize| p == i || (class(p).is_some() && class(p) == class(i));
            assert!(same(nearest), "{} σ = {sigma}: nearest is {}", MESHES[i], MESHES[nearest]);
        }
    }
}

//! The point-cloud case: a random (uniform, not even) 40,000-point sample of the unit sphere.
//! Prints the total mass (4π ≈ 12.566) and the smallest eigenvalues (0, 2 ×3, 6 ×5) of the point-cloud operators.
use kac_core::geometry::{PointCloud, Shape};
use kac_core::operators::{self, OperatorKind, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(40_000);
    let mut seed = 7u64;
    let mut next = || {
        seed = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let points = (0..n)
        .map(|_| {
            let z = 2.0 * next() - 1.0;
            let phi = 2.0 * std::f64::consts::PI * next();
            let r = (1.0 - z * z).sqrt();
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect();
    let s = Shape::PointCloud(PointCloud { points, normals: None });
    for kind in [OperatorKind::PointCloud, OperatorKind::Robust] {
        let t = std::time::Instant::now();
        let o = operators::build(&s, &OperatorOptions { operator: Some(kind), ..Default::default() }).unwrap();
        let total: f64 = o.pair.mass.iter().sum();
        let e = eigs(&o.pair, &EigenOptions { k: 9, ..Default::default() }, None, Control::default()).unwrap();
        println!(
            "{}: n = {n}, nonzeros = {}, total mass = {total:.4} (4π = 12.5664), λ = {:?}, {:.1} s, parameters {:?}",
            kind.name(),
            o.pair.nnz(),
            e.values.iter().map(|v| (v * 1e4).round() / 1e4).collect::<Vec<_>>(),
            t.elapsed().as_secs_f64(),
            o.parameters
        );
    }
}

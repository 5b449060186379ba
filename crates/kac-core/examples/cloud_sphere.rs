//! The point-cloud case: a random (uniform, not even) 40,000-point sample of the unit sphere.
//! Prints the total mass (4π ≈ 12.566) and the smallest eigenvalues (0, 2 ×3, 6 ×5) of the point-cloud operators.
use kac_core::geometry::{PointCloud, Shape};
use kac_core::operators::{self, OperatorKind, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(40_000);
    let points = kac_core::geometry::generate::random_sphere_points(n, 7);
    let s = Shape::PointCloud(PointCloud { points, normals: None, ambient: None });
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

//! Issue 21's case: random samples of the unit sphere with radial Gaussian noise σ, through the point-cloud
//! operator on the points as given and after the moving-least-squares projection (`operators::denoise`).
//! Prints the total measure (4π ≈ 12.566) and λ₂..₄ (2) per σ. Usage: noisy_cloud [N]
use kac_core::geometry::{generate, PointCloud, Shape};
use kac_core::operators::{self, denoise, OperatorKind, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let clean = generate::random_sphere_points(n, 3);
    let mut state = 12345u64;
    let mut uniform = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let gauss: Vec<f64> =
        (0..n).map(|_| (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos()).collect();
    for sigma in [0.0, 0.01, 0.02, 0.04] {
        let noisy: Vec<[f64; 3]> = clean.iter().zip(&gauss).map(|(p, g)| p.map(|c| c * (1.0 + sigma * g))).collect();
        let t = std::time::Instant::now();
        let (projected, report) = denoise::denoise(&noisy, None).unwrap();
        let dt = t.elapsed().as_secs_f64();
        for (what, pts) in [("raw", &noisy), ("projected", &projected)] {
            let s = Shape::PointCloud(PointCloud { points: pts.clone(), ..Default::default() });
            let o = operators::build(
                &s,
                &OperatorOptions { operator: Some(OperatorKind::PointCloud), ..Default::default() },
            )
            .unwrap();
            let total: f64 = o.pair.mass.iter().sum();
            let e = eigs(&o.pair, &EigenOptions { k: 4, ..Default::default() }, None, Control::default()).unwrap();
            println!("σ = {sigma}: {what}: total {total:.3}, λ₂..₄ = {:.3?}", &e.values[1..]);
        }
        println!(
            "   denoise {dt:.2}s: k {}, noise {:.4}, moved median {:.4} max {:.4}, variation {:?}",
            report.k, report.noise, report.moved_median, report.moved_max, report.surface_variation
        );
    }
}

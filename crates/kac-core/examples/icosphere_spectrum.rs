//! The k smallest eigenpairs of the cotan Laplacian on a unit icosphere with the sparse solver, its statistics,
//! and (level ≤ 4) the largest relative difference to the dense solver.
//! Usage: `cargo run --release -p kac-core --example icosphere_spectrum -- LEVEL K [SUBSPACE] [SIGMA]`;
//! KAC_B and KAC_TOL set the block size and tolerance.
use kac_core::geometry::{generate, Shape};
use kac_core::operators::{self, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions, Method};
fn main() {
    let level: u32 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(3);
    let k: usize = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(30);
    let s = Shape::TriangleMesh(generate::icosphere(level));
    let t = std::time::Instant::now();
    let o = operators::build(&s, &OperatorOptions::default()).unwrap();
    println!("assembly {:.3}s n={}", t.elapsed().as_secs_f64(), o.pair.n());
    let sub: Option<usize> = std::env::args().nth(3).and_then(|s| s.parse().ok());
    let sp = eigs(
        &o.pair,
        &EigenOptions {
            k,
            method: Method::Sparse,
            block: std::env::var("KAC_B").ok().and_then(|s| s.parse().ok()),
            tol: std::env::var("KAC_TOL").ok().and_then(|s| s.parse().ok()).unwrap_or(1e-10),
            subspace: sub,
            sigma: std::env::args().nth(4).and_then(|s| s.parse().ok()),
            ..Default::default()
        },
        None,
        Control::default(),
    )
    .unwrap();
    println!("{:?}", sp.stats);
    println!("vals {:?}", &sp.values[..k.min(8)]);
    println!("max resid {:e}", sp.residuals.iter().cloned().fold(0.0, f64::max));
    if level <= 4 {
        let d =
            eigs(&o.pair, &EigenOptions { k, method: Method::Dense, ..Default::default() }, None, Control::default())
                .unwrap();
        let md = d.values.iter().zip(&sp.values).map(|(a, b)| ((a - b) / a.abs().max(1.0)).abs()).fold(0.0, f64::max);
        println!("max rel diff vs dense {md:e}");
    }
}

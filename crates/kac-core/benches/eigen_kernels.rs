//! The eigensolver's inner kernels on unit icospheres (P1 FEM, consistent mass): the block solve with the
//! Cholesky factor of L − σM for 1, 8 and 16 right-hand sides, and the sparse block product with M. Prints one
//! JSON line per case; medians of 9 runs after a warm-up. `KAC_LEVELS=5,6,7` picks the meshes (default 6),
//! `KAC_REPS` the number of runs, `KAC_MIN=1` reports the fastest run instead of the median (steadier for A/B
//! comparisons on a noisy machine).

mod common;
use common::median;

use faer::{Mat, Par};
use kac_core::geometry::{generate, Shape};
use kac_core::operators::{self, sparse, Mass, OperatorOptions};
use kac_core::spectrum::factor::{Cholesky, Symbolic};
use kac_core::spectrum::lanczos::default_sigma;
use std::time::Instant;

fn time(mut f: impl FnMut()) -> f64 {
    f();
    let reps: usize = std::env::var("KAC_REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(9);
    let stat = if std::env::var("KAC_MIN").is_ok() {
        |v: Vec<f64>| v.iter().cloned().fold(f64::MAX, f64::min)
    } else {
        median
    };
    stat(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

fn main() {
    let Some(levels) = common::levels(&[6]) else {
        return;
    };
    for level in levels {
        let shape = Shape::TriangleMesh(generate::icosphere(level));
        let o = OperatorOptions { mass: Some(Mass::Consistent), ..Default::default() };
        let pair = operators::build(&shape, &o).unwrap().pair;
        let n = pair.n();
        let sym = Symbolic::analyze(&pair.pattern).unwrap();
        let chol = Cholesky::factor(&sym, &pair.shifted(default_sigma(&pair)), Par::Seq).unwrap();
        // The memory floor of one triangular sweep: streaming the factor's values once.
        let vals = chol.values();
        let stream = time(|| {
            let mut acc = [0.0f64; 8];
            for c in vals.chunks_exact(8) {
                for t in 0..8 {
                    acc[t] += c[t];
                }
            }
            std::hint::black_box(acc);
        });
        println!("{{\"vertices\": {n}, \"factor_stream_ms\": {:.3}}}", stream * 1e3);
        for b in [1usize, 8, 16] {
            let x = Mat::<f64>::from_fn(n, b, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
            let mut y = x.clone();
            let solve = time(|| {
                y.copy_from(&x);
                chol.solve_in_place(y.as_mut(), Par::Seq);
            });
            let mut scratch = Vec::new();
            let spmm = time(|| sparse::spmm(&pair.pattern, &pair.mass, x.as_ref(), y.as_mut(), &mut scratch));
            println!(
                "{{\"vertices\": {n}, \"factor_nnz\": {}, \"rhs\": {b}, \"solve_ms\": {:.3}, \"solve_ms_per_rhs\": {:.3}, \"mass_product_ms\": {:.3}}}",
                chol.factor_nnz(),
                solve * 1e3,
                solve * 1e3 / b as f64,
                spmm * 1e3
            );
        }
    }
}

//! The eigensolver's inner kernels on unit icospheres (P1 FEM, consistent mass): the block solve with the
//! Cholesky factor of L − σM for 1, 8 and 16 right-hand sides, and the sparse block product with M; the basis
//! products and the solve with the kernels of the CPU's widest instruction set (`isa`) and, where that is AVX-512,
//! with the AVX2 ones too (`*_avx2_ms`). Prints one JSON line per case; medians of 9 runs after a warm-up. `KAC_LEVELS=5,6,7` picks the meshes (default 6),
//! `KAC_REPS` the number of runs, `KAC_MIN=1` reports the fastest run instead of the median (steadier for A/B
//! comparisons on a noisy machine).

mod common;
use common::median;

use faer::{Mat, Par};
use kac_core::geometry::{generate, Shape};
use kac_core::operators::{self, sparse, Mass, OperatorOptions};
use kac_core::simd::Isa;
use kac_core::spectrum::factor::{Cholesky, Symbolic};
use kac_core::spectrum::lanczos::default_sigma;
use std::time::Instant;

fn reps() -> usize {
    std::env::var("KAC_REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(9)
}

/// The median of the runs, or their minimum with `KAC_MIN`.
fn stat(v: Vec<f64>) -> f64 {
    if std::env::var("KAC_MIN").is_ok() {
        v.iter().cloned().fold(f64::MAX, f64::min)
    } else {
        median(v)
    }
}

fn time(mut f: impl FnMut()) -> f64 {
    f();
    stat(
        (0..reps())
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
        // The LDLᵀ factor at the shift inside the spectrum the solver picks for k = 50.
        let interior = kac_core::spectrum::lanczos::weyl_shift(&pair, 50).unwrap();
        let (ldlt, _) = Cholesky::factor_ldlt(&sym, &pair.shifted(interior), Par::Seq).unwrap();
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
        println!("{{\"vertices\": {n}, \"isa\": \"{:?}\", \"factor_stream_ms\": {:.3}}}", Isa::detect(), stream * 1e3);
        // The narrower kernels, timed where the CPU has wider ones (else the same figures again).
        let narrow = if Isa::detect() == Isa::Avx512 { Isa::Avx2 } else { Isa::detect() };
        // The Gram–Schmidt pair on a basis of 128 columns: kac's kernels against faer's general product.
        {
            use faer::linalg::matmul::matmul;
            use faer::Accum;
            use kac_core::spectrum::basis_products;
            let (m, b) = (128usize, 8usize);
            let v = Mat::<f64>::from_fn(n, m, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
            let y: Vec<f64> = (0..n * b).map(|p| ((p * 5) % 11) as f64 - 5.0).collect();
            let gram = time(|| {
                std::hint::black_box(basis_products::gram(v.as_ref(), &y, b));
            });
            let mut c = Mat::<f64>::zeros(m, b);
            let gram_faer = time(|| {
                matmul(
                    c.as_mut(),
                    Accum::Replace,
                    v.transpose(),
                    faer::MatRef::from_row_major_slice(&y, n, b),
                    1.0,
                    Par::Seq,
                )
            });
            let gram_narrow = time(|| {
                std::hint::black_box(basis_products::gram_with(v.as_ref(), &y, b, narrow));
            });
            let mut w = y.clone();
            let update = time(|| basis_products::update(&mut w, b, v.as_ref(), c.as_ref(), -1e-3));
            let update_narrow = time(|| basis_products::update_with(&mut w, b, v.as_ref(), c.as_ref(), -1e-3, narrow));
            let update_faer = time(|| {
                matmul(
                    faer::MatMut::from_row_major_slice_mut(&mut w, n, b),
                    Accum::Add,
                    v.as_ref(),
                    c.as_ref(),
                    -1e-3,
                    Par::Seq,
                )
            });
            println!(
                "{{\"vertices\": {n}, \"basis_columns\": {m}, \"rhs\": {b}, \"basis_stream_ms\": {:.3}, \"gram_ms\": {:.3}, \"gram_avx2_ms\": {:.3}, \"gram_faer_ms\": {:.3}, \"update_ms\": {:.3}, \"update_avx2_ms\": {:.3}, \"update_faer_ms\": {:.3}}}",
                time(|| { std::hint::black_box(v.as_ref().sum()); }) * 1e3,
                gram * 1e3, gram_narrow * 1e3, gram_faer * 1e3, update * 1e3, update_narrow * 1e3, update_faer * 1e3
            );
        }
        for b in [1usize, 8, 16] {
            let x = Mat::<f64>::from_fn(n, b, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
            let mut y = x.clone();
            let solve = time(|| {
                y.copy_from(&x);
                chol.solve_in_place(y.as_mut(), Par::Seq);
            });
            let solve_narrow = time(|| {
                y.copy_from(&x);
                chol.solve_in_place_with(y.as_mut(), Par::Seq, narrow);
            });
            let solve_ldlt = time(|| {
                y.copy_from(&x);
                ldlt.solve_in_place(y.as_mut(), Par::Seq);
            });
            // The same solve after 64 MB of other traffic (the eigensolver streams its basis between solves, so the
            // factor comes from memory, not from the last-level cache): untimed flush, timed solve.
            let mut flush = vec![0.0f64; 8 << 20];
            let mut cold = Vec::new();
            for rep in 0..reps() {
                flush.iter_mut().for_each(|v| *v += rep as f64);
                y.copy_from(&x);
                let t = Instant::now();
                chol.solve_in_place(y.as_mut(), Par::Seq);
                cold.push(t.elapsed().as_secs_f64());
            }
            std::hint::black_box(&flush);
            let cold = stat(cold);
            let mut scratch = Vec::new();
            let spmm = time(|| {
                sparse::spmm(
                    &pair.pattern,
                    &pair.mass,
                    x.as_ref(),
                    y.as_mut(),
                    &mut scratch,
                    rayon::current_num_threads(),
                )
            });
            println!(
                "{{\"vertices\": {n}, \"factor_nnz\": {}, \"rhs\": {b}, \"solve_ms\": {:.3}, \"solve_ms_per_rhs\": {:.3}, \"solve_avx2_ms\": {:.3}, \"solve_after_flush_ms\": {:.3}, \"solve_ldlt_ms\": {:.3}, \"mass_product_ms\": {:.3}}}",
                chol.factor_nnz(),
                solve * 1e3,
                solve * 1e3 / b as f64,
                solve_narrow * 1e3,
                cold * 1e3,
                solve_ldlt * 1e3,
                spmm * 1e3
            );
        }
    }
}

//! The hierarchical subspace iteration of Nasikun & Hildebrandt (2022, ACM TOG, "The Hierarchical Subspace Iteration
//! Method for Laplace–Beltrami Eigenproblems") on its most favourable terms, against kac's block Lanczos: the
//! eigenvectors of the coarser icosphere (level L − 1, solved by kac and not counted in the time) prolonged to level L
//! by the subdivision's own linear interpolation, then shift-invert subspace iteration with Rayleigh–Ritz on level L
//! until the k smallest pairs reach the residual kac's Lanczos reaches on the same problem (kac's measure,
//! ‖L x − λ M x‖ / (max(|λ|, |σ|) ‖M x‖) with the Lanczos run's σ). Nothing in the solver uses
//! it: it measures whether HSIM's finest level alone could beat the Lanczos run (issue 31, item 2).
//!
//! Usage: `cargo run --release -p kac-core --example hsim_fine_level -- LEVEL K P SIGMA_FRACTION [MAX_ITERATIONS]`:
//! P columns in the subspace, σ = SIGMA_FRACTION × the Lanczos λ_k (0 for σ below the spectrum).
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par, Side};
use kac_core::geometry::{generate, Shape};
use kac_core::operators::sparse::spmm;
use kac_core::operators::{self, OperatorOptions};
use kac_core::spectrum::factor::{Cholesky, Symbolic};
use kac_core::spectrum::{eigs, Control, EigenOptions, Method};
use std::time::Instant;

fn arg<T: std::str::FromStr>(i: usize, default: T) -> T {
    std::env::args().nth(i).and_then(|s| s.parse().ok()).unwrap_or(default)
}

fn main() {
    let (level, k, p, frac, max_it): (u32, usize, usize, f64, usize) =
        (arg(1, 6), arg(2, 200), arg(3, 400), arg(4, 0.5), arg(5, 40));
    assert!(level >= 1 && k >= 2 && p >= k, "LEVEL ≥ 1, K ≥ 2 and P ≥ K");
    // Every dense product on this thread (faer's default would use the rayon pool).
    faer::set_global_parallelism(Par::Seq);
    let fine_mesh = generate::icosphere(level);
    let n_coarse = generate::icosphere(level - 1).vertices.len();
    let build = |mesh| operators::build(&Shape::TriangleMesh(mesh), &OperatorOptions::default()).unwrap().pair;
    let fine = build(fine_mesh.clone());
    let coarse = build(generate::icosphere(level - 1));
    let n = fine.n();

    // The reference: kac's block Lanczos on the fine level, one thread.
    let opts = |k| EigenOptions { k, method: Method::Sparse, threads: 1, ..Default::default() };
    let t = Instant::now();
    let lanczos = eigs(&fine, &opts(k), None, Control::default()).unwrap();
    let lanczos_s = t.elapsed().as_secs_f64();
    let target = lanczos.residuals.iter().cloned().fold(0.0, f64::max);
    // kac's residual measure: ‖L x − λ M x‖ / (max(|λ|, |σ|) ‖M x‖) with the Lanczos run's σ.
    let sigma_floor = lanczos.stats.sigma.abs().max(f64::MIN_POSITIVE);
    println!(
        "n = {n}, k = {k}: block Lanczos {lanczos_s:.2} s, {} solved columns, max residual {target:.1e}",
        lanczos.stats.solves
    );

    // Coarse eigenvectors (not timed), prolonged: a vertex of level L − 1 keeps its value, a new vertex (an edge's
    // midpoint) takes the mean of the edge's two ends, the vertices of level L − 1 it shares faces with.
    let coarse_s = eigs(&coarse, &opts(p), None, Control::default()).unwrap();
    let mut parents = vec![Vec::<u32>::new(); n];
    for f in &fine_mesh.faces {
        for &a in f {
            for &b in f {
                if a as usize >= n_coarse && (b as usize) < n_coarse && !parents[a as usize].contains(&b) {
                    parents[a as usize].push(b);
                }
            }
        }
    }
    let mut x = Mat::<f64>::from_fn(n, p, |i, j| {
        if i < n_coarse {
            coarse_s.vectors[(i, j)]
        } else {
            parents[i].iter().map(|&q| coarse_s.vectors[(q as usize, j)]).sum::<f64>() / parents[i].len() as f64
        }
    });

    // Shift-invert subspace iteration on the fine level, timed from the factorization on.
    let t = Instant::now();
    let sigma = frac * lanczos.values[k - 1];
    let sym = Symbolic::analyze(&fine.pattern).unwrap();
    let shifted = fine.shifted(if sigma > 0.0 { sigma } else { -1e-3 });
    let chol = if sigma > 0.0 {
        Cholesky::factor_ldlt(&sym, &shifted, Par::Seq).unwrap().0
    } else {
        Cholesky::factor(&sym, &shifted, Par::Seq).unwrap()
    };
    let (mut lx, mut mx, mut scratch) = (Mat::<f64>::zeros(n, p), Mat::<f64>::zeros(n, p), Vec::new());
    let mut products = |x: &Mat<f64>, lx: &mut Mat<f64>, mx: &mut Mat<f64>| {
        spmm(&fine.pattern, &fine.stiffness, x.as_ref(), lx.as_mut(), &mut scratch, 1);
        spmm(&fine.pattern, &fine.mass, x.as_ref(), mx.as_mut(), &mut scratch, 1);
    };
    products(&x, &mut lx, &mut mx);
    let mut solved = 0;
    for it in 0..=max_it {
        // Rayleigh–Ritz: A = Xᵀ L X, B = Xᵀ M X = Q D Qᵀ, W = Q D^(-1/2), Wᵀ A W = U Λ Uᵀ, X ← X W U.
        let mut a = Mat::<f64>::zeros(p, p);
        let mut b = Mat::<f64>::zeros(p, p);
        matmul(a.as_mut(), Accum::Replace, x.transpose(), lx.as_ref(), 1.0, Par::Seq);
        matmul(b.as_mut(), Accum::Replace, x.transpose(), mx.as_ref(), 1.0, Par::Seq);
        let sym = |m: &Mat<f64>| Mat::from_fn(p, p, |i, j| 0.5 * (m[(i, j)] + m[(j, i)]));
        let bevd = sym(&b).self_adjoint_eigen(Side::Lower).unwrap();
        let w = Mat::from_fn(p, p, |i, j| bevd.U()[(i, j)] / bevd.S()[j].max(1e-300).sqrt());
        let c = w.transpose() * sym(&a) * w.as_ref();
        let evd = sym(&c).self_adjoint_eigen(Side::Lower).unwrap();
        let s = w.as_ref() * evd.U();
        let lam: Vec<f64> = (0..p).map(|i| evd.S()[i]).collect();
        x = x.as_ref() * s.as_ref();
        products(&x, &mut lx, &mut mx);
        let worst = (1..k)
            .map(|j| {
                let res: f64 = (0..n).map(|i| (lx[(i, j)] - lam[j] * mx[(i, j)]).powi(2)).sum::<f64>().sqrt();
                let mn: f64 = (0..n).map(|i| mx[(i, j)].powi(2)).sum::<f64>().sqrt();
                res / (lam[j].abs().max(sigma_floor) * mn)
            })
            .fold(0.0, f64::max);
        let diff = (1..k).map(|j| ((lam[j] - lanczos.values[j]) / lanczos.values[j]).abs()).fold(0.0, f64::max);
        println!(
            "iteration {it}: {solved} solved columns, {:.2} s, max residual {worst:.1e}, max rel. diff to Lanczos {diff:.1e}",
            t.elapsed().as_secs_f64()
        );
        if worst <= target || it == max_it {
            break;
        }
        // X ← (L − σM)⁻¹ M X, eight columns per block solve as in the Lanczos run.
        for j0 in (0..p).step_by(8) {
            let w = 8.min(p - j0);
            let mut blk = mx.as_ref().subcols(j0, w).to_owned();
            chol.solve_in_place(blk.as_mut(), Par::Seq);
            x.as_mut().subcols_mut(j0, w).copy_from(blk.as_ref());
        }
        products(&x, &mut lx, &mut mx);
        solved += p;
    }
}

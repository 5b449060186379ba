//! The functional map fitted to the probes: the small dense least-squares problem E(C).

use super::options::CorrespondenceOptions;
use crate::descriptors::DescriptorError;
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Accum, Mat, Par, Side};

/// Solves the SPD system A X = B (A k × k) by Cholesky; None when A is not positive definite.
pub(super) fn spd_solve(a: &Mat<f64>, b: &Mat<f64>) -> Option<Mat<f64>> {
    let llt = a.llt(Side::Lower).ok()?;
    let mut x = b.clone();
    solve_lower_triangular_in_place(llt.L(), x.as_mut(), Par::Seq);
    solve_upper_triangular_in_place(llt.L().transpose(), x.as_mut(), Par::Seq);
    Some(x)
}

/// The functional map C (k × k) fitted to the probes' coefficients A (source), B (target), the eigenvalues, and
/// pairs of operators (source, target) that C must commute with, each with its weight: the probes' multiplication
/// operators (descriptor commutativity) and orientation operators.
pub(super) fn fit(
    a: &Mat<f64>,
    b: &Mat<f64>,
    lambda_s: &[f64],
    lambda_t: &[f64],
    ops: &[(Mat<f64>, Mat<f64>, f64)],
    o: &CorrespondenceOptions,
) -> Result<Mat<f64>, DescriptorError> {
    let (kt, ks) = (lambda_t.len(), lambda_s.len());
    // (λ_i^T − λ_j^S)², scaled to unit Frobenius norm (the weight then does not depend on the shapes' scale).
    let mut d = Mat::from_fn(kt, ks, |i, j| (lambda_t[i] - lambda_s[j]).powi(2));
    let norm = d.norm_l2();
    if norm > 0.0 {
        d = Mat::from_fn(kt, ks, |i, j| d[(i, j)] / norm);
    }
    let aat = {
        let mut m = Mat::zeros(ks, ks);
        matmul(m.as_mut(), Accum::Replace, a.as_ref(), a.transpose(), 1.0, Par::Seq);
        m
    };
    let bat = {
        let mut m = Mat::zeros(kt, ks);
        matmul(m.as_mut(), Accum::Replace, b.as_ref(), a.transpose(), 1.0, Par::Seq);
        m
    };
    let singular = || DescriptorError::param("correspondence", "the fit's system is singular: give more descriptors");
    if ops.is_empty() {
        // Row by row: (w_d A Aᵀ + w_l diag(D_i)) c_iᵀ = w_d A b_iᵀ.
        let mut c = Mat::zeros(kt, ks);
        for i in 0..kt {
            let sys = Mat::from_fn(ks, ks, |p, q| {
                o.descriptor_weight * aat[(p, q)] + if p == q { o.laplacian_weight * d[(i, p)] } else { 0.0 }
            });
            let rhs = Mat::from_fn(ks, 1, |p, _| o.descriptor_weight * bat[(i, p)]);
            let x = spd_solve(&sys, &rhs).ok_or_else(singular)?;
            for p in 0..ks {
                c[(i, p)] = x[(p, 0)];
            }
        }
        return Ok(c);
    }
    // vec(C) column-major: index i + kt·j. The normal equations of E.
    let m = kt * ks;
    let idx = |i: usize, j: usize| i + kt * j;
    let mut sys = Mat::<f64>::zeros(m, m);
    let mut rhs = Mat::<f64>::zeros(m, 1);
    for j in 0..ks {
        for i in 0..kt {
            // w_d: (A Aᵀ ⊗ I); right-hand side w_d vec(B Aᵀ).
            for q in 0..ks {
                sys[(idx(i, j), idx(i, q))] += o.descriptor_weight * aat[(q, j)];
            }
            rhs[(idx(i, j), 0)] = o.descriptor_weight * bat[(i, j)];
            sys[(idx(i, j), idx(i, j))] += o.laplacian_weight * d[(i, j)];
        }
    }
    // w Σ ‖C X − Y C‖²: K = Xᵀ ⊗ I − I ⊗ Y, KᵀK = (X Xᵀ ⊗ I) − (X ⊗ Y) − (Xᵀ ⊗ Yᵀ) + (I ⊗ YᵀY), summed over the
    // pairs. Σ w X Xᵀ and Σ w YᵀY are formed once. The cross terms: T = Σ w (X ⊗ Y), entry ((i, j), (p, q)) =
    // Σ w X_jq Y_ip = G[(j, q), (i, p)] for G = Σ w vec(X) vec(Y)ᵀ, one product of the stacked vec(X) and vec(Y)
    // (formed for one q at a time, ks × kt² values); the other is Tᵀ, added by symmetrizing the system (every
    // other term is symmetric).
    if !ops.is_empty() {
        let mut xxt = Mat::<f64>::zeros(ks, ks);
        let mut yty = Mat::<f64>::zeros(kt, kt);
        for (x, y, w) in ops {
            matmul(xxt.as_mut(), Accum::Add, x.as_ref(), x.transpose(), *w, Par::Seq);
            matmul(yty.as_mut(), Accum::Add, y.transpose(), y.as_ref(), *w, Par::Seq);
        }
        for j in 0..ks {
            for q in 0..ks {
                for i in 0..kt {
                    sys[(idx(i, j), idx(i, q))] += xxt[(q, j)];
                }
            }
            for p in 0..kt {
                for i in 0..kt {
                    sys[(idx(i, j), idx(p, j))] += yty[(i, p)];
                }
            }
        }
        let nf = ops.len();
        // Row (f, i + kt p) of the stacked vec(Y)ᵀ: Y_f[i, p].
        let yv = Mat::from_fn(nf, kt * kt, |f, r| ops[f].1[(r % kt, r / kt)]);
        let mut g = Mat::<f64>::zeros(ks, kt * kt);
        for q in 0..ks {
            // Rows j of G[(j, q), ·] = Σ_f w_f X_f[j, q] vec(Y_f)ᵀ.
            let xq = Mat::from_fn(ks, nf, |j, f| ops[f].2 * ops[f].0[(j, q)]);
            matmul(g.as_mut(), Accum::Replace, xq.as_ref(), yv.as_ref(), 1.0, Par::Seq);
            for p in 0..kt {
                for j in 0..ks {
                    let column = idx(p, q);
                    for i in 0..kt {
                        // −2T here, then (S − 2T + (S − 2T)ᵀ) / 2 = S − T − Tᵀ below.
                        sys[(idx(i, j), column)] -= 2.0 * g[(j, i + kt * p)];
                    }
                }
            }
        }
        for r in 0..m {
            for c in r + 1..m {
                let mean = 0.5 * (sys[(r, c)] + sys[(c, r)]);
                sys[(r, c)] = mean;
                sys[(c, r)] = mean;
            }
        }
    }
    // A direction no term sees (a symmetric shape without the orientation term: the map and its mirror fit
    // alike) leaves the system singular: a small ridge then picks the least-norm blend of them.
    let v = match spd_solve(&sys, &rhs) {
        Some(v) => v,
        None => {
            let ridge = 1e-10 * (0..m).map(|p| sys[(p, p)]).sum::<f64>() / m as f64;
            for p in 0..m {
                sys[(p, p)] += ridge.max(f64::MIN_POSITIVE);
            }
            spd_solve(&sys, &rhs).ok_or_else(singular)?
        }
    };
    Ok(Mat::from_fn(kt, ks, |i, j| v[(idx(i, j), 0)]))
}

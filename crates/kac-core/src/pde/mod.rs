//! The chapter's PDE tools on a discrete operator pair (L, M). Sign: Δ = −∇·∇ (eq. 9.7), positive semidefinite;
//! L is its weak form, the stiffness matrix L_ij = ∫ ∇ψ_i·∇ψ_j (L ⪰ 0, libigl's `cotmatrix` is −L), and M the mass,
//! so "Δf = g" means L f = M g (§9.5, Galerkin FEM) and eigenpairs Δφ = λφ, λ ≥ 0, are L φ = λ M φ. Each tool
//! solves sparse symmetric positive definite systems by Cholesky (faer), reusing one symbolic analysis where a tool
//! factors several matrices on the same pattern.
//!
//! | tool | equation (Δ ⪰ 0) | discrete system |
//! |---|---|---|
//! | [`smooth`] | u + αΔu = ū (exercise 9.4, eq. 9.40) | (M + αL) u = M ū |
//! | [`heat_implicit`] | ∂u/∂t = −Δu (eq. 9.23, α = 1) | backward Euler (M + τL) u_{j+1} = M u_j, τ = t/steps |
//! | [`harmonic`] | Δu = 0 (§9.2.2), u given on a vertex set | L_II u_I = −L_IB u_B |
//! | [`labels`] | harmonic functions of one-hot labels (Zhu, Ghahramani & Lafferty 2003) | as above, argmax |
//! | [`poisson`] | Δf = g (§9.5) | L f = M g (Neumann: g made compatible, f of mean zero) |
//! | [`wave`] | ∂²u/∂t² = −Δu (example 9.7) | modal superposition over computed eigenpairs (as in eq. 9.4) |
//! | [`geodesic::heat_method`] | distance from heat (Crane, Weischedel & Wardetzky 2013) | two solves |
//!
//! So heat decays (e^{−λt} per mode), waves oscillate (cos √λ t per mode) and on the unit sphere a degree-l
//! spherical harmonic Y_l (Δ Y_l = l(l+1) Y_l) solves Poisson as f = Y_l / (l(l+1)).
//!
//! "Fixed" vertices (Dirichlet data) are eliminated, never replaced by identity rows.

pub mod geodesic;

use crate::descriptors::{graph::components, m_project, Basis, DescriptorError};
use crate::operators::sparse::{matvec, submatrix, Pattern, SparsePair};
use crate::spectrum::factor::{Cholesky, Symbolic};
use faer::{Mat, MatRef, Par};
use serde::Serialize;
use std::sync::Arc;

fn solve_err(message: String) -> DescriptorError {
    DescriptorError::Solve { message }
}

/// Solves K X = B for the rows not fixed, with X = G on the fixed rows: K_FF… eliminated, K_II X_I = B_I − K_IF G_F.
/// `values` are K's entries on `pattern`; the free block must be positive definite.
pub fn solve_spd(
    pattern: &Arc<Pattern>,
    values: &[f64],
    rhs: MatRef<'_, f64>,
    fixed: Option<(&[bool], MatRef<'_, f64>)>,
) -> Result<Mat<f64>, DescriptorError> {
    let n = pattern.n;
    let c = rhs.ncols();
    let Some((mask, g)) = fixed.filter(|(m, _)| m.iter().any(|&x| x)) else {
        let sym = Symbolic::analyze(pattern).map_err(solve_err)?;
        let chol = Cholesky::factor(&sym, values, Par::Seq).map_err(solve_err)?;
        let mut x = rhs.to_owned();
        chol.solve_in_place(x.as_mut(), Par::Seq);
        return Ok(x);
    };
    let free: Vec<usize> = (0..n).filter(|&i| !mask[i]).collect();
    let mut out = Mat::<f64>::zeros(n, c);
    for i in (0..n).filter(|&i| mask[i]) {
        for j in 0..c {
            out[(i, j)] = g[(i, j)];
        }
    }
    if free.is_empty() {
        return Ok(out);
    }
    let mut index = vec![usize::MAX; n];
    for (k, &i) in free.iter().enumerate() {
        index[i] = k;
    }
    let mut b = Mat::from_fn(free.len(), c, |k, j| rhs[(free[k], j)]);
    for f in (0..n).filter(|&i| mask[i]) {
        for pos in pattern.col_ptr[f]..pattern.col_ptr[f + 1] {
            let k = index[pattern.row_idx[pos]];
            if k != usize::MAX {
                for j in 0..c {
                    b[(k, j)] -= values[pos] * g[(f, j)];
                }
            }
        }
    }
    let (sub, vals) = submatrix(pattern, &[values], &free);
    let sub = Arc::new(sub);
    let sym = Symbolic::analyze(&sub).map_err(solve_err)?;
    let chol = Cholesky::factor(&sym, &vals[0], Par::Seq).map_err(solve_err)?;
    chol.solve_in_place(b.as_mut(), Par::Seq);
    for (k, &i) in free.iter().enumerate() {
        for j in 0..c {
            out[(i, j)] = b[(k, j)];
        }
    }
    Ok(out)
}

fn mass_times(pair: &SparsePair, u: MatRef<'_, f64>) -> Mat<f64> {
    let n = pair.n();
    let mut out = Mat::<f64>::zeros(n, u.ncols());
    let mut y = vec![0.0; n];
    for j in 0..u.ncols() {
        let x: Vec<f64> = u.col(j).iter().copied().collect();
        matvec(&pair.pattern, &pair.mass, &x, &mut y);
        out.col_mut(j).iter_mut().zip(&y).for_each(|(o, v)| *o = *v);
    }
    out
}

fn check_len(name: &'static str, got: usize, n: usize) -> Result<(), DescriptorError> {
    if got != n {
        return Err(DescriptorError::param(name, format!("{got} values for {n} vertices")));
    }
    Ok(())
}

fn check_positive(name: &'static str, v: f64) -> Result<(), DescriptorError> {
    if !(v > 0.0 && v.is_finite()) {
        return Err(DescriptorError::param(name, format!("{v} is not a positive finite number")));
    }
    Ok(())
}

/// Smoothing (exercise 9.4): the minimizer of ∫ (u − ū)² + α |∇u|² (eq. 9.40), i.e. u + αΔu = ū, discretely
/// (M + αL) u = M ū, for each column of `ubar`; each mode is damped by 1/(1 + αλ). With `fixed`, those vertices
/// keep ū (a clamped boundary); then, as L annihilates linear functions at interior vertices of a flat mesh
/// (linear precision), a linear ū is reproduced exactly.
pub fn smooth(
    pair: &SparsePair,
    ubar: MatRef<'_, f64>,
    alpha: f64,
    fixed: Option<&[bool]>,
) -> Result<Mat<f64>, DescriptorError> {
    check_len("u", ubar.nrows(), pair.n())?;
    check_positive("alpha", alpha)?;
    let k: Vec<f64> = pair.mass.iter().zip(&pair.stiffness).map(|(m, l)| m + alpha * l).collect();
    let rhs = mass_times(pair, ubar);
    solve_spd(&pair.pattern, &k, rhs.as_ref(), fixed.map(|f| (f, ubar)))
}

/// Heat diffusion ∂u/∂t = −Δu (eq. 9.23), M u̇ = −L u, by backward Euler: for each t, `steps` steps
/// (M + τL) u_{j+1} = M u_j with τ = t/steps from u₀ (one factorization per distinct τ, one symbolic analysis in
/// all). Each mode is multiplied by (1 + τλ)^{−steps} → e^{−λt}: it decays, never grows. Unconditionally stable;
/// first-order in τ.
pub fn heat_implicit(pair: &SparsePair, u0: &[f64], times: &[f64], steps: usize) -> Result<Mat<f64>, DescriptorError> {
    let n = pair.n();
    check_len("u0", u0.len(), n)?;
    crate::descriptors::check_times("times", times)?;
    if steps == 0 {
        return Err(DescriptorError::param("steps", "at least one step"));
    }
    let sym = Symbolic::analyze(&pair.pattern).map_err(solve_err)?;
    let mut out = Mat::<f64>::zeros(n, times.len());
    let mut mu = vec![0.0; n];
    for (c, &t) in times.iter().enumerate() {
        let tau = t / steps as f64;
        let k: Vec<f64> = pair.mass.iter().zip(&pair.stiffness).map(|(m, l)| m + tau * l).collect();
        let chol = Cholesky::factor(&sym, &k, Par::Seq).map_err(solve_err)?;
        let mut u = u0.to_vec();
        for _ in 0..steps {
            matvec(&pair.pattern, &pair.mass, &u, &mut mu);
            let mut x = Mat::from_fn(n, 1, |i, _| mu[i]);
            chol.solve_in_place(x.as_mut(), Par::Seq);
            u.iter_mut().enumerate().for_each(|(i, v)| *v = x[(i, 0)]);
        }
        out.col_mut(c).iter_mut().zip(&u).for_each(|(o, v)| *o = *v);
    }
    Ok(out)
}

/// Checks that every connected component of the operator holds a fixed vertex (else the free block is singular).
fn check_anchored(pair: &SparsePair, mask: &[bool], what: &str) -> Result<(), DescriptorError> {
    let (labels, count) = components(pair);
    let mut anchored = vec![false; count];
    for (i, &m) in mask.iter().enumerate() {
        if m {
            anchored[labels[i] as usize] = true;
        }
    }
    if let Some(c) = anchored.iter().position(|a| !a) {
        let v = labels.iter().position(|&l| l as usize == c).unwrap_or(0);
        return Err(DescriptorError::NotApplicable {
            message: format!("component {c} (containing vertex {v}) has no {what}; every component needs one"),
        });
    }
    Ok(())
}

fn mask_of(n: usize, known: &[(usize, f64)]) -> Result<(Vec<bool>, Vec<f64>), DescriptorError> {
    let mut mask = vec![false; n];
    let mut g = vec![0.0; n];
    for &(i, v) in known {
        if i >= n {
            return Err(DescriptorError::param("vertices", format!("vertex {i} does not exist ({n} vertices)")));
        }
        if !v.is_finite() {
            return Err(DescriptorError::param("values", format!("vertex {i} has value {v}")));
        }
        mask[i] = true;
        g[i] = v;
    }
    Ok((mask, g))
}

/// Harmonic interpolation: Δu = 0 away from the vertices with known values, u equal to them there. Reproduces
/// linear functions on flat meshes with the cotangent Laplacian (linear precision).
pub fn harmonic(pair: &SparsePair, known: &[(usize, f64)]) -> Result<Vec<f64>, DescriptorError> {
    let n = pair.n();
    let (mask, g) = mask_of(n, known)?;
    check_anchored(pair, &mask, "vertex with a known value")?;
    let gm = Mat::from_fn(n, 1, |i, _| g[i]);
    let x = solve_spd(&pair.pattern, &pair.stiffness, Mat::<f64>::zeros(n, 1).as_ref(), Some((&mask, gm.as_ref())))?;
    Ok(x.col(0).iter().copied().collect())
}

/// Semi-supervised labels (Zhu, Ghahramani & Lafferty 2003): one harmonic function per class, 1 on the class's
/// labelled vertices and 0 on the others'; each vertex takes the class of largest value.
#[derive(Debug, Clone, Serialize)]
pub struct Labels {
    pub classes: Vec<u32>,
    #[serde(skip)]
    pub label: Vec<u32>,
    /// n × C harmonic class scores (each row sums to 1 on a connected shape).
    #[serde(skip)]
    pub scores: Mat<f64>,
    pub counts: Vec<usize>,
}

pub fn labels(pair: &SparsePair, labelled: &[(usize, u32)]) -> Result<Labels, DescriptorError> {
    let n = pair.n();
    let mut classes: Vec<u32> = labelled.iter().map(|l| l.1).collect();
    classes.sort_unstable();
    classes.dedup();
    if classes.is_empty() {
        return Err(DescriptorError::param("labels", "no labelled vertices"));
    }
    let (mask, _) = mask_of(n, &labelled.iter().map(|&(i, _)| (i, 0.0)).collect::<Vec<_>>())?;
    check_anchored(pair, &mask, "labelled vertex")?;
    let mut g = Mat::<f64>::zeros(n, classes.len());
    for &(i, c) in labelled {
        let j = classes.binary_search(&c).unwrap_or(0);
        for q in 0..classes.len() {
            g[(i, q)] = if q == j { 1.0 } else { 0.0 };
        }
    }
    let scores = solve_spd(
        &pair.pattern,
        &pair.stiffness,
        Mat::<f64>::zeros(n, classes.len()).as_ref(),
        Some((&mask, g.as_ref())),
    )?;
    let label: Vec<u32> = (0..n)
        .map(|i| {
            let best = (0..classes.len()).max_by(|&a, &b| scores[(i, a)].total_cmp(&scores[(i, b)])).unwrap_or(0);
            classes[best]
        })
        .collect();
    let counts = classes.iter().map(|c| label.iter().filter(|l| *l == c).count()).collect();
    Ok(Labels { classes, label, scores, counts })
}

/// The solution of a Poisson problem Δf = g.
#[derive(Debug, Clone, Serialize)]
pub struct Poisson {
    #[serde(skip)]
    pub values: Vec<f64>,
    pub boundary: &'static str,
    /// Neumann: per component, the M-mean of g removed to make the problem solvable (∫ g = 0 is required);
    /// f is returned with M-mean zero on each component.
    pub removed_mean: Vec<f64>,
}

/// Poisson's equation Δf = g with Δ = −∇·∇ positive semidefinite: L f = M g (Galerkin FEM, §9.5). With
/// `dirichlet`, f takes the given values on those vertices; without, the problem is Neumann (compatible only
/// when g integrates to zero on each component: the mean is removed and reported).
pub fn poisson(pair: &SparsePair, g: &[f64], dirichlet: Option<&[(usize, f64)]>) -> Result<Poisson, DescriptorError> {
    let n = pair.n();
    check_len("g", g.len(), n)?;
    let (labels, count) = components(pair);
    let mut g = g.to_vec();
    let mut removed = Vec::new();
    let (mask, fixed, boundary) = match dirichlet {
        Some(known) => {
            let (mask, vals) = mask_of(n, known)?;
            check_anchored(pair, &mask, "Dirichlet vertex")?;
            (mask, vals, "dirichlet")
        }
        None => {
            removed = component_means(pair, &labels, count, &g);
            g.iter_mut().enumerate().for_each(|(i, v)| *v -= removed[labels[i] as usize]);
            // Pin the first vertex of each component; shifted to mean zero below.
            let mut mask = vec![false; n];
            let mut seen = vec![false; count];
            for i in 0..n {
                if !seen[labels[i] as usize] {
                    seen[labels[i] as usize] = true;
                    mask[i] = true;
                }
            }
            (mask, vec![0.0; n], "neumann")
        }
    };
    let gm = Mat::from_fn(n, 1, |i, _| g[i]);
    let rhs = mass_times(pair, gm.as_ref());
    let fm = Mat::from_fn(n, 1, |i, _| fixed[i]);
    let x = solve_spd(&pair.pattern, &pair.stiffness, rhs.as_ref(), Some((&mask, fm.as_ref())))?;
    let mut f: Vec<f64> = x.col(0).iter().copied().collect();
    if dirichlet.is_none() {
        let means = component_means(pair, &labels, count, &f);
        f.iter_mut().enumerate().for_each(|(i, v)| *v -= means[labels[i] as usize]);
    }
    Ok(Poisson { values: f, boundary, removed_mean: removed })
}

/// The M-weighted mean of `u` on each component: Σ (M1)_i u_i / Σ (M1)_i, M1 the row sums of M (the integral of
/// each hat function).
fn component_means(pair: &SparsePair, labels: &[u32], count: usize, u: &[f64]) -> Vec<f64> {
    let n = pair.n();
    let mut rows = vec![0.0; n];
    matvec(&pair.pattern, &pair.mass, &vec![1.0; n], &mut rows);
    let (mut s, mut w) = (vec![0.0; count], vec![0.0; count]);
    for i in 0..n {
        s[labels[i] as usize] += rows[i] * u[i];
        w[labels[i] as usize] += rows[i];
    }
    (0..count).map(|c| s[c] / w[c]).collect()
}

/// The wave equation ∂²u/∂t² = −Δu (example 9.7) from u₀ with velocity v₀, by modal superposition over the computed
/// eigenpairs (the chapter's (9.4)): u(t) = Σ_i [a_i cos(ω_i t) + b_i sin(ω_i t)/ω_i] φ_i with ω_i = √λ_i,
/// a = ΦᵀM u₀, b = ΦᵀM v₀ (zero modes: a_i + b_i t). Energy is conserved exactly; the part of u₀ outside the
/// basis is dropped (its M-norm is returned).
pub fn wave(
    basis: &Basis<'_>,
    pair: &SparsePair,
    u0: &[f64],
    v0: Option<&[f64]>,
    times: &[f64],
) -> Result<(Mat<f64>, f64), DescriptorError> {
    let n = basis.n();
    check_len("u0", u0.len(), n)?;
    if let Some(v) = v0 {
        check_len("v0", v.len(), n)?;
    }
    if times.iter().any(|t| !t.is_finite()) {
        return Err(DescriptorError::param("times", "times must be finite"));
    }
    let phi = basis.vectors;
    let (a, dropped) = m_project(basis, pair, u0);
    let b = v0.map(|v| m_project(basis, pair, v).0).unwrap_or_else(|| vec![0.0; basis.k()]);
    let w = Mat::from_fn(basis.k(), times.len(), |i, j| {
        let t = times[j];
        if basis.is_zero(i) {
            a[i] + b[i] * t
        } else {
            let om = basis.values[i].sqrt();
            a[i] * (om * t).cos() + b[i] * (om * t).sin() / om
        }
    });
    Ok((phi * w.as_ref(), dropped))
}

//! Hearing the shape: Weyl's law (Theorem 9.1 of the chapter this project follows) read backwards. The counting
//! function N(λ) = #{λ_i ≤ λ} of a d-dimensional domain Ω grows like ω_d |Ω| λ^{d/2} / (2π)^d, so the spectrum
//! tells the dimension (the growth exponent) and the measure |Ω| (length, area, volume); the second term tells the
//! boundary's measure |∂Ω| (a surface's boundary length, a solid's boundary area). Depends on nothing above
//! `spectrum`; the eigenvalues come in sorted, zero modes first.
//!
//! **The heat trace's terms** (Minakshisundaram & Pleijel 1949; Kac 1966; McKean & Singer 1967; Balian & Bloch
//! 1970, for the 3-D terms; Branson & Gilkey 1990, "The asymptotics of the Laplacian on a manifold with boundary",
//! for the signs): as t → 0,
//!
//! Z(t) = Σ e^{−λ_i t} ≈ |Ω| (4πt)^{−d/2} ± ¼ |∂Ω| (4πt)^{−(d−1)/2} + c₂ (4πt)^{−(d−2)/2} + c₃ (4πt)^{−(d−3)/2} + …
//!
//! with **+ for Neumann (free) boundaries and − for Dirichlet**, in every dimension; c₂, c₃ hold the curvature of
//! the boundary, its edges and corners (the same sign for both conditions at a polygon's corner or a polyhedron's
//! edge: (π² − α²)/(24πα) per corner of angle α, times the edge's length (4πt)^{−1/2} in 3-D; van den Berg &
//! Srisatkunarajah 1990) and the Euler characteristic (χ/6 on a closed surface). On a closed manifold only every
//! other term is there (powers (4πt)^{−d/2 + j}). A check: the unit cube's trace is (Σ_n e^{−π²n²t})³ =
//! ((4πt)^{−1/2} ∓ ½)³ + O(e^{−1/t}) = (4πt)^{−3/2} ∓ (3/2)(4πt)^{−1} + (3/4)(4πt)^{−1/2} ∓ 1/8: volume 1,
//! boundary area 4 · 3/2 = 6, the edge term 12 · (π² − π²/4)/(24π · π/2) = 3/4 for both conditions.
//!
//! The boundary term's sign comes from the zero modes: a spectrum with zero modes (a free boundary keeps the
//! constants, one per component) is read as Neumann (+), one without as Dirichlet (−). A spectrum with mixed
//! conditions (Dirichlet on part of the boundary) has no single sign: its boundary estimate means nothing.
//!
//! **Only k eigenvalues** are known: the computed trace Z_k(t) = Σ_{i ≤ k} e^{−λ_i t} is the Laplace–Stieltjes
//! transform of the counting function cut at λ_k. The expansion above is the transform of the smooth counting
//! function N̄(λ) = Σ_j c_j λ^{s_j} / ((4π)^{s_j} Γ(s_j + 1)), s_j the powers; cut at λ_k, each term becomes
//! c_j (4πt)^{−s_j} P(s_j, λ_k t), P the regularized lower incomplete gamma function (P(0, x) = 1: the constant is
//! a step at λ = 0), and the jump of N − N̄ at the cut adds δ e^{−λ_k t}. So the fit holds down to t ≈ 1/λ_k
//! instead of starting at t ≈ 8/λ_k, where the missing eigenvalues no longer weigh (a window that, at small k, lies
//! where the lower-order terms dominate: on the Neumann cube at k = 20 a fit there reads a volume of −2.96).
//!
//! Estimates:
//! - `measure` and `boundary_length`: Z_k fitted by least squares (relative residuals, 32 log-spaced times) with
//!   the terms above: the measure, the boundary term (left out where the domain is known to have none), then one
//!   more on a surface or a solid (c₂: curvature, corners, Euler characteristic, or a solid's edges), plus δ. It is
//!   fitted in three windows, t ∈ [1, 8], [3, 16] and [8, 40] over λ_k, and each estimate is taken from the window
//!   where its uncertainty is smallest (low windows rest on fewer terms, high ones on better resolved
//!   eigenvalues).
//! - The **uncertainty** of a fit is √(s² + w² + h²): s the least-squares standard error; w the largest change of
//!   the estimate when the window's ends are halved or doubled, when one term more is fitted, or (weighted 0.3)
//!   one term fewer; h the change when only the lower half of the non-zero eigenvalues is used, times
//!   1/(1 − 2^{−2/d}) (2 on a surface, 2.7 on a solid): a bias that grows in proportion to λ_k, as the finite
//!   elements' own error does (P1 eigenvalues are high by a relative O(λh²)), extrapolated from the half to the
//!   whole. `docs/weyl.md` measures how often estimate ± 2 × uncertainty covers the truth (the calibration).
//! - An estimate whose 2σ interval reaches zero (or, for the boundary, the wrong sign) is **not resolved** by the
//!   eigenvalues given: it is omitted (`None`) and listed in `unresolved` with its numbers (the analysis warns
//!   `weyl-estimate-omitted`).
//! - `dimension`: 2p from a fit log N ≈ p log λ + c + e λ^{−1/2} over the upper three quarters of the non-zero
//!   eigenvalues (N at the i-th eigenvalue, counted from 0 with the zero modes, taken as i + ½, the midpoint of
//!   the jump); e λ^{−1/2} takes up the boundary's second term, which alone biased a plain slope to 1.92 on the
//!   Neumann cube (k = 20). Its uncertainty: √(s² + (d₁ − d)² + (d_h − d)²), s the standard error of 2p, d₁ twice
//!   the plain slope over the same range, d_h the same fit over the lower half's upper three quarters. Where that
//!   is 1 or more (few eigenvalues: the correction is not determined) d₁ is reported instead, with the same
//!   uncertainty (which holds |d₁ − d|).
//! - `measure_leading`: from N ≈ a λ^{d/2} alone (the first term of the law) over the upper half;
//! - `string_length`: ℓ = π / √λ₁ (λ₁ the first non-zero eigenvalue), for curves only: exact for a string fixed
//!   at both ends or free at both ends.

use super::shape_dna::Measures;
use super::DescriptorError;
use serde::Serialize;
use std::f64::consts::PI;

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WeylEstimate {
    pub eigenvalues_used: usize,
    /// λ_k, the highest eigenvalue used (the estimates rest on it: callers judge its resolution).
    pub highest_eigenvalue: Option<f64>,
    pub zero_modes: usize,
    /// 2 × the growth exponent of the counting function (see the module's documentation); NaN where there are
    /// too few eigenvalues.
    pub dimension_estimate: f64,
    /// The dimension estimate's uncertainty (one σ; see the module's documentation); absent where the
    /// eigenvalues are too few to form it.
    pub dimension_uncertainty: Option<f64>,
    pub dimension: u8,
    pub measure_name: &'static str,
    /// Measured on the geometry (absent for graphs and point clouds).
    pub measure: Option<f64>,
    /// From the heat trace's first term (see the module's documentation), with its uncertainty (one σ); absent
    /// where the eigenvalues do not resolve it (then listed in `unresolved`).
    pub measure_estimate: Option<f64>,
    pub measure_uncertainty: Option<f64>,
    pub measure_estimate_leading: f64,
    /// The boundary's measure (length for a surface, area for a solid) from the heat trace's second term; absent
    /// for a domain without a boundary, where it is not known whether there is one (clouds, graphs, curves) and
    /// where the eigenvalues do not resolve it (then listed in `unresolved`).
    pub boundary_length_estimate: Option<f64>,
    pub boundary_length_uncertainty: Option<f64>,
    /// Curves only: π/√λ₁.
    pub string_length_estimate: Option<f64>,
    /// Estimates omitted because their 2σ interval reaches zero or the wrong sign: the eigenvalues given do not
    /// resolve them (more eigenvalues, or a finer mesh, would).
    pub unresolved: Vec<UnresolvedEstimate>,
    /// How `measure_estimate` and `boundary_length_estimate` were read.
    pub method: &'static str,
}

/// An estimate left out of a [`WeylEstimate`], with the numbers that did not resolve it.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct UnresolvedEstimate {
    /// The field it would have filled: `measure_estimate` or `boundary_length_estimate`.
    pub field: &'static str,
    /// The estimate and its one σ, as for the reported estimates; absent where no fit gave a finite one.
    pub estimate: Option<f64>,
    pub uncertainty: Option<f64>,
    /// Why it is left out.
    pub reason: &'static str,
}

/// The windows of the heat trace fit, t ∈ [a/λ_k, b/λ_k].
const WINDOWS: [(f64, f64); 3] = [(1.0, 8.0), (3.0, 16.0), (8.0, 40.0)];
/// Times per fit, log-spaced over the window.
const TIMES: usize = 32;
/// The weight of the change with one term fewer (a term left out biases the fit by about its own size, which
/// overstates what the fit with it still misses).
const FEWER_TERMS_WEIGHT: f64 = 0.3;

/// The regularized lower incomplete gamma function P(s, x) = γ(s, x)/Γ(s), with P(0, x) = 1 for the expansion's
/// constant term (a cut at λ_k leaves a constant whole): the operators' incomplete gamma otherwise.
fn gamma_p(s: f64, x: f64) -> f64 {
    if s <= 0.0 {
        return 1.0;
    }
    crate::operators::manifold::gamma_p(s, x)
}

/// A least-squares solution with the standard errors of its coefficients.
struct LeastSquares {
    coefficients: Vec<f64>,
    /// √(σ̂² [(XᵀX)⁻¹]_jj), σ̂² the residual variance; 0 where there are no more rows than coefficients.
    standard_errors: Vec<f64>,
}

/// Solves a small least-squares fit y ≈ X c (rows (x, y)), columns scaled to unit norm first.
fn least_squares(rows: &[(Vec<f64>, f64)]) -> Option<LeastSquares> {
    let p = rows.first()?.0.len();
    let n = rows.len();
    if n < p || p == 0 {
        return None;
    }
    let scale: Vec<f64> = (0..p).map(|j| rows.iter().map(|(x, _)| x[j] * x[j]).sum::<f64>().sqrt()).collect();
    if scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return None;
    }
    let mut a = faer::Mat::<f64>::zeros(n, p);
    let mut b = faer::Mat::<f64>::zeros(n, 1);
    for (i, (x, y)) in rows.iter().enumerate() {
        for j in 0..p {
            a[(i, j)] = x[j] / scale[j];
        }
        b[(i, 0)] = *y;
    }
    use faer::linalg::solvers::{DenseSolveCore, SolveLstsq};
    let c = a.qr().solve_lstsq(b.as_ref());
    let scaled: Vec<f64> = (0..p).map(|j| c[(j, 0)]).collect();
    let coefficients: Vec<f64> = scaled.iter().zip(&scale).map(|(c, s)| c / s).collect();
    if !coefficients.iter().all(|v| v.is_finite()) {
        return None;
    }
    let residual: f64 =
        rows.iter().map(|(x, y)| (y - x.iter().zip(&coefficients).map(|(u, v)| u * v).sum::<f64>()).powi(2)).sum();
    let standard_errors = if n > p {
        let variance = residual / (n - p) as f64;
        let normal = a.transpose() * &a;
        match normal.as_ref().llt(faer::Side::Lower) {
            Ok(llt) => {
                let inverse = llt.inverse();
                (0..p).map(|j| (variance * inverse[(j, j)].max(0.0)).sqrt() / scale[j]).collect()
            }
            Err(_) => vec![f64::INFINITY; p],
        }
    } else {
        vec![0.0; p]
    };
    Some(LeastSquares { coefficients, standard_errors })
}

/// The expansion's powers s_j of (4πt)^{−s_j} for `terms` terms: d/2, (d−1)/2, … with a boundary; d/2, d/2 − 1,
/// … without one (a closed manifold has only every other term).
fn powers(d: u8, boundary: bool, terms: usize) -> Vec<f64> {
    let step = if boundary { 0.5 } else { 1.0 };
    (0..terms).map(|j| f64::from(d) / 2.0 - step * j as f64).collect()
}

/// The terms fitted by default: the measure, the boundary term where there is one, and c₂ on surfaces and solids.
fn default_terms(d: u8, boundary: bool) -> usize {
    match (d, boundary) {
        (1, _) => 2,
        (_, true) => 3,
        (_, false) => 2,
    }
}

/// One heat trace fit.
#[derive(Debug, Clone, Copy)]
struct Fit {
    measure: f64,
    measure_error: f64,
    /// 4 × the second term's coefficient, with its sign (+ Neumann, − Dirichlet): where the boundary is fitted.
    boundary: Option<(f64, f64)>,
}

/// The heat trace fit over times in [`a`/λ_k, `b`/λ_k] (λ_k the last eigenvalue given; zero modes included,
/// each adds 1 to Z) with the given powers of (4πt) and the cut's jump δ e^{−λ_k t}.
fn heat_trace_fit(eigenvalues: &[f64], powers: &[f64], boundary: bool, (a, b): (f64, f64)) -> Option<Fit> {
    let lk = *eigenvalues.last()?;
    if !(lk > 0.0) {
        return None;
    }
    let (t0, t1) = (a / lk, b / lk);
    let rows: Vec<(Vec<f64>, f64)> = (0..TIMES)
        .map(|j| {
            let t = t0 * (t1 / t0).powf(j as f64 / (TIMES - 1) as f64);
            let z: f64 = eigenvalues.iter().map(|&l| (-l.max(0.0) * t).exp()).sum();
            let s = 4.0 * PI * t;
            let mut x: Vec<f64> =
                powers.iter().map(|&p| if p > 0.0 { s.powf(-p) * gamma_p(p, lk * t) } else { s.powf(-p) }).collect();
            x.push((-lk * t).exp());
            // Relative residuals: every time weighs alike.
            (x.iter().map(|v| v / z).collect(), 1.0)
        })
        .collect();
    let fit = least_squares(&rows)?;
    let (c, e) = (&fit.coefficients, &fit.standard_errors);
    Some(Fit {
        measure: c[0],
        measure_error: e[0],
        boundary: (boundary && powers.len() >= 2).then(|| (4.0 * c[1], 4.0 * e[1])),
    })
}

/// An estimate with its uncertainty from the fits in one window.
#[derive(Debug, Clone, Copy)]
struct WindowEstimate {
    measure: (f64, f64),
    boundary: Option<(f64, f64)>,
}

/// The fit in one window and its uncertainty (see the module's documentation): the standard error, the largest
/// change over the neighbouring fits, and the change with the lower half of the spectrum, extrapolated.
fn window_estimate(
    eigenvalues: &[f64],
    zeros: usize,
    d: u8,
    boundary: bool,
    window: (f64, f64),
) -> Option<WindowEstimate> {
    let terms = default_terms(d, boundary);
    let main = heat_trace_fit(eigenvalues, &powers(d, boundary, terms), boundary, window)?;
    let (a, b) = window;
    let neighbours: [((f64, f64), usize, f64); 6] = [
        ((a / 2.0, b), terms, 1.0),
        ((a * 2.0, b), terms, 1.0),
        ((a, b / 2.0), terms, 1.0),
        ((a, b * 2.0), terms, 1.0),
        ((a, b), terms + 1, 1.0),
        ((a, b), terms - 1, FEWER_TERMS_WEIGHT),
    ];
    let (mut wide_m, mut wide_b) = (0.0f64, 0.0f64);
    for (w, t, weight) in neighbours {
        if t == 0 {
            continue;
        }
        if let Some(f) = heat_trace_fit(eigenvalues, &powers(d, boundary, t), boundary, w) {
            wide_m = wide_m.max(weight * (f.measure - main.measure).abs());
            if let (Some(x), Some(y)) = (f.boundary, main.boundary) {
                wide_b = wide_b.max(weight * (x.0 - y.0).abs());
            }
        }
    }
    let nonzero = eigenvalues.len() - zeros;
    let half = &eigenvalues[..zeros + nonzero / 2];
    let grow = 1.0 / (1.0 - 0.5f64.powf(2.0 / f64::from(d)));
    let lower = heat_trace_fit(half, &powers(d, boundary, terms), boundary, window);
    let (half_m, half_b) = match lower {
        Some(f) => (
            grow * (f.measure - main.measure).abs(),
            f.boundary.zip(main.boundary).map_or(0.0, |(x, y)| grow * (x.0 - y.0).abs()),
        ),
        // Too few eigenvalues for the half: nothing resolves the estimate.
        None => (f64::INFINITY, f64::INFINITY),
    };
    let total = |s: f64, w: f64, h: f64| (s * s + w * w + h * h).sqrt();
    Some(WindowEstimate {
        measure: (main.measure, total(main.measure_error, wide_m, half_m)),
        boundary: main.boundary.map(|(x, e)| (x, total(e, wide_b, half_b))),
    })
}

pub use crate::spectrum::weyl_law::weyl_eigenvalue;

fn omega(d: u8) -> f64 {
    crate::spectrum::weyl_law::unit_ball_volume(d)
}

/// 2 × the exponent of a fit log N ≈ p log λ + c (+ e λ^{−1/2} with `corrected`), with its standard error.
fn counting_exponent(nz: &[(f64, f64)], corrected: bool) -> Option<(f64, f64)> {
    let rows: Vec<(Vec<f64>, f64)> = nz
        .iter()
        .map(|&(l, n)| {
            let mut x = vec![l.ln(), 1.0];
            if corrected {
                x.push(l.powf(-0.5));
            }
            (x, n.ln())
        })
        .collect();
    let f = least_squares(&rows)?;
    Some((2.0 * f.coefficients[0], 2.0 * f.standard_errors[0])).filter(|(p, s)| p.is_finite() && s.is_finite())
}

/// The dimension estimate and its uncertainty (see the module's documentation).
fn dimension_estimate(nz: &[(f64, f64)]) -> (f64, Option<f64>) {
    let upper = &nz[nz.len() / 4..];
    let lower_half = &nz[..nz.len() / 2];
    let corrected = (upper.len() > 3).then(|| counting_exponent(upper, true)).flatten();
    let plain = counting_exponent(upper, false);
    let half = (lower_half.len() >= 8).then(|| counting_exponent(&lower_half[lower_half.len() / 4..], true)).flatten();
    match (corrected, plain, half) {
        (Some((d, s)), Some((d1, _)), Some((dh, _))) => {
            let u = (s * s + (d1 - d).powi(2) + (dh - d).powi(2)).sqrt();
            // Where the correction is not determined (σ ≥ 1) the plain slope, as good a guess, inside the interval.
            let estimate = if u < MAX_CORRECTED_DIMENSION_UNCERTAINTY { d } else { d1 };
            (estimate, Some(u).filter(|u| u.is_finite()))
        }
        // Too few for the correction: the plain slope over the upper half, without an uncertainty.
        _ => (counting_exponent(&nz[nz.len() / 2..], false).map_or(f64::NAN, |(p, _)| p), None),
    }
}

/// Above this uncertainty the corrected dimension estimate gives way to the plain slope.
const MAX_CORRECTED_DIMENSION_UNCERTAINTY: f64 = 1.0;

pub fn weyl_estimate(eigenvalues: &[f64], zero_tol: f64, measures: &Measures) -> Result<WeylEstimate, DescriptorError> {
    let zeros = eigenvalues.iter().take_while(|&&l| l <= zero_tol).count();
    let nz: Vec<(f64, f64)> = eigenvalues.iter().enumerate().skip(zeros).map(|(i, &l)| (l, i as f64 + 0.5)).collect();
    if nz.len() < 4 {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!("Weyl estimates need at least 4 non-zero eigenvalues; {} computed", nz.len()),
        });
    }
    let (dimension_estimate, dimension_uncertainty) = dimension_estimate(&nz);
    let upper = &nz[nz.len() / 2..];
    let d = if (1..=3).contains(&measures.dimension) { measures.dimension } else { 2 };
    let dh = d as f64 / 2.0;
    let to_measure = |a: f64| a * (2.0 * PI).powi(d as i32) / omega(d);
    let lead_rows: Vec<(Vec<f64>, f64)> = upper.iter().map(|(l, n)| (vec![l.powf(dh)], *n)).collect();
    let measure_estimate_leading = least_squares(&lead_rows).map_or(f64::NAN, |f| to_measure(f.coefficients[0]));
    // The boundary term is fitted unless the domain is known to have no boundary, and reported only where it is
    // known to have one; its sign is + with zero modes (a free boundary), − without (Dirichlet).
    use super::shape_dna::BoundaryCondition;
    let fit_boundary = measures.has_boundary != Some(false);
    let sign = match measures.condition {
        Some(BoundaryCondition::Neumann) => 1.0,
        Some(BoundaryCondition::Dirichlet | BoundaryCondition::Mixed) => -1.0,
        None if zeros > 0 => 1.0,
        None => -1.0,
    };
    // Under mixed conditions the two signs' parts of the boundary cannot be told apart: no boundary estimate.
    let report_boundary = measures.has_boundary == Some(true) && measures.condition != Some(BoundaryCondition::Mixed);
    let windows: Vec<WindowEstimate> = if nz.len() >= 8 {
        WINDOWS.iter().filter_map(|&w| window_estimate(eigenvalues, zeros, d, fit_boundary, w)).collect()
    } else {
        vec![]
    };
    let finite = |(x, u): (f64, f64)| x.is_finite() && u.is_finite();
    let measure = windows.iter().map(|w| w.measure).filter(|&m| finite(m)).min_by(|a, b| a.1.total_cmp(&b.1));
    let boundary = windows
        .iter()
        .filter_map(|w| w.boundary)
        .map(|(x, u)| (sign * x, u))
        .filter(|&b| finite(b))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|_| report_boundary);
    let mut unresolved = vec![];
    // Resolved: the 2σ interval stays above zero (for the boundary: on the side its condition gives). An estimate
    // no fit gave (too few eigenvalues, every window's fit failed) is listed too: nothing is left out silently.
    let too_few = nz.len() < 8;
    let mut resolved = |field: &'static str, wanted: bool, e: Option<(f64, f64)>| match e {
        Some((x, u)) if x > 2.0 * u => Some((x, u)),
        Some((x, u)) => {
            let reason = "its 2σ interval reaches zero or the wrong sign";
            unresolved.push(UnresolvedEstimate { field, estimate: Some(x), uncertainty: Some(u), reason });
            None
        }
        None if wanted => {
            let reason = if too_few {
                "fewer than 8 non-zero eigenvalues: no fit"
            } else {
                "no window's fit gave a finite estimate and uncertainty"
            };
            unresolved.push(UnresolvedEstimate { field, estimate: None, uncertainty: None, reason });
            None
        }
        None => None,
    };
    let measure = resolved("measure_estimate", true, measure);
    let boundary = resolved("boundary_length_estimate", report_boundary, boundary);
    let measure_name = match d {
        1 => "length",
        2 => "area",
        _ => "volume",
    };
    Ok(WeylEstimate {
        eigenvalues_used: nz.len(),
        highest_eigenvalue: eigenvalues.last().copied(),
        zero_modes: zeros,
        dimension_estimate,
        dimension_uncertainty,
        dimension: d,
        measure_name,
        measure: measures.measure(),
        measure_estimate: measure.map(|m| m.0),
        measure_uncertainty: measure.map(|m| m.1),
        measure_estimate_leading,
        boundary_length_estimate: boundary.map(|b| b.0),
        boundary_length_uncertainty: boundary.map(|b| b.1),
        string_length_estimate: (d == 1).then(|| PI / nz[0].0.sqrt()),
        unresolved,
        method: "heat trace Z(t) = Σ e^{−λt} of the k eigenvalues fitted as Σ_j c_j (4πt)^{−s_j} P(s_j, λ_k t) + δ \
                 e^{−λ_k t}, s_j = d/2, (d−1)/2, …: c_0 = |Ω|, c_1 = ±¼|∂Ω| (+ Neumann, − Dirichlet: the \
                 operator's condition, else + with zero modes), P the regularized incomplete gamma function (the trace cut at λ_k), over \
                 t in [1, 8], [3, 16] or [8, 40] / λ_k (the window with the smallest uncertainty); uncertainty \
                 (1σ): standard error, the largest change with the window's ends halved or doubled and one term \
                 more or fewer, and the change with the lower half of the spectrum extrapolated (docs/weyl.md)",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// P(s, x) against closed forms: P(1, x) = 1 − e^{−x}, P(2, x) = 1 − e^{−x}(1 + x), P(½, x) = erf √x
    /// (erf 1 = 0.8427007929497149, Abramowitz & Stegun table 7.1), P(3/2, x) = P(½, x) − 2√(x/π) e^{−x}.
    #[test]
    fn incomplete_gamma_matches_closed_forms() {
        for x in [0.01, 0.3, 1.0, 2.5, 7.0, 30.0] {
            assert!((gamma_p(1.0, x) - (1.0 - (-x).exp())).abs() < 1e-13, "{x}");
            assert!((gamma_p(2.0, x) - (1.0 - (-x).exp() * (1.0 + x))).abs() < 1e-13, "{x}");
            let p32 = gamma_p(0.5, x) - 2.0 * (x / PI).sqrt() * (-x).exp();
            assert!((gamma_p(1.5, x) - p32).abs() < 1e-13, "{x}");
        }
        assert!((gamma_p(0.5, 1.0) - 0.842_700_792_949_714_9).abs() < 1e-14);
        assert_eq!(gamma_p(0.0, 3.0), 1.0);
    }

    /// The unit cube's exact spectra, π²(l² + m² + n²) with l, m, n ≥ 1 (Dirichlet) or ≥ 0 (Neumann): the
    /// volume is heard within its stated 2σ and the boundary area 6 too, with the right sign for each condition.
    #[test]
    fn heat_trace_fit_hears_the_cube_with_either_condition() {
        for start in [1usize, 0] {
            let mut ev: Vec<f64> = (start..12)
                .flat_map(|l| (start..12).flat_map(move |m| (start..12).map(move |n| (l * l + m * m + n * n) as f64)))
                .map(|s| PI * PI * s)
                .collect();
            ev.sort_by(f64::total_cmp);
            let meas = Measures { dimension: 3, volume: Some(1.0), has_boundary: Some(true), ..Default::default() };
            let w = weyl_estimate(&ev[..201 - start], 1e-9, &meas).unwrap();
            let (v, dv) = (w.measure_estimate.unwrap(), w.measure_uncertainty.unwrap());
            assert!((v - 1.0).abs() < 2.0 * dv && dv < 0.15, "{start}: volume {v} ± {dv}");
            let (s, ds) = (w.boundary_length_estimate.unwrap(), w.boundary_length_uncertainty.unwrap());
            assert!((s - 6.0).abs() < 2.0 * ds, "{start}: boundary {s} ± {ds}");
            let (dim, du) = (w.dimension_estimate, w.dimension_uncertainty.unwrap());
            assert!((dim - 3.0).abs() < 2.0 * du, "{start}: dimension {dim} ± {du}");
        }
    }

    /// The operator's condition gives the boundary term's sign, whatever the zero modes say: the Dirichlet unit
    /// square's exact spectrum with a zero mode beside it (a closed component the boundary does not anchor) is
    /// still heard as a square of perimeter 4 when the condition is given, and as a wrong-signed boundary, left
    /// out, when it is read from the zero modes. Mixed conditions give no boundary estimate; too few eigenvalues
    /// for a fit are listed as unresolved, with the reason.
    #[test]
    fn the_boundary_sign_follows_the_condition_given() {
        use super::super::shape_dna::BoundaryCondition;
        let mut ev: Vec<f64> =
            (1..40).flat_map(|m| (1..40).map(move |n| PI * PI * (m * m + n * n) as f64)).collect::<Vec<_>>();
        ev.sort_by(f64::total_cmp);
        ev.truncate(200);
        ev.insert(0, 0.0);
        let square = |condition| Measures {
            dimension: 2,
            area: Some(1.0),
            has_boundary: Some(true),
            condition,
            ..Default::default()
        };
        let w = weyl_estimate(&ev, 1e-9, &square(Some(BoundaryCondition::Dirichlet))).unwrap();
        let (b, db) = (w.boundary_length_estimate.expect("the perimeter"), w.boundary_length_uncertainty.unwrap());
        assert!((b - 4.0).abs() < 2.0 * db, "perimeter {b} ± {db}");
        let read = weyl_estimate(&ev, 1e-9, &square(None)).unwrap();
        assert!(read.boundary_length_estimate.is_none(), "read as Neumann: {read:?}");
        assert!(read.unresolved.iter().any(|u| u.field == "boundary_length_estimate"));
        let mixed = weyl_estimate(&ev, 1e-9, &square(Some(BoundaryCondition::Mixed))).unwrap();
        assert!(mixed.boundary_length_estimate.is_none() && mixed.unresolved.is_empty(), "{mixed:?}");
        assert!(mixed.measure_estimate.is_some());
        let few = weyl_estimate(&ev[1..7], 1e-9, &square(Some(BoundaryCondition::Dirichlet))).unwrap();
        assert!(few.measure_estimate.is_none());
        let reasons: Vec<&str> = few.unresolved.iter().map(|u| u.reason).collect();
        assert_eq!(reasons, ["fewer than 8 non-zero eigenvalues: no fit"; 2], "{few:?}");
    }
}

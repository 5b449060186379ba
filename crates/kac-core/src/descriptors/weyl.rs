//! Hearing the shape: Weyl's law (Theorem 9.1 of the chapter this project follows) read backwards. The counting
//! function N(λ) = #{λ_i ≤ λ} of a d-dimensional domain Ω grows like ω_d |Ω| λ^{d/2} / (2π)^d, so the spectrum
//! tells the dimension (the growth exponent) and the measure |Ω| (length, area, volume). For d = 2 the second
//! term, ∓ |∂Ω| √λ / (4π) (Dirichlet −, Neumann +), tells the boundary length too.
//!
//! Estimates:
//! - `dimension`: 2 × the slope of log N against log λ over the upper half of the non-zero eigenvalues (N taken at
//!   the i-th, counted from 0 with the zero modes, as i + ½, the midpoint of the jump);
//! - `measure` and `boundary_length`: from the heat trace Z(t) = Σ e^{−λ_i t} of the computed eigenvalues, fitted
//!   by least squares as Z ≈ |Ω| (4πt)^{−d/2} ± ¼ |∂Ω| (4πt)^{−(d−1)/2} + Σ_{j=2..d} c_j (4πt)^{−(d−j)/2} (the
//!   heat trace's expansion: Weyl's law and its second term, Dirichlet −, Neumann +; the c_j hold the curvature,
//!   edge, corner and Euler-characteristic terms),
//!   over 24 log-spaced times in [8/λ_k, 40/λ_k]: late enough that the missing eigenvalues weigh e^{−8} of the
//!   first term, early enough that the expansion holds. The counting function's own fit is too rough for the
//!   second term (on the Dirichlet unit square, k = 200, it read a boundary of 0.41 for 4); the heat trace smooths
//!   it. The boundary term is left out for a domain known to have no boundary, and its length reported only for
//!   one known to have one (a mesh with open edges, a solid). Each
//!   comes with an uncertainty: the change of the estimate when the window is halved ([8/λ_k, 20/λ_k]);
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
    pub dimension_estimate: f64,
    pub dimension: u8,
    pub measure_name: &'static str,
    /// Measured on the geometry (absent for graphs and point clouds).
    pub measure: Option<f64>,
    /// From the heat trace's first term (see the module's documentation); with its uncertainty.
    pub measure_estimate: Option<f64>,
    pub measure_uncertainty: Option<f64>,
    pub measure_estimate_leading: f64,
    /// The boundary's measure (length for a surface, area for a solid) from the heat trace's second term; absent
    /// for a domain without a boundary and where it is not known whether there is one (clouds, graphs, curves).
    pub boundary_length_estimate: Option<f64>,
    pub boundary_length_uncertainty: Option<f64>,
    /// Curves only: π/√λ₁.
    pub string_length_estimate: Option<f64>,
    /// How `measure_estimate` and `boundary_length_estimate` were read.
    pub method: &'static str,
}

/// The heat trace fit over times in [8/λ_k, `upper`/λ_k]: (measure, boundary measure when fitted).
fn heat_trace_fit(eigenvalues: &[f64], d: u8, boundary: bool, upper: f64) -> Option<(f64, Option<f64>)> {
    let lk = *eigenvalues.last()?;
    if !(lk > 0.0) {
        return None;
    }
    let (t0, t1) = (8.0 / lk, upper / lk);
    let dh = d as f64 / 2.0;
    let rows: Vec<(Vec<f64>, f64)> = (0..24)
        .map(|j| {
            let t = t0 * (t1 / t0).powf(j as f64 / 23.0);
            let z: f64 = eigenvalues.iter().map(|&l| (-l.max(0.0) * t).exp()).sum();
            let s = 4.0 * PI * t;
            // The expansion's powers (4πt)^{−(d−j)/2}, j = 0..=d: the volume, the boundary (j = 1, left out
            // without one), then the curvature, corner and edge terms down to the constant.
            let x: Vec<f64> = (0..=d).filter(|&j| boundary || j != 1).map(|j| s.powf(-(dh - 0.5 * j as f64))).collect();
            (x, z)
        })
        .collect();
    let c = least_squares(&rows)?;
    Some((c[0], boundary.then(|| 4.0 * c[1].abs())))
}

pub use crate::spectrum::weyl_law::weyl_eigenvalue;

fn omega(d: u8) -> f64 {
    crate::spectrum::weyl_law::unit_ball_volume(d)
}

/// Solves the small normal equations of a least-squares fit y ≈ X c (columns of X given as functions).
fn least_squares(rows: &[(Vec<f64>, f64)]) -> Option<Vec<f64>> {
    let p = rows.first()?.0.len();
    if rows.len() < p {
        return None;
    }
    let mut a = faer::Mat::<f64>::zeros(rows.len(), p);
    let mut b = faer::Mat::<f64>::zeros(rows.len(), 1);
    for (i, (x, y)) in rows.iter().enumerate() {
        for j in 0..p {
            a[(i, j)] = x[j];
        }
        b[(i, 0)] = *y;
    }
    let qr = a.qr();
    use faer::linalg::solvers::SolveLstsq;
    let c = qr.solve_lstsq(b.as_ref());
    let c: Vec<f64> = (0..p).map(|j| c[(j, 0)]).collect();
    c.iter().all(|v| v.is_finite()).then_some(c)
}

pub fn weyl_estimate(eigenvalues: &[f64], zero_tol: f64, measures: &Measures) -> Result<WeylEstimate, DescriptorError> {
    let zeros = eigenvalues.iter().take_while(|&&l| l <= zero_tol).count();
    let nz: Vec<(f64, f64)> = eigenvalues.iter().enumerate().skip(zeros).map(|(i, &l)| (l, i as f64 + 0.5)).collect();
    if nz.len() < 4 {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!("Weyl estimates need at least 4 non-zero eigenvalues; {} computed", nz.len()),
        });
    }
    let upper = &nz[nz.len() / 2..];
    let slope_rows: Vec<(Vec<f64>, f64)> = upper.iter().map(|(l, n)| (vec![l.ln(), 1.0], n.ln())).collect();
    let dimension_estimate = least_squares(&slope_rows).map_or(f64::NAN, |c| 2.0 * c[0]);
    let d = if (1..=3).contains(&measures.dimension) { measures.dimension } else { 2 };
    let dh = d as f64 / 2.0;
    let to_measure = |a: f64| a * (2.0 * PI).powi(d as i32) / omega(d);
    let lead_rows: Vec<(Vec<f64>, f64)> = upper.iter().map(|(l, n)| (vec![l.powf(dh)], *n)).collect();
    let measure_estimate_leading = least_squares(&lead_rows).map_or(f64::NAN, |c| to_measure(c[0]));
    // The heat trace of every computed eigenvalue (zero modes included: each adds 1 to Z).
    // The boundary term is fitted unless the domain is known to have no boundary, and reported only where it is
    // known to have one.
    let fit_boundary = measures.has_boundary != Some(false);
    let report = |f: Option<(f64, Option<f64>)>| f.map(|(m, b)| (m, b.filter(|_| measures.has_boundary == Some(true))));
    let wide = report(if nz.len() >= 8 { heat_trace_fit(eigenvalues, d, fit_boundary, 40.0) } else { None });
    let narrow = report(if nz.len() >= 8 { heat_trace_fit(eigenvalues, d, fit_boundary, 20.0) } else { None });
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
        dimension: d,
        measure_name,
        measure: measures.measure(),
        measure_estimate: wide.map(|w| w.0),
        measure_uncertainty: wide.zip(narrow).map(|(w, n)| (w.0 - n.0).abs()),
        measure_estimate_leading,
        boundary_length_estimate: wide.and_then(|w| w.1),
        boundary_length_uncertainty: wide.zip(narrow).and_then(|(w, n)| Some((w.1? - n.1?).abs())),
        string_length_estimate: (d == 1).then(|| PI / nz[0].0.sqrt()),
        method: "heat trace Z(t) = Σ e^{−λt} fitted as |Ω|(4πt)^{−d/2} ± ¼|∂Ω|(4πt)^{−(d−1)/2} + Σ_j c_j \
                 (4πt)^{−(d−j)/2} over t in [8/λ_k, 40/λ_k]; uncertainty: the change with [8/λ_k, 20/λ_k]",
    })
}

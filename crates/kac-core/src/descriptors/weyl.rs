//! Hearing the shape: Weyl's law (Theorem 9.1 of the chapter this project follows) read backwards. The counting
//! function N(λ) = #{λ_i ≤ λ} of a d-dimensional domain Ω grows like ω_d |Ω| λ^{d/2} / (2π)^d, so the spectrum
//! tells the dimension (the growth exponent) and the measure |Ω| (length, area, volume). For d = 2 the second
//! term, ∓ |∂Ω| √λ / (4π) (Dirichlet −, Neumann +), tells the boundary length too.
//!
//! Estimates (least squares over the computed non-zero eigenvalues, N taken at each eigenvalue as i + ½ for the
//! i-th of them counted from 0 with zero modes, the midpoint of the jump):
//! - `dimension`: 2 × the slope of log N against log λ over the upper half of the eigenvalues;
//! - `measure`: from the fit N ≈ a λ^{d/2} + b λ^{(d−1)/2} + c with d the shape's dimension: |Ω| = a (2π)^d / ω_d;
//!   for d = 2, |∂Ω| ≈ 4π |b|;
//! - `measure_leading`: from N ≈ a λ^{d/2} alone (the first term of the law);
//! - `string_length`: ℓ = π / √λ₁ (λ₁ the first non-zero eigenvalue): exact for a string fixed at both ends or
//!   free at both ends.

use super::shape_dna::Measures;
use super::DescriptorError;
use serde::Serialize;
use std::f64::consts::PI;

#[derive(Debug, Clone, Serialize)]
pub struct WeylEstimate {
    pub eigenvalues_used: usize,
    pub zero_modes: usize,
    pub dimension_estimate: f64,
    pub dimension: u8,
    pub measure_name: &'static str,
    /// Measured on the geometry (absent for graphs and point clouds).
    pub measure: Option<f64>,
    pub measure_estimate: Option<f64>,
    pub measure_estimate_leading: f64,
    /// d = 2 only: |b|·4π from the second term.
    pub boundary_length_estimate: Option<f64>,
    pub string_length_estimate: f64,
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
    let two_rows: Vec<(Vec<f64>, f64)> =
        nz.iter().map(|(l, n)| (vec![l.powf(dh), l.powf(dh - 0.5), 1.0], *n)).collect();
    let two = if nz.len() >= 8 { least_squares(&two_rows) } else { None };
    let measure_name = match d {
        1 => "length",
        2 => "area",
        _ => "volume",
    };
    Ok(WeylEstimate {
        eigenvalues_used: nz.len(),
        zero_modes: zeros,
        dimension_estimate,
        dimension: d,
        measure_name,
        measure: measures.measure(),
        measure_estimate: two.as_ref().map(|c| to_measure(c[0])),
        measure_estimate_leading,
        boundary_length_estimate: if d == 2 { two.as_ref().map(|c| 4.0 * PI * c[1].abs()) } else { None },
        string_length_estimate: PI / nz[0].0.sqrt(),
    })
}

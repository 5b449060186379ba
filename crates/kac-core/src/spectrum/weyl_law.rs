//! Weyl's law read forward (Theorem 9.1 of the chapter): the counting function of a d-dimensional domain Ω grows
//! like N(λ) ≈ ω_d |Ω| λ^{d/2} / (2π)^d, ω_d the volume of the unit ball in R^d. The eigensolver places its shift
//! with it; the descriptors normalize shape-DNA by it and read it backwards (`descriptors::weyl`).

use std::f64::consts::PI;

/// ω_d, the volume of the unit ball in R^d (d = 1, 2, 3).
pub fn unit_ball_volume(dimension: u8) -> f64 {
    match dimension {
        1 => 2.0,
        2 => PI,
        _ => 4.0 * PI / 3.0,
    }
}

/// The eigenvalue at which Weyl's leading term N(λ) = ω_d |Ω| λ^{d/2} / (2π)^d reaches `count`:
/// λ ≈ (2π)² (count / (ω_d |Ω|))^{2/d}. A first guess, not an estimate to report.
pub fn weyl_eigenvalue(dimension: u8, measure: f64, count: f64) -> f64 {
    let d = f64::from(dimension);
    (2.0 * PI).powi(2) * (count / (unit_ball_volume(dimension) * measure)).powf(2.0 / d)
}

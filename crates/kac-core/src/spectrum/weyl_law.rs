//! Weyl's law read forward (Theorem 9.1 of the chapter): the counting function of a d-dimensional domain Ω grows
//! like N(λ) ≈ ω_d |Ω| λ^{d/2} / (2π)^d, ω_d the volume of the unit ball in R^d. The eigensolver places its shift
//! with it; the descriptors normalize shape-DNA by it and read it backwards (`descriptors::weyl`).

use std::f64::consts::PI;

/// ω_d, the volume of the unit ball in R^d (d = 0, 1, 2, 3).
pub fn unit_ball_volume(dimension: u8) -> f64 {
    match dimension {
        0 => 1.0,
        1 => 2.0,
        2 => PI,
        _ => 4.0 * PI / 3.0,
    }
}

/// Weyl's counting function: the number of eigenvalues up to λ that the law predicts for a d-dimensional domain
/// of measure |Ω|, N(λ) ≈ ω_d |Ω| λ^{d/2} / (2π)^d, with, where the boundary's measure |∂Ω| is given, the second
/// term ∓ ω_{d−1} |∂Ω| λ^{(d−1)/2} / (4 (2π)^{d−1}) (− Dirichlet, + Neumann; Ivrii 1980), i.e. ∓ |∂Ω|√λ / 4π for a
/// plane domain and ∓ |∂Ω| λ / 16π for a solid.
pub fn weyl_count(dimension: u8, measure: f64, lambda: f64, boundary: Option<(f64, bool)>) -> f64 {
    let d = f64::from(dimension);
    let l = lambda.max(0.0);
    let lead = unit_ball_volume(dimension) * measure * l.powf(d / 2.0) / (2.0 * PI).powf(d);
    match boundary {
        Some((b, dirichlet)) => {
            let second =
                unit_ball_volume(dimension - 1) * b * l.powf((d - 1.0) / 2.0) / (4.0 * (2.0 * PI).powf(d - 1.0));
            if dirichlet {
                lead - second
            } else {
                lead + second
            }
        }
        None => lead,
    }
}

/// The eigenvalue at which Weyl's leading term N(λ) = ω_d |Ω| λ^{d/2} / (2π)^d reaches `count`:
/// λ ≈ (2π)² (count / (ω_d |Ω|))^{2/d}. A first guess, not an estimate to report.
pub fn weyl_eigenvalue(dimension: u8, measure: f64, count: f64) -> f64 {
    let d = f64::from(dimension);
    (2.0 * PI).powi(2) * (count / (unit_ball_volume(dimension) * measure)).powf(2.0 / d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit square with Dirichlet conditions: λ = π²(a² + b²), a, b ≥ 1; the two-term law tracks the exact
    /// count far better than the leading term.
    #[test]
    fn two_term_count_follows_the_dirichlet_square() {
        let mut values: Vec<f64> =
            (1..200).flat_map(|a| (1..200).map(move |b| PI * PI * (a * a + b * b) as f64)).collect();
        values.sort_by(f64::total_cmp);
        let lambda = values[2000];
        let exact = values.iter().filter(|&&v| v <= lambda).count() as f64;
        let lead = weyl_count(2, 1.0, lambda, None);
        let two = weyl_count(2, 1.0, lambda, Some((4.0, true)));
        assert!((two - exact).abs() < 0.02 * exact, "{two} vs {exact}");
        assert!((two - exact).abs() < 0.2 * (lead - exact).abs(), "{two} {lead} {exact}");
        // The interval [0, π] with Dirichlet ends: λ = j², N(λ) = ⌊√λ⌋ ≈ √λ − 1/2.
        assert!((weyl_count(1, PI, 100.0, Some((2.0, true))) - 9.5).abs() < 1e-12);
    }
}

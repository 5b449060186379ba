//! Continuum eigenvalues from a sequence of uniformly refined meshes (Richardson extrapolation). With mesh sizes
//! h, h/2, h/4 and λ(h) = λ + C h^p + …, the observed order is p = log₂((λ_h − λ_{h/2}) / (λ_{h/2} − λ_{h/4}))
//! and λ ≈ λ_{h/4} + (λ_{h/4} − λ_{h/2}) / (2^p − 1). The nominal order is 2k for elements of degree k on smooth
//! problems; near re-entrant corners the eigenfunctions are singular and the observed order falls (on an
//! L-shaped domain to 4/3 for the first eigenvalue), which is why it is reported. The error estimate is the
//! larger of the gap between the extrapolations at the observed and the nominal order and a tenth of the
//! correction itself: where the asymptotic regime holds these are small, where it does not they say so. Where no
//! order can be observed (two levels, or differences that do not shrink monotonically) it is at least the whole
//! correction, and with three or more levels at least the last level's change.

use serde::Serialize;

/// One extrapolated eigenvalue.
#[derive(Debug, Clone, Serialize)]
pub struct Extrapolated {
    /// The estimate of the continuum eigenvalue.
    pub value: f64,
    /// The estimate of its error (absolute).
    pub error_estimate: f64,
    /// The order observed from the last three levels (`None` with two levels, or where the differences do not
    /// decrease monotonically: then the nominal order was used).
    pub observed_order: Option<f64>,
    /// The order used: the observed one, clamped to [0.5, 2 × nominal], or the nominal one.
    pub order_used: f64,
}

/// Extrapolates each eigenvalue from its values on levels of mesh sizes h, h/2, h/4, … (`levels[l][i]`: the i-th
/// eigenvalue on level l; every level holds at least as many as the first), with the elements' nominal order.
pub fn richardson(levels: &[Vec<f64>], nominal: f64) -> Vec<Extrapolated> {
    let l = levels.len();
    let count = levels.iter().map(Vec::len).min().unwrap_or(0);
    (0..count)
        .map(|i| {
            let fine = levels[l - 1][i];
            if l < 2 {
                return Extrapolated {
                    value: fine,
                    error_estimate: f64::NAN,
                    observed_order: None,
                    order_used: nominal,
                };
            }
            let mid = levels[l - 2][i];
            let at = |p: f64| fine + (fine - mid) / (2f64.powf(p) - 1.0);
            let observed = (l >= 3)
                .then(|| {
                    let (d1, d2) = (levels[l - 3][i] - mid, mid - fine);
                    (d1 * d2 > 0.0 && d2 != 0.0).then(|| (d1 / d2).log2())
                })
                .flatten()
                .filter(|p| p.is_finite());
            let order_used = observed.map_or(nominal, |p| p.clamp(0.5, 2.0 * nominal));
            let value = at(order_used);
            // Where no order could be observed (two levels, or differences that do not shrink monotonically:
            // the levels are not yet in the asymptotic regime) nothing says the nominal order holds: the estimate
            // is then at least the whole correction, and with three or more levels the last change too.
            let unobserved = match (observed, l) {
                (Some(_), _) => 0.0,
                (None, 2) => (value - fine).abs(),
                (None, _) => (value - fine).abs().max((fine - mid).abs()),
            };
            let error_estimate = (value - at(nominal)).abs().max(0.1 * (value - fine).abs()).max(unobserved);
            Extrapolated { value, error_estimate, observed_order: observed, order_used }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_power_law_is_extrapolated_exactly() {
        // λ(h) = 10 + 3h² − h^{4/3}·0 on h = 1, 1/2, 1/4: observed order 2, the limit 10.
        let levels: Vec<Vec<f64>> =
            [1.0, 0.5, 0.25].iter().map(|h: &f64| vec![10.0 + 3.0 * h * h, 5.0 + 2.0 * h.powf(4.0 / 3.0)]).collect();
        let e = richardson(&levels, 2.0);
        assert!((e[0].value - 10.0).abs() < 1e-12 && (e[0].observed_order.unwrap() - 2.0).abs() < 1e-12);
        // A singular-corner order (4/3) is observed and used.
        assert!((e[1].value - 5.0).abs() < 1e-12 && (e[1].order_used - 4.0 / 3.0).abs() < 1e-12, "{:?}", e[1]);
        assert!(e[1].error_estimate > 0.01, "far from the nominal order: the estimate says so");
    }

    #[test]
    fn without_an_observed_order_the_estimate_covers_the_last_change() {
        // Differences that change sign (1 → 1.5 → 1.4): no order is observed; the estimate is at least the last
        // change, 0.1. With two levels it is at least the whole correction.
        let e = richardson(&[vec![1.0], vec![1.5], vec![1.4]], 2.0);
        assert!(e[0].observed_order.is_none() && e[0].error_estimate >= 0.1 - 1e-15, "{:?}", e[0]);
        let e = richardson(&[vec![1.0], vec![1.3]], 2.0);
        assert!((e[0].error_estimate - 0.1).abs() < 1e-12, "{:?}", e[0]);
    }
}

//! Distances to rows kept in single precision, and the bound on what their rounding changes.

use super::*;

/// The rounding bound of one row stored in single precision: ‖x − x₃₂‖₁ ≤ 2⁻²⁴‖x‖₁ for values in single
/// precision's normal range (6.0·10⁻⁸ covers 2⁻²⁴ and the rounding of the sum), infinite when a value is outside it
/// (such a row is always re-ranked from its exact values).
pub(crate) fn rounding_bound(values: &[f64], stored: &[f32]) -> f32 {
    let normal =
        values.iter().all(|v| *v == 0.0 || (v.abs() >= f32::MIN_POSITIVE as f64 && v.abs() <= f32::MAX as f64));
    if !normal {
        return f32::INFINITY;
    }
    let l1: f64 = stored.iter().map(|v| v.abs() as f64).sum();
    (6.0e-8 * l1 * (1.0 + 1e-6)) as f32
}

/// The distance from a query to a row kept in single precision, computed in double precision (four partial sums,
/// so that the compiler may use vector lanes).
pub(crate) fn approx_distance(q: &[f64], x: &[f32], metric: Metric) -> f64 {
    let term = |a: f64, b: f32| -> f64 {
        let d = a - b as f64;
        match metric {
            Metric::Euclidean => d * d,
            Metric::Manhattan => d.abs(),
            Metric::Canberra => {
                let s = a.abs() + (b as f64).abs();
                if s > 0.0 {
                    d.abs() / s
                } else {
                    0.0
                }
            }
        }
    };
    let mut acc = [0.0f64; 4];
    let (qc, xc) = (q.chunks_exact(4), x.chunks_exact(4));
    let (qr, xr) = (qc.remainder(), xc.remainder());
    for (a, b) in qc.zip(xc) {
        for l in 0..4 {
            acc[l] += term(a[l], b[l]);
        }
    }
    let tail: f64 = qr.iter().zip(xr).map(|(a, &b)| term(*a, b)).sum();
    let sum = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
    if metric == Metric::Euclidean {
        sum.sqrt()
    } else {
        sum
    }
}

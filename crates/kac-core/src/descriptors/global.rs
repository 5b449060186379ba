//! Global descriptors for retrieval: one fixed-length vector per shape, read from its eigenpairs, that a search
//! index can hold and compare by Euclidean distance. Both are distributions over the shape, written as their
//! quantile functions sampled at fixed levels, so that the Euclidean distance of two descriptors is (up to a
//! constant) the 2-Wasserstein distance of the two distributions (for one-dimensional distributions W₂ is the L²
//! distance of the quantile functions).
//!
//! - [`heat_distribution`]: the distribution over the surface of the heat kernel signature at fixed times, after
//!   the shape is scaled to unit measure; the "temperature distribution" descriptor of Fang, Sun and Ramani
//!   ("Temperature distribution descriptor for robust 3D shape retrieval", CVPR Workshops 2011), made
//!   scale-invariant by the unit-measure normalization and relative to the heat trace.
//! - [`gps_d2`]: the distribution of distances between pairs of points in the global point signature embedding
//!   (Rustamov, "Laplace–Beltrami eigenfunctions for deformation invariant shape representation", SGP 2007, which
//!   uses the D2 distribution of these distances for retrieval).
//!
//! Both are invariant to a uniform scaling of the shape, to isometries (which leave the spectrum and the
//! eigenfunctions' values unchanged), to the eigenvectors' signs and to rotations within an eigenspace (the heat
//! kernel signature is a function of the eigenspaces; a GPS distance sums over them with equal weights, except
//! where the last eigenspace kept is cut by the truncation).

use super::{Basis, DescriptorError};
use serde::Serialize;

/// Quantile levels sampled per distribution: (j + ½)/Q for j = 0..Q.
pub const HEAT_QUANTILES: usize = 16;
/// Times at which the heat distribution is taken, in units of the shape scaled to unit measure: log-spaced from
/// [`HEAT_TIMES`]`.0` to `.1`. On a surface of unit area the 50th non-zero eigenvalue is about 4π·50 ≈ 630 (Weyl's
/// law), so at the smallest time e^{-λ t} has fallen to about 0.05 where the computed spectrum ends; at the largest
/// only the first modes of elongated shapes remain. Six times and 16 levels (96 values) ranked the retrieval
/// benchmark's class-level collection as well as more of either (docs/retrieval.md).
pub const HEAT_TIMES: (f64, f64, usize) = (0.005, 2.0, 6);
/// Quantile levels of the GPS distance distribution.
pub const GPS_QUANTILES: usize = 32;
/// Non-zero eigenpairs the global point signature is built from (fewer when fewer were computed).
pub const GPS_DIMENSIONS: usize = 20;
/// Points sampled for the pairwise distances (all pairs among them): chosen by their share of the shape's
/// measure, deterministically, so that the same shape always gives the same descriptor.
pub const GPS_POINTS: usize = 400;

/// A global descriptor and what it was computed from.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct GlobalDescriptor {
    /// The fixed-length vector.
    pub values: Vec<f64>,
    /// Non-zero eigenpairs used.
    pub eigenpairs: usize,
    /// The shape's measure (area, volume or length) it was scaled by.
    pub measure: f64,
}

/// Per-vertex weights of a mass matrix (its row sums: the lumped mass), from its values on a symmetric pattern.
pub fn lumped_weights(pair: &crate::operators::sparse::SparsePair) -> Vec<f64> {
    let p = &pair.pattern;
    (0..p.n).map(|j| pair.mass[p.col_ptr[j]..p.col_ptr[j + 1]].iter().sum()).collect()
}

fn check(basis: &Basis<'_>, weights: &[f64], measure: f64, dimension: u8) -> Result<(usize, f64), DescriptorError> {
    if weights.len() != basis.n() {
        return Err(DescriptorError::param("weights", format!("{} weights for {} vertices", weights.len(), basis.n())));
    }
    if !(measure > 0.0 && measure.is_finite()) {
        return Err(DescriptorError::NotApplicable {
            message: format!("a global descriptor needs the shape's measure, which is {measure}"),
        });
    }
    if !(1..=3).contains(&dimension) {
        return Err(DescriptorError::NotApplicable {
            message: "a global descriptor scales the shape to unit measure, which a graph does not have".into(),
        });
    }
    if weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) || weights.iter().sum::<f64>() <= 0.0 {
        return Err(DescriptorError::param("weights", "the mass weights must be finite, non-negative, not all zero"));
    }
    let zeros = basis.values.iter().take_while(|&&l| l <= basis.zero_tol).count();
    if basis.values.len() <= zeros {
        return Err(DescriptorError::TooFewEigenpairs { message: "no non-zero eigenvalue was computed".into() });
    }
    // λ scales as measure^(-2/d) under a uniform scaling: this factor makes the eigenvalues those of the shape
    // scaled to unit measure.
    Ok((zeros, measure.powf(2.0 / dimension as f64)))
}

/// Weighted quantiles of `values` at the levels (j + ½)/q: the smallest value whose cumulative weight reaches the
/// level. `values` and `weights` are of equal length, weights non-negative with a positive sum.
pub fn weighted_quantiles(values: &[f64], weights: &[f64], q: usize) -> Vec<f64> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let total: f64 = weights.iter().sum();
    let mut out = Vec::with_capacity(q);
    let (mut acc, mut i) = (0.0, 0);
    for j in 0..q {
        let level = (j as f64 + 0.5) / q as f64 * total;
        while i + 1 < order.len() && acc + weights[order[i]] < level {
            acc += weights[order[i]];
            i += 1;
        }
        out.push(values[order[i]]);
    }
    out
}

/// The heat distribution: for each time t of [`HEAT_TIMES`] (of the shape scaled to unit measure), the
/// distribution over the shape (weighted by `weights`, the lumped mass) of log(h(x, t) / Z(t)), where h is the heat
/// kernel signature Σ e^{-λ'ᵢ t} φ'ᵢ(x)² of the scaled shape and Z(t) = Σ e^{-λ'ᵢ t} its heat trace (the signature's
/// mean over the scaled shape), sampled at [`HEAT_QUANTILES`] levels: `HEAT_TIMES.2 × HEAT_QUANTILES` values, time
/// by time. Zero modes enter the sums (one per component: the constant's share); the pairs are cut at a cluster's
/// end ([`whole_clusters`]). `measure` is the shape's area, volume or length, `dimension` 2, 3 or 1.
pub fn heat_distribution(
    basis: &Basis<'_>,
    weights: &[f64],
    measure: f64,
    dimension: u8,
) -> Result<GlobalDescriptor, DescriptorError> {
    // Whole eigenspaces only: a sum of φ² over part of one depends on the basis the solver chose in it.
    let k = whole_clusters(basis.values, basis.k());
    let cut = Basis::new(&basis.values[..k], basis.vectors.subcols(0, k), basis.zero_tol);
    heat_distribution_of_pairs(&cut, weights, measure, dimension)
}

/// [`heat_distribution`] over every pair of `basis`, wherever it ends.
pub fn heat_distribution_of_pairs(
    basis: &Basis<'_>,
    weights: &[f64],
    measure: f64,
    dimension: u8,
) -> Result<GlobalDescriptor, DescriptorError> {
    let (zeros, scale) = check(basis, weights, measure, dimension)?;
    let (t0, t1, count) = HEAT_TIMES;
    let times: Vec<f64> = (0..count).map(|i| t0 * (t1 / t0).powf(i as f64 / (count - 1) as f64)).collect();
    let (n, k) = (basis.n(), basis.k());
    let mut values = Vec::with_capacity(count * HEAT_QUANTILES);
    let mut h = vec![0.0; n];
    for &t in &times {
        // exp(-λ' t) with λ' = λ·scale; φ'² = φ²·measure.
        let decay: Vec<f64> = basis.values.iter().map(|&l| (-(l.max(0.0)) * scale * t).exp()).collect();
        let trace: f64 = decay.iter().sum();
        for (x, hx) in h.iter_mut().enumerate() {
            let mut s = 0.0;
            for (i, d) in decay.iter().enumerate().take(k) {
                let p = basis.vectors[(x, i)];
                s += d * p * p;
            }
            // Floored: a vertex on a nodal set of every mode kept would give log 0.
            *hx = (s * measure / trace).max(1e-12).ln();
        }
        values.extend(weighted_quantiles(&h, weights, HEAT_QUANTILES));
    }
    Ok(GlobalDescriptor { values, eigenpairs: k - zeros, measure })
}

/// Eigenvalues closer than this (relatively) are one cluster: a basis of their eigenspace is not determined.
pub const CLUSTER_GAP: f64 = 0.01;

/// How many of the ascending `values` to keep, about `want`, ending at a cluster's end: the cut is moved up past a
/// cluster it would split; where the values end (the last cluster may go on beyond them), it goes before the last
/// cluster unless that is all there is. A sum over whole eigenspaces with equal weights does not depend on the
/// basis chosen in each.
pub fn whole_clusters(values: &[f64], want: usize) -> usize {
    let n = values.len();
    // Value i belongs to value i − 1's cluster.
    let joined = |i: usize| values[i] <= values[i - 1] * (1.0 + CLUSTER_GAP);
    let mut d = want.min(n).max(1);
    while d < n && joined(d) {
        d += 1;
    }
    if d == n {
        let mut start = n - 1;
        while start > 0 && joined(start) {
            start -= 1;
        }
        if start > 0 {
            d = start;
        }
    }
    d
}

/// The GPS D2 distribution: the global point signature GPS(x) = (φ'ᵢ(x)/√λ'ᵢ) of the shape scaled to unit
/// measure, over the first [`GPS_DIMENSIONS`] non-zero eigenpairs, or as many more or fewer as end a cluster of
/// eigenvalues ([`whole_clusters`]) (GPS · measure^(1/2 − 1/d): on a surface the signature is scale-invariant as it
/// stands), the Euclidean distances between all pairs of [`GPS_POINTS`] points chosen by their share of the
/// measure, and the distribution of those distances sampled at [`GPS_QUANTILES`] levels.
pub fn gps_d2(
    basis: &Basis<'_>,
    weights: &[f64],
    measure: f64,
    dimension: u8,
) -> Result<GlobalDescriptor, DescriptorError> {
    let (zeros, _) = check(basis, weights, measure, dimension)?;
    let d = whole_clusters(&basis.values[zeros..], GPS_DIMENSIONS);
    let unit = measure.powf(0.5 - 1.0 / dimension as f64);
    let n = basis.n();
    // Points at the levels (j + ½)/P of the cumulative measure, in vertex order: a deterministic sample whose
    // density follows the measure (a vertex holding more than 1/P of it is taken more than once).
    let total: f64 = weights.iter().sum();
    let points = GPS_POINTS.min(n.max(2));
    let mut picked = Vec::with_capacity(points);
    let (mut acc, mut x) = (0.0, 0);
    for j in 0..points {
        let level = (j as f64 + 0.5) / points as f64 * total;
        while x + 1 < n && acc + weights[x] < level {
            acc += weights[x];
            x += 1;
        }
        picked.push(x);
    }
    let inv: Vec<f64> = (zeros..zeros + d).map(|i| unit / basis.values[i].sqrt()).collect();
    let gps: Vec<Vec<f64>> =
        picked.iter().map(|&x| (0..d).map(|c| basis.vectors[(x, zeros + c)] * inv[c]).collect()).collect();
    let mut dist = Vec::with_capacity(points * (points - 1) / 2);
    for a in 0..points {
        for b in a + 1..points {
            dist.push(gps[a].iter().zip(&gps[b]).map(|(p, q)| (p - q) * (p - q)).sum::<f64>().sqrt());
        }
    }
    let ones = vec![1.0; dist.len()];
    Ok(GlobalDescriptor { values: weighted_quantiles(&dist, &ones, GPS_QUANTILES), eigenpairs: d, measure })
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    /// The unit circle of n equal arcs (a 1-D "shape" of length 2π): eigenpairs in closed form, λ = m², φ = cos,
    /// sin / √π, the constant 1/√(2π).
    fn circle(n: usize, modes: usize) -> (Vec<f64>, Mat<f64>, Vec<f64>) {
        let mut values = vec![0.0];
        let mut cols: Vec<Vec<f64>> = vec![vec![1.0 / (2.0 * std::f64::consts::PI).sqrt(); n]];
        for m in 1..=modes {
            for f in [f64::cos, f64::sin] {
                values.push((m * m) as f64);
                cols.push(
                    (0..n)
                        .map(|x| {
                            f(m as f64 * 2.0 * std::f64::consts::PI * x as f64 / n as f64) / std::f64::consts::PI.sqrt()
                        })
                        .collect(),
                );
            }
        }
        let v = Mat::from_fn(n, cols.len(), |i, j| cols[j][i]);
        (values, v, vec![2.0 * std::f64::consts::PI / n as f64; n])
    }

    #[test]
    fn the_cut_never_splits_a_cluster() {
        let v = [1.0, 2.0, 2.001, 2.002, 5.0, 5.0, 9.0];
        assert_eq!(whole_clusters(&v, 2), 4, "moved up past the cluster at 2");
        assert_eq!(whole_clusters(&v, 4), 4);
        assert_eq!(whole_clusters(&v, 5), 6);
        // Where the values end, the last cluster may be incomplete: cut before it.
        assert_eq!(whole_clusters(&v[..6], 5), 4);
        assert_eq!(whole_clusters(&v, 20), 6);
        assert_eq!(whole_clusters(&[3.0, 3.0, 3.0], 2), 3, "all of one cluster: all of it");
    }

    #[test]
    fn weighted_quantiles_of_a_uniform_sample_are_its_order_statistics() {
        let v: Vec<f64> = (0..100).rev().map(|i| i as f64).collect();
        let q = weighted_quantiles(&v, &vec![1.0; 100], 4);
        assert_eq!(q, vec![12.0, 37.0, 62.0, 87.0]);
        // A weight moves the quantiles toward its value.
        let mut w = vec![1.0; 100];
        w[0] = 300.0; // the value 99
        assert_eq!(weighted_quantiles(&v, &w, 4)[1], 99.0);
    }

    /// On the circle the heat kernel signature is the same at every point (it is homogeneous), so every quantile
    /// of log(h / Z) is log(1) = 0; scaling the circle changes nothing (λ by 1/s², φ² by 1/s, the length by s).
    #[test]
    fn a_homogeneous_shape_has_a_flat_heat_distribution_at_every_scale() {
        let (values, v, w) = circle(256, 10);
        let b = Basis::new(&values, v.as_ref(), 1e-9);
        let d = heat_distribution(&b, &w, 2.0 * std::f64::consts::PI, 1).unwrap();
        assert_eq!(d.values.len(), HEAT_TIMES.2 * HEAT_QUANTILES);
        assert!(d.values.iter().all(|x| x.abs() < 1e-9), "{:?}", &d.values[..4]);
        let s: f64 = 3.0;
        let scaled: Vec<f64> = values.iter().map(|l| l / (s * s)).collect();
        let vs = Mat::from_fn(v.nrows(), v.ncols(), |i, j| v[(i, j)] / s.sqrt());
        let ws: Vec<f64> = w.iter().map(|x| x * s).collect();
        let g = gps_d2(&Basis::new(&values, v.as_ref(), 1e-9), &w, 2.0 * std::f64::consts::PI, 1).unwrap();
        let gs = gps_d2(&Basis::new(&scaled, vs.as_ref(), 1e-9), &ws, 2.0 * std::f64::consts::PI * s, 1).unwrap();
        for (a, b) in g.values.iter().zip(&gs.values) {
            assert!((a - b).abs() < 1e-12 * a.abs().max(1.0), "{a} vs {b}");
        }
    }

    /// GPS distances on the circle in closed form: with modes 1..M, |GPS(x) − GPS(y)|² = Σ_m (2/(π m²))(1 − cos mθ)
    /// for the angle θ between x and y, times 1/(2π) once the circle is scaled to unit length; the largest quantile
    /// lies near the antipodal distance.
    #[test]
    fn gps_distances_on_the_circle_match_the_closed_form() {
        let (values, v, w) = circle(400, 10);
        let b = Basis::new(&values, v.as_ref(), 1e-9);
        let g = gps_d2(&b, &w, 2.0 * std::f64::consts::PI, 1).unwrap();
        let at = |theta: f64| -> f64 {
            (2.0 * std::f64::consts::PI).powf(-0.5)
                * (1..=10)
                    .map(|m| 2.0 / (std::f64::consts::PI * (m * m) as f64) * (1.0 - (m as f64 * theta).cos()))
                    .sum::<f64>()
                    .sqrt()
        };
        let antipodal = at(std::f64::consts::PI);
        let top = *g.values.last().unwrap();
        assert!(top <= antipodal + 1e-12 && top > 0.97 * antipodal, "{top} vs {antipodal}");
        assert!(g.values.windows(2).all(|p| p[0] <= p[1]));
        // The median pair is a quarter turn apart (θ uniform on [0, π]).
        let median = (g.values[15] + g.values[16]) / 2.0;
        assert!((median - at(std::f64::consts::FRAC_PI_2)).abs() < 0.02 * antipodal, "{median}");
    }

    #[test]
    fn a_graph_or_a_bad_weight_is_refused() {
        let (values, v, w) = circle(16, 2);
        let b = Basis::new(&values, v.as_ref(), 1e-9);
        assert!(matches!(heat_distribution(&b, &w, 1.0, 0), Err(DescriptorError::NotApplicable { .. })));
        assert!(gps_d2(&b, &w[..3], 1.0, 1).is_err());
        let mut bad = w.clone();
        bad[2] = f64::NAN;
        assert!(heat_distribution(&b, &bad, 1.0, 1).is_err());
    }
}

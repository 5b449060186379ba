//! Point-cloud Laplacians. Neighbourhoods come from a k-d tree (kiddo). Each point gets a tangent frame (PCA of
//! its k nearest neighbours) and a local area A_i: the area of its Voronoi cell among the neighbours projected
//! to the tangent plane. These areas are what keeps the operator right on randomly sampled clouds: the
//! quadrature weight of each point is the area it stands for, not 1/n.
//!
//! Belkin–Niyogi heat-kernel weights (eq. 9.39), written symmetrically with the areas as quadrature weights:
//! `L_ij = −A_i A_j e^{−|x_i − x_j|²/4t} / (4π t² m)` for |x_i − x_j| < r, `L_ii = −Σ_j L_ij`, `M = diag(A_i)`,
//! where m = 1 − e^{−a}(1 + a), a = r²/4t, corrects for the kernel's truncation at r (the second moment of the
//! truncated Gaussian), so that (M⁻¹L f)_i → Δf(x_i) as t → 0 (Δ = −∇·∇, positive semidefinite). Defaults: the
//! time follows the local spacing: each point gets t_i (about 5h² where the sampling is uniform, h the mean
//! distance to the nearest neighbour, [`UNIFORM_TIME`]; larger where the local areas are larger, and reaching the 4th neighbour),
//! a pair t_ij = (t_i + t_j)/2, which keeps L symmetric and its quadratic form the Dirichlet energy to leading
//! order (the Gaussian's second moment does not depend on t); r = 3√t_ij. With `Knn` neighbourhoods the sum runs over the symmetrized k-nearest-neighbour
//! graph instead, t defaults to (d_k/3)² (d_k the mean distance to the k-th neighbour, so the graph reaches about
//! 3√t) and m is that of r = 3√t, an approximation where the k-th neighbour is nearer or farther. Sign: L positive semidefinite. Units: L
//! dimensionless·area, M area.

use super::sparse::{assemble, Kernel, SparsePair};
use super::{CloudParams, Neighbourhood, OperatorError};
use crate::geometry::{vec3, Point};
use kiddo::SquaredEuclidean;
use rayon::prelude::*;
use std::sync::Arc;

// The point-cloud geometry the operator stands on (`crate::point_cloud`), reachable from the operator too.
pub use crate::point_cloud::{local_areas, local_frames, voronoi_cell, Cell, Neighbourhoods};

/// The default time of a uniform sample, in units of h² (h the mean distance to the nearest neighbour). Smaller
/// times leave too few points under the kernel and the eigenvalues fall below the surface's, larger ones smooth
/// them upward (an O(t) bias): on random samples of the unit sphere λ₂..₄ were 1.94–1.98 with 4h², 1.98–2.01 with
/// 5h² and 1.99–2.02 with 6h² at 2,000 points, 1.97–1.98, 2.000–2.003 and 2.010–2.012 at 200,000. 5h² was
/// chosen there and confirmed elsewhere: a torus within 0.7 % of a fine mesh (4h²: 2.0 %), and clouds sampled from
/// six shared meshes nearer their meshes' shape-DNA in 11 of 12 cases.
pub const UNIFORM_TIME: f64 = 5.0;

/// The Belkin–Niyogi pair and the parameters it used (h, t, radius, k, total area).
pub fn belkin_niyogi_pair(
    points: &[Point],
    params: &CloudParams,
) -> Result<(SparsePair, serde_json::Map<String, serde_json::Value>), OperatorError> {
    let nb = Neighbourhoods::knn(points, params.k)?;
    let n = points.len();
    // The mean distance to the j-th nearest neighbour (0-based).
    let mean_to = |j: usize| {
        (0..n).map(|i| vec3::norm(vec3::sub(points[nb.of(i)[j] as usize], points[i]))).sum::<f64>() / n as f64
    };
    let (h, dk) = (mean_to(0), mean_to(nb.k - 1));
    if !(h > 0.0) {
        return Err(OperatorError::InvalidParameter {
            name: "points",
            message: "the points have no spacing (all coincide)".into(),
        });
    }
    let frames = local_frames(points, &nb);
    let areas = local_areas(points, &nb, &frames);
    let given_t = match params.t {
        Some(t) if t > 0.0 && t.is_finite() => Some(t),
        Some(t) => {
            return Err(OperatorError::InvalidParameter { name: "t", message: format!("{t} is not a positive time") })
        }
        None => None,
    };
    let given_r = match params.radius {
        Some(r) if r > 0.0 && r.is_finite() => Some(r),
        Some(r) => {
            return Err(OperatorError::InvalidParameter {
                name: "radius",
                message: format!("{r} is not a positive radius"),
            })
        }
        None => None,
    };
    // A kernel narrower than the spacing joins no point to any other: every point its own component and every
    // eigenvalue 0, which is no spectrum of the surface. Refused, naming the least that reaches a neighbour.
    if let Some(t) = given_t {
        let reach = given_r.unwrap_or(3.0 * t.sqrt());
        if reach < h {
            return Err(OperatorError::InvalidParameter {
                name: "t",
                message: format!(
                    "t = {t:e} gives a kernel of radius {reach:.3e}, below the mean spacing h = {h:.3e}: no point \
                     has a neighbour under it; give t ≥ (h/3)² = {:.3e} (the default is about {UNIFORM_TIME}h²)",
                    (h / 3.0).powi(2)
                ),
            });
        }
    }
    if let Some(r) = given_r {
        if r < h {
            return Err(OperatorError::InvalidParameter {
                name: "radius",
                message: format!("radius {r:.3e} is below the mean spacing h = {h:.3e}: no point has a neighbour"),
            });
        }
    }
    let distance_to = |i: usize, j: usize| vec3::norm(vec3::sub(points[nb.of(i)[j.min(nb.k - 1)] as usize], points[i]));
    // Each point's time t_i (a pair uses t_ij = (t_i + t_j)/2, so the kernel stays symmetric and its quadratic
    // form is the Dirichlet energy to leading order wherever t varies slowly).
    let (times, bandwidth): (Vec<f64>, &str) = match (given_t, params.neighbourhood) {
        (Some(t), _) => (vec![t; n], "given"),
        // k-NN neighbourhoods: the k-th neighbour at about 3√t on average, as the radius mode's default.
        (None, Neighbourhood::Knn) => (vec![dk * dk / 9.0; n], "global: (d_k/3)²"),
        // Local: 5h² where the sampling is uniform, following the local spacing where it is not. The spacing is
        // read from the local areas averaged over each neighbourhood (t_i = c·Ā_i, with c = 5h²/mean A so a
        // uniform sample keeps 5h²), and every kernel reaches the point's 4th nearest neighbour, or sparse parts
        // fall apart into pieces of their own. Times above 100× the median (a stray point far away, with
        // denoising off) are capped.
        (None, Neighbourhood::Radius) => {
            let mean_area = areas.iter().sum::<f64>() / n as f64;
            let c = UNIFORM_TIME * h * h / mean_area.max(f64::MIN_POSITIVE);
            let mut t: Vec<f64> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let nbh = nb.of(i);
                    let smooth =
                        (areas[i] + nbh.iter().map(|&j| areas[j as usize]).sum::<f64>()) / (nbh.len() + 1) as f64;
                    let d4 = distance_to(i, 3);
                    (c * smooth).max(d4 * d4 / 9.0)
                })
                .collect();
            let mut sorted = t.clone();
            sorted.sort_by(f64::total_cmp);
            let cap = 100.0 * sorted[n / 2];
            for x in &mut t {
                *x = x.min(cap);
            }
            (t, "local: t_i = max(c·Ā_i, d₄²/9), c = 5h²/mean A; pairs within 3√t_ij, t_ij = (t_i + t_j)/2")
        }
    };
    // The pairs the kernel joins, estimated per point as k (r / d_k,i)² with its own k-th-neighbour distance (a
    // dense cluster holds more pairs than the mean spacing says) — refused above the limit before the search (a
    // given t or radius far above the spacing).
    let radius_of = |ti: f64| given_r.unwrap_or(3.0 * ti.sqrt());
    let expected: f64 = (0..n)
        .map(|i| {
            let local = distance_to(i, nb.k - 1).max(1e-3 * dk).max(f64::MIN_POSITIVE);
            0.5 * nb.k as f64 * (radius_of(times[i]) / local).powi(2)
        })
        .sum();
    if params.neighbourhood == Neighbourhood::Radius && expected > super::manifold::MAX_PAIRS {
        return Err(OperatorError::InvalidParameter {
            name: "radius",
            message: format!(
                "a kernel of radius up to {:.4e} joins about {expected:.2e} pairs of the {n} points, above the limit \
                 of {:.0e}; give a smaller time or radius",
                times.iter().map(|&t| radius_of(t)).fold(0.0, f64::max),
                super::manifold::MAX_PAIRS
            ),
        });
    }
    // The second moment of the kernel truncated at r corrects for the truncation: a = r²/4t, the same 9/4 for
    // every pair under the default radius 3√t_ij.
    let moment = |a: f64| 1.0 - (-a).exp() * (1.0 + a);
    let default_moment = moment(9.0 / 4.0);
    let weight = |i: usize, j: usize, d2: f64| {
        let t = 0.5 * (times[i] + times[j]);
        let m = given_r.map_or(default_moment, |r| moment(r * r / (4.0 * t)));
        areas[i] * areas[j] * (-d2 / (4.0 * t)).exp() / (4.0 * std::f64::consts::PI * t * t * m)
    };
    let off: Vec<(u32, u32, [f64; 2])> = match params.neighbourhood {
        // Each pair within 3√t_ij (or the given radius) is found by the point with the larger time (ties: the
        // smaller index), whose search radius covers it, and emitted once from there.
        Neighbourhood::Radius => (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                let reach = radius_of(times[i]);
                let found = nb.tree.within_unsorted::<SquaredEuclidean>(&points[i], reach * reach);
                let times = &times;
                found.into_iter().filter_map(move |f| {
                    let j = f.item as usize;
                    let mine = times[i] > times[j] || (times[i] == times[j] && i < j);
                    let r = radius_of(0.5 * (times[i] + times[j]));
                    (j != i && mine && f.distance < r * r).then(|| {
                        let (a, b) = (i.min(j) as u32, i.max(j) as u32);
                        (a, b, [-weight(i, j, f.distance), 0.0])
                    })
                })
            })
            .collect(),
        Neighbourhood::Knn => {
            let mut pairs: Vec<(u32, u32)> = (0..n)
                .flat_map(|i| nb.of(i).iter().map(move |&j| (i.min(j as usize) as u32, i.max(j as usize) as u32)))
                .filter(|p| p.0 != p.1)
                .collect();
            pairs.sort_unstable();
            pairs.dedup();
            pairs
                .into_par_iter()
                .map(|(i, j)| {
                    let d2 = vec3::dot(
                        vec3::sub(points[i as usize], points[j as usize]),
                        vec3::sub(points[i as usize], points[j as usize]),
                    );
                    (i, j, [-weight(i as usize, j as usize, d2), 0.0])
                })
                .collect()
        }
    };
    let mut diag = vec![0.0; n];
    for &(i, j, [w, _]) in &off {
        diag[i as usize] -= w;
        diag[j as usize] -= w;
    }
    let (pattern, [stiffness, mass]) = assemble(n, &off, [&diag, &areas]);
    let mut used = serde_json::Map::new();
    used.insert("k".into(), nb.k.into());
    used.insert("neighbourhood".into(), serde_json::to_value(params.neighbourhood).unwrap_or_default());
    used.insert("spacing_h".into(), h.into());
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[n / 2];
    used.insert("t".into(), median.into());
    used.insert("t_range".into(), serde_json::json!([sorted[0], sorted[n - 1]]));
    used.insert("bandwidth".into(), bandwidth.into());
    used.insert("radius".into(), radius_of(median).into());
    used.insert("total_area".into(), areas.iter().sum::<f64>().into());
    used.insert("normalization".into(), "symmetric".into());
    used.insert("ambient_dimension".into(), 3.into());
    used.insert("intrinsic_dimension".into(), 2.into());
    Ok((
        SparsePair {
            pattern: Arc::new(pattern),
            stiffness,
            mass,
            mass_is_diagonal: true,
            dimension: Some(2),
            kernel: Kernel::CONSTANTS,
        },
        used,
    ))
}

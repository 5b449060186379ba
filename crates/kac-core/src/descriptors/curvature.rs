//! Curvature heard from the Laplacian (the chapter's Example 9.9) and from the heat kernel (Example 9.10), beside
//! the angle-defect Gaussian curvature they are compared with.
//!
//! - **Mean curvature.** With Δ = −∇·∇ (kac's sign), the Laplacian of the embedding's coordinate functions is
//!   Δx = 2H n on a surface, n the outward unit normal and H the mean of the principal curvatures (H = 1/r on a
//!   sphere of radius r). Discretely M⁻¹LX = 2Hn per vertex with the cotan stiffness L and the mixed Voronoi
//!   area M (Meyer, Desbrun, Schröder & Barr 2003). The identity does not hold at boundary vertices (the Neumann
//!   stiffness there measures the boundary's geodesic curvature too): they are flagged and get no value.
//! - **Gaussian curvature from the heat kernel.** On a surface, k_t(x, x) = (4πt)⁻¹ (1 + t K(x)/3 + O(t²)): the
//!   prefactor is (4πt)^(−d/2) with d = 2, and the first heat invariant is a₁ = R/6 with scalar curvature R = 2K.
//!   The chapter (Example 9.10) writes (4πt)^(−1/2) Σ a_k t^k with a₁ = K/6, a prefactor for d = 1 and a
//!   coefficient that takes K for R; both are wrong on a surface. K(x) is estimated by fitting
//!   4πt·k_t(x,x) − 1 = a t + b t² over a window of small times, K = 3a.
//! - **The window.** It is squeezed from both sides. From below: the computed eigenpairs decide the kernel only
//!   from e^{−λ_k t} = 10⁻⁴ on (the truncation bound of the heat trace there is reported), and the mesh resolves
//!   it only from a few rings of triangles on (`resolved`, passed by the caller). From above: the expansion is an
//!   expansion in t κ², κ the principal curvatures, so the window's largest time is kept at or below the
//!   curvature scale 1/κ_max² ([`curvature_scale`]: κ = H ± √max(H² − K, 0) from the two estimates above, κ_max
//!   their 95th percentile in absolute value over interior vertices). Measured, the fit's bias from the terms it
//!   neglects at t_max = 1/κ²: −2.8 % on the unit sphere (closed-form kernel), +0.2 % / −2.8 % at the outer /
//!   inner equator of the ring torus R = 2, r = 1/2 (P2, n = 64); at t_max = 2/κ² it is −13 % and −6.7 %, and at
//!   t_max = 6/κ² on that torus −33 %. The default window is [t₀, 4t₀] when that lies
//!   below the scale, else [t₀, 1/κ_max²] while that spans a factor of 2 at least (a narrower window no longer
//!   separates the t and t² terms), else [t₀, 2t₀]: then it reaches beyond the scale and
//!   [`HeatCurvature::beyond_scale`] says so (the analysis warns `curvature-window-too-coarse`: a finer mesh or
//!   more eigenpairs move t₀ down). Times given explicitly are used as given, and flagged the same way.
//! - **Angle defect.** K(x) = (2π − Σ angles at x) / A(x), A the mixed Voronoi area; boundary vertices flagged.

use crate::descriptors::{Basis, DescriptorError};
use crate::geometry::topology::boundary_vertices;
use crate::geometry::{Point, TriangleMesh};
use crate::operators::{self, Mass, OperatorError, OperatorKind, OperatorOptions};
use serde::Serialize;

/// Per-vertex mean curvature with its normals.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct MeanCurvature {
    /// H per vertex (NaN on the boundary).
    #[serde(skip)]
    pub h: Vec<f64>,
    /// Outward unit normal per vertex (area-weighted face normals; for an open mesh, as the faces are oriented).
    #[serde(skip)]
    pub normals: Vec<Point>,
    /// Boundary vertices (no value there).
    #[serde(skip)]
    pub boundary: Vec<bool>,
    /// `outward` (a closed mesh, turned so that its signed volume is positive) or `as-given` (an open mesh).
    pub orientation: &'static str,
    pub boundary_vertices: usize,
    pub mass: &'static str,
}

fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: Point, b: Point) -> Point {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn dot(a: Point, b: Point) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: Point) -> f64 {
    dot(a, a).sqrt()
}

/// Area-weighted vertex normals (unnormalized sums of face cross products), turned outward for a closed mesh.
fn vertex_normals(mesh: &TriangleMesh, closed: bool) -> (Vec<Point>, &'static str) {
    let mut n = vec![[0.0; 3]; mesh.vertices.len()];
    let mut volume = 0.0;
    for f in &mesh.faces {
        let [a, b, c] = f.map(|i| mesh.vertices[i as usize]);
        let fn_ = cross(sub(b, a), sub(c, a));
        volume += dot(a, cross(b, c)) / 6.0;
        for &i in f {
            for (k, x) in fn_.iter().enumerate() {
                n[i as usize][k] += x;
            }
        }
    }
    let flip = closed && volume < 0.0;
    for v in &mut n {
        let l = norm(*v);
        *v = if l > 0.0 { v.map(|x| if flip { -x } else { x } / l) } else { [f64::NAN; 3] };
    }
    (n, if closed { "outward" } else { "as-given" })
}

/// Mean curvature H and the outward unit normal at every vertex of a triangle mesh, from M⁻¹LX = 2Hn.
pub fn mean_curvature(mesh: &TriangleMesh) -> Result<MeanCurvature, OperatorError> {
    let shape = crate::Shape::TriangleMesh(mesh.clone());
    let options =
        OperatorOptions { operator: Some(OperatorKind::Cotan), mass: Some(Mass::Voronoi), ..Default::default() };
    let op = operators::build(&shape, &options)?;
    let n = mesh.vertices.len();
    let m = op.pair.mass_diagonal();
    let mut lx = vec![vec![0.0; n]; 3];
    for (c, out) in lx.iter_mut().enumerate() {
        let x: Vec<f64> = mesh.vertices.iter().map(|p| p[c]).collect();
        operators::sparse::matvec(&op.pair.pattern, &op.pair.stiffness, &x, out);
    }
    let boundary = boundary_vertices(mesh);
    let closed = !boundary.iter().any(|&b| b);
    let (normals, orientation) = vertex_normals(mesh, closed);
    let h = (0..n)
        .map(|i| {
            if boundary[i] || m[i] <= 0.0 {
                return f64::NAN;
            }
            let hn = [lx[0][i], lx[1][i], lx[2][i]].map(|x| x / (2.0 * m[i]));
            let magnitude = norm(hn);
            if dot(hn, normals[i]) < 0.0 {
                -magnitude
            } else {
                magnitude
            }
        })
        .collect();
    Ok(MeanCurvature {
        h,
        normals,
        boundary_vertices: boundary.iter().filter(|&&b| b).count(),
        boundary,
        orientation,
        mass: "voronoi",
    })
}

/// The angle-defect Gaussian curvature (2π − Σ angles) / A at every vertex (NaN on the boundary), A the mixed
/// Voronoi area.
pub fn angle_defect(mesh: &TriangleMesh) -> Result<Vec<f64>, OperatorError> {
    let shape = crate::Shape::TriangleMesh(mesh.clone());
    let options =
        OperatorOptions { operator: Some(OperatorKind::Cotan), mass: Some(Mass::Voronoi), ..Default::default() };
    let area = operators::build(&shape, &options)?.pair.mass_diagonal();
    let mut angles = vec![0.0; mesh.vertices.len()];
    for f in &mesh.faces {
        let p = f.map(|i| mesh.vertices[i as usize]);
        for k in 0..3 {
            let (a, b) = (sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
            angles[f[k] as usize] += norm(cross(a, b)).atan2(dot(a, b));
        }
    }
    let boundary = boundary_vertices(mesh);
    Ok((0..angles.len())
        .map(
            |i| {
                if boundary[i] || area[i] <= 0.0 {
                    f64::NAN
                } else {
                    (2.0 * std::f64::consts::PI - angles[i]) / area[i]
                }
            },
        )
        .collect())
}

/// The quantile of max(|κ₁|, |κ₂|) over interior vertices that sets the curvature scale: a few vertices at creases,
/// corners or noise (where κ grows like 1/h) do not set it; the estimate there is local anyway.
pub const CURVATURE_SCALE_QUANTILE: f64 = 0.95;

/// The heat-curvature window's largest time is kept at or below this × 1/κ_max² (see the module's notes for the
/// measurement that sets it).
pub const CURVATURE_TIME_FACTOR: f64 = 1.0;

/// The smallest ratio t_max / t_min of a default window: narrower, the fit no longer separates the t and t² terms.
pub const MIN_WINDOW_RATIO: f64 = 2.0;

/// The ratio t_max / t_min of the default window where the curvature scale does not constrain it.
pub const DEFAULT_WINDOW_RATIO: f64 = 4.0;

/// The shape's own curvature scale, which bounds the times at which the heat kernel's small-time expansion holds.
#[derive(Debug, Clone, Copy, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CurvatureScale {
    /// The 95th percentile over interior vertices of max(|κ₁|, |κ₂|), κ = H ± √max(H² − K, 0) with H from
    /// M⁻¹LX = 2Hn and K the angle defect (1/r on a sphere of radius r, 1/r on a torus of tube radius r).
    pub kappa_max: f64,
    /// The quantile taken (0.95).
    pub quantile: f64,
    /// 1/κ_max²: the window's times are kept at or below it; absent on a flat shape (κ_max = 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_bound: Option<f64>,
    /// Interior vertices with a finite estimate, over which the quantile was taken.
    pub vertices: usize,
}

/// The curvature scale of a triangle mesh (see [`CurvatureScale`]).
pub fn curvature_scale(mesh: &TriangleMesh) -> Result<CurvatureScale, OperatorError> {
    let h = mean_curvature(mesh)?;
    let k = angle_defect(mesh)?;
    let mut kappa: Vec<f64> =
        h.h.iter()
            .zip(&k)
            .filter(|(h, k)| h.is_finite() && k.is_finite())
            .map(|(h, k)| h.abs() + (h * h - k).max(0.0).sqrt())
            .collect();
    kappa.sort_by(f64::total_cmp);
    let kappa_max = match kappa.len() {
        0 => 0.0,
        len => kappa[((len - 1) as f64 * CURVATURE_SCALE_QUANTILE).round() as usize],
    };
    // Flat: a radius of curvature 10⁴ times the shape's extent or more. A plane's H and K are rounding (~1e-12),
    // which the square root in κ lifts to ~1e-6.
    let extent = (0..3)
        .map(|c| {
            let (lo, hi) = mesh.vertices.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[c]), b.max(p[c])));
            (hi - lo).max(0.0)
        })
        .fold(0.0, f64::max);
    let time_bound = (kappa_max * extent > 1e-4).then(|| CURVATURE_TIME_FACTOR / (kappa_max * kappa_max));
    Ok(CurvatureScale { kappa_max, quantile: CURVATURE_SCALE_QUANTILE, time_bound, vertices: kappa.len() })
}

/// The time from which k eigenpairs decide the heat kernel: e^{−λ_k t} = 10⁻⁴, t = 4 ln 10 / λ_k.
pub fn pairs_time(lambda_k: f64) -> f64 {
    4.0 * std::f64::consts::LN_10 / lambda_k.max(1e-300)
}

/// The default window, 8 log-spaced times over [t₀, t₁]: t₀ the larger of `pairs_time(λ_k)` and `resolved`, t₁ =
/// 4t₀ clamped to the curvature scale's bound but never below 2t₀ (see the module's notes).
pub fn default_window(lambda_k: f64, resolved: f64, time_bound: Option<f64>) -> Vec<f64> {
    let t0 = pairs_time(lambda_k).max(resolved);
    let t1 =
        time_bound.map_or(DEFAULT_WINDOW_RATIO * t0, |b| b.clamp(MIN_WINDOW_RATIO * t0, DEFAULT_WINDOW_RATIO * t0));
    (0..8).map(|j| t0 * (t1 / t0).powf(j as f64 / 7.0)).collect()
}

/// The Gaussian curvature estimated from the heat kernel's diagonal, with how it was fitted.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct HeatCurvature {
    #[serde(skip)]
    pub k: Vec<f64>,
    /// The times of the fit, log-spaced over [t_min, t_max].
    pub times: Vec<f64>,
    /// What truncation can miss of the heat trace at t_min, relative to it: (n − k) e^{−λ_k t_min} / Z(t_min).
    pub truncation_bound: f64,
    /// The expansion used: 4πt·k_t(x,x) = 1 + t K/3 + O(t²), fitted by least squares with a t² term.
    pub expansion: &'static str,
    /// The shape's curvature scale that bounded the window (absent where the caller gave none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub curvature_scale: Option<CurvatureScale>,
    /// The window's largest time exceeds the curvature scale's bound 1/κ_max²: the expansion's neglected terms
    /// bias the estimate (more than 3 % on a sphere, 7 % at 2/κ_max², 30 % at 6/κ_max² on a torus).
    pub beyond_scale: bool,
}

/// K(x) from k_t(x, x) = Σ e^{−λt} φ(x)² at small times (see the module's notes). `times`: the window, or None
/// for [`default_window`]; `resolved`: the smallest time the discretization resolves (the analyses pass 20 × the
/// mean vertex area: the kernel then spans a few rings of triangles; below that the estimate follows the mesh, not
/// the surface); `scale`: the shape's curvature scale ([`curvature_scale`]), which bounds the default window from
/// above and flags given times beyond it (None: no bound).
pub fn heat_curvature(
    basis: &Basis<'_>,
    times: Option<&[f64]>,
    resolved: f64,
    scale: Option<&CurvatureScale>,
) -> Result<HeatCurvature, DescriptorError> {
    let k = basis.k();
    if k < 2 {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!("heat curvature needs at least 2 eigenpairs; {k} given"),
        });
    }
    let lk = basis.values[k - 1];
    let time_bound = scale.and_then(|s| s.time_bound);
    let times: Vec<f64> = match times {
        Some(t) => t.to_vec(),
        None => default_window(lk, resolved, time_bound),
    };
    crate::descriptors::check_times("times", &times)?;
    let largest = times.iter().copied().fold(0.0, f64::max);
    // A relative slack so that a window clamped to the bound is not flagged by rounding.
    let beyond_scale = time_bound.is_some_and(|b| largest > b * (1.0 + 1e-9));
    let n = basis.n();
    let z0: f64 = basis.values.iter().map(|l| (-l * times[0]).exp()).sum();
    let truncation_bound = crate::descriptors::heat::heat_trace_tail_bound(basis.values, n, times[0]) / z0;
    // Least squares of y(t) = a t + b t² per vertex: the 2×2 normal equations are the same for every vertex.
    let (s2, s3, s4) = times.iter().fold((0.0, 0.0, 0.0), |(a, b, c), t| (a + t * t, b + t * t * t, c + t * t * t * t));
    let det = s2 * s4 - s3 * s3;
    let weights: Vec<Vec<f64>> = times.iter().map(|t| basis.values.iter().map(|l| (-l * t).exp()).collect()).collect();
    let phi = basis.vectors;
    let kx = (0..n)
        .map(|x| {
            let (mut ty, mut t2y) = (0.0, 0.0);
            for (t, w) in times.iter().zip(&weights) {
                let ktt: f64 = (0..k).map(|i| w[i] * phi[(x, i)] * phi[(x, i)]).sum();
                let y = 4.0 * std::f64::consts::PI * t * ktt - 1.0;
                ty += t * y;
                t2y += t * t * y;
            }
            let a = (s4 * ty - s3 * t2y) / det;
            3.0 * a
        })
        .collect();
    Ok(HeatCurvature {
        k: kx,
        times,
        truncation_bound,
        expansion: "4πt·k_t(x,x) = 1 + t·K(x)/3 + O(t²)",
        curvature_scale: scale.copied(),
        beyond_scale,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::generate;

    fn scaled(mut m: TriangleMesh, r: f64) -> TriangleMesh {
        for p in &mut m.vertices {
            *p = p.map(|x| x * r);
        }
        m
    }

    fn max_error(values: &[f64], exact: impl Fn(usize) -> f64) -> f64 {
        values.iter().enumerate().filter(|(_, v)| v.is_finite()).map(|(i, v)| (v - exact(i)).abs()).fold(0.0, f64::max)
    }

    /// A sphere of radius 2: H = 1/2, K = 1/4 at every vertex, the normal the position's direction; the error of
    /// H falls under refinement.
    #[test]
    fn sphere_mean_and_gaussian_curvature() {
        let mut errors = vec![];
        for level in [3, 4, 5] {
            let m = scaled(generate::icosphere(level), 2.0);
            let h = mean_curvature(&m).unwrap();
            assert_eq!((h.orientation, h.boundary_vertices), ("outward", 0));
            let e = max_error(&h.h, |_| 0.5);
            errors.push(e);
            for (p, n) in m.vertices.iter().zip(&h.normals) {
                assert!(dot(*p, *n) / 2.0 > 0.999, "outward normals");
            }
            let k = angle_defect(&m).unwrap();
            assert!(max_error(&k, |_| 0.25) < 0.02, "K on the sphere, level {level}");
        }
        assert!(errors[2] < 0.01 && errors[1] < errors[0] && errors[2] < errors[1], "H errors {errors:?}");
    }

    /// A torus (R = 2, r = 1): H = (R + 2r cos v) / (2r(R + r cos v)) and K = cos v / (r(R + r cos v)), v the
    /// angle around the tube (cos v = (ρ − R)/r with ρ the distance from the axis).
    #[test]
    fn torus_curvature_follows_the_tube_angle() {
        let (big, small) = (2.0, 1.0);
        let m = generate::torus(big, small, 160, 80);
        let cos_v = |i: usize| {
            let p = m.vertices[i];
            ((p[0] * p[0] + p[1] * p[1]).sqrt() - big) / small
        };
        let h = mean_curvature(&m).unwrap();
        let eh = max_error(&h.h, |i| (big + 2.0 * small * cos_v(i)) / (2.0 * small * (big + small * cos_v(i))));
        assert!(eh < 0.02, "H on the torus: {eh}");
        let k = angle_defect(&m).unwrap();
        let ek = max_error(&k, |i| cos_v(i) / (small * (big + small * cos_v(i))));
        assert!(ek < 0.02, "K on the torus: {ek}");
    }

    /// A flat disk: H = 0 and K = 0 inside, the boundary flagged.
    #[test]
    fn flat_disk_has_no_curvature() {
        let m = generate::unit_disk(20);
        let h = mean_curvature(&m).unwrap();
        assert!(h.boundary_vertices > 0 && h.orientation == "as-given");
        assert!(max_error(&h.h, |_| 0.0) < 1e-9);
        assert!(h.h.iter().zip(&h.boundary).all(|(v, &b)| v.is_nan() == b));
        assert!(max_error(&angle_defect(&m).unwrap(), |_| 0.0) < 1e-9);
    }

    /// The heat kernel hears K = 1/r² on a sphere of radius r.
    #[test]
    fn heat_kernel_hears_the_sphere_curvature() {
        let m = scaled(generate::icosphere(4), 1.5);
        let op = operators::build(&crate::Shape::TriangleMesh(m.clone()), &OperatorOptions::default()).unwrap();
        let opts = crate::spectrum::EigenOptions { k: 300, ..Default::default() };
        let s = crate::spectrum::eigs(&op.pair, &opts, None, Default::default()).unwrap();
        let basis = Basis::of(&s, &op.pair);
        let resolved = 20.0 * op.pair.mass.iter().sum::<f64>() / op.pair.n() as f64;
        let scale = curvature_scale(&m).unwrap();
        let hk = heat_curvature(&basis, None, resolved, Some(&scale)).unwrap();
        // The scale (1/r² = 0.44 here) lies beyond the whole default window [t₀, 4t₀]: the window is unchanged.
        assert!(!hk.beyond_scale && (hk.times[7] / hk.times[0] - 4.0).abs() < 1e-9, "{:?}", hk.times);
        let exact = 1.0 / (1.5 * 1.5);
        let mean = hk.k.iter().sum::<f64>() / hk.k.len() as f64;
        assert!((mean - exact).abs() < 0.03 * exact, "mean K {mean} vs {exact}; window {:?}", hk.times);
        // Pointwise: 4πt·k_t − 1 ≈ tK/3 is a few per cent at these times; where t is below what the mesh resolves
        // the P1 kernel's own error swamps it (worst at the icosphere's twelve valence-5 vertices), hence the
        // window's lower bound.
        let mut errs: Vec<f64> = hk.k.iter().map(|v| (v - exact).abs() / exact).collect();
        errs.sort_by(f64::total_cmp);
        let q = |p: f64| errs[((errs.len() - 1) as f64 * p) as usize];
        assert!(q(0.5) < 0.02 && q(1.0) < 0.1, "relative errors: median {}, worst {}", q(0.5), q(1.0));
        assert!(hk.truncation_bound < 1e-2, "{}", hk.truncation_bound);
    }

    /// The curvature scale is the largest principal curvature: 1/r on a sphere of radius r, the tube's 1/r on a
    /// ring torus (its other principal curvature, cos θ/(R + r cos θ), is at most 1/(R − r) in size); none on a
    /// flat disk.
    #[test]
    fn curvature_scale_is_the_largest_principal_curvature() {
        let s = curvature_scale(&scaled(generate::icosphere(4), 2.0)).unwrap();
        assert!((s.kappa_max - 0.5).abs() < 0.01, "sphere: {s:?}");
        assert!((s.time_bound.unwrap() - 4.0).abs() < 0.2, "sphere: {s:?}");
        let s = curvature_scale(&generate::torus(2.0, 0.5, 128, 64)).unwrap();
        assert!((s.kappa_max - 2.0).abs() < 0.04 && s.vertices == 128 * 64, "torus: {s:?}");
        let s = curvature_scale(&generate::unit_disk(20)).unwrap();
        assert!(s.time_bound.is_none() && s.vertices > 0, "disk: {s:?}");
    }

    /// The default window: [t₀, 4t₀] below the scale, cut at the scale while it spans a factor of 2, else
    /// [t₀, 2t₀] (beyond the scale: the caller warns).
    #[test]
    fn default_window_is_clamped_to_the_curvature_scale() {
        let lk = 4.0 * std::f64::consts::LN_10 / 0.1; // t₀ = 0.1 from the pairs
        let ends = |w: Vec<f64>| (w[0], w[7], w.len());
        let close =
            |(a, b, n): (f64, f64, usize), (x, y): (f64, f64)| n == 8 && (a - x).abs() < 1e-12 && (b - y).abs() < 1e-12;
        assert!(close(ends(default_window(lk, 0.0, None)), (0.1, 0.4)));
        assert!(close(ends(default_window(lk, 0.0, Some(10.0))), (0.1, 0.4)));
        assert!(close(ends(default_window(lk, 0.0, Some(0.25))), (0.1, 0.25)));
        assert!(close(ends(default_window(lk, 0.0, Some(0.15))), (0.1, 0.2)));
        // The resolution bound moves t₀ up (the torus R = 2, r = 1/2 at n = 32: 0.385 against a bound of 0.25).
        assert!(close(ends(default_window(lk, 0.385, Some(0.25))), (0.385, 0.77)));
    }
}

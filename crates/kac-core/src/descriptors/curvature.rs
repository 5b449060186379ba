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
//!   4πt·k_t(x,x) − 1 = a t + b t² over a window of small times, K = 3a; by default the window starts where the
//!   computed eigenpairs decide the kernel (e^{−λ_k t} = 10⁻⁴), and the truncation bound of the heat trace there
//!   is reported.
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
}

/// K(x) from k_t(x, x) = Σ e^{−λt} φ(x)² at small t (see the module's notes). `times`: the window, or None for
/// the default: 8 log-spaced times over [t₀, 4 t₀] with t₀ the larger of 4 ln 10 / λ_k (where the computed
/// eigenpairs decide the kernel) and `resolved`, the smallest time the discretization resolves (the analyses pass
/// 20 × the mean vertex area: the kernel then spans a few rings of triangles; below that the estimate follows the
/// mesh, not the surface).
pub fn heat_curvature(
    basis: &Basis<'_>,
    times: Option<&[f64]>,
    resolved: f64,
) -> Result<HeatCurvature, DescriptorError> {
    let k = basis.k();
    if k < 2 {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!("heat curvature needs at least 2 eigenpairs; {k} given"),
        });
    }
    let lk = basis.values[k - 1];
    let times: Vec<f64> = match times {
        Some(t) => t.to_vec(),
        None => {
            // e^{−λ_k t_min} = 10⁻⁴: beyond λ_k the kernel's terms are below that.
            let t0 = (4.0 * std::f64::consts::LN_10 / lk.max(1e-300)).max(resolved);
            (0..8).map(|j| t0 * 4f64.powf(j as f64 / 7.0)).collect()
        }
    };
    crate::descriptors::check_times("times", &times)?;
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
    Ok(HeatCurvature { k: kx, times, truncation_bound, expansion: "4πt·k_t(x,x) = 1 + t·K(x)/3 + O(t²)" })
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
        let op = operators::build(&crate::Shape::TriangleMesh(m), &OperatorOptions::default()).unwrap();
        let opts = crate::spectrum::EigenOptions { k: 300, ..Default::default() };
        let s = crate::spectrum::eigs(&op.pair, &opts, None, Default::default()).unwrap();
        let basis = Basis::of(&s, &op.pair);
        let resolved = 20.0 * op.pair.mass.iter().sum::<f64>() / op.pair.n() as f64;
        let hk = heat_curvature(&basis, None, resolved).unwrap();
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
}

//! Point clouds as samples of an m-dimensional manifold in Rⁿ (manifold learning): the Belkin–Niyogi heat-kernel
//! Laplacian (Belkin & Niyogi 2003, 2008; the chapter's §9.5.4, eq. 9.39) for any ambient dimension n and
//! intrinsic dimension m, given or estimated from the neighbourhoods.
//!
//! With w_ij = e^{−|x_i − x_j|²/4t} for |x_i − x_j| < r, both normalizations are graph Laplacians (9.14) with
//! weights proportional to w_ij, and both approximate Δ = −∇·∇ (positive semidefinite) as t → 0:
//!
//! - `symmetric` (kac's default): each point carries the m-volume A_i it stands for, `L_ij = −A_i A_j w_ij c`,
//!   `M = diag(A_i)`, c = 1 / (t (4πt)^{m/2} P((m+2)/2, r²/4t)), where P is the regularized lower incomplete gamma
//!   function: the share of the Gaussian's second moment inside the radius, which corrects the truncation (for
//!   m = 2, P(2, a) = 1 − e^{−a}(1 + a)). A_i is the area of the point's Voronoi cell among its neighbours
//!   projected to its tangent plane (m = 2; the plane from the top two principal directions of the
//!   neighbourhood, in any n), the length of its cell on the tangent line (m = 1), or the kernel density estimate
//!   (4πt)^{m/2} P(m/2, r²/4t) / Σ_j w_ij (m ≥ 3). Uneven sampling is weighed out.
//! - `chapter` (eq. 9.39): uniform weights, every point standing for V/K of the manifold's volume, `M = (V/K) I`,
//!   `L_ij = −(V/K)² w_ij / (t (4πt)^{m/2})`, so that (M⁻¹L f)_i = (V/K)/(t (4πt)^{m/2}) Σ_j w_ij (f_i − f_j). The
//!   chapter writes 1/K where the integral it discretizes needs vol(M)/K (it holds for vol(M) = 1): kac takes V
//!   as the sum of the same local volumes A_i, so that eigenvalues come out in the manifold's own units. The
//!   chapter has no truncation correction: its radius defaults to 6√t, where what the Gaussian loses outside is
//!   below 10⁻³ for m ≤ 3. With uniform weights the sum is a Monte-Carlo estimate of the integral, and Belkin &
//!   Niyogi's convergence needs n t^{m/2+1} → ∞: t must shrink more slowly than the spacing h. Its default t is
//!   (2h)² up to 1,000 points and (2h)² (n/1000)^{2/m − 2/(m+4)} beyond, i.e. t ∝ n^{−2/(m+4)} (with t ∝ h², the
//!   symmetric operator's default, its error stalls near 15 % on a random sample of the flat torus). It assumes
//!   uniform sampling; under uneven density it converges to a weighted Laplacian, not Δ.
//!
//! The intrinsic dimension, when not given, is the maximum-likelihood estimate of Levina & Bickel (2005) from the
//! distances to the k nearest neighbours, averaged over points as MacKay & Ghahramani (2005) propose (the mean of
//! the inverse estimates), rounded; both the raw value and the m used are reported.
//!
//! Neighbourhoods: a k-d tree (kiddo) for n ≤ 8, an exhaustive search (N² distances, in parallel) beyond.

use super::sparse::{assemble, Kernel, SparsePair};
use super::{CloudParams, Neighbourhood, OperatorError};
use kiddo::{KdTree, SquaredEuclidean};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::sync::Arc;

/// How far from an integer the estimated intrinsic dimension may be and still be taken (rounded); beyond, the
/// dimension must be given.
pub const MAX_DIMENSION_DOUBT: f64 = 0.2;

/// The chapter's operator's default t is (2h)² up to this many points, then shrinks more slowly than the spacing.
const CHAPTER_T_POINTS: f64 = 1000.0;

/// Non-zeros the operator may hold (about 16 bytes each in the pair): beyond, the request is refused with the
/// count it would need, before the pairs are searched.
pub const MAX_PAIRS: f64 = 1e8;

/// Points an exhaustive neighbour search (more than 8 coordinates) takes.
pub const MAX_EXHAUSTIVE: usize = 50_000;

/// How the point-cloud operator weighs its points (see the module documentation).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum CloudNormalization {
    /// Local volumes as quadrature weights, truncation corrected (default).
    #[default]
    Symmetric,
    /// The chapter's eq. 9.39: uniform weights vol/K, no truncation correction (radius 6√t).
    Chapter,
}

/// Points in Rⁿ, row-major.
#[derive(Clone, Copy)]
pub struct Points<'a> {
    pub dim: usize,
    pub coords: &'a [f64],
}

impl<'a> Points<'a> {
    pub fn len(&self) -> usize {
        self.coords.len() / self.dim.max(1)
    }
    pub fn is_empty(&self) -> bool {
        self.coords.is_empty()
    }
    pub fn row(&self, i: usize) -> &'a [f64] {
        &self.coords[i * self.dim..(i + 1) * self.dim]
    }
    fn d2(&self, i: usize, j: usize) -> f64 {
        self.row(i).iter().zip(self.row(j)).map(|(a, b)| (a - b) * (a - b)).sum()
    }
}

/// The k nearest neighbours of every point (itself excluded, nearest first; none for k = 0) with squared
/// distances, and optionally every pair (i < j) within squared distance r2.
struct Found {
    k: usize,
    knn: Vec<u32>,
    knn_d2: Vec<f64>,
    pairs: Vec<(u32, u32, f64)>,
    method: &'static str,
}

impl Found {
    fn of(&self, i: usize) -> &[u32] {
        &self.knn[i * self.k..(i + 1) * self.k]
    }
    fn d2(&self, i: usize) -> &[f64] {
        &self.knn_d2[i * self.k..(i + 1) * self.k]
    }
}

fn search_tree<const D: usize>(p: Points<'_>, k: usize, r2: Option<f64>) -> Found {
    let n = p.len();
    let row = |i: usize| -> [f64; D] { p.row(i).try_into().unwrap_or([0.0; D]) };
    let mut tree: KdTree<f64, D> = KdTree::with_capacity(n);
    for i in 0..n {
        tree.add(&row(i), i as u64);
    }
    let lists: Vec<(Vec<u32>, Vec<f64>)> = (0..if k > 0 { n } else { 0 })
        .into_par_iter()
        .map(|i| {
            let found = tree.nearest_n::<SquaredEuclidean>(&row(i), k + 1);
            found.iter().filter(|f| f.item as usize != i).take(k).map(|f| (f.item as u32, f.distance)).unzip()
        })
        .collect();
    let pairs = match r2 {
        Some(r2) => (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                tree.within_unsorted::<SquaredEuclidean>(&row(i), r2)
                    .into_iter()
                    .filter(move |f| f.item as usize > i)
                    .map(move |f| (i as u32, f.item as u32, f.distance))
            })
            .collect(),
        None => vec![],
    };
    let (knn, knn_d2) = flatten(lists, k);
    Found { k, knn, knn_d2, pairs, method: "k-d tree" }
}

fn search_exhaustive(p: Points<'_>, k: usize, r2: Option<f64>) -> Found {
    let n = p.len();
    let lists: Vec<(Vec<u32>, Vec<f64>)> = (0..if k > 0 { n } else { 0 })
        .into_par_iter()
        .map(|i| {
            let mut d: Vec<(f64, u32)> = (0..n).filter(|&j| j != i).map(|j| (p.d2(i, j), j as u32)).collect();
            let k = k.min(d.len());
            if k < d.len() {
                d.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
            }
            d.truncate(k);
            d.sort_by(|a, b| a.0.total_cmp(&b.0));
            d.into_iter().map(|(dd, j)| (j, dd)).unzip()
        })
        .collect();
    let pairs = match r2 {
        Some(r2) => (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                (i + 1..n).filter_map(move |j| {
                    let d = p.d2(i, j);
                    (d < r2).then_some((i as u32, j as u32, d))
                })
            })
            .collect(),
        None => vec![],
    };
    let (knn, knn_d2) = flatten(lists, k);
    Found { k, knn, knn_d2, pairs, method: "exhaustive" }
}

/// Fixed-width neighbour lists (short lists padded with their last entry, as the 3-D operator does).
fn flatten(lists: Vec<(Vec<u32>, Vec<f64>)>, k: usize) -> (Vec<u32>, Vec<f64>) {
    let mut knn = Vec::with_capacity(lists.len() * k);
    let mut d2 = Vec::with_capacity(lists.len() * k);
    for (mut a, mut b) in lists {
        while a.len() < k {
            a.push(a.last().copied().unwrap_or(0));
            b.push(b.last().copied().unwrap_or(0.0));
        }
        knn.extend_from_slice(&a[..k]);
        d2.extend_from_slice(&b[..k]);
    }
    (knn, d2)
}

fn search(p: Points<'_>, k: usize, r2: Option<f64>) -> Found {
    match p.dim {
        1 => search_tree::<1>(p, k, r2),
        2 => search_tree::<2>(p, k, r2),
        3 => search_tree::<3>(p, k, r2),
        4 => search_tree::<4>(p, k, r2),
        5 => search_tree::<5>(p, k, r2),
        6 => search_tree::<6>(p, k, r2),
        7 => search_tree::<7>(p, k, r2),
        8 => search_tree::<8>(p, k, r2),
        _ => search_exhaustive(p, k, r2),
    }
}

/// The regularized lower incomplete gamma function P(s, x) (series for x < s + 1, continued fraction beyond;
/// Numerical Recipes §6.2), to 1e-14.
pub fn gamma_p(s: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let ln_prefix = s * x.ln() - x - ln_gamma(s);
    if x < s + 1.0 {
        let (mut term, mut sum, mut a) = (1.0 / s, 1.0 / s, s);
        for _ in 0..1000 {
            a += 1.0;
            term *= x / a;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (sum.ln() + ln_prefix).exp()
    } else {
        // Lentz's continued fraction for Q(s, x).
        let tiny = 1e-300;
        let mut b = x + 1.0 - s;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1000 {
            let an = -(i as f64) * (i as f64 - s);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        1.0 - (ln_prefix.exp() * h)
    }
}

/// ln Γ(s) for s > 0 (Lanczos, g = 7, 9 terms; relative error below 1e-15).
fn ln_gamma(s: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if s < 0.5 {
        return (PI / (PI * s).sin()).ln() - ln_gamma(1.0 - s);
    }
    let x = s - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, &c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The Levina–Bickel maximum-likelihood intrinsic dimension from each point's `k` nearest distances, averaged
/// as MacKay & Ghahramani propose (the inverse of the mean inverse); points whose neighbours coincide are left
/// out. `None` where no point has k distinct distances.
fn estimate_dimension(found: &Found, k: usize) -> Option<f64> {
    let k = k.min(found.k);
    if k < 3 {
        return None;
    }
    let inverses: Vec<f64> = (0..found.knn.len() / found.k)
        .into_par_iter()
        .filter_map(|i| {
            let d = found.d2(i);
            let tk = d[k - 1].sqrt();
            let logs: Vec<f64> = d[..k - 1].iter().map(|&x| (tk / x.sqrt()).ln()).collect();
            (logs.iter().all(|l| l.is_finite()) && tk > 0.0).then(|| logs.iter().sum::<f64>() / (k - 1) as f64)
        })
        .collect();
    let mean = inverses.iter().sum::<f64>() / inverses.len().max(1) as f64;
    (!inverses.is_empty() && mean > 0.0).then(|| 1.0 / mean)
}

/// Coordinates of a point's neighbours in its m-dimensional tangent space: the top m principal directions of
/// the differences D (k × n), found from the k × k Gram matrix D Dᵀ = U S Uᵀ, where the neighbours' coordinates
/// are √s_a U[:, a].
fn tangent_coordinates(p: Points<'_>, i: usize, nb: &[u32], m: usize) -> Vec<Vec<f64>> {
    let k = nb.len();
    let diff: Vec<Vec<f64>> =
        nb.iter().map(|&j| p.row(j as usize).iter().zip(p.row(i)).map(|(a, b)| a - b).collect()).collect();
    let g = faer::Mat::<f64>::from_fn(k, k, |a, b| diff[a].iter().zip(&diff[b]).map(|(x, y)| x * y).sum());
    let Ok(evd) = g.self_adjoint_eigen(faer::Side::Lower) else {
        return vec![vec![0.0; m]; k];
    };
    let (s, u) = (evd.S(), evd.U());
    (0..k).map(|j| (0..m.min(k)).map(|a| s[k - 1 - a].max(0.0).sqrt() * u[(j, k - 1 - a)]).collect()).collect()
}

/// Area of the Voronoi cell of the origin among 2-D points, clipped to the square of half-size the farthest one.
fn cell_area_2d(q: &[Vec<f64>]) -> f64 {
    let q: Vec<(f64, f64)> = q.iter().map(|c| (c[0], c[1])).filter(|&(x, y)| x * x + y * y > 0.0).collect();
    let r = q.iter().map(|&(x, y)| (x * x + y * y).sqrt()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let mut poly = vec![[-r, -r], [r, -r], [r, r], [-r, r]];
    for &(qx, qy) in &q {
        let c = 0.5 * (qx * qx + qy * qy);
        let side = |x: [f64; 2]| x[0] * qx + x[1] * qy - c;
        let mut out = Vec::with_capacity(poly.len() + 1);
        for k in 0..poly.len() {
            let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
            let (sa, sb) = (side(a), side(b));
            if sa <= 0.0 {
                out.push(a);
            }
            if (sa <= 0.0) != (sb <= 0.0) {
                let t = sa / (sa - sb);
                out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
            }
        }
        poly = out;
        if poly.is_empty() {
            return 0.0;
        }
    }
    let mut area = 0.0;
    for k in 0..poly.len() {
        let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
        area += a[0] * b[1] - a[1] * b[0];
    }
    0.5 * area.abs()
}

/// Length of the 1-D Voronoi cell of the origin among points on a line, clipped to the farthest one's distance.
fn cell_length_1d(q: &[Vec<f64>]) -> f64 {
    let r = q.iter().map(|c| c[0].abs()).fold(0.0, f64::max);
    let right = q.iter().map(|c| c[0]).filter(|&x| x > 0.0).fold(2.0 * r, f64::min);
    let left = q.iter().map(|c| -c[0]).filter(|&x| x > 0.0).fold(2.0 * r, f64::min);
    0.5 * (right + left)
}

/// The Belkin–Niyogi pair of points in Rⁿ with intrinsic dimension m (given, or estimated), in either
/// normalization, and the parameters it used.
pub fn manifold_pair(
    p: Points<'_>,
    params: &CloudParams,
) -> Result<(SparsePair, serde_json::Map<String, serde_json::Value>), OperatorError> {
    let n = p.len();
    let invalid = |name: &'static str, message: String| OperatorError::InvalidParameter { name, message };
    if n < 4 {
        return Err(invalid("points", format!("{n} points; a point-cloud Laplacian needs at least 4")));
    }
    if p.dim > 8 && n > MAX_EXHAUSTIVE {
        return Err(invalid(
            "points",
            format!(
                "{n} points in R^{}: above 8 coordinates neighbours are found exhaustively (n² distances), for at most \
                 {MAX_EXHAUSTIVE} points; reduce the dimension (e.g. by PCA) or the count",
                p.dim
            ),
        ));
    }
    let k = params.k.clamp(3, n - 1);
    // First the k nearest (spacing, dimension, tangent spaces); the radius pairs once t is known.
    let near = search(p, k, None);
    let h = (0..n).map(|i| near.d2(i)[0].sqrt()).sum::<f64>() / n as f64;
    if !(h > 0.0) {
        return Err(invalid("points", "the points have no spacing (all coincide)".into()));
    }
    let estimate = estimate_dimension(&near, k.min(20));
    let m = match params.dimension {
        Some(m) if m >= 1 && m <= p.dim => m,
        Some(m) => {
            return Err(invalid(
                "intrinsic_dimension",
                format!("{m} is not between 1 and the points' ambient dimension {}", p.dim),
            ))
        }
        // In R³ the points sample a surface unless told otherwise (the documented default, whatever the estimate:
        // Levina–Bickel reads 2.88 on a sphere's vertices, whose neighbourhoods curve within 20 neighbours).
        None if p.dim == 3 => 2,
        // In Rⁿ the estimate decides only where it is near an integer: a regular 70 × 70 grid on the flat torus in
        // R⁴ reads 2.73 (its tied distances bias the estimate), which rounded to 3 gave eigenvalues 11 % off.
        None => match estimate {
            Some(e) if (e - e.round()).abs() <= MAX_DIMENSION_DOUBT => (e.round() as usize).clamp(1, p.dim),
            Some(e) => {
                return Err(invalid(
                    "intrinsic_dimension",
                    format!(
                        "the estimate from the nearest distances (Levina–Bickel) is {e:.2}, not within \
                         {MAX_DIMENSION_DOUBT} of an integer: give intrinsic_dimension (the manifold's dimension m)"
                    ),
                ))
            }
            None => {
                return Err(invalid(
                    "intrinsic_dimension",
                    "no estimate: the neighbours coincide; give intrinsic_dimension".into(),
                ))
            }
        },
    };
    let md = m as f64;
    let dk = (0..n).map(|i| near.d2(i)[k - 1].sqrt()).sum::<f64>() / n as f64;
    let t = match params.t {
        Some(t) if t > 0.0 && t.is_finite() => t,
        Some(t) => return Err(invalid("t", format!("{t} is not a positive time"))),
        None if params.neighbourhood == Neighbourhood::Knn => dk * dk / 9.0,
        None if params.normalization == CloudNormalization::Chapter => {
            (4.0 * h * h).max(dk * dk / 9.0) * (n as f64 / CHAPTER_T_POINTS).max(1.0).powf(2.0 / md - 2.0 / (md + 4.0))
        }
        // (2h)², or where the k-th neighbour lies farther than 3 · 2h, the time at which the kernel's radius
        // 3√t reaches it; on curves 1.5 times farther (random gaps on a line are long: the largest of N is about
        // ln N mean gaps, which would split the kernel's graph).
        None => (4.0 * h * h).max(dk * dk / if m == 1 { 4.0 } else { 9.0 }),
    };
    let chapter = params.normalization == CloudNormalization::Chapter;
    let r = match params.radius {
        Some(r) if r > 0.0 && r.is_finite() => r,
        Some(r) => return Err(invalid("radius", format!("{r} is not a positive radius"))),
        None => (if chapter { 6.0 } else { 3.0 }) * t.sqrt(),
    };
    // The pairs within r, estimated from the distance to the k-th neighbour (k (r / d_k)^m per point).
    let expected = 0.5 * n as f64 * k as f64 * (r / dk).powf(md);
    if params.neighbourhood == Neighbourhood::Radius && expected > MAX_PAIRS {
        return Err(invalid(
            "radius",
            format!(
                "a kernel of radius {r:.4e} (t = {t:.4e}) joins about {expected:.2e} pairs of the {n} points, above \
                 the limit of {MAX_PAIRS:.0e}; give a smaller time or radius"
            ),
        ));
    }
    let a = r * r / (4.0 * t);
    let weight = |d2: f64| (-d2 / (4.0 * t)).exp();
    let pairs: Vec<(u32, u32, f64)> = match params.neighbourhood {
        Neighbourhood::Radius => search(p, 0, Some(r * r)).pairs,
        Neighbourhood::Knn => {
            let mut e: Vec<(u32, u32)> = (0..n)
                .flat_map(|i| near.of(i).iter().map(move |&j| (i.min(j as usize) as u32, i.max(j as usize) as u32)))
                .filter(|e| e.0 != e.1)
                .collect();
            e.sort_unstable();
            e.dedup();
            e.into_par_iter().map(|(i, j)| (i, j, p.d2(i as usize, j as usize))).collect()
        }
    };
    // Local m-volumes.
    let areas: Vec<f64> = match m {
        1 | 2 => (0..n)
            .into_par_iter()
            .map(|i| {
                let q = tangent_coordinates(p, i, near.of(i), m);
                if m == 2 {
                    cell_area_2d(&q)
                } else {
                    cell_length_1d(&q)
                }
            })
            .collect(),
        _ => {
            let mut density = vec![1.0; n];
            for &(i, j, d2) in &pairs {
                density[i as usize] += weight(d2);
                density[j as usize] += weight(d2);
            }
            let mass = (4.0 * PI * t).powf(md / 2.0) * gamma_p(md / 2.0, a);
            density.iter().map(|d| mass / d).collect()
        }
    };
    let volume: f64 = areas.iter().sum();
    let (scale, mass): (f64, Vec<f64>) = if chapter {
        let per = volume / n as f64;
        (per * per / (t * (4.0 * PI * t).powf(md / 2.0)), vec![per; n])
    } else {
        (1.0 / (t * (4.0 * PI * t).powf(md / 2.0) * gamma_p((md + 2.0) / 2.0, a)), areas.clone())
    };
    let off: Vec<(u32, u32, [f64; 2])> = pairs
        .par_iter()
        .map(|&(i, j, d2)| {
            let w = if chapter { weight(d2) } else { areas[i as usize] * areas[j as usize] * weight(d2) };
            (i, j, [-w * scale, 0.0])
        })
        .collect();
    let mut diag = vec![0.0; n];
    for &(i, j, [w, _]) in &off {
        diag[i as usize] -= w;
        diag[j as usize] -= w;
    }
    let (pattern, [stiffness, mass]) = assemble(n, &off, [&diag, &mass]);
    let mut used = serde_json::Map::new();
    used.insert("k".into(), k.into());
    used.insert("neighbourhood".into(), serde_json::to_value(params.neighbourhood).unwrap_or_default());
    used.insert("normalization".into(), serde_json::to_value(params.normalization).unwrap_or_default());
    used.insert("ambient_dimension".into(), p.dim.into());
    used.insert("intrinsic_dimension".into(), m.into());
    used.insert("intrinsic_dimension_given".into(), params.dimension.is_some().into());
    used.insert("intrinsic_dimension_estimate".into(), estimate.into());
    used.insert("spacing_h".into(), h.into());
    used.insert("t".into(), t.into());
    used.insert("radius".into(), r.into());
    used.insert("truncation_moment".into(), gamma_p((md + 2.0) / 2.0, a).into());
    used.insert("total_area".into(), volume.into());
    used.insert(
        "local_volumes".into(),
        match m {
            2 => "tangent-plane Voronoi cells",
            1 => "tangent-line Voronoi cells",
            _ => "kernel density estimate",
        }
        .into(),
    );
    used.insert("neighbour_search".into(), near.method.into());
    Ok((
        SparsePair {
            pattern: Arc::new(pattern),
            stiffness,
            mass,
            mass_is_diagonal: true,
            dimension: u8::try_from(m).ok().filter(|&d| d <= 3),
            kernel: Kernel::CONSTANTS,
        },
        used,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn incomplete_gamma_matches_closed_forms() {
        for a in [0.1, 1.0, 2.25, 9.0, 30.0] {
            // P(1, a) = 1 − e^{−a}; P(2, a) = 1 − e^{−a}(1 + a); P(1/2, a) = erf(√a).
            assert!((gamma_p(1.0, a) - (1.0 - (-a).exp())).abs() < 1e-14, "{a}");
            assert!((gamma_p(2.0, a) - (1.0 - (-a).exp() * (1.0 + a))).abs() < 1e-14, "{a}");
        }
        // erf(1.5) = 0.966105146475310713936 (Abramowitz & Stegun, table 7.1).
        assert!((gamma_p(0.5, 2.25) - 0.966_105_146_475_310_7).abs() < 1e-13);
        assert!((ln_gamma(0.5) - PI.sqrt().ln()).abs() < 1e-14);
        assert!((ln_gamma(10.0) - 362_880f64.ln()).abs() < 1e-12);
    }
}

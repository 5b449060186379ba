//! Scanned point clouds: noise across the surface thickens it into a shell, which the heat kernel and the local
//! areas see as extra surface (a 21k-point sphere scan with σ ≈ 0.04 read as three times its area). Before the
//! operator is built, every point is moved onto a moving-least-squares surface (Levin 2003; Alexa et al. 2003,
//! "Computing and rendering point set surfaces"): around each point a weighted tangent plane (principal
//! directions of its neighbourhood, or the given normals), a quadratic height function fitted over it by
//! weighted least squares, and the point projected onto that surface along the plane's normal.
//!
//! Outliers (points off the surface, such as a scanner's stray returns) are found first: a point whose mean
//! distance to its 16 nearest neighbours exceeds five times the median of that distance over the cloud (a
//! robust form of the statistical outlier removal of Rusu et al. 2008). Five times leaves surface regions sampled
//! ten times more sparsely than the median (√10 ≈ 3.2 times the distance) alone; stray points within a few
//! spacings of the surface are not found, and need not be: the projection moves them onto it. A clump of stray
//! points close together passes that rule; it is found as a small piece of the neighbour graph (below 1 % of the
//! points, at least 16) and dropped too.
//!
//! The neighbourhood must be wider than the noise is thick. Its size is chosen once for the cloud, among
//! k = 16, 32, …, 4096 neighbours (at most an eighth of the cloud), as the one where the median surface variation σ₃/(σ₁ + σ₂ + σ₃) of the
//! neighbourhoods (the smallest principal variance's share; Pauly, Gross & Kobbelt 2002) is lowest: noise raises
//! it at small scales, curvature at large ones (Mitra & Nguyen 2003 make the same trade-off for normals). The
//! noise level reported is the median, over the fits, of the weighted RMS distance of the neighbours to the fitted
//! quadratic.
//!
//! Cost: a neighbourhood's shape needs its extent, not every point in it, so above 256 neighbours both the scale
//! search and the fits read a hashed subsample of about 256 points in the same radius; and the fits are made at
//! anchors, about 64 per neighbourhood, each point projected onto its nearest anchor's quadratic (which holds over
//! the whole neighbourhood). Fitting at every point with every neighbour gives the same eigenvalues to three digits
//! at many times the cost.

use super::frames::eigen3;
use super::Neighbourhoods;
use crate::geometry::{vec3, Point};
use crate::operators::error::OperatorError;
use rayon::prelude::*;

/// What the projection did, for the operator's parameters.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Denoised {
    /// Neighbours per fit (the scale chosen).
    pub k: usize,
    /// The median surface variation at each candidate scale.
    pub surface_variation: Vec<(usize, f64)>,
    /// The noise level: median weighted RMS residual of the quadratic fits (length).
    pub noise: f64,
    /// Median and largest distance a point moved.
    pub moved_median: f64,
    pub moved_max: f64,
    /// Whether the given normals oriented the fits.
    pub normals_used: bool,
    /// The points the fits were made at (every point projects onto its nearest one's fit).
    pub anchors: usize,
    /// Points farther than half a fit's radius from every anchor, fitted on their own.
    pub own_fits: usize,
}

/// Weighted centroid and covariance of point i's neighbourhood (Gaussian weights of width half the farthest
/// neighbour's distance).
fn moments(points: &[Point], i: usize, nb: &[u32]) -> (Point, [[f64; 3]; 3], f64) {
    let p = points[i];
    let r = nb.iter().map(|&j| vec3::norm(vec3::sub(points[j as usize], p))).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let w = |q: Point| (-vec3::dot(vec3::sub(q, p), vec3::sub(q, p)) / (0.5 * r * r)).exp();
    let mut total = w(p);
    let mut c = vec3::scale(p, total);
    for &j in nb {
        let q = points[j as usize];
        let wj = w(q);
        total += wj;
        c = vec3::add(c, vec3::scale(q, wj));
    }
    let c = vec3::scale(c, 1.0 / total);
    let mut cov = [[0.0; 3]; 3];
    for q in std::iter::once(p).chain(nb.iter().map(|&j| points[j as usize])) {
        let d = vec3::sub(q, c);
        let wq = w(q) / total;
        for a in 0..3 {
            for b in 0..3 {
                cov[a][b] += wq * d[a] * d[b];
            }
        }
    }
    (c, cov, r)
}

/// The median surface variation of a sample of the points at a scale of k neighbours (found for the sample only).
fn variation(points: &[Point], tree: &kiddo::KdTree<f64, 3>, k: usize, sample: &[usize]) -> f64 {
    let mut v: Vec<f64> = sample
        .par_iter()
        .map(|&i| {
            let found = tree.nearest_n::<kiddo::SquaredEuclidean>(&points[i], k + 1);
            let near: Vec<u32> = found.iter().map(|f| f.item as u32).filter(|&j| j as usize != i).take(k).collect();
            let (_, cov, _) = moments(points, i, &near);
            let (l, _) = eigen3(cov);
            let s = l.iter().map(|x| x.max(0.0)).sum::<f64>();
            if s > 0.0 {
                l[0].max(0.0) / s
            } else {
                0.0
            }
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// A well-mixed 64-bit hash of a point's coordinates (SplitMix64's finalizer over their bits).
fn position_hash(p: &Point) -> u64 {
    let mut h = 0x9e37_79b9_7f4a_7c15u64;
    for c in p {
        h ^= (c + 0.0).to_bits();
        h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        h ^= h >> 31;
    }
    h
}

/// Projects every point onto its local moving-least-squares quadratic (see the module documentation).
pub fn denoise(points: &[Point], normals: Option<&[Point]>) -> Result<(Vec<Point>, Denoised), OperatorError> {
    let n = points.len();
    // Every choice of points below (the sample, the subsamples, the anchors) hashes the point's position, not its
    // index, so that the same cloud in another order (one shape id) is denoised the same way.
    let key: Vec<u64> = points.par_iter().map(position_hash).collect();
    // A fixed, spread sample of points to choose the scale on (every point for small clouds).
    let step = (n / 2000).max(1) as u64;
    let sample: Vec<usize> = (0..n).filter(|&i| key[i].is_multiple_of(step)).collect();
    let sample = if sample.is_empty() { (0..n).collect() } else { sample };
    let mut scales = vec![];
    let mut k = 16usize;
    // Above 256 neighbours a neighbourhood's shape is read from one point in k/256 of it (a hashed subsample,
    // so that no order of the input, such as a scanner's lines, aliases with it): the same radius, 256 points.
    let subsample = |stride: usize| {
        let keep = |i: usize| stride == 1 || key[i] >> 40 & (stride as u64 - 1) == 0;
        let chosen: Vec<u32> = (0..n as u32).filter(|&i| keep(i as usize)).collect();
        let mut tree: kiddo::KdTree<f64, 3> = kiddo::KdTree::with_capacity(chosen.len().max(1));
        for &i in &chosen {
            tree.add(&points[i as usize], u64::from(i));
        }
        (tree, chosen.len())
    };
    if n < 4 {
        return Err(OperatorError::InvalidParameter {
            name: "points",
            message: format!("{n} points; a point-cloud Laplacian needs at least 4"),
        });
    }
    // Up to 4,096 neighbours (the noise's thickness, not the count, sets the scale: a dense cloud needs more
    // neighbours for the same radius) and at most an eighth of the cloud.
    while k <= 4096 && (k == 16 || k <= n / 8) {
        let (tree, size) = subsample((k / 256).max(1));
        let per = (k / (k / 256).max(1)).min(size.saturating_sub(1)).max(3);
        scales.push((k, variation(points, &tree, per, &sample)));
        // Past a small least variation (the neighbourhoods are already flat: below 0.01, where pure noise gives
        // about 1/3) once it has risen at two scales in a row, curvature has taken over: no need to look further.
        let least = scales.iter().map(|s| s.1).fold(f64::INFINITY, f64::min);
        if least < 0.01 && scales.len() >= 3 && scales[scales.len() - 2..].iter().all(|s| s.1 > least) {
            break;
        }
        k *= 2;
    }
    let (best, _) = scales.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((16, 0.0));
    // The fits likewise draw about 256 neighbours from the subsample of one point in `stride` (fewer would leave
    // the fitted surface itself noisy by more than a dense cloud's spacing).
    let stride = (best / 256).max(1);
    let (tree, size) = subsample(stride);
    let chosen_len = size;
    let per = (best / stride).min(chosen_len.saturating_sub(1)).max(3);
    // The fits are made at anchors, one point in `every` (by the same hash: anchors are among the subsample), so
    // that about 64 anchors stand in each fit's neighbourhood; every point is projected onto the fit of its
    // nearest anchor, which holds over the whole neighbourhood (its radius is √(k/64) anchor spacings or more).
    // Below 128 neighbours every point is its own anchor.
    let every = (best / 64).max(1);
    let anchor = |i: usize| every == 1 || key[i] >> 40 & (every as u64 - 1) == 0;
    let mut anchors: Vec<u32> = (0..n as u32).filter(|&i| anchor(i as usize)).collect();
    if anchors.is_empty() {
        anchors = (0..n as u32).collect();
    }
    let every = if anchors.len() == n { 1 } else { every };
    let fit_at = |i: usize| {
        let found = tree.nearest_n::<kiddo::SquaredEuclidean>(&points[i], per + 1);
        let near: Vec<u32> = found.iter().map(|f| f.item as u32).filter(|&j| j as usize != i).take(per).collect();
        fit(points, normals, i, &near)
    };
    let fits: Vec<Fit> = anchors.par_iter().map(|&i| fit_at(i as usize)).collect();
    let mut anchor_tree: kiddo::KdTree<f64, 3> = kiddo::KdTree::with_capacity(anchors.len());
    for (a, &i) in anchors.iter().enumerate() {
        anchor_tree.add(&points[i as usize], a as u64);
    }
    // A point whose nearest anchor stands farther than half that fit's radius (its weights' width: a thin part or
    // a small piece no anchor fell in) would be projected onto a surface extrapolated beyond its data: it gets a
    // fit of its own.
    let (projected, own_fits): (Vec<Point>, Vec<bool>) = (0..n)
        .into_par_iter()
        .map(|i| {
            if every == 1 {
                return (fits[i].project(points[i]), false);
            }
            let nearest = anchor_tree.nearest_one::<kiddo::SquaredEuclidean>(&points[i]);
            let f = &fits[nearest.item as usize];
            if nearest.distance.sqrt() > 0.5 * f.r {
                (fit_at(i).project(points[i]), true)
            } else {
                (f.project(points[i]), false)
            }
        })
        .unzip();
    let own_fits = own_fits.iter().filter(|&&x| x).count();
    let mut moved: Vec<f64> = projected.iter().zip(points).map(|(f, p)| vec3::norm(vec3::sub(*f, *p))).collect();
    let mut noise: Vec<f64> = fits.iter().map(|f| f.rms).collect();
    noise.sort_by(f64::total_cmp);
    moved.sort_by(f64::total_cmp);
    let report = Denoised {
        k: best,
        surface_variation: scales,
        noise: noise[noise.len() / 2],
        moved_median: moved[moved.len() / 2],
        moved_max: moved.last().copied().unwrap_or(0.0),
        normals_used: normals.is_some(),
        anchors: anchors.len(),
        own_fits,
    };
    Ok((projected, report))
}

/// A local quadratic surface: height w = a + b u + c v + d u² + e uv + f v² over the plane through `origin`
/// spanned by (e1, e2), coordinates scaled by `r`, and the weighted RMS residual of its fit.
struct Fit {
    origin: Point,
    frame: [Point; 3],
    r: f64,
    coef: [f64; 6],
    rms: f64,
}

impl Fit {
    fn height(&self, u: f64, v: f64) -> f64 {
        let b = [1.0, u, v, u * u, u * v, v * v];
        (0..6).map(|a| self.coef[a] * b[a]).sum()
    }
    /// The point of the surface above (or below) q, along the plane's normal.
    fn project(&self, q: Point) -> Point {
        let [e1, e2, normal] = self.frame;
        let d = vec3::sub(q, self.origin);
        let (u, v) = (vec3::dot(d, e1) / self.r, vec3::dot(d, e2) / self.r);
        let h = self.height(u, v);
        vec3::add(
            self.origin,
            vec3::add(vec3::add(vec3::scale(e1, u * self.r), vec3::scale(e2, v * self.r)), vec3::scale(normal, h)),
        )
    }
}

/// The moving-least-squares quadratic around point i over its neighbours `near`.
fn fit(points: &[Point], normals: Option<&[Point]>, i: usize, near: &[u32]) -> Fit {
    let (c, cov, r) = moments(points, i, near);
    let (_, vecs) = eigen3(cov);
    let mut normal = vecs[0];
    if let Some(ns) = normals {
        // The given normals: their weighted mean orients (and, where consistent, sets) the plane.
        let mut m = ns[i];
        for &j in near {
            let nj = ns[j as usize];
            m = vec3::add(m, if vec3::dot(nj, ns[i]) < 0.0 { vec3::scale(nj, -1.0) } else { nj });
        }
        let l = vec3::norm(m);
        if l > 0.0 && l.is_finite() {
            normal = vec3::scale(m, 1.0 / l);
        }
    }
    let helper = if normal[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let e1 = vec3::cross(normal, helper);
    let e1 = vec3::scale(e1, 1.0 / vec3::norm(e1));
    let e2 = vec3::cross(normal, e1);
    // Weighted least squares (normal equations, 6 × 6).
    let p = points[i];
    let weight = |q: Point| (-vec3::dot(vec3::sub(q, p), vec3::sub(q, p)) / (0.5 * r * r)).exp();
    let mut ata = [[0.0; 6]; 6];
    let mut atb = [0.0; 6];
    let mut rows = Vec::with_capacity(near.len() + 1);
    for q in std::iter::once(p).chain(near.iter().map(|&j| points[j as usize])) {
        let d = vec3::sub(q, c);
        let (u, v, w) = (vec3::dot(d, e1) / r, vec3::dot(d, e2) / r, vec3::dot(d, normal));
        let basis = [1.0, u, v, u * u, u * v, v * v];
        let wq = weight(q);
        for a in 0..6 {
            atb[a] += wq * basis[a] * w;
            for b in 0..6 {
                ata[a][b] += wq * basis[a] * basis[b];
            }
        }
        rows.push((basis, w, wq));
    }
    let coef = solve6(ata, atb).unwrap_or([0.0; 6]);
    let f = Fit { origin: c, frame: [e1, e2, normal], r, coef, rms: 0.0 };
    let (mut ss, mut ws) = (0.0, 0.0);
    for (b, w, wq) in &rows {
        ss += wq * (w - f.height(b[1], b[2])).powi(2);
        ws += wq;
    }
    Fit { rms: (ss / ws.max(f64::MIN_POSITIVE)).sqrt(), ..f }
}
/// Points off the surface (see the module documentation).
pub struct Outliers {
    /// One flag per point: dropped.
    pub flags: Vec<bool>,
    /// The distance rule's threshold (5 × the median mean distance to the 16 nearest neighbours).
    pub threshold: f64,
    /// Points dropped by the distance rule.
    pub isolated: usize,
    /// Clumps dropped: pieces of the neighbour graph below `min_piece` points, and the points in them.
    pub clumps: usize,
    pub clump_points: usize,
    /// Points in small pieces that were kept because together they hold more than `MAX_CLUMP_SHARE` of the cloud.
    pub clumps_kept: usize,
    pub min_piece: usize,
}

/// The largest share of a cloud that may be dropped as clumps: above it the small pieces are the sampling itself.
pub const MAX_CLUMP_SHARE: f64 = 0.02;

/// Finds the points off the surface: first those far from their neighbours (the distance rule), then clumps of
/// stray points close together, which that rule cannot see: the pieces of the graph joining each point to its 16
/// nearest neighbours within the threshold that hold fewer than max(16, 1 %) of the points (Rusu et al. 2008's
/// Euclidean clustering with a minimum cluster size; a scan of several objects keeps every object above 1 %).
pub fn outliers(points: &[Point]) -> Result<Outliers, OperatorError> {
    let n = points.len();
    let nb = Neighbourhoods::knn(points, 16)?;
    let dist = |i: usize, j: u32| vec3::norm(vec3::sub(points[j as usize], points[i]));
    let mean: Vec<f64> =
        (0..n).into_par_iter().map(|i| nb.of(i).iter().map(|&j| dist(i, j)).sum::<f64>() / nb.k as f64).collect();
    let mut sorted = mean.clone();
    sorted.sort_by(f64::total_cmp);
    let threshold = 5.0 * sorted[n / 2];
    let mut flags: Vec<bool> = mean.iter().map(|&d| d > threshold).collect();
    let isolated = flags.iter().filter(|&&f| f).count();
    let mut sets = crate::geometry::topology::UnionFind::new(n);
    for i in 0..n {
        if flags[i] {
            continue;
        }
        for &j in nb.of(i) {
            if !flags[j as usize] && dist(i, j) <= threshold {
                sets.union(i as u32, j);
            }
        }
    }
    let (labels, count) = sets.labels();
    let mut size = vec![0usize; count];
    for (i, &l) in labels.iter().enumerate() {
        if !flags[i] {
            size[l as usize] += 1;
        }
    }
    let min_piece = (n / 100).max(16);
    let small: Vec<bool> = size.iter().map(|&s| s > 0 && s < min_piece).collect();
    let in_small: usize = size.iter().zip(&small).filter(|(_, &x)| x).map(|(&s, _)| s).sum();
    // Never everything, nor much: where no piece is large enough (a cloud of scattered pieces), or where the
    // small pieces together hold more than `MAX_CLUMP_SHARE` of the points (a scan whose lines lie farther apart
    // than 16 neighbours reach along them: every line a piece of its own), they are the sampling, not strays, and
    // nothing is dropped as a clump (`clumps_kept` says how many points were spared).
    let (mut clumps, mut clump_points, mut clumps_kept) = (small.iter().filter(|&&x| x).count(), 0, 0);
    if size.iter().zip(&small).all(|(&s, &x)| s == 0 || x) {
        clumps = 0;
    } else if in_small as f64 > MAX_CLUMP_SHARE * n as f64 {
        clumps = 0;
        clumps_kept = in_small;
    } else {
        for (i, &l) in labels.iter().enumerate() {
            if !flags[i] && small[l as usize] {
                flags[i] = true;
                clump_points += 1;
            }
        }
    }
    Ok(Outliers { flags, threshold, isolated, clumps, clump_points, clumps_kept, min_piece })
}

/// Solves a 6 × 6 symmetric system by Gaussian elimination with partial pivoting (None when singular).
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|i| a[i][i].abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    for col in 0..6 {
        let piv = (col..6).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-12 * scale {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..6 {
            let f = a[r][col] / a[col][col];
            for c in col..6 {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 6];
    for r in (0..6).rev() {
        let s = (r + 1..6).map(|c| a[r][c] * x[c]).sum::<f64>();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

//! The null space the operator knows: zero modes put in a spectrum exactly instead of being searched for.
//!
//! For an operator whose constants lie in the kernel ([`Kernel::Components`]: cotan, intrinsic Delaunay, robust,
//! tet, combinatorial and random-walk graph Laplacians, point clouds, the string), L 1_c = 0 for the indicator 1_c
//! of every connected component c of L's graph, so the eigenvalue 0 has one eigenvector per component; for the
//! normalized graph Laplacian the vectors are D^½ 1_c; under Dirichlet conditions only the components that kept no
//! vertex coupled to the eliminated ones. A Krylov method finds such a null space badly: a shape in 100 parts has
//! 100 equal eigenvalues, more than any block, and the iteration can miss some of them (or stall) without noticing.
//! Here they are built directly, M-orthonormal, each checked numerically (‖L z‖ small against ‖L‖), and the
//! iteration runs on their M-orthogonal complement ([`Deflation`]).
//!
//! No I/O; depends on `operators::sparse` only.

use crate::operators::sparse::{Kernel, SparsePair};
use faer::{Mat, MatRef};

/// Entries of a sparse deflation vector per thread below which [`Deflation::project`] stays on one thread (a piece
/// then streams at least 32,768 rows of W and M W, about 2 MB at b = 8, against a rayon task's few microseconds).
const PROJECT_PIECE: usize = 1 << 15;

/// A vector with few non-zeros: `values` at rows `rows`, and M times it on the same rows (a zero mode's support
/// is closed under M's pattern).
#[derive(Debug, Clone)]
pub struct SparseVector {
    pub rows: Vec<u32>,
    pub values: Vec<f64>,
    pub m_values: Vec<f64>,
}

impl SparseVector {
    /// The vector as n dense values.
    pub fn to_dense(&self, n: usize) -> Vec<f64> {
        let mut out = vec![0.0; n];
        for (&i, &v) in self.rows.iter().zip(&self.values) {
            out[i as usize] = v;
        }
        out
    }
}

/// The exact zero modes of an operator.
#[derive(Debug, Clone, Default)]
pub struct ZeroModes {
    /// Connected components of L's graph.
    pub components: usize,
    /// One M-orthonormal vector per component whose (weighted) indicator is in the kernel, in the order of the
    /// components' first rows.
    pub vectors: Vec<SparseVector>,
}

impl ZeroModes {
    pub fn len(&self) -> usize {
        self.vectors.len()
    }
    pub fn is_empty(&self) -> bool {
        self.vectors.is_empty()
    }
}

/// Largest ‖L z‖∞ / (max_i Σ_j |L_ij| · ‖z‖∞) accepted for a zero mode. Exact kernel vectors measure at rounding
/// level (10⁻¹⁶ – 10⁻¹⁴ on the shared meshes); a component whose vector fails is left to the iteration.
const KERNEL_RESIDUAL: f64 = 1e-10;

/// The zero modes the operator's [`Kernel`] names, M-orthonormalized. Components that M couples to each other
/// (possible only where an L entry is exactly zero but the M entry is not) are orthonormalized together.
pub fn zero_modes(pair: &SparsePair) -> ZeroModes {
    let Kernel::Components { weights, anchored } = &pair.kernel else {
        return ZeroModes::default();
    };
    let n = pair.n();
    let p = &pair.pattern;
    let (labels, count) = pair.components();
    let mut in_kernel = vec![true; count];
    if let Some(a) = anchored {
        for (i, &anchor) in a.iter().enumerate() {
            if anchor {
                in_kernel[labels[i] as usize] = false;
            }
        }
    }
    let w = |i: usize| weights.as_ref().map_or(1.0, |w| w[i]);
    // Rows of each component, in order.
    let mut start = vec![0usize; count + 1];
    for &l in &labels {
        start[l as usize + 1] += 1;
    }
    for c in 0..count {
        start[c + 1] += start[c];
    }
    let mut rows = vec![0u32; n];
    let mut fill = start.clone();
    for (i, &l) in labels.iter().enumerate() {
        rows[fill[l as usize]] = i as u32;
        fill[l as usize] += 1;
    }
    // ‖L z‖∞ against the operator's scale, per component.
    let row_abs_max = (0..n)
        .map(|j| (p.col_ptr[j]..p.col_ptr[j + 1]).map(|pos| pair.stiffness[pos].abs()).sum::<f64>())
        .fold(0.0, f64::max);
    for c in 0..count {
        if !in_kernel[c] {
            continue;
        }
        let members = &rows[start[c]..start[c + 1]];
        let zmax = members.iter().map(|&i| w(i as usize).abs()).fold(0.0, f64::max);
        let worst = members
            .iter()
            .map(|&j| {
                let j = j as usize;
                (p.col_ptr[j]..p.col_ptr[j + 1]).map(|pos| pair.stiffness[pos] * w(p.row_idx[pos])).sum::<f64>().abs()
            })
            .fold(0.0, f64::max);
        if !(zmax > 0.0) || !(worst <= KERNEL_RESIDUAL * row_abs_max.max(f64::MIN_POSITIVE) * zmax) {
            in_kernel[c] = false;
        }
    }
    // Components coupled by M (through entries whose L value is exactly zero) form groups.
    let mut uf = crate::geometry::topology::UnionFind::new(count);
    let mut coupled = false;
    for j in 0..n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            let (a, b) = (labels[p.row_idx[pos]], labels[j]);
            if a != b && pair.mass[pos] != 0.0 && in_kernel[a as usize] && in_kernel[b as usize] {
                uf.union(a, b);
                coupled = true;
            }
        }
    }
    let mut vectors = Vec::new();
    let m_times = |support: &[u32], values: &[f64], index: &dyn Fn(usize) -> Option<usize>| -> Vec<f64> {
        support
            .iter()
            .map(|&j| {
                let j = j as usize;
                (p.col_ptr[j]..p.col_ptr[j + 1])
                    .filter_map(|pos| index(p.row_idx[pos]).map(|k| pair.mass[pos] * values[k]))
                    .sum()
            })
            .collect()
    };
    if !coupled {
        for c in (0..count).filter(|&c| in_kernel[c]) {
            let support = rows[start[c]..start[c + 1]].to_vec();
            let values: Vec<f64> = support.iter().map(|&i| w(i as usize)).collect();
            let local = |i: usize| support.binary_search(&(i as u32)).ok();
            let m_values = m_times(&support, &values, &local);
            let norm = values.iter().zip(&m_values).map(|(a, b)| a * b).sum::<f64>().sqrt();
            vectors.push(SparseVector {
                values: values.iter().map(|v| v / norm).collect(),
                m_values: m_values.iter().map(|v| v / norm).collect(),
                rows: support,
            });
        }
        return ZeroModes { components: count, vectors };
    }
    // Rare: orthonormalize each coupled group by the Cholesky factor of its small Gram matrix G = Zᵀ M Z.
    let (group_of, groups) = uf.labels();
    for g in 0..groups as u32 {
        let members: Vec<usize> = (0..count).filter(|&c| in_kernel[c] && group_of[c] == g).collect();
        if members.is_empty() {
            continue;
        }
        let mut support: Vec<u32> =
            members.iter().flat_map(|&c| rows[start[c]..start[c + 1]].iter().copied()).collect();
        support.sort_unstable();
        let local = |i: usize| support.binary_search(&(i as u32)).ok();
        let raw: Vec<Vec<f64>> = members
            .iter()
            .map(|&c| {
                support.iter().map(|&i| if labels[i as usize] as usize == c { w(i as usize) } else { 0.0 }).collect()
            })
            .collect();
        let m_raw: Vec<Vec<f64>> = raw.iter().map(|z| m_times(&support, z, &local)).collect();
        let q = members.len();
        let gram = Mat::from_fn(q, q, |a, b| raw[a].iter().zip(&m_raw[b]).map(|(x, y)| x * y).sum::<f64>());
        let Ok(r) = super::small_dense::cholesky_lower(gram.as_ref(), faer::Par::Seq) else { continue };
        // Z R⁻ᵀ with G = R Rᵀ: column j = Σ_a Z_a (R⁻ᵀ)_{a j}.
        let mut rinv_t = Mat::<f64>::identity(q, q);
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(r.as_ref(), rinv_t.as_mut(), faer::Par::Seq);
        let rinv_t = rinv_t.transpose().to_owned();
        for j in 0..q {
            let combine = |src: &[Vec<f64>]| -> Vec<f64> {
                (0..support.len()).map(|r| (0..q).map(|a| src[a][r] * rinv_t[(a, j)]).sum()).collect()
            };
            vectors.push(SparseVector { values: combine(&raw), m_values: combine(&m_raw), rows: support.clone() });
        }
    }
    ZeroModes { components: count, vectors }
}

/// Vectors the iteration must stay M-orthogonal to: exact zero modes and, when a spectrum is repaired, the
/// eigenvectors found before (`dense`, n × p, M-orthonormal, with M times them).
pub struct Deflation<'a> {
    pub sparse: &'a [SparseVector],
    pub dense: Option<(MatRef<'a, f64>, MatRef<'a, f64>)>,
}

impl Deflation<'_> {
    /// Deflated directions.
    pub fn len(&self) -> usize {
        self.sparse.len() + self.dense.map_or(0, |(y, _)| y.ncols())
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// W ← W − Z Zᵀ M W for a row-major n × b block W with M W in `mw` (updated alike: M W − (M Z) Zᵀ M W).
    pub fn project(&self, w: &mut [f64], mw: &mut [f64], b: usize, threads: usize) {
        use rayon::prelude::*;
        assert_eq!(w.len(), mw.len(), "W and M W have the same shape");
        if b == 0 {
            return;
        }
        assert_eq!(w.len() % b, 0, "W is n × b");
        let n = w.len() / b;
        for z in self.sparse {
            let len = z.rows.len();
            // On several threads each piece sums the coefficients over its share of the vector's entries, then updates
            // its own range of rows (reading every entry and keeping those in its range).
            let pieces = if threads > 1 { threads.min(len / PROJECT_PIECE).max(1) } else { 1 };
            let sum = |(a, e): (usize, usize)| {
                let mut coef = vec![0.0; b];
                for (&i, &v) in z.rows[a..e].iter().zip(&z.values[a..e]) {
                    let row = &mw[i as usize * b..i as usize * b + b];
                    for (c, x) in coef.iter_mut().zip(row) {
                        *c += v * x;
                    }
                }
                coef
            };
            let ranges: Vec<(usize, usize)> = (0..pieces).map(|p| (p * len / pieces, (p + 1) * len / pieces)).collect();
            let parts: Vec<Vec<f64>> = if pieces > 1 {
                ranges.into_par_iter().map(sum).collect()
            } else {
                ranges.into_iter().map(sum).collect()
            };
            let coef: Vec<f64> = (0..b).map(|c| parts.iter().map(|p| p[c]).sum()).collect();
            let update = |(r0, w, mw): (usize, &mut [f64], &mut [f64])| {
                let r1 = r0 + w.len() / b;
                for ((&i, &v), &mv) in z.rows.iter().zip(&z.values).zip(&z.m_values) {
                    let i = i as usize;
                    if i < r0 || i >= r1 {
                        continue;
                    }
                    let at = (i - r0) * b;
                    for c in 0..b {
                        w[at + c] -= coef[c] * v;
                        mw[at + c] -= coef[c] * mv;
                    }
                }
            };
            if pieces > 1 {
                let rows = n.div_ceil(pieces);
                w.par_chunks_mut(rows * b)
                    .zip(mw.par_chunks_mut(rows * b))
                    .enumerate()
                    .for_each(|(p, (w, mw))| update((p * rows, w, mw)));
            } else {
                update((0, w, mw));
            }
        }
        if let Some((y, my)) = self.dense {
            assert_eq!(y.nrows(), n, "deflation vectors have one row per unknown");
            let c = super::basis_products::gram_par(y, mw, b, threads);
            super::basis_products::update_par(w, b, y, c.as_ref(), -1.0, threads);
            super::basis_products::update_par(mw, b, my, c.as_ref(), -1.0, threads);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The projection removes each sparse vector's component, w − z (zᵀ M w) and M w − M z (zᵀ M w), then the dense
    /// vectors' (w − Y Yᵀ M w, M w − (M Y) Yᵀ M w), the same on one thread as on several: two vectors on disjoint
    /// supports (one with its rows out of order) on enough rows for the pieces to split, one on a few rows (one
    /// piece), and two dense vectors.
    #[test]
    fn projection_is_the_same_on_any_threads() {
        let (n, b) = (3 * (1 << 15) + 17, 3);
        let even: Vec<u32> = (0..n as u32).filter(|i| i % 2 == 0).collect();
        let odd: Vec<u32> = (0..n as u32).filter(|i| i % 2 == 1).rev().collect();
        let vector = |rows: Vec<u32>, s: f64| SparseVector {
            values: rows.iter().map(|&i| s * (1.0 + (i % 5) as f64)).collect(),
            m_values: rows.iter().map(|&i| s * (2.0 - (i % 3) as f64)).collect(),
            rows,
        };
        let zs = vec![vector(even, 0.01), vector(odd, -0.02), vector((100..140).collect(), 0.3)];
        let y = Mat::<f64>::from_fn(n, 2, |i, j| ((i * (j + 3)) % 11) as f64 / 1e3);
        let my = Mat::<f64>::from_fn(n, 2, |i, j| ((i * (j + 5)) % 13) as f64 / 1e3);
        let w0: Vec<f64> = (0..n * b).map(|p| ((p * 13) % 17) as f64 / 5.0 - 1.5).collect();
        let mw0: Vec<f64> = (0..n * b).map(|p| ((p * 7) % 23) as f64 / 9.0 - 1.0).collect();
        // The definition, one vector after the other (each coefficient from M W after the earlier vectors).
        let (mut want_w, mut want_mw) = (w0.clone(), mw0.clone());
        for z in &zs {
            let (zd, mzd) = (z.to_dense(n), SparseVector { values: z.m_values.clone(), ..z.clone() }.to_dense(n));
            for c in 0..b {
                let coef: f64 = (0..n).map(|i| zd[i] * want_mw[i * b + c]).sum();
                for i in 0..n {
                    want_w[i * b + c] -= coef * zd[i];
                    want_mw[i * b + c] -= coef * mzd[i];
                }
            }
        }
        for c in 0..b {
            let coef: Vec<f64> = (0..2).map(|j| (0..n).map(|i| y[(i, j)] * want_mw[i * b + c]).sum()).collect();
            for i in 0..n {
                want_w[i * b + c] -= y[(i, 0)] * coef[0] + y[(i, 1)] * coef[1];
                want_mw[i * b + c] -= my[(i, 0)] * coef[0] + my[(i, 1)] * coef[1];
            }
        }
        for threads in [1usize, 2, 3] {
            let (mut w, mut mw) = (w0.clone(), mw0.clone());
            Deflation { sparse: &zs, dense: Some((y.as_ref(), my.as_ref())) }.project(&mut w, &mut mw, b, threads);
            for p in 0..n * b {
                assert!((w[p] - want_w[p]).abs() <= 1e-9 * (1.0 + want_w[p].abs()), "W at {p}, {threads} threads");
                assert!((mw[p] - want_mw[p]).abs() <= 1e-9 * (1.0 + want_mw[p].abs()), "M W at {p}, {threads} threads");
            }
        }
    }
}

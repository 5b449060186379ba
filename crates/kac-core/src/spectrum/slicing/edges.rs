//! The edges between slices: the parts' pairs in one ascending spectrum, and the Rayleigh–Ritz step on each edge's
//! neighbourhood, where a cluster may be split between two slices.

use super::*;

/// The slices' pairs in one ascending spectrum after `head`'s (the known zero modes), with each edge's neighbourhood
/// Rayleigh–Ritz'd (see the module docs). Statistics add up the slices' work; σ and the inertia are the lowest
/// slice's.
pub(super) fn stitch(
    pair: &SparsePair,
    parts: Vec<Spectrum>,
    head: Option<&Spectrum>,
    slices: &[(Window, usize)],
    control: &Control<'_>,
    threads: usize,
) -> Result<Spectrum, EigenError> {
    let n = pair.n();
    let total: usize = parts.iter().map(|p| p.values.len()).sum::<usize>() + head.map_or(0, |h| h.values.len());
    // Filled slice by slice, each slice's vectors dropped once copied: the peak holds one copy of the
    // eigenvectors and one slice's.
    // The copies run on the slices' threads.
    let mut vectors = crate::spectrum::Columns::new(n, total);
    let mut values = Vec::with_capacity(total);
    let mut stats = Stats { method: "block-lanczos", factorization: "ldlt", ..Default::default() };
    if let Some(h) = head {
        vectors.append(h.values.len(), control, threads, |j, col| {
            for (x, y) in col.iter_mut().zip(h.vectors.col(j).iter()) {
                *x = *y;
            }
        })?;
        values.extend_from_slice(&h.values);
    }
    for (i, p) in parts.into_iter().enumerate() {
        control.check()?;
        let from = p.vectors.as_ref();
        vectors.append(p.values.len(), control, threads, |j, col| {
            for (x, y) in col.iter_mut().zip(from.col(j).iter()) {
                *x = *y;
            }
        })?;
        values.extend_from_slice(&p.values);
        let ps = &p.stats;
        if i == 0 {
            stats.sigma = ps.sigma;
            stats.below_sigma = ps.below_sigma;
            stats.factor_nnz = ps.factor_nnz;
            stats.block = ps.block;
        }
        stats.subspace = stats.subspace.max(ps.subspace);
        stats.restarts += ps.restarts;
        stats.block_steps += ps.block_steps;
        stats.solves += ps.solves;
        let (t, pt) = (&mut stats.timings, &ps.timings);
        t.numeric_s += pt.numeric_s;
        t.solve_s += pt.solve_s;
        t.orthogonalize_s += pt.orthogonalize_s;
        t.rayleigh_ritz_s += pt.rayleigh_ritz_s;
        t.restart_s += pt.restart_s;
    }
    let mut s = Spectrum { values, vectors: vectors.done(), residuals: vec![], stats };
    // Each interior edge: the slices' windows meet there.
    for j in 1..slices.len() {
        control.check()?;
        let edge = slices[j].0.lo;
        let width = |w: &Window| -> f64 {
            let lo = if w.lo.is_finite() { w.lo } else { 0.0 };
            let hi = if w.hi.is_finite() { w.hi } else { s.values.last().copied().unwrap_or(lo) };
            (hi - lo).max(0.0)
        };
        let reach = EDGE_FRACTION * width(&slices[j - 1].0).min(width(&slices[j].0));
        let a = s.values.partition_point(|&v| v < edge - reach);
        let b = s.values.partition_point(|&v| v < edge + reach);
        if b > a {
            rayleigh_ritz(pair, &mut s, (a, b), threads, control)?;
        }
    }
    Ok(s)
}

/// Replaces the pairs a..b of `s` by the Ritz pairs of their span (M-orthonormal; a direction the others already
/// hold, as a pair found by both slices, is dropped), on `threads` threads.
///
/// The projected matrices Xᵀ M X and Xᵀ L X are taken eight columns at a time: each group is copied row-major once,
/// multiplied by M and L, and met by the whole of X in the basis' Gram kernel; the Ritz vectors are formed in place
/// by rows. No n × p matrix is allocated: copies of X, M X, L X and the Ritz vectors would be four per edge, and
/// allocating and filling them would cost more than the products.
pub(crate) fn rayleigh_ritz(
    pair: &SparsePair,
    s: &mut Spectrum,
    (a, b): (usize, usize),
    threads: usize,
    control: &Control<'_>,
) -> Result<(), EigenError> {
    const W: usize = 8;
    let (n, p) = (s.vectors.nrows(), b - a);
    let (mut g, mut l) = (Mat::<f64>::zeros(p, p), Mat::<f64>::zeros(p, p));
    {
        let x = s.vectors.as_ref().subcols(a, p);
        let (mut xr, mut mr, mut lr) = (vec![0.0; n * W], vec![0.0; n * W], vec![0.0; n * W]);
        let mut scratch = Vec::new();
        for c0 in (0..p).step_by(W) {
            control.check()?;
            let w = W.min(p - c0);
            for c in 0..w {
                for (i, &v) in x.col(c0 + c).iter().enumerate() {
                    xr[i * w + c] = v;
                }
            }
            let xb = MatRef::from_row_major_slice(&xr[..n * w], n, w);
            for (values, out, projected) in [(&pair.mass, &mut mr, &mut g), (&pair.stiffness, &mut lr, &mut l)] {
                let y = faer::MatMut::from_row_major_slice_mut(&mut out[..n * w], n, w);
                crate::operators::sparse::spmm(&pair.pattern, values, xb, y, &mut scratch, threads);
                let part = crate::spectrum::basis_products::gram_par(x, &out[..n * w], w, threads);
                projected.as_mut().subcols_mut(c0, w).copy_from(part.as_ref());
            }
        }
    }
    let g = Mat::from_fn(p, p, |i, j| 0.5 * (g[(i, j)] + g[(j, i)]));
    // The small eigenproblems and products on one thread (faer's `self_adjoint_eigen` and `*` would take the whole
    // pool).
    let Ok((gs, gu)) = crate::spectrum::small_dense::symmetric_eigen(g.as_ref(), faer::Par::Seq) else { return Ok(()) };
    let top = gs.iter().copied().fold(0.0, f64::max);
    let kept: Vec<usize> = (0..p).filter(|&i| gs[i] > 1e-10 * top).collect();
    let whiten = Mat::from_fn(p, kept.len(), |i, j| gu[(i, kept[j])] / gs[kept[j]].sqrt());
    let seq = |a: faer::MatRef<'_, f64>, b: faer::MatRef<'_, f64>| {
        let mut c = Mat::<f64>::zeros(a.nrows(), b.ncols());
        faer::linalg::matmul::matmul(c.as_mut(), faer::Accum::Replace, a, b, 1.0, faer::Par::Seq);
        c
    };
    let lw = seq(seq(whiten.transpose(), l.as_ref()).as_ref(), whiten.as_ref());
    let r = kept.len();
    let lw = Mat::from_fn(r, r, |i, j| 0.5 * (lw[(i, j)] + lw[(j, i)]));
    let Ok((ls, lu)) = crate::spectrum::small_dense::symmetric_eigen(lw.as_ref(), faer::Par::Seq) else {
        return Ok(());
    };
    // X ← X (whiten U₂): the r new vectors in columns a..a + r.
    let t = seq(whiten.as_ref(), lu.as_ref());
    let par = if threads > 1 { faer::Par::rayon(threads) } else { faer::Par::Seq };
    lanczos::ritz_in_place(&mut s.vectors, a, p, t.as_ref(), par, control)?;
    s.values[a..a + r].copy_from_slice(&ls[..r]);
    if r < p {
        // A direction held twice: the columns after the edge move down over the p − r dropped ones.
        let total = s.values.len() - (p - r);
        for j in a + r..total {
            crate::spectrum::copy_column(&mut s.vectors, j + (p - r), j);
        }
        s.values.drain(a + r..b);
        s.vectors.truncate(n, total);
    }
    Ok(())
}

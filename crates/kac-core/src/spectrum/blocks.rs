//! The dense path: the whole pencil, or its connected blocks one by one (the spectrum of a block-diagonal pencil
//! is the union of the blocks'), with the known zero modes in place, and a stop flag honoured between blocks and
//! around each decomposition.

use super::*;

/// Whether a problem of `n` unknowns (`free` of them left after deflation, `k` pairs wanted beyond the deflated
/// ones) is solved densely; `block` is the largest problem the dense path would factor (a component's size
/// when the components are solved one by one, see [`Blocks`]).
pub fn use_dense(method: Method, block: usize, free: usize, k: usize) -> bool {
    match method {
        Method::Dense => true,
        Method::Sparse => false,
        Method::Auto => block <= 1500 || (3 * k > free && block <= 8000) || k + 1 >= free,
    }
}

/// The connected components of L's graph when M couples none of them either: the pencil is then block diagonal
/// (after a permutation) and its spectrum the union of the blocks' spectra, so the dense path factors each
/// component alone (Σ n_c³ work instead of n³).
pub(crate) struct Blocks {
    pub(crate) labels: Vec<u32>,
    pub(crate) count: usize,
    pub(crate) largest: usize,
}

impl Blocks {
    pub(crate) fn of(pair: &SparsePair) -> Option<Blocks> {
        let (labels, count) = pair.components();
        if count < 2 {
            return None;
        }
        let p = &pair.pattern;
        for j in 0..p.n {
            for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
                if labels[p.row_idx[pos]] != labels[j] && pair.mass[pos] != 0.0 {
                    return None;
                }
            }
        }
        let mut size = vec![0usize; count];
        labels.iter().for_each(|&l| size[l as usize] += 1);
        let largest = size.iter().copied().max().unwrap_or(0);
        Some(Blocks { labels, count, largest })
    }

    /// Rows of each block, ascending.
    pub(crate) fn rows(&self) -> Vec<Vec<usize>> {
        let mut rows = vec![Vec::new(); self.count];
        for (i, &l) in self.labels.iter().enumerate() {
            rows[l as usize].push(i);
        }
        rows
    }
}

/// The dense solve (every eigenvalue is computed, so nothing can be missed), block by block where the pencil is
/// block diagonal, with the known zero modes in place of the dense solver's basis of the null space when the
/// dense solver agrees on its dimension.
pub(crate) fn dense_with_zero_modes(
    pair: &SparsePair,
    zeros: &ZeroModes,
    blocks: Option<&Blocks>,
    k: usize,
    threads: usize,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    control.phase("dense", 0, k)?;
    let mut s = match blocks {
        Some(b) => dense_by_blocks(pair, b, k, threads, control)?,
        None => dense_stoppable(pair, k, threads, &control)?,
    };
    control.check()?;
    let z = zeros.len().min(k);
    let scale = crate::spectrum::lanczos::default_sigma(pair).abs() * pair.n() as f64;
    // The dense solver's first z eigenvalues are zeros to rounding (10⁻¹⁴ of the operator's scale); its (z + 1)-th
    // is not, or the known zero modes do not span its null space and its own basis stays.
    let agrees = s.values[..z].iter().all(|l| l.abs() <= 1e-9 * scale)
        && s.values.get(zeros.len()).is_none_or(|l| l.abs() > 1e-9 * scale);
    if z > 0 && agrees {
        let head = zero_mode_spectrum(pair, zeros, z);
        s.vectors.as_mut().subcols_mut(0, z).copy_from(head.vectors.as_ref());
        s.values[..z].iter_mut().for_each(|v| *v = 0.0);
    }
    Ok(s)
}

/// [`dense::eigs_dense`], which is one decomposition that cannot stop inside (its time grows as the cube of
/// the unknowns: minutes at a few thousand): with a stop flag it runs on a thread of its own while this one watches the flag every
/// 50 ms, and a stop returns `Canceled` at once. The abandoned decomposition then finishes on its thread and
/// its result is dropped (its cores stay busy until then; the caller's worker is free). It runs on `threads` threads
/// (those of the rayon pool it is called on, or of the global pool from that thread of its own).
pub(crate) fn dense_stoppable(
    pair: &SparsePair,
    k: usize,
    threads: usize,
    control: &Control<'_>,
) -> Result<Spectrum, EigenError> {
    let par = if threads > 1 { faer::Par::rayon(threads) } else { faer::Par::Seq };
    if control.stop.is_none() || pair.n() <= 1500 {
        // No flag, or at most about half a second of work.
        return dense::eigs_dense(pair, k, par);
    }
    let owned = pair.clone();
    control.abandonable("dense", move || dense::eigs_dense(&owned, k, par))?
}

/// Every eigenpair of each block, merged: the k smallest of the union, ascending.
pub(crate) fn dense_by_blocks(
    pair: &SparsePair,
    blocks: &Blocks,
    k: usize,
    threads: usize,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    let t0 = Instant::now();
    let n = pair.n();
    let mut parts = Vec::with_capacity(blocks.count);
    for rows in blocks.rows() {
        control.check()?;
        let (pattern, mut values) =
            crate::operators::sparse::submatrix(&pair.pattern, &[&pair.stiffness, &pair.mass], &rows);
        let mass = values.pop().unwrap_or_default();
        let stiffness = values.pop().unwrap_or_default();
        let sub = SparsePair {
            pattern: std::sync::Arc::new(pattern),
            stiffness,
            mass,
            mass_is_diagonal: pair.mass_is_diagonal,
            dimension: pair.dimension,
            kernel: crate::operators::sparse::Kernel::Unknown,
        };
        let m = rows.len();
        parts.push((rows, dense_stoppable(&sub, m, threads, &control)?));
    }
    let mut order: Vec<(f64, usize, usize)> = parts
        .iter()
        .enumerate()
        .flat_map(|(b, (_, s))| s.values.iter().enumerate().map(move |(j, &v)| (v, b, j)))
        .collect();
    order.sort_by(|x, y| x.0.total_cmp(&y.0));
    order.truncate(k);
    let mut vectors = Mat::<f64>::zeros(n, order.len());
    for (c, &(_, b, j)) in order.iter().enumerate() {
        let (rows, s) = &parts[b];
        for (r, &i) in rows.iter().enumerate() {
            vectors[(i, c)] = s.vectors[(r, j)];
        }
    }
    let total = t0.elapsed().as_secs_f64();
    Ok(Spectrum {
        values: order.iter().map(|o| o.0).collect(),
        vectors,
        residuals: vec![],
        stats: Stats {
            method: "dense",
            sigma: lanczos::default_sigma(pair),
            subspace: blocks.largest,
            factor_nnz: parts.iter().map(|(r, _)| r.len() * (r.len() + 1) / 2).sum(),
            factorization: "cholesky",
            timings: Timings { iteration_s: total, total_s: total, ..Default::default() },
            ..Default::default()
        },
    })
}

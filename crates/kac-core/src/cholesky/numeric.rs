//! The numeric supernodal factorization in pieces, so that a stop flag ends it within a fraction of a second and
//! its memory is released at once. faer's own numeric factorization is one call that cannot be interrupted; this
//! is the same left-looking supernodal algorithm (George & Liu's supernodal form of left-looking Cholesky; Ng &
//! Peyton 1993, "Block sparse Cholesky algorithms on advanced uniprocessor computers", SIAM J. Sci. Comput. 14)
//! on faer's symbolic analysis, writing faer's storage (so every solve of [`super::factor::Cholesky`] reads it as
//! it reads faer's), with faer's dense kernels for the blocks. The flag is checked before every supernode, every
//! 32 updates from descendants, and between the column panels of a large supernode's dense factorization.
//!
//! On several threads, disjoint subtrees of the supernodal tree are factored side by side (see [`super::tree`]), each
//! reading and writing only its own supernodes' values, and the supernodes above them after, their dense blocks on
//! every thread; a thread whose subtree fails makes the others give up.
//!
//! LDLᵀ is without pivoting, as faer's: D on the diagonal of each supernode's diagonal block, L unit lower.

use super::tree::Split;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use std::sync::atomic::{AtomicBool, Ordering};

/// Why a factorization in pieces did not finish.
#[derive(Debug, Clone, PartialEq)]
pub enum FactorError {
    /// The stop flag was set: nothing is returned, the partial factor is dropped.
    Stopped,
    /// The matrix is not positive definite (Cholesky), or a pivot is exactly zero (LDLᵀ).
    Failed(String),
}

impl std::fmt::Display for FactorError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FactorError::Stopped => f.write_str("stopped on request"),
            FactorError::Failed(m) => f.write_str(m),
        }
    }
}

/// Columns of a supernode's dense factorization between two checks of the stop flag.
const PANEL: usize = 192;
/// Updates from descendant supernodes between two checks.
const UPDATES_PER_CHECK: usize = 32;

/// Threads for a block operation of `flops` multiply-adds: one below about a quarter of a million (spawning
/// costs more than it saves there).
fn par_for(flops: usize, par: Par) -> Par {
    if flops < 1 << 18 {
        Par::Seq
    } else {
        par
    }
}

fn stopped(stop: Option<&AtomicBool>) -> bool {
    stop.is_some_and(|s| s.load(Ordering::Relaxed))
}

/// The lower triangle of P A Pᵀ in compressed columns (rows unsorted), from a symmetric matrix given by its
/// pattern (entries with row ≥ column are read) and values; `inv[old] = new`.
fn permuted_lower(
    n: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
    values: &[f64],
    inv: Option<&[usize]>,
) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let map = |i: usize| inv.map_or(i, |p| p[i]);
    let mut count = vec![0usize; n + 1];
    for j in 0..n {
        for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
            if i >= j {
                count[map(i).min(map(j))] += 1;
            }
        }
    }
    let mut ptr = vec![0usize; n + 1];
    for c in 0..n {
        ptr[c + 1] = ptr[c] + count[c];
    }
    let mut next = ptr.clone();
    let nnz = ptr[n];
    let (mut rows, mut vals) = (vec![0usize; nnz], vec![0.0f64; nnz]);
    for j in 0..n {
        for (&i, &v) in row_idx[col_ptr[j]..col_ptr[j + 1]].iter().zip(&values[col_ptr[j]..col_ptr[j + 1]]) {
            if i >= j {
                let (a, b) = (map(i), map(j));
                let (r, c) = (a.max(b), a.min(b));
                rows[next[c]] = r;
                vals[next[c]] = v;
                next[c] += 1;
            }
        }
    }
    (ptr, rows, vals)
}

/// The numeric factor of the symmetric matrix (`col_ptr`, `row_idx`, `values`: its pattern and values in the
/// original numbering) on faer's supernodal symbolic analysis `sn` with fill-reducing permutation `inv`
/// (`inv[old] = new`; `None`: identity): LLᵀ, or LDLᵀ without pivoting when `ldlt`. The values are laid out as
/// faer lays out its supernodal factors.
#[allow(clippy::too_many_arguments)]
pub fn factor_supernodal(
    sn: &SymbolicSupernodalCholesky<usize>,
    inv: Option<&[usize]>,
    col_ptr: &[usize],
    row_idx: &[usize],
    values: &[f64],
    ldlt: bool,
    par: Par,
    stop: Option<&AtomicBool>,
) -> Result<Vec<f64>, FactorError> {
    let n = sn.nrows();
    let ns = sn.n_supernodes();
    let begin = sn.supernode_begin();
    let end = sn.supernode_end();
    let val_ptr = sn.col_ptr_for_val();
    if stopped(stop) {
        return Err(FactorError::Stopped);
    }
    let (a_ptr, a_rows, a_vals) = permuted_lower(n, col_ptr, row_idx, values, inv);
    // The supernode of every column, and each supernode's descendants (the supernodes whose pattern reaches its
    // columns), in increasing order.
    let mut owner = vec![0usize; n];
    for s in 0..ns {
        owner[begin[s]..end[s]].fill(s);
    }
    let mut descendants: Vec<Vec<usize>> = vec![Vec::new(); ns];
    for d in 0..ns {
        for &r in sn.supernode(d).pattern() {
            let s = owner[r];
            if descendants[s].last() != Some(&d) {
                descendants[s].push(d);
            }
        }
    }
    // Raised by a thread whose subtree failed, so that the others give up too.
    let abort = AtomicBool::new(false);
    let job = Job {
        sn,
        a_ptr: &a_ptr,
        a_rows: &a_rows,
        a_vals: &a_vals,
        descendants: &descendants,
        ldlt,
        stop,
        abort: &abort,
    };
    let mut l = vec![0.0f64; sn.len_val()];
    let threads = match par {
        Par::Rayon(t) => t.get(),
        Par::Seq => 1,
    };
    // Several threads: disjoint subtrees side by side (each reads and writes only its own supernodes' values, see
    // `tree`), then the supernodes above them here, their dense blocks on every thread.
    let split = (threads > 1).then(|| Split::new(sn, threads, &work_of(sn, &descendants)));
    let top: Vec<usize> = match split.flatten() {
        Some(split) => {
            use rayon::prelude::*;
            let mut ranges: Vec<(usize, usize, usize)> = split
                .parts
                .iter()
                .enumerate()
                .flat_map(|(w, part)| part.iter().map(move |&(lo, hi)| (lo, hi, w)))
                .collect();
            ranges.sort_unstable();
            // Each subtree's values, cut out of the factor in order.
            let mut work: Vec<Vec<(usize, usize, &mut [f64])>> = (0..threads).map(|_| Vec::new()).collect();
            let mut rest: &mut [f64] = &mut l;
            let mut at = 0;
            for &(lo, hi, w) in &ranges {
                let (_, tail) = std::mem::take(&mut rest).split_at_mut(val_ptr[lo] - at);
                let (mine, tail) = tail.split_at_mut(val_ptr[hi] - val_ptr[lo]);
                work[w].push((lo, hi, mine));
                rest = tail;
                at = val_ptr[hi];
            }
            let outcomes: Vec<Result<(), FactorError>> = work
                .into_par_iter()
                .map(|ranges| {
                    let mut scratch = Scratch::new(&job, n, ranges.iter().flat_map(|&(lo, hi, _)| lo..hi), Par::Seq);
                    for (lo, hi, values) in ranges {
                        for s in lo..hi {
                            if let Err(e) = job.factor(s, values, val_ptr[lo], &mut scratch, Par::Seq) {
                                abort.store(true, Ordering::Relaxed);
                                return Err(e);
                            }
                        }
                    }
                    Ok(())
                })
                .collect();
            // A failure is reported over the stops it caused in the other threads.
            if let Some(Err(failed)) = outcomes.iter().find(|r| matches!(r, Err(FactorError::Failed(_)))) {
                return Err(failed.clone());
            }
            outcomes.into_iter().collect::<Result<Vec<()>, FactorError>>()?;
            split.top
        }
        None => (0..ns).collect(),
    };
    let mut scratch = Scratch::new(&job, n, top.iter().copied(), par);
    for s in top {
        job.factor(s, &mut l[..val_ptr[s + 1]], 0, &mut scratch, par)?;
    }
    Ok(l)
}

/// The multiply-adds of factoring each supernode s (left-looking: the updates it gathers from its descendants, then
/// its own block), the weights of the tree's [`Split`].
fn work_of(sn: &SymbolicSupernodalCholesky<usize>, descendants: &[Vec<usize>]) -> Vec<f64> {
    let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
    (0..sn.n_supernodes())
        .map(|s| {
            let (c, r) = ((end[s] - begin[s]) as f64, sn.supernode(s).pattern().len() as f64);
            let gathered: f64 = descendants[s]
                .iter()
                .map(|&d| {
                    let p = sn.supernode(d).pattern();
                    let first = p.partition_point(|&x| x < begin[s]);
                    let mid = p[first..].partition_point(|&x| x < end[s]);
                    ((p.len() - first) * mid * (end[d] - begin[d])) as f64
                })
                .sum();
            gathered + c * c * c / 3.0 + c * c * r
        })
        .collect()
}

/// What every supernode's factorization reads: the structure, A's lower triangle in factor order, who updates whom.
struct Job<'a> {
    sn: &'a SymbolicSupernodalCholesky<usize>,
    a_ptr: &'a [usize],
    a_rows: &'a [usize],
    a_vals: &'a [f64],
    descendants: &'a [Vec<usize>],
    ldlt: bool,
    stop: Option<&'a AtomicBool>,
    /// Set when another thread's subtree failed.
    abort: &'a AtomicBool,
}

/// One thread's working memory for [`Job::factor`].
struct Scratch {
    /// Each pattern row's position in the supernode being factored (`usize::MAX` elsewhere).
    local: Vec<usize>,
    /// The dense kernels' scratch (sized for the largest diagonal panel).
    mem: MemBuffer,
    update: Vec<f64>,
    scaled: Vec<f64>,
    rowmap: Vec<usize>,
}

impl Scratch {
    fn new(job: &Job<'_>, n: usize, supernodes: impl Iterator<Item = usize>, par: Par) -> Self {
        let (begin, end) = (job.sn.supernode_begin(), job.sn.supernode_end());
        let largest = supernodes.map(|s| end[s] - begin[s]).max().unwrap_or(0).min(PANEL);
        let scratch = if job.ldlt {
            faer::linalg::cholesky::ldlt::factor::cholesky_in_place_scratch::<f64>(largest, par, Default::default())
        } else {
            faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(largest, par, Default::default())
        };
        Scratch {
            local: vec![usize::MAX; n],
            mem: MemBuffer::new(scratch),
            update: Vec::new(),
            scaled: Vec::new(),
            rowmap: Vec::new(),
        }
    }
}

impl Job<'_> {
    /// The stop flag, or another thread's failure.
    fn halted(&self) -> bool {
        stopped(self.stop) || self.abort.load(Ordering::Relaxed)
    }
    /// Factors supernode `s` into `l`, which holds the factor's values from offset `base` on, up to the end of
    /// `s`'s own: every descendant of `s` lies at or after `base` (its own subtree's values, or the whole factor).
    fn factor(&self, s: usize, l: &mut [f64], base: usize, w: &mut Scratch, par: Par) -> Result<(), FactorError> {
        let sn = self.sn;
        let (begin, end, val_ptr) = (sn.supernode_begin(), sn.supernode_end(), sn.col_ptr_for_val());
        let (a_ptr, a_rows, a_vals, ldlt) = (self.a_ptr, self.a_rows, self.a_vals, self.ldlt);
        if self.halted() {
            return Err(FactorError::Stopped);
        }
        let (s_start, s_end) = (begin[s], end[s]);
        let s_pattern = sn.supernode(s).pattern();
        let nc = s_end - s_start;
        let nr = nc + s_pattern.len();
        let local = &mut w.local;
        for (i, &row) in s_pattern.iter().enumerate() {
            local[row] = nc + i;
        }
        let (head, tail) = l.split_at_mut(val_ptr[s] - base);
        let block = &mut tail[..val_ptr[s + 1] - val_ptr[s]];
        // Zero already, but written before it is read: a first read of fresh memory maps the shared zero page, and
        // the write after it then replaces that mapping, which interrupts every other core running this process
        // to flush its TLB (measured: two threads factoring side by side each ran at half speed).
        block.fill(0.0);
        let mut ls = MatMut::from_column_major_slice_mut(block, nr, nc);
        // A's columns of this supernode.
        for j in s_start..s_end {
            for (&i, &v) in a_rows[a_ptr[j]..a_ptr[j + 1]].iter().zip(&a_vals[a_ptr[j]..a_ptr[j + 1]]) {
                let r = if i < s_end { i - s_start } else { local[i] };
                ls[(r, j - s_start)] += v;
            }
        }
        // Updates from every descendant d: Ls[rows, cols] −= L_d[rows] · D_d · L_d[cols]ᵀ over d's rows that fall
        // in this supernode's columns (cols) and at or below them (rows).
        for (count, &d) in self.descendants[s].iter().enumerate() {
            if count % UPDATES_PER_CHECK == UPDATES_PER_CHECK - 1 && self.halted() {
                return Err(FactorError::Stopped);
            }
            let (d_start, d_end) = (begin[d], end[d]);
            let d_pattern = sn.supernode(d).pattern();
            let dc = d_end - d_start;
            let ld = MatRef::from_column_major_slice(
                &head[val_ptr[d] - base..val_ptr[d + 1] - base],
                dc + d_pattern.len(),
                dc,
            );
            let first = d_pattern.partition_point(|&r| r < s_start);
            let mid = d_pattern[first..].partition_point(|&r| r < s_end);
            let rows = &d_pattern[first..];
            let below = ld.subrows(dc + first, rows.len());
            let cols = below.subrows(0, mid);
            // cols · D when LDLᵀ (D on the diagonal of d's diagonal block).
            // Scratch kept between updates (every entry is written before it is read).
            if w.scaled.len() < mid * dc {
                w.scaled.resize(mid * dc, 0.0);
            }
            let rhs: MatRef<'_, f64> = if ldlt {
                let mut m = MatMut::from_column_major_slice_mut(&mut w.scaled[..mid * dc], mid, dc);
                for k in 0..dc {
                    let dk = ld[(k, k)];
                    for i in 0..mid {
                        m[(i, k)] = cols[(i, k)] * dk;
                    }
                }
                MatRef::from_column_major_slice(&w.scaled[..mid * dc], mid, dc)
            } else {
                cols
            };
            if w.update.len() < rows.len() * mid {
                w.update.resize(rows.len() * mid, 0.0);
            }
            let mut u = MatMut::from_column_major_slice_mut(&mut w.update[..rows.len() * mid], rows.len(), mid);
            faer::linalg::matmul::matmul(
                u.as_mut(),
                Accum::Replace,
                below,
                rhs.transpose(),
                1.0,
                par_for(rows.len() * mid * dc, par),
            );
            // Scattered into the supernode's rows: a row map for this descendant, then column by column.
            w.rowmap.clear();
            w.rowmap.extend(rows.iter().map(|&r| if r < s_end { r - s_start } else { local[r] }));
            let u = u.rb();
            for c in 0..mid {
                let target = ls.rb_mut().col_mut(rows[c] - s_start).try_as_col_major_mut().expect("contiguous");
                let target = target.as_slice_mut();
                let source = u.col(c).try_as_col_major().expect("contiguous").as_slice();
                for (&row, &x) in w.rowmap[c..].iter().zip(&source[c..]) {
                    target[row] -= x;
                }
            }
        }
        factor_block(ls.as_mut(), nc, s_start, ldlt, par, MemStack::new(&mut w.mem), self.stop)?;
        for &row in s_pattern {
            local[row] = usize::MAX;
        }
        Ok(())
    }
}

/// Factors a supernode's block (nr × nc: the diagonal block on top, the pattern's rows below) in column panels:
/// each panel's diagonal block by faer's dense kernel, the rows below it by a triangular solve, the columns to its
/// right updated; the stop flag between panels. The strict upper triangle of the diagonal block is left zero.
fn factor_block(
    mut ls: MatMut<'_, f64>,
    nc: usize,
    first_column: usize,
    ldlt: bool,
    par: Par,
    stack: &mut MemStack,
    stop: Option<&AtomicBool>,
) -> Result<(), FactorError> {
    let nr = ls.nrows();
    let mut c0 = 0;
    while c0 < nc {
        if c0 > 0 && stopped(stop) {
            return Err(FactorError::Stopped);
        }
        let c1 = (c0 + PANEL).min(nc);
        let w = c1 - c0;
        let par = par_for(w * w * (nr - c0), par);
        {
            let diag = ls.rb_mut().submatrix_mut(c0, c0, w, w);
            let failed = if ldlt {
                faer::linalg::cholesky::ldlt::factor::cholesky_in_place(
                    diag,
                    LdltRegularization::default(),
                    par,
                    stack,
                    Default::default(),
                )
                .err()
                .map(|e| match e {
                    faer::linalg::cholesky::ldlt::factor::LdltError::ZeroPivot { index } => {
                        format!("zero pivot (ZeroPivot {{ index: {} }})", first_column + c0 + index)
                    }
                })
            } else {
                faer::linalg::cholesky::llt::factor::cholesky_in_place(
                    diag,
                    LltRegularization::default(),
                    par,
                    stack,
                    Default::default(),
                )
                .err()
                .map(|e| match e {
                    faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } => format!(
                        "the matrix is not positive definite (NonPositivePivot {{ index: {} }})",
                        first_column + c0 + index
                    ),
                })
            };
            if let Some(m) = failed {
                return Err(FactorError::Failed(m));
            }
        }
        // The rows below the panel's diagonal block: B ← B L_p⁻ᵀ (then D_p⁻¹ for LDLᵀ).
        if c1 < nr {
            let (top, bottom) = ls.rb_mut().split_at_row_mut(c1);
            let lp = top.rb().submatrix(c0, c0, w, w);
            let mut b = bottom.subcols_mut(c0, w);
            if ldlt {
                faer::linalg::triangular_solve::solve_unit_lower_triangular_in_place(
                    lp,
                    b.rb_mut().transpose_mut(),
                    par,
                );
                for k in 0..w {
                    let inv_d = 1.0 / lp[(k, k)];
                    for i in 0..b.nrows() {
                        b[(i, k)] *= inv_d;
                    }
                }
            } else {
                faer::linalg::triangular_solve::solve_lower_triangular_in_place(lp, b.rb_mut().transpose_mut(), par);
            }
        }
        // The columns to the right: Ls[c1.., c1..nc] −= B · D_p · B[..nc − c1]ᵀ.
        if c1 < nc {
            let rows = nr - c1;
            // The panel's columns and the ones to its right are disjoint: read one, write the other.
            let (left, mut right) = ls.rb_mut().split_at_col_mut(c1);
            let b = left.rb().submatrix(c1, c0, rows, w);
            let scaled = ldlt.then(|| {
                let d: Vec<f64> = (0..w).map(|k| left[(c0 + k, c0 + k)]).collect();
                Mat::from_fn(nc - c1, w, |i, k| b[(i, k)] * d[k])
            });
            // Column block by column block, from each block's diagonal down: the lower triangle only.
            let mut j0 = 0;
            while j0 < nc - c1 {
                let j1 = (j0 + PANEL).min(nc - c1);
                let target = right.rb_mut().submatrix_mut(c1 + j0, j0, rows - j0, j1 - j0);
                let lhs = b.subrows(j0, rows - j0);
                let rhs = match &scaled {
                    Some(m) => m.as_ref().subrows(j0, j1 - j0),
                    None => b.subrows(j0, j1 - j0),
                };
                faer::linalg::matmul::matmul(target, Accum::Add, lhs, rhs.transpose(), -1.0, par);
                j0 = j1;
            }
        }
        c0 = c1;
    }
    // The diagonal block's strict upper triangle holds nothing (the trailing updates wrote there).
    for j in 1..nc {
        for i in 0..j {
            ls[(i, j)] = 0.0;
        }
    }
    Ok(())
}

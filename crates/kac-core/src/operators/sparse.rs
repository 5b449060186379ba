//! Sparse symmetric storage for operator pairs (L, M): one compressed-column pattern (full storage, both
//! triangles, rows sorted, diagonal always present) shared by the stiffness and mass values, so that
//! L − σM for any σ and either mass has the same pattern and one symbolic Cholesky analysis serves them all.

use faer::reborrow::ReborrowMut;
use faer::sparse::SparseColMatRef;
use rayon::prelude::*;
use std::sync::Arc;

// The pattern is vocabulary below the operators and the readers and writers (`crate::pattern`).
pub use crate::pattern::Pattern;

/// Stiffness and mass on one pattern.
#[derive(Debug, Clone)]
pub struct SparsePair {
    pub pattern: Arc<Pattern>,
    /// L: symmetric positive semidefinite stiffness.
    pub stiffness: Vec<f64>,
    /// M: symmetric positive definite mass (zeros off the diagonal when lumped).
    pub mass: Vec<f64>,
    pub mass_is_diagonal: bool,
    /// Dimension d of the domain the operator discretizes, whose measure (length, area, volume) the mass matrix
    /// sums to: 1 for strings, 2 for surfaces and point clouds, 3 for tetrahedral meshes; `None` for graphs.
    /// The eigensolver reads Weyl's law with it to place its shift (see `spectrum::lanczos::weyl_shift`).
    pub dimension: Option<u8>,
    /// What is known of L's null space; the eigensolver puts these zero modes in its result exactly and
    /// iterates only on their M-orthogonal complement (see `spectrum::null_space`).
    pub kernel: Kernel,
}

/// L's null space as the operator knows it.
#[derive(Debug, Clone, PartialEq)]
pub enum Kernel {
    /// Nothing is known: zero eigenvalues are found like any other.
    Unknown,
    /// L w_c = 0 for the restriction w_c of a per-vertex weight vector w to each connected component c of L's
    /// graph (its non-zero off-diagonal entries) that holds no anchored vertex. `weights`: w, all ones when
    /// `None` (operators whose constants lie in the kernel); `anchored`: vertices that lost a coupling when
    /// Dirichlet vertices were eliminated (their component's constant is no longer in the kernel).
    Components { weights: Option<Arc<Vec<f64>>>, anchored: Option<Arc<Vec<bool>>> },
}

impl Kernel {
    /// Constants on each connected component.
    pub const CONSTANTS: Kernel = Kernel::Components { weights: None, anchored: None };
}

/// Connected components of the graph of a symmetric matrix's non-zero off-diagonal entries: a label per row
/// (numbered in order of each component's first row) and the count. For a Laplacian with constants in its
/// kernel, the count is the multiplicity of the eigenvalue 0.
pub fn components(p: &Pattern, values: &[f64]) -> (Vec<u32>, usize) {
    let mut uf = crate::geometry::topology::UnionFind::new(p.n);
    for j in 0..p.n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            let i = p.row_idx[pos];
            if i < j && values[pos] != 0.0 {
                uf.union(i as u32, j as u32);
            }
        }
    }
    uf.labels()
}

impl SparsePair {
    pub fn n(&self) -> usize {
        self.pattern.n
    }
    pub fn l(&self) -> SparseColMatRef<'_, usize, f64> {
        SparseColMatRef::new(self.pattern.faer(), &self.stiffness)
    }
    pub fn m(&self) -> SparseColMatRef<'_, usize, f64> {
        SparseColMatRef::new(self.pattern.faer(), &self.mass)
    }
    /// Values of L − σ·M on the shared pattern.
    pub fn shifted(&self, sigma: f64) -> Vec<f64> {
        self.stiffness.iter().zip(&self.mass).map(|(l, m)| l - sigma * m).collect()
    }
    /// The diagonal of M.
    pub fn mass_diagonal(&self) -> Vec<f64> {
        (0..self.n()).map(|j| self.mass[self.pattern.diag_pos(j)]).collect()
    }
    /// Connected components of L's graph (see [`components`]).
    pub fn components(&self) -> (Vec<u32>, usize) {
        components(&self.pattern, &self.stiffness)
    }
    /// Non-zero count of L (off-diagonal entries that are stored).
    pub fn nnz(&self) -> usize {
        self.pattern.nnz()
    }
}

/// y = A·x on `threads` threads, one contiguous range of rows each (one thread below 8,192 rows; 0: the current
/// pool's threads), for a solve that must keep to the threads it was given.
pub fn matvec_on(p: &Pattern, values: &[f64], x: &[f64], y: &mut [f64], threads: usize) {
    let threads = if threads == 0 { rayon::current_num_threads() } else { threads };
    let n = y.len();
    let parts = threads.min(n / 4096).max(1);
    let rows = |j0: usize, out: &mut [f64]| {
        for (k, yj) in out.iter_mut().enumerate() {
            let j = j0 + k;
            let (a, b) = (p.col_ptr[j], p.col_ptr[j + 1]);
            *yj = p.row_idx[a..b].iter().zip(&values[a..b]).map(|(&i, v)| v * x[i]).sum();
        }
    };
    if parts == 1 {
        return rows(0, y);
    }
    let per = n.div_ceil(parts);
    y.par_chunks_mut(per).enumerate().for_each(|(c, out)| rows(c * per, out));
}

/// y = A·x for a symmetric matrix stored in full on `p`, on every thread of the current pool.
pub fn matvec(p: &Pattern, values: &[f64], x: &[f64], y: &mut [f64]) {
    matvec_on(p, values, x, y, 0);
}

/// Assembles symmetric matrices from off-diagonal contributions.
///
/// `off` holds (i, j, values) with i ≠ j, each pair once (the assembler mirrors it); duplicates are summed.
/// `diag` holds the diagonal of each matrix (dense). Returns the pattern (with every diagonal entry) and the
/// value arrays, one per matrix. Counting sort by column, then a small sort per column, in parallel.
pub fn assemble<const K: usize>(n: usize, off: &[(u32, u32, [f64; K])], diag: [&[f64]; K]) -> (Pattern, [Vec<f64>; K]) {
    // Counting sort of both (i, j) and (j, i) by column.
    let mut count = vec![0usize; n + 1];
    for &(i, j, _) in off {
        count[i as usize + 1] += 1;
        count[j as usize + 1] += 1;
    }
    for c in 0..n {
        count[c + 1] += count[c];
    }
    let mut fill = count.clone();
    let mut bucket: Vec<(u32, [f64; K])> = vec![(0, [0.0; K]); 2 * off.len()];
    for &(i, j, v) in off {
        bucket[fill[j as usize]] = (i, v);
        fill[j as usize] += 1;
        bucket[fill[i as usize]] = (j, v);
        fill[i as usize] += 1;
    }
    // Per column: sort rows, merge duplicates; count the entries kept (+1 for the diagonal).
    let mut slices: Vec<&mut [(u32, [f64; K])]> = Vec::with_capacity(n);
    let mut rest: &mut [(u32, [f64; K])] = &mut bucket;
    for c in 0..n {
        let (a, b) = rest.split_at_mut(count[c + 1] - count[c]);
        slices.push(a);
        rest = b;
    }
    let kept: Vec<usize> = slices
        .par_iter_mut()
        .map(|s| {
            s.sort_unstable_by_key(|e| e.0);
            let mut w = 0;
            for r in 0..s.len() {
                if w > 0 && s[w - 1].0 == s[r].0 {
                    for k in 0..K {
                        s[w - 1].1[k] += s[r].1[k];
                    }
                } else {
                    s[w] = s[r];
                    w += 1;
                }
            }
            w
        })
        .collect();
    let mut col_ptr = vec![0usize; n + 1];
    for c in 0..n {
        col_ptr[c + 1] = col_ptr[c] + kept[c] + 1;
    }
    let nnz = col_ptr[n];
    let mut row_idx = vec![0usize; nnz];
    let mut vals: [Vec<f64>; K] = std::array::from_fn(|_| vec![0.0; nnz]);
    // Write columns (sequential writes into disjoint ranges).
    {
        let mut rows_rest: &mut [usize] = &mut row_idx;
        let mut val_rest: [&mut [f64]; K] = vals.each_mut().map(|v| v.as_mut_slice());
        let mut jobs = Vec::with_capacity(n);
        for c in 0..n {
            let len = kept[c] + 1;
            let (r, rr) = rows_rest.split_at_mut(len);
            rows_rest = rr;
            let mut vs: [&mut [f64]; K] = std::array::from_fn(|_| &mut [][..]);
            for k in 0..K {
                let taken = std::mem::take(&mut val_rest[k]);
                let (a, b) = taken.split_at_mut(len);
                vs[k] = a;
                val_rest[k] = b;
            }
            jobs.push((c, r, vs));
        }
        jobs.into_par_iter().zip(slices.into_par_iter()).for_each(|((c, rows, vs), s)| {
            let s = &s[..kept[c]];
            let mut w = 0;
            let mut placed = false;
            for e in s {
                if !placed && e.0 as usize > c {
                    rows[w] = c;
                    for k in 0..K {
                        vs[k][w] = diag[k][c];
                    }
                    w += 1;
                    placed = true;
                }
                rows[w] = e.0 as usize;
                for k in 0..K {
                    vs[k][w] = e.1[k];
                }
                w += 1;
            }
            if !placed {
                rows[w] = c;
                for k in 0..K {
                    vs[k][w] = diag[k][c];
                }
            }
        });
    }
    (Pattern { n, col_ptr, row_idx }, vals)
}

/// The principal submatrix on `keep` (sorted indices): pattern and values of each matrix.
pub fn submatrix(p: &Pattern, values: &[&[f64]], keep: &[usize]) -> (Pattern, Vec<Vec<f64>>) {
    let mut new_index = vec![usize::MAX; p.n];
    for (k, &i) in keep.iter().enumerate() {
        new_index[i] = k;
    }
    let mut col_ptr = vec![0usize];
    let mut row_idx = Vec::new();
    let mut out: Vec<Vec<f64>> = values.iter().map(|_| Vec::new()).collect();
    for &j in keep {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            let ni = new_index[p.row_idx[pos]];
            if ni != usize::MAX {
                row_idx.push(ni);
                for (o, v) in out.iter_mut().zip(values) {
                    o.push(v[pos]);
                }
            }
        }
        col_ptr.push(row_idx.len());
    }
    (Pattern { n: keep.len(), col_ptr, row_idx }, out)
}

/// Rows `j0..` of Y = A·X for B right-hand sides stored row-major (`xr`), compiled for AVX-512 (eight or more
/// columns) or AVX2 + FMA when the CPU has them (checked at run time).
fn spmm_rows_dispatch<const B: usize>(p: &Pattern, values: &[f64], xr: &[f64], out: &mut [f64], j0: usize) {
    #[inline(always)]
    fn rows<const B: usize, const FMA: bool>(p: &Pattern, values: &[f64], xr: &[f64], out: &mut [f64], j0: usize) {
        for (k, row) in out.chunks_exact_mut(B).enumerate() {
            let j = j0 + k;
            let mut acc = [0.0f64; B];
            for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
                let a = values[pos];
                let r = p.row_idx[pos] * B;
                let xi: &[f64; B] = xr[r..r + B].try_into().expect("a row of B values");
                for t in 0..B {
                    acc[t] = if FMA { a.mul_add(xi[t], acc[t]) } else { acc[t] + a * xi[t] };
                }
            }
            row.copy_from_slice(&acc);
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma")]
        fn avx2<const B: usize>(p: &Pattern, values: &[f64], xr: &[f64], out: &mut [f64], j0: usize) {
            rows::<B, true>(p, values, xr, out, j0)
        }
        #[target_feature(enable = "avx512f")]
        fn avx512<const B: usize>(p: &Pattern, values: &[f64], xr: &[f64], out: &mut [f64], j0: usize) {
            rows::<B, true>(p, values, xr, out, j0)
        }
        use crate::simd::Isa;
        match Isa::detect() {
            // SAFETY: the CPU has AVX-512F (`Isa::detect` checked it); the body indexes with bounds checks.
            Isa::Avx512 if B >= 8 => return unsafe { avx512::<B>(p, values, xr, out, j0) },
            // SAFETY: the CPU has AVX2 + FMA (`Isa::detect` checked it; AVX-512 CPUs count as such only with AVX2 +
            // FMA too); the body indexes with bounds checks.
            Isa::Avx512 | Isa::Avx2 => return unsafe { avx2::<B>(p, values, xr, out, j0) },
            Isa::Scalar => {}
        }
    }
    rows::<B, false>(p, values, xr, out, j0)
}

/// Y = A·X for a symmetric A on `p` and a block X (n × b, column-major): X is copied to row-major so each entry
/// of A meets b contiguous values; rows of Y are computed on `threads` threads, each on one contiguous range of
/// rows (on one thread below 2,048 rows; 0: the current pool's threads), so a solve given t threads of a shared
/// pool keeps to t. `scratch` holds both row-major copies; it grows once and is reused.
///
/// # Panics
/// If X is not `p.n` rows, Y not the shape of X, or `values` not one value per stored entry of `p`. X and Y may be
/// any views (strided, reversed, transposed).
pub fn spmm(
    p: &Pattern,
    values: &[f64],
    x: faer::MatRef<'_, f64>,
    mut y: faer::MatMut<'_, f64>,
    scratch: &mut Vec<f64>,
    threads: usize,
) {
    let (n, b) = (x.nrows(), x.ncols());
    assert_eq!(n, p.n, "spmm: X must have one row per row of A");
    assert_eq!((y.nrows(), y.ncols()), (n, b), "spmm: Y must have the shape of X");
    assert_eq!(values.len(), p.nnz(), "spmm: one value per stored entry of A");
    let nb = n.checked_mul(b).expect("spmm: n × b block too large");
    // Row i at offset i·b, entries contiguous: (column stride 1 or one column) and (row stride b or one row).
    let row_major = |rs: isize, cs: isize| (b == 1 || cs == 1) && (n == 1 || rs == b as isize);
    if row_major(x.row_stride(), x.col_stride()) && row_major(y.row_stride(), y.col_stride()) {
        // Both blocks already row-major (the eigensolver's layout): no transposes.
        // SAFETY: X is n × b, and the `row_major` check (column stride 1 or one column, row stride b or one row)
        // puts its entry (i, c) at offset i·b + c: the n·b values from the pointer are exactly its entries.
        let xr = unsafe { std::slice::from_raw_parts(x.as_ptr(), nb) };
        // SAFETY: as for X, Y being n × b by the `assert_eq!` on its shape above; `y` is borrowed mutably for this
        // call, so no other reference (`x` included) reaches its entries.
        let yr = unsafe { std::slice::from_raw_parts_mut(y.rb_mut().as_ptr_mut(), nb) };
        spmm_row_major(p, values, xr, yr, b, threads);
        return;
    }
    let both = nb.checked_mul(2).expect("spmm: n × b block too large");
    if scratch.len() < both {
        scratch.resize(both, 0.0);
    }
    let (xr, yr) = scratch[..both].split_at_mut(nb);
    // Transposes in tiles of 64 rows: each column's run is read contiguously and each row-major row written
    // whole (column by column over all n rows wrote one value per cache line: most of the product's time).
    for i0 in (0..n).step_by(64) {
        let i1 = n.min(i0 + 64);
        for c in 0..b {
            let col = x.col(c);
            for i in i0..i1 {
                xr[i * b + c] = col[i];
            }
        }
    }
    spmm_row_major(p, values, xr, yr, b, threads);
    for i0 in (0..n).step_by(64) {
        let i1 = n.min(i0 + 64);
        for c in 0..b {
            let mut col = y.rb_mut().col_mut(c);
            for i in i0..i1 {
                col[i] = yr[i * b + c];
            }
        }
    }
}

/// Y = A·X for blocks stored row-major (row i of X at `xr[i·b..(i + 1)·b]`), on `threads` threads by contiguous
/// ranges of rows.
fn spmm_row_major(p: &Pattern, values: &[f64], xr: &[f64], yr: &mut [f64], b: usize, threads: usize) {
    let n = p.n;
    let threads = if threads == 0 { rayon::current_num_threads() } else { threads };
    let parts = threads.min(n / 1024).max(1);
    if parts == 1 {
        return spmm_rows(p, values, xr, yr, 0, b);
    }
    let mut pieces: Vec<(usize, &mut [f64])> = Vec::with_capacity(parts);
    let mut rest = yr;
    for i in 0..parts {
        let (a, e) = (i * n / parts, (i + 1) * n / parts);
        let (head, tail) = rest.split_at_mut((e - a) * b);
        pieces.push((a, head));
        rest = tail;
    }
    pieces.into_par_iter().with_max_len(1).for_each(|(j0, out)| spmm_rows(p, values, xr, out, j0, b));
}

/// Rows `j0..` of Y = A·X (as many as `out` holds) for blocks stored row-major.
fn spmm_rows(p: &Pattern, values: &[f64], xr: &[f64], out: &mut [f64], j0: usize, b: usize) {
    #[cfg(test)]
    tests::saw_rows(values);
    match b {
        8 => spmm_rows_dispatch::<8>(p, values, xr, out, j0),
        16 => spmm_rows_dispatch::<16>(p, values, xr, out, j0),
        _ => {
            for (k, row) in out.chunks_mut(b).enumerate() {
                let j = j0 + k;
                row.fill(0.0);
                for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
                    let a = values[pos];
                    let xi = &xr[p.row_idx[pos] * b..p.row_idx[pos] * b + b];
                    for (r, xv) in row.iter_mut().zip(xi) {
                        *r += a * xv;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;

    /// The address of the values whose block products are recorded (0: none), and the pool thread of every range of
    /// rows such a product ran; one test at a time watches (`ONE`).
    static WATCHED: AtomicUsize = AtomicUsize::new(0);
    static SEEN: Mutex<Vec<Option<usize>>> = Mutex::new(Vec::new());
    static ONE: Mutex<()> = Mutex::new(());

    pub(super) fn saw_rows(values: &[f64]) {
        if values.as_ptr() as usize == WATCHED.load(Ordering::SeqCst) {
            SEEN.lock().unwrap().push(rayon::current_thread_index());
        }
    }

    /// Runs `f`, and gives with its result the pool thread of every range of rows of each block product with
    /// `values` that `f` ran.
    pub(crate) fn ranges_of<T>(values: &[f64], f: impl FnOnce() -> T) -> (T, Vec<Option<usize>>) {
        let _one = ONE.lock().unwrap_or_else(|e| e.into_inner());
        SEEN.lock().unwrap().clear();
        WATCHED.store(values.as_ptr() as usize, Ordering::SeqCst);
        let out = f();
        WATCHED.store(0, Ordering::SeqCst);
        (out, std::mem::take(&mut *SEEN.lock().unwrap()))
    }

    /// A block product given two threads of a pool of four makes exactly two ranges of rows, on at most two
    /// threads, every time, and gives the product it gives on one thread. 400,000 rows: enough work that the pool's
    /// idle threads would take ranges of rows if they were offered (splitting over the whole pool would make
    /// hundreds of ranges on three or four threads).
    #[test]
    fn a_block_product_keeps_to_the_threads_given() {
        let n: usize = 400_000;
        // The path graph's Laplacian: 2 on the diagonal, −1 beside it.
        let mut col_ptr = vec![0];
        let (mut row_idx, mut values) = (Vec::new(), Vec::new());
        for j in 0..n {
            for i in j.saturating_sub(1)..(j + 2).min(n) {
                row_idx.push(i);
                values.push(if i == j { 2.0 } else { -1.0 });
            }
            col_ptr.push(row_idx.len());
        }
        let p = super::Pattern { n, col_ptr, row_idx };
        let x = faer::Mat::from_fn(n, 8, |i, c| ((i * 7 + c * 13) % 17) as f64);
        let mut one = faer::Mat::<f64>::zeros(n, 8);
        super::spmm(&p, &values, x.as_ref(), one.as_mut(), &mut Vec::new(), 1);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        for _ in 0..20 {
            let mut two = faer::Mat::<f64>::zeros(n, 8);
            let ((), seen) = ranges_of(&values, || {
                pool.install(|| super::spmm(&p, &values, x.as_ref(), two.as_mut(), &mut Vec::new(), 2))
            });
            assert_eq!(one, two);
            assert_eq!(seen.len(), 2, "ranges of rows: {seen:?}");
            let threads: std::collections::HashSet<_> = seen.into_iter().collect();
            assert!(threads.len() <= 2, "threads used: {threads:?}");
        }
        // The product itself: row 0 is 2x₀ − x₁, an inner row −x_{i−1} + 2xᵢ − x_{i+1}.
        for c in 0..8 {
            assert_eq!(one[(0, c)], 2.0 * x[(0, c)] - x[(1, c)]);
            assert_eq!(one[(500, c)], -x[(499, c)] + 2.0 * x[(500, c)] - x[(501, c)]);
        }
    }
}

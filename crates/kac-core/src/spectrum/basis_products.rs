//! The eigensolver's products of its tall basis V (n × m, column-major: faer's `Mat` layout) with a work block
//! (n × b, row-major: row i at `[i·b, (i + 1)·b)`): the Gram product C = Vᵀ Y and the update W ← W + α V C, the two
//! passes of a classical Gram–Schmidt step and most of the sparse eigensolver's orthogonalization time.
//!
//! Both stream V exactly once, in chunks of rows small enough that the block's rows stay in cache while a few
//! columns of V pass by, with the accumulators (Gram) or the coefficients (update) of those columns held in
//! registers. faer's general product packs V into its own buffers first, a second trip through memory for an
//! operand read only once, which takes it nearly twice the kernels' time (`cargo bench -p kac-core --bench
//! eigen_kernels` measures both). The kernels cover block widths 4, 8 and 16 on CPUs with AVX2 and FMA, and use
//! AVX-512 for widths 8 and 16 where the CPU has it (checked at run time; twice the lanes per instruction); other
//! widths and CPUs use faer's product. Nothing here knows about Lanczos.

pub use crate::simd::Isa;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// Rows per chunk: 1024 rows of an 8-wide block are 64 KiB, which stay in L2 while the columns of V stream by
/// (measured best of 256, 512, 1024 and 2048 at 10k–164k rows).
const ROWS: usize = 1024;

/// The kernels' view of V when they apply: a width they cover, a non-empty V whose columns run forward in memory
/// (see [`Columns::new`]; reversed and row-strided views go to faer), a CPU with AVX2 and FMA at least.
#[cfg(target_arch = "x86_64")]
fn kernel_columns(v: MatRef<'_, f64>, b: usize, isa: Isa) -> Option<Columns<'_>> {
    let applies = matches!(b, 4 | 8 | 16) && v.nrows() > 0 && v.ncols() > 0 && isa != Isa::Scalar && isa.supported();
    if applies {
        Columns::new(v)
    } else {
        None
    }
}

/// n·b, the length of a row-major n × b block; panics (rather than wrapping) when it overflows.
fn block_len(n: usize, b: usize) -> usize {
    n.checked_mul(b).expect("n × b block too large")
}

/// C = Vᵀ Y for V (n × m) and Y row-major n × b; C is m × b.
pub fn gram(v: MatRef<'_, f64>, y: &[f64], b: usize) -> Mat<f64> {
    gram_with(v, y, b, Isa::detect())
}

/// W ← W + α V C for V (n × m), C (m × b) and W row-major n × b.
pub fn update(w: &mut [f64], b: usize, v: MatRef<'_, f64>, c: MatRef<'_, f64>, alpha: f64) {
    update_with(w, b, v, c, alpha, Isa::detect())
}

/// Rows below which a product stays on one thread (the split's overhead would outweigh the work).
const PARALLEL_ROWS: usize = 8 * ROWS;

/// Row ranges of about equal length, one per thread, for `n` rows.
fn row_ranges(n: usize, threads: usize) -> Vec<(usize, usize)> {
    let parts = threads.min(n / (PARALLEL_ROWS / 2)).max(1);
    (0..parts).map(|i| (i * n / parts, (i + 1) * n / parts)).collect()
}

/// [`gram`] on `threads` threads: each takes a range of rows, and the partial products are summed (V is streamed
/// once in all, each core reading its share).
pub fn gram_par(v: MatRef<'_, f64>, y: &[f64], b: usize, threads: usize) -> Mat<f64> {
    let (n, m) = (v.nrows(), v.ncols());
    if threads <= 1 || n < PARALLEL_ROWS {
        return gram(v, y, b);
    }
    assert_eq!(y.len(), block_len(n, b), "Y must be n × b row-major");
    let parts = by_rows(n, threads, |a, e| gram(v.subrows(a, e - a), &y[a * b..e * b], b));
    let mut out = Mat::<f64>::zeros(m, b);
    for p in &parts {
        out += p;
    }
    out
}

/// [`update`] on `threads` threads, each on a range of rows of W and V.
pub fn update_par(w: &mut [f64], b: usize, v: MatRef<'_, f64>, c: MatRef<'_, f64>, alpha: f64, threads: usize) {
    use rayon::prelude::*;
    let n = v.nrows();
    if threads <= 1 || n < PARALLEL_ROWS {
        return update(w, b, v, c, alpha);
    }
    assert_eq!(w.len(), block_len(n, b), "W must be n × b row-major");
    let ranges = row_ranges(n, threads);
    let mut pieces: Vec<(usize, &mut [f64])> = Vec::with_capacity(ranges.len());
    let mut rest = w;
    for &(a, e) in &ranges {
        let (head, tail) = rest.split_at_mut((e - a) * b);
        pieces.push((a, head));
        rest = tail;
    }
    pieces.into_par_iter().for_each(|(a, piece)| {
        let rows = piece.len() / b;
        update(piece, b, v.subrows(a, rows), c, alpha);
    });
}

/// `part(a, e)` for about equal ranges of `n` rows, one per thread (one range below [`PARALLEL_ROWS`] rows or on
/// one thread), in the ranges' order.
fn by_rows<T: Send>(n: usize, threads: usize, part: impl Fn(usize, usize) -> T + Sync) -> Vec<T> {
    use rayon::prelude::*;
    if threads <= 1 || n < PARALLEL_ROWS {
        return vec![part(0, n)];
    }
    row_ranges(n, threads).into_par_iter().map(|(a, e)| part(a, e)).collect()
}

/// DST = SRC for two row-major n × b blocks, on `threads` threads by equal pieces (one below [`PARALLEL_ROWS`]
/// rows or on one thread).
pub fn copy_par(dst: &mut [f64], src: &[f64], b: usize, threads: usize) {
    use rayon::prelude::*;
    assert_eq!(dst.len(), src.len(), "copy_par: blocks of different lengths");
    if threads <= 1 || dst.len() / b.max(1) < PARALLEL_ROWS {
        dst.copy_from_slice(src);
        return;
    }
    let piece = dst.len().div_ceil(threads);
    dst.par_chunks_mut(piece).zip(src.par_chunks(piece)).for_each(|(d, s)| d.copy_from_slice(s));
}

/// The column-wise inner products ⟨x_c, y_c⟩ of two row-major n × b blocks (the diagonal of Xᵀ Y), on `threads`
/// threads by ranges of rows.
pub fn col_dots_par(x: &[f64], y: &[f64], b: usize, threads: usize) -> Vec<f64> {
    let n = x.len() / b.max(1);
    assert_eq!((x.len(), y.len()), (block_len(n, b), block_len(n, b)), "X and Y must be n × b row-major");
    let parts = by_rows(n, threads, |a, e| {
        let mut acc = vec![0.0; b];
        for (xr, yr) in x[a * b..e * b].chunks_exact(b).zip(y[a * b..e * b].chunks_exact(b)) {
            for ((s, xv), yv) in acc.iter_mut().zip(xr).zip(yr) {
                *s += xv * yv;
            }
        }
        acc
    });
    (0..b).map(|c| parts.iter().map(|p| p[c]).sum()).collect()
}

/// OUT = X T for a row-major n × b block X and a small b × p matrix T, into any n × p view (a run of the basis's
/// columns, or a row-major block), on `threads` threads by ranges of rows (faer's product on each).
pub fn block_times_par(x: &[f64], b: usize, t: MatRef<'_, f64>, out: faer::MatMut<'_, f64>, threads: usize) {
    use rayon::prelude::*;
    let (n, p) = (out.nrows(), out.ncols());
    assert_eq!(x.len(), block_len(n, b), "X must be n × b row-major");
    assert_eq!((t.nrows(), t.ncols()), (b, p), "T must be b × p");
    let ranges = if threads <= 1 || n < PARALLEL_ROWS { vec![(0, n)] } else { row_ranges(n, threads) };
    let mut pieces = Vec::with_capacity(ranges.len());
    let mut rest = out;
    for &(a, e) in &ranges {
        let (head, tail) = rest.split_at_row_mut(e - a);
        pieces.push((a, e, head));
        rest = tail;
    }
    pieces.into_par_iter().for_each(|(a, e, piece)| {
        let xs = MatRef::from_row_major_slice(&x[a * b..e * b], e - a, b);
        matmul(piece, Accum::Replace, xs, t, 1.0, Par::Seq);
    });
}

/// [`gram`] with the kernels of a given instruction set (widths 8 and 16 use AVX-512 where given; `Scalar` means
/// faer's product). V may be any view (strided, reversed, transposed); the kernels take forward column-major ones.
///
/// # Panics
/// If `y.len()` is not n·b.
pub fn gram_with(v: MatRef<'_, f64>, y: &[f64], b: usize, isa: Isa) -> Mat<f64> {
    let (n, m) = (v.nrows(), v.ncols());
    assert_eq!(y.len(), block_len(n, b), "Y must be n × b row-major");
    #[cfg(target_arch = "x86_64")]
    if let Some(cols) = kernel_columns(v, b, isa) {
        let mut c = vec![0.0f64; block_len(m, b)];
        // SAFETY: `kernel_columns` checked that the CPU has `isa`'s instructions (`isa.supported()`; AVX-512 CPUs
        // have AVX2 + FMA too) and built `cols` with `Columns::new`'s stride checks; the `match` gives each width
        // b its kernel with R·LANES = b; the kernel asserts the lengths of Y and C against n·b and m·b.
        unsafe {
            match (isa, b) {
                (Isa::Avx512, 8) => kernels::gram_avx512::<1, 8>(&cols, y, &mut c),
                (Isa::Avx512, 16) => kernels::gram_avx512::<2, 4>(&cols, y, &mut c),
                (_, 4) => kernels::gram_avx2::<1, 8>(&cols, y, &mut c),
                (_, 8) => kernels::gram_avx2::<2, 4>(&cols, y, &mut c),
                _ => kernels::gram_avx2::<4, 2>(&cols, y, &mut c),
            }
        }
        return Mat::from_fn(m, b, |r, t| c[r * b + t]);
    }
    let mut out = Mat::<f64>::zeros(m, b);
    matmul(out.as_mut(), Accum::Replace, v.transpose(), MatRef::from_row_major_slice(y, n, b), 1.0, Par::Seq);
    out
}

/// [`update`] with the kernels of a given instruction set. V and C may be any views.
///
/// # Panics
/// If `w.len()` is not n·b or C is not m × b.
pub fn update_with(w: &mut [f64], b: usize, v: MatRef<'_, f64>, c: MatRef<'_, f64>, alpha: f64, isa: Isa) {
    let (n, m) = (v.nrows(), v.ncols());
    assert_eq!(w.len(), block_len(n, b), "W must be n × b row-major");
    assert_eq!((c.nrows(), c.ncols()), (m, b), "C must be m × b");
    #[cfg(target_arch = "x86_64")]
    if let Some(cols) = kernel_columns(v, b, isa) {
        // α folded into a row-major copy of C (m × b values, small).
        let ac: Vec<f64> = (0..m * b).map(|p| alpha * c[(p / b, p % b)]).collect();
        // SAFETY: as in `gram_with`: `kernel_columns` checked the CPU and V's strides; the kernel asserts the
        // lengths of C and W against m·b and n·b.
        unsafe {
            match (isa, b) {
                (Isa::Avx512, 8) => kernels::update_avx512::<1, 8>(&cols, &ac, w),
                (Isa::Avx512, 16) => kernels::update_avx512::<2, 4>(&cols, &ac, w),
                (_, 4) => kernels::update_avx2::<1, 8>(&cols, &ac, w),
                (_, 8) => kernels::update_avx2::<2, 4>(&cols, &ac, w),
                _ => kernels::update_avx2::<4, 2>(&cols, &ac, w),
            }
        }
        return;
    }
    matmul(faer::MatMut::from_row_major_slice_mut(w, n, b), Accum::Add, v, c, alpha, Par::Seq);
}

/// A borrowed V (n × m) whose entry (i, j) is at `ptr + j·stride + i`: a pointer, not a slice, because the gaps
/// between the columns of a view into a taller matrix are memory V does not borrow. Built only by
/// [`Columns::new`], which checks the strides; the kernels rely on that.
#[cfg(target_arch = "x86_64")]
struct Columns<'a> {
    ptr: *const f64,
    stride: usize,
    n: usize,
    m: usize,
    _borrow: std::marker::PhantomData<MatRef<'a, f64>>,
}

#[cfg(target_arch = "x86_64")]
impl<'a> Columns<'a> {
    /// `None` unless entry (i, j) of V is at `ptr + j·stride + i` with a non-negative `stride`: row stride 1 (or
    /// at most one row) and a non-negative column stride (or at most one column). faer's `try_as_col_major` checks
    /// only the row stride, so a reversed-column view (negative column stride) would pass it.
    fn new(v: MatRef<'a, f64>) -> Option<Self> {
        let (n, m) = (v.nrows(), v.ncols());
        if n > 1 && v.row_stride() != 1 {
            return None;
        }
        let stride = if m > 1 { usize::try_from(v.col_stride()).ok()? } else { 0 };
        Some(Columns { ptr: v.as_ptr(), stride, n, m, _borrow: std::marker::PhantomData })
    }
}

/// The kernels, generic over the register type: a block row is R registers of `S::LANES` doubles (B = R·LANES),
/// and G columns of V go together (G·R accumulators or coefficient registers: 8 of AVX2's 16, 8 of AVX-512's 32).
/// Written with intrinsics because the compiler vectorized plain loops across rows instead (gathers, shuffles,
/// operands on the stack).
#[cfg(target_arch = "x86_64")]
mod kernels {
    use super::{Columns, ROWS};
    use crate::simd::F64s;
    use std::arch::x86_64::{__m256d, __m512d};

    /// C[j] += Σ_i V[i, j] Y[i] (C row-major m × B, Y row-major n × B).
    ///
    /// # Safety
    /// The CPU has `S`'s instruction set (the caller checks `Isa::supported`). Lengths are asserted here; V's
    /// layout is `Columns`' invariant.
    #[inline(always)]
    unsafe fn gram<S: F64s, const R: usize, const G: usize>(v: &Columns<'_>, y: &[f64], c: &mut [f64]) {
        let b = S::LANES * R;
        let (n, m) = (v.n, v.m);
        assert!(y.len() >= n * b && c.len() >= m * b, "Y must hold n × b values and C m × b");
        let (vp, yp, cp) = (v.ptr, y.as_ptr(), c.as_mut_ptr());
        // SAFETY: V is read at `vp + (j + u)·stride + r0 + i` for j + u < m, r0 + i < n: entry (r0 + i, j + u),
        // which V borrows (`Columns::new` checked the strides that place it there). Y is read at rows r0 + i < n
        // and C at rows j + u < m, b values each, inside the lengths asserted above. The register operations need
        // the instruction set of this function's contract.
        unsafe {
            for r0 in (0..n).step_by(ROWS) {
                let len = ROWS.min(n - r0);
                let mut j = 0;
                while j < m {
                    let g = if j + G <= m { G } else { 1 };
                    let mut cols = [vp; G];
                    let mut acc = [[S::zero(); R]; G];
                    for u in 0..g {
                        cols[u] = vp.add((j + u) * v.stride + r0);
                        for q in 0..R {
                            acc[u][q] = S::load(cp.add((j + u) * b + S::LANES * q));
                        }
                    }
                    if g == G {
                        for i in 0..len {
                            let row = yp.add((r0 + i) * b);
                            let mut yi = [S::zero(); R];
                            for q in 0..R {
                                yi[q] = S::load(row.add(S::LANES * q));
                            }
                            for u in 0..G {
                                let s = S::splat(cols[u].add(i));
                                for q in 0..R {
                                    acc[u][q] = s.mul_add(yi[q], acc[u][q]);
                                }
                            }
                        }
                    } else {
                        for i in 0..len {
                            let row = yp.add((r0 + i) * b);
                            let s = S::splat(cols[0].add(i));
                            for q in 0..R {
                                acc[0][q] = s.mul_add(S::load(row.add(S::LANES * q)), acc[0][q]);
                            }
                        }
                    }
                    for u in 0..g {
                        for q in 0..R {
                            acc[u][q].store(cp.add((j + u) * b + S::LANES * q));
                        }
                    }
                    j += g;
                }
            }
        }
    }

    /// W[i] += Σ_j V[i, j] C[j] (C row-major m × B, already scaled; W row-major n × B).
    ///
    /// # Safety
    /// As [`gram`]: the CPU has `S`'s instruction set.
    #[inline(always)]
    unsafe fn update<S: F64s, const R: usize, const G: usize>(v: &Columns<'_>, c: &[f64], w: &mut [f64]) {
        let b = S::LANES * R;
        let (n, m) = (v.n, v.m);
        assert!(w.len() >= n * b && c.len() >= m * b, "W must hold n × b values and C m × b");
        let (vp, cp, wp) = (v.ptr, c.as_ptr(), w.as_mut_ptr());
        // SAFETY: as in `gram`: V entries (r0 + i, j + u) through `Columns`' checked strides, C rows j + u < m and
        // W rows r0 + i < n inside the lengths asserted above; the instruction set is this function's contract.
        unsafe {
            for r0 in (0..n).step_by(ROWS) {
                let len = ROWS.min(n - r0);
                let mut j = 0;
                while j < m {
                    let g = if j + G <= m { G } else { 1 };
                    let mut cols = [vp; G];
                    let mut coef = [[S::zero(); R]; G];
                    for u in 0..g {
                        cols[u] = vp.add((j + u) * v.stride + r0);
                        for q in 0..R {
                            coef[u][q] = S::load(cp.add((j + u) * b + S::LANES * q));
                        }
                    }
                    if g == G {
                        for i in 0..len {
                            let row = wp.add((r0 + i) * b);
                            let mut wi = [S::zero(); R];
                            for q in 0..R {
                                wi[q] = S::load(row.add(S::LANES * q));
                            }
                            for u in 0..G {
                                let s = S::splat(cols[u].add(i));
                                for q in 0..R {
                                    wi[q] = s.mul_add(coef[u][q], wi[q]);
                                }
                            }
                            for q in 0..R {
                                wi[q].store(row.add(S::LANES * q));
                            }
                        }
                    } else {
                        for i in 0..len {
                            let row = wp.add((r0 + i) * b);
                            let s = S::splat(cols[0].add(i));
                            for q in 0..R {
                                let x = S::load(row.add(S::LANES * q));
                                s.mul_add(coef[0][q], x).store(row.add(S::LANES * q));
                            }
                        }
                    }
                    j += g;
                }
            }
        }
    }

    /// [`gram`] with AVX2 + FMA registers (B = 4·R).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn gram_avx2<const R: usize, const G: usize>(v: &Columns<'_>, y: &[f64], c: &mut [f64]) {
        // SAFETY: this function's contract is the kernel's.
        unsafe { gram::<__m256d, R, G>(v, y, c) }
    }
    /// [`gram`] with AVX-512 registers (B = 8·R).
    ///
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn gram_avx512<const R: usize, const G: usize>(v: &Columns<'_>, y: &[f64], c: &mut [f64]) {
        // SAFETY: this function's contract is the kernel's.
        unsafe { gram::<__m512d, R, G>(v, y, c) }
    }
    /// [`update`] with AVX2 + FMA registers (B = 4·R).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn update_avx2<const R: usize, const G: usize>(v: &Columns<'_>, c: &[f64], w: &mut [f64]) {
        // SAFETY: this function's contract is the kernel's.
        unsafe { update::<__m256d, R, G>(v, c, w) }
    }
    /// [`update`] with AVX-512 registers (B = 8·R).
    ///
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn update_avx512<const R: usize, const G: usize>(v: &Columns<'_>, c: &[f64], w: &mut [f64]) {
        // SAFETY: this function's contract is the kernel's.
        unsafe { update::<__m512d, R, G>(v, c, w) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both products against a plain triple loop, for every width and every instruction set this CPU runs (the
    /// kernels and faer's fallback), column counts that leave remainders after the groups of columns, row counts
    /// that leave a partial chunk, and a view of columns out of a wider matrix (column stride larger than n).
    #[test]
    fn gram_and_update_match_the_definition() {
        for isa in Isa::available() {
            for &b in &[1usize, 2, 3, 4, 8, 16] {
                for &(n, m) in &[(1usize, 1usize), (7, 3), (300, 9), (600, 13), (257, 4), (2100, 11)] {
                    let big = Mat::<f64>::from_fn(n, m + 3, |i, j| ((i * 37 + j * 11) % 29) as f64 / 7.0 - 2.0);
                    let v = big.as_ref().subcols(1, m);
                    let y: Vec<f64> = (0..n * b).map(|p| ((p * 13) % 17) as f64 / 5.0 - 1.5).collect();
                    let c = gram_with(v, &y, b, isa);
                    for j in 0..m {
                        for t in 0..b {
                            let want: f64 = (0..n).map(|i| v[(i, j)] * y[i * b + t]).sum();
                            let ok = (c[(j, t)] - want).abs() <= 1e-12 * (1.0 + want.abs());
                            assert!(ok, "gram {isa:?} b={b} n={n} m={m}");
                        }
                    }
                    let mut w = y.clone();
                    update_with(&mut w, b, v, c.as_ref(), -0.5, isa);
                    for i in 0..n {
                        for t in 0..b {
                            let want = y[i * b + t] - 0.5 * (0..m).map(|j| v[(i, j)] * c[(j, t)]).sum::<f64>();
                            let ok = (w[i * b + t] - want).abs() <= 1e-11 * (1.0 + want.abs());
                            assert!(ok, "update {isa:?} b={b} n={n} m={m}");
                        }
                    }
                }
            }
        }
    }

    /// The block step's small products (Xᵀ Y of two row-major blocks, column dots, X T) against plain loops, on one
    /// thread and on several (no rows, and row counts on both sides of the split's threshold; widths 1, 3 and 8, T
    /// with one column fewer, so none at width 1), X T written into a run of columns of a wider column-major matrix
    /// and into a row-major block, the columns beside them left as they were.
    #[test]
    fn block_products_match_the_definition_on_any_threads() {
        for &n in &[0usize, 7, PARALLEL_ROWS + 123, 3 * PARALLEL_ROWS] {
            for &b in &[1usize, 3, 8] {
                let x: Vec<f64> = (0..n * b).map(|p| ((p * 13) % 17) as f64 / 5.0 - 1.5).collect();
                let y: Vec<f64> = (0..n * b).map(|p| ((p * 7) % 23) as f64 / 9.0 - 1.0).collect();
                let t = Mat::<f64>::from_fn(b, b - 1, |c, j| (c * 3 + j) as f64 / 4.0 - 1.0);
                for threads in [1usize, 2, 3] {
                    // Xᵀ Y for a row-major X: `gram_par` on a row-major view (faer's product on each range of rows).
                    let g = gram_par(MatRef::from_row_major_slice(&x, n, b), &y, b, threads);
                    let d = col_dots_par(&x, &y, b, threads);
                    for i in 0..b {
                        for j in 0..b {
                            let want: f64 = (0..n).map(|r| x[r * b + i] * y[r * b + j]).sum();
                            assert!((g[(i, j)] - want).abs() <= 1e-10 * (1.0 + want.abs()), "gram n={n} b={b}");
                            if i == j {
                                assert!((d[i] - want).abs() <= 1e-10 * (1.0 + want.abs()), "dots n={n} b={b}");
                            }
                        }
                    }
                    let mut wide = Mat::<f64>::zeros(n, b + 2);
                    block_times_par(&x, b, t.as_ref(), wide.as_mut().subcols_mut(1, b - 1), threads);
                    let mut rows = vec![0.0; n * b];
                    let row_major = faer::MatMut::from_row_major_slice_mut(&mut rows, n, b);
                    block_times_par(&x, b, t.as_ref(), row_major.subcols_mut(0, b - 1), threads);
                    for r in 0..n {
                        assert_eq!(
                            (wide[(r, 0)], wide[(r, b)], wide[(r, b + 1)], rows[r * b + b - 1]),
                            (0.0, 0.0, 0.0, 0.0)
                        );
                        for j in 0..b - 1 {
                            let want: f64 = (0..b).map(|c| x[r * b + c] * t[(c, j)]).sum();
                            assert!((wide[(r, 1 + j)] - want).abs() <= 1e-12 * (1.0 + want.abs()), "X T n={n} b={b}");
                            assert!((rows[r * b + j] - want).abs() <= 1e-12 * (1.0 + want.abs()), "X T n={n} b={b}");
                        }
                    }
                }
            }
        }
    }
}

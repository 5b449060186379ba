//! The intrinsic kernels of the sparse Cholesky block solve (`spectrum::factor`): `supernodal_solve` for
//! B = R·LANES right-hand sides (R registers of `S::LANES` doubles per row of X: AVX2's four or AVX-512's eight, see
//! [`crate::simd`]), the same passes and groups of four columns as the portable solve, with the group's solved rows
//! (forward) or its four accumulators (backward) in registers. Written with intrinsics because the compiler
//! vectorized the portable loops across rows of X instead (transposing shuffles and operands spilled to the stack).
//!
//! They take faer's supernodal structure on trust: the factor asserts it once (`assert_supernodes_fit`), and its
//! safe dispatch checks the length of X before calling them.

use crate::simd::F64s;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use std::arch::x86_64::{__m256d, __m512d};

type SupernodalFactor<'a> = SupernodalLltRef<'a, usize, f64>;

// Register helpers of the two sweeps, for a row of B = R·LANES values at a pointer. `S` and `R` are the
// expanding function's register type and count (macro_rules resolve them where the macro is used).
macro_rules! load {
    ($p:expr) => {{
        let p: *mut f64 = $p;
        let mut v = [S::zero(); R];
        for q in 0..R {
            v[q] = S::load(p.add(S::LANES * q));
        }
        v
    }};
}
macro_rules! store {
    ($p:expr, $v:expr) => {{
        let (p, v): (*mut f64, [S; R]) = ($p, $v);
        for q in 0..R {
            v[q].store(p.add(S::LANES * q));
        }
    }};
}
macro_rules! scale {
    ($v:expr, $d:expr) => {{
        let d = S::splat(&(1.0 / $d));
        for q in 0..R {
            $v[q] = $v[q].mul(d);
        }
    }};
}
// x ← x − a·g for one broadcast factor entry a.
macro_rules! axpy {
    ($x:expr, $a:expr, $g:expr) => {{
        let a = S::splat($a);
        for q in 0..R {
            $x[q] = a.neg_mul_add($g[q], $x[q]);
        }
    }};
}

/// [`supernodal_solve`] with AVX2 + FMA registers (B = 4·R right-hand sides).
///
/// # Safety
/// As [`supernodal_solve`] with `S = __m256d`: the CPU has AVX2 and FMA, `x.len()` is a multiple of 4·R, and
/// `assert_supernodes_fit(f, x.len() / (4·R))` holds.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn solve_avx2<const R: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [f64]) {
    // SAFETY: this function's contract is the kernel's.
    unsafe { supernodal_solve::<__m256d, R, UNIT>(f, x) }
}

/// [`supernodal_solve`] with AVX-512 registers (B = 8·R right-hand sides).
///
/// # Safety
/// As [`supernodal_solve`] with `S = __m512d`: the CPU has AVX-512F, `x.len()` is a multiple of 8·R, and
/// `assert_supernodes_fit(f, x.len() / (8·R))` holds.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn solve_avx512<const R: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [f64]) {
    // SAFETY: this function's contract is the kernel's.
    unsafe { supernodal_solve::<__m512d, R, UNIT>(f, x) }
}

/// Where a forward sweep reads and writes (see [`forward`]): X, and the rows redirected into a buffer.
pub(crate) struct Sweep<'a> {
    /// Row r of X at `x + r·b`.
    pub x: *mut f64,
    /// Pattern rows at or above this go to `buf` (`usize::MAX`: none).
    pub limit: usize,
    /// `n_top` rows of b values.
    pub buf: *mut f64,
    /// The buffer row of each redirected row (n entries; others are not read).
    pub top_pos: &'a [usize],
    pub n_top: usize,
}

/// One sweep of the block solve ([`forward`] or [`backward`], on `sw.x`) over supernodes `lo..hi` with AVX2 +
/// FMA registers (B = 4·R right-hand sides).
///
/// # Safety
/// As [`forward`] or [`backward`] with `S = __m256d`: the CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn sweep_avx2<const R: usize, const UNIT: bool>(
    f: &SupernodalFactor<'_>,
    fwd: bool,
    lo: usize,
    hi: usize,
    sw: &Sweep<'_>,
) {
    // SAFETY: this function's contract is the sweep's.
    unsafe {
        if fwd {
            forward::<__m256d, R, UNIT>(f, lo, hi, sw)
        } else {
            backward::<__m256d, R, UNIT>(f, lo, hi, sw.x)
        }
    }
}

/// [`sweep_avx2`] with AVX-512 registers (B = 8·R right-hand sides).
///
/// # Safety
/// As [`forward`] or [`backward`] with `S = __m512d`: the CPU has AVX-512F.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn sweep_avx512<const R: usize, const UNIT: bool>(
    f: &SupernodalFactor<'_>,
    fwd: bool,
    lo: usize,
    hi: usize,
    sw: &Sweep<'_>,
) {
    // SAFETY: this function's contract is the sweep's.
    unsafe {
        if fwd {
            forward::<__m512d, R, UNIT>(f, lo, hi, sw)
        } else {
            backward::<__m512d, R, UNIT>(f, lo, hi, sw.x)
        }
    }
}

/// The block solve on X row-major (row r at `x[r·b..(r + 1)·b]`, b = R·LANES), through raw pointers.
///
/// # Safety
/// - The CPU has `S`'s instruction set (the caller checks `Isa::supported`).
/// - `x.len()` is a multiple of b; with n = x.len() / b, `assert_supernodes_fit(f, n)` holds: every row the
///   structure names is < n (so `row!` stays in `x`), and each supernode's values are a column-major `ld × nc`
///   block with column stride `ld` (so `lp + j·ld + i`, i < ld, j < nc, stays in the block).
#[inline(always)]
unsafe fn supernodal_solve<S: F64s, const R: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [f64]) {
    let ns = f.symbolic().n_supernodes();
    let xp = x.as_mut_ptr();
    let whole = Sweep { x: xp, limit: usize::MAX, buf: std::ptr::null_mut(), top_pos: &[], n_top: 0 };
    // SAFETY: the contract above is `forward`'s and `backward`'s for the whole range of supernodes, with no rows
    // redirected (limit past every row).
    unsafe {
        forward::<S, R, UNIT>(f, 0, ns, &whole);
        backward::<S, R, UNIT>(f, 0, ns, xp);
    }
}

/// The forward sweep (L y = x, D⁻¹ y stored for LDLᵀ) over supernodes `lo..hi`, in order. Rows below
/// `sw.limit` are rows of X at `sw.x`; a pattern row at or above it (an ancestor's, in the top of a
/// `spectrum::tree::Split`) is updated in `sw.buf` at row `sw.top_pos[r]` instead.
///
/// # Safety
/// As [`supernodal_solve`], for X at `sw.x` (n rows of b, n the factor's); every supernode of `lo..hi` lies
/// below `sw.limit` with its columns; and where some pattern row is at or above `sw.limit`, `sw.top_pos` has n
/// entries and `sw.buf` holds `sw.n_top` rows of b (positions are checked against `n_top`). No other thread
/// touches the rows written meanwhile.
#[inline(always)]
unsafe fn forward<S: F64s, const R: usize, const UNIT: bool>(
    f: &SupernodalFactor<'_>,
    lo: usize,
    hi: usize,
    sw: &Sweep<'_>,
) {
    // SAFETY: the contract above. Every pointer below is `row!(r)` or `top!(r)` (then up to b values from it)
    // for a row r the structure names, or `lp.add(j·ld + i)` with j < nc, i < ld inside a supernode's value
    // block: in bounds by `assert_supernodes_fit`, which `Cholesky::checked` ran on the factor, and by the
    // `top_pos` check. The register operations need the instruction set the caller checked.
    unsafe {
        let b = S::LANES * R;
        let xp = sw.x;
        macro_rules! row {
            ($r:expr) => {{
                let r: usize = $r;
                xp.add(r * b)
            }};
        }
        macro_rules! top {
            ($r:expr) => {{
                let pos = sw.top_pos[$r];
                assert!(pos < sw.n_top, "a pattern row above the range that is not in the top");
                sw.buf.add(pos * b)
            }};
        }
        for s in lo..hi {
            let sn = f.supernode(s);
            let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
            let nc = l.ncols();
            let ld = nc + rows.len();
            let lp = l.as_ptr();
            let lead = nc % 4;
            // Pattern rows below the limit are the range's own; the rest are the top's.
            let own = if sw.limit == usize::MAX { rows.len() } else { rows.partition_point(|&r| r < sw.limit) };
            for j in 0..lead {
                let cj = lp.add(j * ld);
                let mut g = load!(row!(c0 + j));
                if UNIT {
                    let mut stored = g;
                    scale!(stored, *cj.add(j));
                    store!(row!(c0 + j), stored);
                } else {
                    scale!(g, *cj.add(j));
                    store!(row!(c0 + j), g);
                }
                for i in j + 1..nc {
                    let p = row!(c0 + i);
                    let mut xi = load!(p);
                    axpy!(xi, cj.add(i), g);
                    store!(p, xi);
                }
                for (t, &r) in rows[..own].iter().enumerate() {
                    let p = row!(r);
                    let mut xi = load!(p);
                    axpy!(xi, cj.add(nc + t), g);
                    store!(p, xi);
                }
                for (t, &r) in rows[own..].iter().enumerate() {
                    let p = top!(r);
                    let mut xi = load!(p);
                    axpy!(xi, cj.add(nc + own + t), g);
                    store!(p, xi);
                }
            }
            for j in (lead..nc).step_by(4) {
                let c = [lp.add(j * ld), lp.add((j + 1) * ld), lp.add((j + 2) * ld), lp.add((j + 3) * ld)];
                // The group's triangle: g_u = (x_u − Σ_{v<u} L[j+u, j+v] g_v) / L[j+u, j+u].
                let mut g = [[S::zero(); R]; 4];
                for u in 0..4 {
                    let mut xu = load!(row!(c0 + j + u));
                    for v in 0..u {
                        axpy!(xu, c[v].add(j + u), g[v]);
                    }
                    if UNIT {
                        let mut stored = xu;
                        scale!(stored, *c[u].add(j + u));
                        store!(row!(c0 + j + u), stored);
                    } else {
                        scale!(xu, *c[u].add(j + u));
                        store!(row!(c0 + j + u), xu);
                    }
                    g[u] = xu;
                }
                // Every row below (diagonal block, then pattern) once with all four: two independent pairs.
                macro_rules! update4 {
                    ($p:expr, $o:expr) => {{
                        let (p, o): (*mut f64, usize) = ($p, $o);
                        let a0 = S::splat(c[0].add(o));
                        let a1 = S::splat(c[1].add(o));
                        let a2 = S::splat(c[2].add(o));
                        let a3 = S::splat(c[3].add(o));
                        let mut xi = load!(p);
                        for q in 0..R {
                            let t = a1.neg_mul_add(g[1][q], a0.neg_mul_add(g[0][q], xi[q]));
                            let u = a3.mul_add(g[3][q], a2.mul(g[2][q]));
                            xi[q] = t.sub(u);
                        }
                        store!(p, xi);
                    }};
                }
                for i in j + 4..nc {
                    update4!(row!(c0 + i), i);
                }
                for (t, &r) in rows[..own].iter().enumerate() {
                    update4!(row!(r), nc + t);
                }
                for (t, &r) in rows[own..].iter().enumerate() {
                    update4!(top!(r), nc + own + t);
                }
            }
        }
    }
}

/// The backward sweep (Lᵀ x = y) over supernodes `lo..hi`, in reverse: reads the rows of their patterns
/// (final already: the range's ancestors are swept before it) and writes the range's own rows.
///
/// # Safety
/// As [`supernodal_solve`], for X at `x` (n rows of b, n the factor's). No other thread writes the rows read or
/// touches the rows written meanwhile.
#[inline(always)]
unsafe fn backward<S: F64s, const R: usize, const UNIT: bool>(
    f: &SupernodalFactor<'_>,
    lo: usize,
    hi: usize,
    xp: *mut f64,
) {
    // SAFETY: as in `forward`, without redirected rows.
    unsafe {
        let b = S::LANES * R;
        macro_rules! row {
            ($r:expr) => {{
                let r: usize = $r;
                xp.add(r * b)
            }};
        }
        for s in (lo..hi).rev() {
            let sn = f.supernode(s);
            let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
            let nc = l.ncols();
            let ld = nc + rows.len();
            let lp = l.as_ptr();
            let lead = nc % 4;
            for j in (lead..nc).step_by(4).rev() {
                let c = [lp.add(j * ld), lp.add((j + 1) * ld), lp.add((j + 2) * ld), lp.add((j + 3) * ld)];
                let mut acc =
                    [load!(row!(c0 + j)), load!(row!(c0 + j + 1)), load!(row!(c0 + j + 2)), load!(row!(c0 + j + 3))];
                // Each row below gathered once into the four accumulators (independent FMA chains).
                macro_rules! gather4 {
                    ($p:expr, $o:expr) => {{
                        let (p, o): (*mut f64, usize) = ($p, $o);
                        let xr = load!(p);
                        for u in 0..4 {
                            axpy!(acc[u], c[u].add(o), xr);
                        }
                    }};
                }
                for (t, &r) in rows.iter().enumerate() {
                    gather4!(row!(r), nc + t);
                }
                for i in j + 4..nc {
                    gather4!(row!(c0 + i), i);
                }
                // The group's triangle, last column first: x_u = (acc_u − Σ_{v>u} L[j+v, j+u] x_v) / L[j+u, j+u].
                let mut xs = [[S::zero(); R]; 4];
                for u in (0..4).rev() {
                    let mut xu = acc[u];
                    for v in u + 1..4 {
                        axpy!(xu, c[u].add(j + v), xs[v]);
                    }
                    if !UNIT {
                        scale!(xu, *c[u].add(j + u));
                    }
                    xs[u] = xu;
                    store!(row!(c0 + j + u), xu);
                }
            }
            for j in (0..lead).rev() {
                let cj = lp.add(j * ld);
                let mut acc = load!(row!(c0 + j));
                for (t, &r) in rows.iter().enumerate() {
                    let xr = load!(row!(r));
                    axpy!(acc, cj.add(nc + t), xr);
                }
                for i in j + 1..nc {
                    let xr = load!(row!(c0 + i));
                    axpy!(acc, cj.add(i), xr);
                }
                if !UNIT {
                    scale!(acc, *cj.add(j));
                }
                store!(row!(c0 + j), acc);
            }
        }
    }
}

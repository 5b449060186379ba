//! The block solve with a factor: the portable supernodal sweeps, the intrinsic kernels' dispatch
//! ([`crate::simd::supernodal`]) and the parallel plan that runs subtrees side by side.

use crate::simd::Isa;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use crate::cholesky::tree::Split;
#[cfg(target_arch = "x86_64")]
use crate::simd::supernodal as kernels;

type SupernodalFactor<'a> = faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef<'a, usize, f64>;

/// Asserts what the intrinsic kernels take on trust from faer's supernodal structure, for a block X of `n` rows:
/// every supernode's columns `start..start + nc` and pattern rows are rows of X (< n), and its value block is
/// `ld × nc` column-major with column stride `ld = nc + pattern length`, so that entry (i, j) is at `j·ld + i`.
/// One pass over the supernodes' patterns, run once per factor by `Cholesky::checked` rather than before every
/// solve, whose time it would add to.
pub(super) fn assert_supernodes_fit(f: &SupernodalFactor<'_>, n: usize) {
    for s in 0..f.symbolic().n_supernodes() {
        let sn = f.supernode(s);
        let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
        let nc = l.ncols();
        let ld = nc.checked_add(rows.len()).expect("supernode size");
        assert!(c0 <= n && nc <= n - c0, "supernode {s}: columns {c0}..{c0}+{nc} outside {n} rows");
        assert!(rows.iter().copied().max().is_none_or(|r| r < n), "supernode {s}: a pattern row outside {n} rows");
        assert!(
            l.nrows() == ld && l.row_stride() == 1 && (nc <= 1 || l.col_stride() == ld as isize),
            "supernode {s}: values not a column-major {ld} × {nc} block"
        );
    }
}

/// The fewest rows per task of a parallel solve's permutations (one range per thread above that).
pub(super) const PERMUTE_ROWS: usize = 8192;

/// How the block solve runs on several threads: the tree's [`Split`] for the factor's values, each subtree's
/// column limit, and the buffer row of every column of the top.
pub(super) struct SolvePlan {
    split: Split,
    /// Per worker, per subtree: the first column past the subtree (its pattern rows at or above it are the top's).
    limits: Vec<Vec<usize>>,
    /// The buffer row of each top column (`usize::MAX` elsewhere), and the top's columns in order.
    top_pos: Vec<usize>,
    top_cols: Vec<usize>,
}

/// Each supernode's weight in a block solve: each sweep streams its lower triangle and its rows below once.
pub(super) fn solve_weights(sn: &SymbolicSupernodalCholesky<usize>) -> Vec<f64> {
    let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
    (0..sn.n_supernodes())
        .map(|s| {
            let (c, r) = (end[s] - begin[s], sn.supernode(s).pattern().len());
            (c * (c + 1) / 2 + c * r) as f64
        })
        .collect()
}

impl SolvePlan {
    /// `None` where the tree does not split usefully for `threads` (see [`Split::new`]).
    pub(super) fn new(sn: &SymbolicSupernodalCholesky<usize>, threads: usize) -> Option<Self> {
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        let split = Split::new(sn, threads, &solve_weights(sn))?;
        // What keeps the threads on their own rows (the kernels' redirection splits each pattern at the subtree's
        // limit): every supernode's pattern is strictly ascending and lies past its own columns, so a subtree's
        // rows below the limit are its own and those at or above it are its ancestors' (the top's). Checked once per
        // plan rather than taken on trust from faer.
        for s in 0..sn.n_supernodes() {
            let p = sn.supernode(s).pattern();
            assert!(
                p.first().is_none_or(|&r| r >= end[s]) && p.windows(2).all(|w| w[0] < w[1]),
                "supernode {s}: pattern not ascending past its columns"
            );
        }
        let limits = split.parts.iter().map(|p| p.iter().map(|&(_, hi)| end[hi - 1]).collect()).collect();
        let mut top_pos = vec![usize::MAX; sn.nrows()];
        let top_cols: Vec<usize> = split.top.iter().flat_map(|&s| begin[s]..end[s]).collect();
        for (i, &c) in top_cols.iter().enumerate() {
            top_pos[c] = i;
        }
        Some(SolvePlan { split, limits, top_pos, top_cols })
    }
}

/// A pointer shared by the threads of one parallel solve, each writing its own rows (see [`parallel_solve`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Shared(*mut f64);
// SAFETY: `parallel_solve` hands the pointer to threads that write disjoint rows of X while it lives (each
// subtree's own columns; `SolvePlan::new` checked the patterns that make them disjoint) and read rows no thread
// writes meanwhile (the top's, in the backward sweep).
#[cfg(target_arch = "x86_64")]
unsafe impl Send for Shared {}
// SAFETY: as above.
#[cfg(target_arch = "x86_64")]
unsafe impl Sync for Shared {}

#[cfg(target_arch = "x86_64")]
impl Shared {
    /// The pointer (a method, so that closures capture the `Shared`, not its field).
    fn get(self) -> *mut f64 {
        self.0
    }
}

/// The block solve on the plan's threads. Forward: the workers sweep their subtrees side by side, each updating the
/// top's rows in a buffer of its own, which are then added to X; then the top, in order, on this thread. Backward:
/// the top first, then the subtrees side by side (each reads the top's final rows and writes its own). Subtrees are
/// closed under descendants ([`Split`]), so no two workers touch the same row of X.
///
/// `sweep` must be sound to call on X (n rows of B) for any range of supernodes with rows at or above the limit
/// redirected to a buffer of the plan's top rows: the kernels' contract given the factor and the CPU.
#[cfg(target_arch = "x86_64")]
fn parallel_solve<const B: usize>(
    f: &SupernodalFactor<'_>,
    x: &mut [[f64; B]],
    plan: &SolvePlan,
    sweep: impl Fn(&SupernodalFactor<'_>, bool, usize, usize, &kernels::Sweep<'_>) + Sync,
) {
    use rayon::prelude::*;
    let n_top = plan.top_cols.len();
    let xp = Shared(x.as_mut_ptr().cast::<f64>());
    let mut bufs: Vec<Vec<f64>> = vec![vec![0.0; n_top * B]; plan.split.parts.len()];
    bufs.par_iter_mut().zip(&plan.split.parts).zip(&plan.limits).for_each(|((buf, part), limits)| {
        for (&(lo, hi), &limit) in part.iter().zip(limits) {
            let sw = kernels::Sweep { x: xp.get(), limit, buf: buf.as_mut_ptr(), top_pos: &plan.top_pos, n_top };
            sweep(f, true, lo, hi, &sw);
        }
    });
    for buf in &bufs {
        for (i, &c) in plan.top_cols.iter().enumerate() {
            for (xv, bv) in x[c].iter_mut().zip(&buf[i * B..(i + 1) * B]) {
                *xv += bv;
            }
        }
    }
    // X was written through its reference just now: the pointer is taken again for what follows.
    let xp = Shared(x.as_mut_ptr().cast::<f64>());
    let whole = |buf: *mut f64, limit: usize| kernels::Sweep { x: xp.get(), limit, buf, top_pos: &plan.top_pos, n_top };
    let sw = whole(std::ptr::null_mut(), usize::MAX);
    for &s in &plan.split.top {
        sweep(f, true, s, s + 1, &sw);
    }
    for &s in plan.split.top.iter().rev() {
        sweep(f, false, s, s + 1, &sw);
    }
    plan.split.parts.par_iter().for_each(|part| {
        let sw = kernels::Sweep { x: xp.get(), limit: usize::MAX, buf: std::ptr::null_mut(), top_pos: &[], n_top: 0 };
        for &(lo, hi) in part {
            sweep(f, false, lo, hi, &sw);
        }
    });
}

/// Runs the block solve with intrinsics for 4, 8 or 16 right-hand sides when `isa` is AVX2 + FMA or AVX-512 and
/// the CPU has it (detected at run time by the caller, as faer's own kernels do), else the portable
/// `supernodal_solve` (compiled for AVX2 + FMA where available).
///
/// `f` must be the factor of a `Cholesky` (whose constructor ran `assert_supernodes_fit` on it against its n rows);
/// the length of `x` is asserted equal to that n here.
pub(super) fn supernodal_solve_with<const B: usize>(
    f: &SupernodalFactor<'_>,
    x: &mut [[f64; B]],
    ldlt: bool,
    isa: Isa,
    plan: Option<&SolvePlan>,
) {
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(plan) = plan.filter(|_| isa != Isa::Scalar && isa.supported()) {
            type Sweep = unsafe fn(&SupernodalFactor<'_>, bool, usize, usize, &kernels::Sweep<'_>);
            let sweep: Option<Sweep> = match (isa, B, ldlt) {
                (Isa::Avx512, 8, false) => Some(kernels::sweep_avx512::<1, false>),
                (Isa::Avx512, 8, true) => Some(kernels::sweep_avx512::<1, true>),
                (Isa::Avx512, 16, false) => Some(kernels::sweep_avx512::<2, false>),
                (Isa::Avx512, 16, true) => Some(kernels::sweep_avx512::<2, true>),
                (_, 4, false) => Some(kernels::sweep_avx2::<1, false>),
                (_, 4, true) => Some(kernels::sweep_avx2::<1, true>),
                (_, 8, false) => Some(kernels::sweep_avx2::<2, false>),
                (_, 8, true) => Some(kernels::sweep_avx2::<2, true>),
                _ => None,
            };
            if let Some(sweep) = sweep {
                assert_eq!(x.len(), f.symbolic().nrows(), "the block must have one row per unknown");
                assert_eq!(plan.top_pos.len(), x.len(), "a plan for another factor");
                parallel_solve(f, x, plan, |f, fwd, lo, hi, sw| {
                    // SAFETY: the CPU has the sweep's instruction set (`isa.supported()` above); X is n rows of
                    // B = R·LANES values (the `match` pairs each width with its sweep; n asserted just above), the
                    // factor passed `assert_supernodes_fit` against n in `Cholesky::checked`, and `parallel_solve`
                    // keeps the rest of the sweep's contract (see there).
                    unsafe { sweep(f, fwd, lo, hi, sw) }
                });
                return;
            }
        }
        #[target_feature(enable = "avx2,fma")]
        fn portable_avx2<const B: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [[f64; B]]) {
            supernodal_solve::<B, true, UNIT>(f, x)
        }
        if isa != Isa::Scalar && isa.supported() {
            type Kernel = unsafe fn(&SupernodalFactor<'_>, &mut [f64]);
            // Each kernel's width R·LANES is B: AVX-512 has 8 lanes, AVX2 4.
            let kernel: Option<Kernel> = match (isa, B, ldlt) {
                (Isa::Avx512, 8, false) => Some(kernels::solve_avx512::<1, false>),
                (Isa::Avx512, 8, true) => Some(kernels::solve_avx512::<1, true>),
                (Isa::Avx512, 16, false) => Some(kernels::solve_avx512::<2, false>),
                (Isa::Avx512, 16, true) => Some(kernels::solve_avx512::<2, true>),
                (_, 4, false) => Some(kernels::solve_avx2::<1, false>),
                (_, 4, true) => Some(kernels::solve_avx2::<1, true>),
                (_, 8, false) => Some(kernels::solve_avx2::<2, false>),
                (_, 8, true) => Some(kernels::solve_avx2::<2, true>),
                _ => None,
            };
            match kernel {
                Some(kernel) => {
                    assert_eq!(x.len(), f.symbolic().nrows(), "the block must have one row per unknown");
                    // SAFETY: the CPU has the kernel's instruction set (`isa.supported()` above; an AVX-512 CPU
                    // counts as such only with AVX2 + FMA too); the flattened block is x.len() rows of B = R·LANES
                    // values (the `match` pairs each width with its kernel), x.len() is the factor's n (the
                    // `assert_eq!` just above), and `Cholesky::checked` ran `assert_supernodes_fit` on this factor
                    // against n when it was built: the kernel's `# Safety`.
                    unsafe { kernel(f, x.as_flattened_mut()) };
                }
                // SAFETY: the CPU has AVX2 + FMA (`isa.supported()` above); the portable body indexes with checks.
                None if ldlt => unsafe { portable_avx2::<B, true>(f, x) },
                // SAFETY: as in the arm above.
                None => unsafe { portable_avx2::<B, false>(f, x) },
            }
            return;
        }
    }
    // The split solve needs the intrinsic kernels: elsewhere the plan goes unused.
    let _ = plan;
    if ldlt {
        supernodal_solve::<B, false, true>(f, x)
    } else {
        supernodal_solve::<B, false, false>(f, x)
    }
}

/// Solves L Lᵀ X = Y (or, with `UNIT`, L D Lᵀ X = Y for an LDLᵀ factor: unit diagonal in L, D on the diagonal)
/// in place for a supernodal factor, X given row-major in the factor's (permuted) numbering. For LDLᵀ the forward
/// sweep stores D⁻¹y for each solved row while it updates the rows below with y itself, so no third pass is needed.
///
/// Columns of a supernode are taken four at a time (the first `nc % 4` one by one). Forward: the group's 4 × 4
/// diagonal triangle, then every row below it (in the diagonal block and in the supernode's pattern) is updated once
/// with all four columns, whose solved rows of X stay in registers — four sequential streams of the factor and one
/// read-modify-write of X per row instead of four. Backward: each of the four columns gathers the rows below into
/// its own accumulator in one pass (independent FMA chains), then the group's triangle.
#[inline(always)]
fn supernodal_solve<const B: usize, const FMA: bool, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [[f64; B]]) {
    // x − a·y, fused where the CPU has FMA (the body is compiled twice, see `supernodal_solve_with`).
    let sub = |x: f64, a: f64, y: f64| if FMA { (-a).mul_add(y, x) } else { x - a * y };
    let ns = f.symbolic().n_supernodes();
    for s in 0..ns {
        let sn = f.supernode(s);
        let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
        let nc = l.ncols();
        let col = |j: usize| l.col(j).try_as_col_major().expect("supernode columns are contiguous").as_slice();
        let lead = nc % 4;
        for j in 0..lead {
            let cj = col(j);
            let d = 1.0 / cj[j];
            let mut xj = x[c0 + j];
            let mut stored = xj;
            for (v, st) in xj.iter_mut().zip(stored.iter_mut()) {
                if UNIT {
                    *st *= d;
                } else {
                    *v *= d;
                    *st = *v;
                }
            }
            x[c0 + j] = stored;
            for (i, &a) in cj[j + 1..nc].iter().enumerate() {
                let xi = &mut x[c0 + j + 1 + i];
                for t in 0..B {
                    xi[t] = sub(xi[t], a, xj[t]);
                }
            }
            for (&r, &a) in rows.iter().zip(&cj[nc..]) {
                let xr = &mut x[r];
                for t in 0..B {
                    xr[t] = sub(xr[t], a, xj[t]);
                }
            }
        }
        for j in (lead..nc).step_by(4) {
            let c = [col(j), col(j + 1), col(j + 2), col(j + 3)];
            // The group's triangle: x_u = (x_u − Σ_{v<u} L[j+u, j+v] x_v) / L[j+u, j+u].
            let mut g = [[0.0f64; B]; 4];
            for u in 0..4 {
                let mut xu = x[c0 + j + u];
                for v in 0..u {
                    for t in 0..B {
                        xu[t] = sub(xu[t], c[v][j + u], g[v][t]);
                    }
                }
                let d = 1.0 / c[u][j + u];
                let mut stored = xu;
                for (v, st) in xu.iter_mut().zip(stored.iter_mut()) {
                    if UNIT {
                        *st *= d;
                    } else {
                        *v *= d;
                        *st = *v;
                    }
                }
                g[u] = xu;
                x[c0 + j + u] = stored;
            }
            let (g0, g1, g2, g3) = (g[0], g[1], g[2], g[3]);
            let (c0v, c1v, c2v, c3v) = (c[0], c[1], c[2], c[3]);
            for i in j + 4..nc {
                let (a0, a1, a2, a3) = (c0v[i], c1v[i], c2v[i], c3v[i]);
                let xr = &mut x[c0 + i];
                for t in 0..B {
                    xr[t] = sub(sub(sub(sub(xr[t], a0, g0[t]), a1, g1[t]), a2, g2[t]), a3, g3[t]);
                }
            }
            let (b0, b1, b2, b3) = (&c0v[nc..], &c1v[nc..], &c2v[nc..], &c3v[nc..]);
            for (p, &r) in rows.iter().enumerate() {
                let (a0, a1, a2, a3) = (b0[p], b1[p], b2[p], b3[p]);
                let xr = &mut x[r];
                for t in 0..B {
                    xr[t] = sub(sub(sub(sub(xr[t], a0, g0[t]), a1, g1[t]), a2, g2[t]), a3, g3[t]);
                }
            }
        }
    }
    for s in (0..ns).rev() {
        let sn = f.supernode(s);
        let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
        let nc = l.ncols();
        let col = |j: usize| l.col(j).try_as_col_major().expect("supernode columns are contiguous").as_slice();
        let lead = nc % 4;
        for j in (lead..nc).step_by(4).rev() {
            let c = [col(j), col(j + 1), col(j + 2), col(j + 3)];
            let (mut p0, mut p1, mut p2, mut p3) = (x[c0 + j], x[c0 + j + 1], x[c0 + j + 2], x[c0 + j + 3]);
            let (c0v, c1v, c2v, c3v) = (c[0], c[1], c[2], c[3]);
            for i in j + 4..nc {
                let (a0, a1, a2, a3) = (c0v[i], c1v[i], c2v[i], c3v[i]);
                let xr = &x[c0 + i];
                for t in 0..B {
                    p0[t] = sub(p0[t], a0, xr[t]);
                    p1[t] = sub(p1[t], a1, xr[t]);
                    p2[t] = sub(p2[t], a2, xr[t]);
                    p3[t] = sub(p3[t], a3, xr[t]);
                }
            }
            let (b0, b1, b2, b3) = (&c0v[nc..], &c1v[nc..], &c2v[nc..], &c3v[nc..]);
            for (p, &r) in rows.iter().enumerate() {
                let (a0, a1, a2, a3) = (b0[p], b1[p], b2[p], b3[p]);
                let xr = &x[r];
                for t in 0..B {
                    p0[t] = sub(p0[t], a0, xr[t]);
                    p1[t] = sub(p1[t], a1, xr[t]);
                    p2[t] = sub(p2[t], a2, xr[t]);
                    p3[t] = sub(p3[t], a3, xr[t]);
                }
            }
            let acc = [p0, p1, p2, p3];
            // The group's triangle, last column first: x_u = (acc_u − Σ_{v>u} L[j+v, j+u] x_v) / L[j+u, j+u].
            for u in (0..4).rev() {
                let mut xu = acc[u];
                for v in u + 1..4 {
                    let xv = x[c0 + j + v];
                    for t in 0..B {
                        xu[t] = sub(xu[t], c[u][j + v], xv[t]);
                    }
                }
                if !UNIT {
                    let d = 1.0 / c[u][j + u];
                    for v in xu.iter_mut() {
                        *v *= d;
                    }
                }
                x[c0 + j + u] = xu;
            }
        }
        for j in (0..lead).rev() {
            let cj = col(j);
            let mut acc = x[c0 + j];
            for (&r, &a) in rows.iter().zip(&cj[nc..]) {
                let xr = &x[r];
                for t in 0..B {
                    acc[t] = sub(acc[t], a, xr[t]);
                }
            }
            for (i, &a) in cj[j + 1..nc].iter().enumerate() {
                let xi = &x[c0 + j + 1 + i];
                for t in 0..B {
                    acc[t] = sub(acc[t], a, xi[t]);
                }
            }
            if !UNIT {
                let d = 1.0 / cj[j];
                for v in acc.iter_mut() {
                    *v *= d;
                }
            }
            x[c0 + j] = acc;
        }
    }
}

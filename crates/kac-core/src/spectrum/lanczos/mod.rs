//! Thick-restart block Lanczos in the M-inner product for T = (L − σM)⁻¹M (see the module docs of
//! [`super`]). Notation: V holds M-orthonormal basis columns; the first `m` are "expanded" (T applied), the next
//! `b` form the block Q waiting for expansion. H = Vᵀ M T V on the expanded part; E = Qᵀ M T V couples Q to it.
//! A Ritz pair (θ, V s) has residual ‖T x − θ x‖_M = ‖E s‖₂.

mod block;
mod shift;
mod window;

pub(crate) use block::ritz_in_place;
pub(crate) use shift::solve_backward_error;
pub use shift::{default_sigma, weyl_shift, WEYL_FRACTION};
pub use window::Window;

use super::basis_products;
use super::null_space::Deflation;
use super::{Control, EigenError, EigenOptions, Spectrum, Stats, Timings};
use crate::cholesky::factor::Symbolic;
use crate::operators::sparse::SparsePair;
use block::{lap, Clock, Ctx, Ritz, Rng, RowBlock};
use faer::linalg::matmul::matmul;
use faer::reborrow::ReborrowMut;
use faer::{Accum, Mat, Par};
use shift::{factor_shift, Shifted};
use std::time::Instant;
use window::select;

/// What one block-Lanczos run is asked beyond [`EigenOptions`] (whose `k` counts the pairs this run finds).
pub struct Run<'a> {
    /// Directions the basis stays M-orthogonal to: exact zero modes, and pairs found before a repair.
    pub deflation: &'a Deflation<'a>,
    /// Their eigenvalues (each deflated direction's), to count them against the inertia of L − σM.
    pub deflated_values: &'a [f64],
    /// Whether σ may go inside the spectrum by Weyl's law (counting the deflated pairs as found): yes for a first
    /// solve; a repair looks for pairs lying among others it does not count, and keeps σ below the spectrum.
    pub interior_shift: bool,
    /// A slice of the spectrum ([`super::slicing`]): the run factors at the window's shift and returns the pairs in
    /// the window instead of the `k` smallest (`k` then sizes the subspace: the pairs the window is expected to hold).
    pub window: Option<Window>,
    /// Pairs the result starts with, ahead of the run's own (the known zero modes): written into the eigenvector
    /// matrix as it is allocated, so that no second n × k copy is made to put them in front (with it, two n × k
    /// matrices at once would set the process' peak memory).
    pub head: Option<&'a Spectrum>,
}

impl Run<'_> {
    /// Deflated pairs with eigenvalues below σ (they are among those the inertia of L − σM counts).
    fn deflated_below(&self, sigma: f64) -> usize {
        self.deflated_values.iter().filter(|&&v| v < sigma).count()
    }
}

/// The block size and subspace a run with these options would use on `n` unknowns of which `deflated` are
/// deflated, or `None` when the problem is too small for the Krylov method (the caller solves it densely).
pub fn plan(n: usize, deflated: usize, o: &EigenOptions) -> Option<(usize, usize, usize)> {
    // The iteration lives in the M-orthogonal complement of the deflated directions.
    let n = n.saturating_sub(deflated);
    if n < 2 || o.k + 1 > n {
        return None;
    }
    // Block 8 and a subspace of about 3w for w up to ~50 (2w beyond): the best on 10k–41k icospheres for k = 10…200
    // with one thread (a block of 16 takes more solves per converged pair, and bigger dense products).
    let b = o.block.unwrap_or(8).clamp(1, n - 1);
    let guard = (b / 2).max(2);
    let want = (o.k + guard).min(n - 1);
    let default_m = (2 * want).max(want + 6 * b).max((3 * want).min(want + 100));
    let msize = o.subspace.unwrap_or(default_m).max(want + 2 * b).min(n);
    // Room for the wanted pairs, one expanded and one waiting block (a thick restart keeps the wanted pairs and
    // appends the waiting block).
    (msize >= want + 2 * b).then_some((b, want, msize))
}

/// The `o.k` smallest eigenpairs of the problem deflated by `run.deflation`, and the converged guard pairs above
/// them (the result holds `want` ≥ k pairs, ascending, for the completeness check to place its shift above λ_k).
/// `Ok(None)` when the problem is too small for the Krylov method (see [`plan`]).
pub fn eigs_block_lanczos(
    pair: &SparsePair,
    o: &EigenOptions,
    symbolic: Option<&Symbolic>,
    control: Control<'_>,
    run: &Run<'_>,
) -> Result<Option<Spectrum>, EigenError> {
    let t_start = Instant::now();
    let n = pair.n();
    let k = o.k;
    let par = o.par();
    let Some((b, want, msize)) = plan(n, run.deflation.len(), o) else { return Ok(None) };
    // The basis is the solve's widest array: refused before anything is factored or allocated.
    let basis = n.saturating_mul(msize);
    if basis > o.max_values {
        return Err(EigenError::TooLarge {
            what: format!("the Krylov basis ({n} unknowns × {msize} columns)"),
            values: basis,
            limit: o.max_values,
        });
    }
    // Factor L − σM (symbolic analysis reused when given).
    let t0 = Instant::now();
    let (sym, reused) = match symbolic {
        Some(s) if s.fits(pair) => (s.clone(), true),
        _ => (Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?, false),
    };
    let symbolic_s = t0.elapsed().as_secs_f64();
    control.phase("factorization", 0, k)?;
    let t1 = Instant::now();
    let threads = o.thread_count();
    // V: the basis. It is the largest allocation (1.3 GB at 164k × 1006): filled column group by column group, so
    // that a stop during its first touch of memory (about a second there) takes effect. On more than one thread it
    // is made on one of them beside the numeric factorization on the others, which gains little from a second
    // thread. If the factorization fails, the basis
    // was made for nothing: the solve ends with the factorization's error.
    let (shifted, made) = if threads > 1 {
        let fpar = if threads > 2 { Par::rayon(threads - 1) } else { Par::Seq };
        let (shifted, v) = rayon::join(
            || factor_shift(pair, o, &sym, fpar, run, &control),
            || super::zeros_checked(n, msize, &control, 1),
        );
        (shifted?, Some(v?))
    } else {
        (factor_shift(pair, o, &sym, par, run, &control)?, None)
    };
    let Shifted { sigma, factor: chol, below_sigma } = shifted;
    control.check()?;
    // Eigenvalues below σ the iteration must find itself (the inertia less the deflated ones).
    let below_undeflated = below_sigma.map(|nu| nu.saturating_sub(run.deflated_below(sigma)));
    let numeric_s = t1.elapsed().as_secs_f64();
    // A slice whose window holds far more pairs than it was planned for (Weyl's law misjudged the spectrum's
    // density: thin shapes) gives up at once; the caller solves in one run.
    if let Some(w) = &run.window {
        // The pairs the slice must hold: from lo to the `total`-th eigenvalue or to σ, whichever is further (top
        // slice); every one below σ (lowest slice).
        let over = match (w.total, below_sigma, below_undeflated) {
            (Some(total), Some(b), _) => b.max(total).saturating_sub(w.below_lo) > k + k / 2 + 8,
            (None, _, Some(nu)) => w.lo == f64::NEG_INFINITY && nu > k,
            _ => false,
        };
        if over {
            return Err(EigenError::NoConvergence { converged: 0, wanted: k, steps: 0 });
        }
    }
    let t2 = Instant::now();
    let mut clock = Clock::default();
    let mdiag = pair.mass_diagonal();
    let mean_mass = mdiag.iter().sum::<f64>() / n as f64;
    let mut ctx = Ctx {
        pair,
        deflation: run.deflation,
        mdiag: pair.mass_is_diagonal.then_some(mdiag),
        mean_mass,
        scratch: Vec::new(),
        threads,
    };
    let mut rng = Rng(o.seed);

    // V: the basis (expanded columns, then the waiting block Q); MQ = M Q; H = Vᵀ M T V on the expanded part;
    // E: Q's coupling, T V_exp = V_exp H + Q E, nonzero from column `e_lo` on.
    let mut v = match made {
        Some(v) => v,
        None => super::zeros_checked(n, msize, &control, ctx.threads)?,
    };
    let mut mq = RowBlock::zeros(n, b);
    let mut h = Mat::<f64>::zeros(msize, msize);
    let mut w = RowBlock::zeros(n, b);
    let mut mw = RowBlock::zeros(n, b);
    {
        let mut q0 = RowBlock::zeros(n, b);
        q0.data.iter_mut().for_each(|x| *x = rng.next());
        ctx.apply_m(q0.as_ref(), mw.as_mut());
        run.deflation.project(&mut q0.data, &mut mw.data, b, ctx.threads);
        ctx.normalize(v.as_mut(), 0, &q0, &mw, mq.as_mut(), &mut rng, &[1.0]);
    }
    let mut m = 0usize; // expanded columns
    let mut locked = 0usize;
    let mut e = Mat::<f64>::zeros(b, 0);
    let mut e_lo = 0usize;
    let (mut steps, mut restarts, mut solves) = (0usize, 0usize, 0usize);
    let mut best_converged = 0;
    // The next block step after which the projected problem is solved to test convergence (see `far` below).
    let mut next_test = 0usize;
    control.report("iterating", 0, k);
    loop {
        if control.stopped() {
            return Err(EigenError::Canceled);
        }
        let mut t = Instant::now();
        // Expand the waiting block while it fits.
        if m + 2 * b <= msize {
            basis_products::copy_par(&mut w.data, &mq.data, b, ctx.threads);
            chol.solve_in_place(w.as_mut(), par);
            clock.solve += lap(&mut t);
            solves += b;
            steps += 1;
            // Scale for the rank test: Euclidean norms² times the mean mass (no extra M-product).
            let gram: Vec<f64> = basis_products::col_dots_par(&w.data, &w.data, b, ctx.threads)
                .iter()
                .map(|g| g * ctx.mean_mass)
                .collect();
            let mut coef = Mat::<f64>::zeros(m + b, b);
            {
                let (basis, _) = v.as_ref().split_at_col(m + b);
                // The recurrence: Vᵀ M T Q = Eᵀ on the expanded part (exact arithmetic), Qᵀ M T Q = A.
                if e_lo < m {
                    let et = e.as_ref().subcols(e_lo, m - e_lo).transpose();
                    basis_products::update_par(&mut w.data, b, basis.subcols(e_lo, m - e_lo), et, -1.0, ctx.threads);
                    coef.as_mut().subrows_mut(e_lo, m - e_lo).copy_from(et);
                }
                let a = basis_products::gram_par(mq.as_ref(), &w.data, b, ctx.threads);
                basis_products::update_par(&mut w.data, b, basis.subcols(m, b), a.as_ref(), -1.0, ctx.threads);
                coef.as_mut().subrows_mut(m, b).copy_from(a.as_ref());
                // Full reorthogonalization against the whole basis (locked vectors included), after the deflated
                // directions (T keeps their complement, so this removes rounding only).
                ctx.apply_m(w.as_ref(), mw.as_mut());
                run.deflation.project(&mut w.data, &mut mw.data, b, ctx.threads);
                ctx.project_out(basis, &mut w.data, &mut mw.data, coef.as_mut());
            }
            for r in locked..m + b {
                for c in 0..b {
                    h[(r, m + c)] = coef[(r, c)];
                    h[(m + c, r)] = coef[(r, c)];
                }
            }
            for r in 0..locked {
                for c in 0..b {
                    h[(r, m + c)] = 0.0;
                    h[(m + c, r)] = 0.0;
                }
            }
            let bm = ctx.normalize(v.as_mut(), m + b, &w, &mw, mq.as_mut(), &mut rng, &gram);
            m += b;
            e = Mat::<f64>::zeros(b, m);
            e.as_mut().subcols_mut(m - b, b).copy_from(bm.as_ref());
            e_lo = m - b;
            clock.orthogonalize += lap(&mut t);
            if m < want || (m + 2 * b <= msize && steps < next_test) {
                continue;
            }
        }
        // Rayleigh–Ritz on the active (unlocked) part of the expanded basis; locked columns are Ritz vectors
        // already, with H = diag(θ) there and no coupling (deflated).
        control.check()?;
        let a0 = locked;
        let ma = m - a0;
        let hs = Mat::from_fn(ma, ma, |i, j| 0.5 * (h[(a0 + i, a0 + j)] + h[(a0 + j, a0 + i)]));
        // On the solve's threads (faer's `self_adjoint_eigen` would take the whole pool).
        let (theta_a, s_a) = super::small_dense::symmetric_eigen(hs.as_ref(), par)
            .map_err(|err| EigenError::Factorization { message: format!("projected eigenproblem: {err:?}") })?;
        let s_a = s_a.as_ref();
        let mut es = Mat::<f64>::zeros(b, ma);
        matmul(es.as_mut(), Accum::Replace, e.as_ref().subcols(a0, ma), s_a, 1.0, Par::Seq);
        // Candidates: (θ, locked column or active Ritz index, residual ‖E s‖₂; zero for locked pairs).
        let mut cand: Vec<(f64, Ritz, f64)> = (0..a0).map(|i| (h[(i, i)], Ritz::Locked(i), 0.0)).collect();
        for c in 0..ma {
            let r = (0..b).map(|rr| es[(rr, c)] * es[(rr, c)]).sum::<f64>().sqrt();
            cand.push((theta_a[c], Ritz::Active(c), r));
        }
        let converged = |c: &(f64, Ritz, f64)| c.2 <= o.tol * c.0.abs();
        // Ascending λ = σ + 1/θ: descending θ when σ is below the spectrum (every θ > 0); with σ inside it the
        // negative θ (λ < σ) come first, then the positive ones from the largest down.
        cand.sort_by(|x, y| (sigma + 1.0 / x.0).total_cmp(&(sigma + 1.0 / y.0)));
        let pick = select(&cand, sigma, want, run.window.as_ref(), below_sigma);
        let req = &cand[pick.req_start..pick.req_end];
        let leading = cand.iter().take_while(|c| converged(c)).count();
        // How far the wanted pairs are from the tolerance: the largest ratio of residual to tol·|θ| among the
        // candidates that must converge. Residuals fall by at most ~10–15× per block step in measured runs (10k–41k
        // spheres, k = 50…200), so at 100× per step the test cannot succeed in fewer than log₁₀₀ of that ratio steps.
        let far = req.iter().map(|c| c.2 / (o.tol * c.0.abs())).fold(0.0, f64::max);
        next_test = steps + ((far.max(1.0).log10() / 2.0) as usize).max(1);
        clock.rayleigh_ritz += lap(&mut t);
        let progress = if run.window.is_some() { req.iter().filter(|c| converged(c)).count() } else { leading };
        if progress.min(k) > best_converged {
            best_converged = progress.min(k);
            control.report("iterating", best_converged, k);
        }
        // With σ inside the spectrum, the inertia says how many eigenvalues lie below it: all of them must be among
        // the pairs returned (a cluster member the Krylov space has not met yet would otherwise go unnoticed). A
        // slice above the bottom returns only part of them; the check of the whole result counts the rest.
        let done = match &run.window {
            None => {
                let inertia_met =
                    below_undeflated.is_none_or(|nu| cand.iter().take(k).filter(|c| c.0 < 0.0).count() == nu);
                leading >= want && inertia_met
            }
            Some(w) => {
                let inertia_met = w.lo != f64::NEG_INFINITY
                    || below_undeflated.is_none_or(|nu| cand.partition_point(|c| c.0 < 0.0) == nu);
                // More converged pairs in an interior window than its inertia counts cannot be, unless an eigenvalue
                // lies within rounding of an edge and a slice beside this one claims it too: that count can never be
                // met, so the slice gives up (the caller solves in one run) instead of iterating to `max_steps`.
                let inside = cand[pick.start..pick.end].iter().filter(|c| converged(c)).count();
                if w.count.is_some_and(|count| inside > count) {
                    return Err(EigenError::NoConvergence { converged: inside, wanted: k, steps });
                }
                pick.enough && req.iter().all(converged) && inertia_met
            }
        };
        let full = m + 2 * b > msize;
        if !done && !full {
            continue;
        }
        if !done && steps >= o.max_steps {
            return Err(EigenError::NoConvergence { converged: leading.min(k), wanted: k, steps });
        }
        if done {
            // The k smallest λ: locked columns as they are, active ones as V_active S; written in ascending λ
            // (the candidates' order already; sorted defensively).
            // The k wanted pairs and the converged guard pairs above them (for the completeness check's shift).
            let top = &cand[pick.start..pick.end];
            let want = top.len();
            let act: Vec<usize> =
                top.iter().filter_map(|c| if let Ritz::Active(j) = c.1 { Some(j) } else { None }).collect();
            let s_sel = Mat::from_fn(ma, act.len(), |i, j| s_a[(i, act[j])]);
            control.report("ritz-vectors", k, k);
            ritz_in_place(&mut v, a0, ma, s_sel.as_ref(), par, &control)?;
            // Column of each candidate in V: locked ones where they are, active ones from a0 on in `top` order.
            let mut next_active = a0;
            let src: Vec<usize> = top
                .iter()
                .map(|c| match c.1 {
                    Ritz::Locked(i) => i,
                    Ritz::Active(_) => {
                        next_active += 1;
                        next_active - 1
                    }
                })
                .collect();
            let raw: Vec<f64> = top.iter().map(|c| sigma + 1.0 / c.0).collect();
            let mut idx: Vec<usize> = (0..want).collect();
            idx.sort_by(|&x, &y| raw[x].total_cmp(&raw[y]));
            let head_values = run.head.map_or(&[][..], |h| &h.values[..]);
            let h = head_values.len();
            let values: Vec<f64> = head_values.iter().copied().chain(idx.iter().map(|&j| raw[j])).collect();
            // The factor is no longer needed: freed before the eigenvectors are allocated beside the basis (at 10⁶
            // vertices, k = 100, the basis is 1.6 GB, the factor 0.5 GB and the eigenvectors 0.8 GB).
            let (factor_nnz, ldlt) = (chol.factor_nnz(), chol.is_ldlt());
            drop(chol);
            // So are the basis columns past the last one copied out (about half the basis).
            super::release_columns(&mut v, src.iter().map(|&c| c + 1).max().unwrap_or(0));
            let vectors = super::columns_checked(n, h + want, &control, ctx.threads, |j, col| {
                let from = match run.head {
                    Some(head) if j < h => head.vectors.col(j),
                    _ => v.col(src[idx[j - h]]),
                };
                for (x, y) in col.iter_mut().zip(from.iter()) {
                    *x = *y;
                }
            })?;
            clock.restart += lap(&mut t);
            control.report("converged", k, k);
            let iteration_s = t2.elapsed().as_secs_f64();
            return Ok(Some(Spectrum {
                values,
                vectors,
                residuals: vec![],
                stats: Stats {
                    method: "block-lanczos",
                    sigma,
                    block: b,
                    subspace: msize,
                    restarts,
                    block_steps: steps,
                    solves,
                    factor_nnz,
                    factorization: if ldlt { "ldlt" } else { "cholesky" },
                    below_sigma,
                    symbolic_reused: reused,
                    timings: Timings {
                        symbolic_s,
                        numeric_s,
                        iteration_s,
                        solve_s: clock.solve,
                        orthogonalize_s: clock.orthogonalize,
                        rayleigh_ritz_s: clock.rayleigh_ritz,
                        restart_s: clock.restart,
                        total_s: t_start.elapsed().as_secs_f64(),
                        ..Default::default()
                    },
                    ..Default::default()
                },
            }));
        }
        // Thick restart: [locked | kept active Ritz vectors | Q], H = diag(θ), E ← E S. Locked columns stay in
        // place (never recomputed); active pairs in the converged leading prefix are locked now (E columns zero:
        // deflated) and come first. Q and M Q stay as they are.
        restarts += 1;
        let keep = (want + msize.saturating_sub(want + 2 * b) / 2).min(m - b).max(want.min(m - b)).max(a0 + 1);
        let mut lock_now: Vec<usize> = Vec::new();
        let mut rest: Vec<usize> = Vec::new();
        // A slice keeps the candidates nearest its window (the standard run: ascending λ, as sorted).
        let order: Vec<usize> = match &run.window {
            None => (0..cand.len()).collect(),
            Some(w) => {
                let lam = |c: &(f64, Ritz, f64)| sigma + 1.0 / c.0;
                let hi = match w.total {
                    Some(_) if pick.enough && pick.end > pick.start => lam(&cand[pick.end - 1]),
                    Some(_) => f64::INFINITY,
                    None => w.hi,
                };
                let dist = |c: &(f64, Ritz, f64)| (w.lo - lam(c)).max(lam(c) - hi).max(0.0);
                let mut order: Vec<usize> = (0..cand.len()).collect();
                order.sort_by(|&x, &y| dist(&cand[x]).total_cmp(&dist(&cand[y])));
                order
            }
        };
        let lockable = |pos: usize| match run.window {
            None => pos < leading,
            Some(_) => (pick.req_start..pick.req_end).contains(&pos) && converged(&cand[pos]),
        };
        for &pos in &order {
            let c = &cand[pos];
            if let Ritz::Active(j) = c.1 {
                if lockable(pos) {
                    lock_now.push(j);
                } else if a0 + lock_now.len() + rest.len() < keep {
                    rest.push(j);
                }
            }
        }
        if run.window.is_some() && a0 + lock_now.len() + 3 * b > msize {
            // The window holds more pairs than its subspace was sized for: the caller solves without slicing.
            return Err(EigenError::NoConvergence { converged: a0 + lock_now.len(), wanted: k, steps });
        }
        let sel: Vec<usize> = lock_now.iter().chain(&rest).copied().collect();
        let keep = a0 + sel.len();
        let s_keep = Mat::from_fn(ma, sel.len(), |i, j| s_a[(i, sel[j])]);
        // V[:, a0..keep] = V[:, a0..m] S_keep in place, then Q moved to keep..keep + b (keep + b ≤ m: Q's columns
        // are not among those overwritten, and every read of the product is done before the move).
        ritz_in_place(&mut v, a0, ma, s_keep.as_ref(), par, &control)?;
        {
            let (mut left, right) = v.as_mut().split_at_col_mut(m);
            left.rb_mut().subcols_mut(keep, b).copy_from(right.subcols(0, b));
        }
        let locked_theta: Vec<f64> = (0..a0).map(|i| h[(i, i)]).collect();
        h.fill(0.0);
        for (i, &th) in locked_theta.iter().enumerate() {
            h[(i, i)] = th;
        }
        locked = a0 + lock_now.len();
        let mut e_new = Mat::<f64>::zeros(b, keep);
        for (j, &c) in sel.iter().enumerate() {
            h[(a0 + j, a0 + j)] = theta_a[c];
            if a0 + j >= locked {
                for r in 0..b {
                    e_new[(r, a0 + j)] = es[(r, c)];
                }
            }
        }
        e = e_new;
        e_lo = locked;
        m = keep;
        clock.restart += lap(&mut t);
    }
}

#[cfg(test)]
mod tests {
    use super::shift::LDLT_BACKWARD_ERROR;
    use super::*;
    use crate::cholesky::factor::{Cholesky, Symbolic};
    use crate::geometry::{generate, Shape};
    use crate::operators;

    /// The stability test of an LDLᵀ factor can fail: the factor of a nearby matrix (standing in for a factor
    /// whose entries grew without pivoting) shows a large backward error, the matrix's own factor a tiny one.
    #[test]
    fn backward_error_tells_a_good_solve_from_a_bad_one() {
        let shape = Shape::TriangleMesh(generate::icosphere(4));
        let pair = operators::build(&shape, &Default::default()).unwrap().pair;
        let sym = Symbolic::analyze(&pair.pattern).unwrap();
        let k = pair.shifted(7.0);
        let (good, _) = Cholesky::factor_ldlt(&sym, &k, Par::Seq).unwrap();
        let (other, _) = Cholesky::factor_ldlt(&sym, &pair.shifted(7.5), Par::Seq).unwrap();
        let e_good = solve_backward_error(&pair, &k, &good, Par::Seq);
        let e_other = solve_backward_error(&pair, &k, &other, Par::Seq);
        assert!(e_good < 1e-15, "{e_good}");
        assert!(e_other > LDLT_BACKWARD_ERROR, "{e_other}");
    }
}

//! Thick-restart block Lanczos in the M-inner product for T = (L − σM)⁻¹M (see the module docs of
//! [`super`]). Notation: V holds M-orthonormal basis columns; the first `m` are "expanded" (T applied), the next
//! `b` form the block Q waiting for expansion. H = Vᵀ M T V on the expanded part; E = Qᵀ M T V couples Q to it.
//! A Ritz pair (θ, V s) has residual ‖T x − θ x‖_M = ‖E s‖₂.

use super::factor::{Cholesky, Symbolic};
use super::{Control, EigenError, EigenOptions, Spectrum, Stats, Timings};
use crate::operators::sparse::SparsePair;
use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use std::time::Instant;

/// The default shift: σ = −mean_j(L_jj / M_jj) / n. The mean diagonal ratio scales like the top of the
/// spectrum (≈ c/h² ≈ c·n/area on a surface), so σ lands near the bottom of the spectrum (about λ₁/4 on a
/// unit sphere), far from the null space: a shift much closer to 0 makes the null modes dominate T and costs
/// the small Ritz values digits (measured: 10⁻⁸ relative with σ = −10⁻⁶·mean, 10⁻¹³ with this σ).
pub fn default_sigma(pair: &SparsePair) -> f64 {
    let n = pair.n();
    let mut s = 0.0;
    for j in 0..n {
        let d = pair.pattern.diag_pos(j);
        if pair.mass[d] > 0.0 {
            s += pair.stiffness[d].abs() / pair.mass[d];
        }
    }
    let scale = s / n.max(1) as f64;
    -(if scale > 0.0 && scale.is_finite() { scale } else { 1.0 }) / n.max(1) as f64
}

/// Deterministic pseudo-random numbers (SplitMix64), uniform in [−1, 1].
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

struct Ctx<'a> {
    pair: &'a SparsePair,
    mdiag: Option<Vec<f64>>,
    mean_mass: f64,
}

impl Ctx<'_> {
    /// out = M x
    fn apply_m(&self, x: MatRef<'_, f64>, mut out: MatMut<'_, f64>) {
        match &self.mdiag {
            Some(d) => {
                for c in 0..x.ncols() {
                    for i in 0..x.nrows() {
                        out[(i, c)] = d[i] * x[(i, c)];
                    }
                }
            }
            None => crate::operators::sparse::spmm(&self.pair.pattern, &self.pair.mass, x, out),
        }
    }

    /// M-orthogonalizes `w` against `v` twice (classical Gram–Schmidt, DGKS); returns Vᵀ M (T-image) coefficients.
    fn orthogonalize(&self, v: MatRef<'_, f64>, mut w: MatMut<'_, f64>) -> Mat<f64> {
        let (n, b, m) = (w.nrows(), w.ncols(), v.ncols());
        let mut coef = Mat::<f64>::zeros(m, b);
        if m == 0 {
            return coef;
        }
        let mut mw = Mat::<f64>::zeros(n, b);
        let mut c = Mat::<f64>::zeros(m, b);
        let mut self_norms = vec![0.0; b];
        for pass in 0..2 {
            self.apply_m(w.rb(), mw.as_mut());
            if pass == 0 {
                for (col, sn) in self_norms.iter_mut().enumerate() {
                    *sn = (0..n).map(|i| w[(i, col)] * mw[(i, col)]).sum();
                }
            }
            matmul(c.as_mut(), Accum::Replace, v.transpose(), mw.as_ref(), 1.0, Par::Seq);
            matmul(w.rb_mut(), Accum::Add, v, c.as_ref(), -1.0, Par::Seq);
            coef += &c;
            if pass == 0 {
                // DGKS: a second pass only if some column lost more than half its M-norm² to the projection
                // (‖w − Vc‖²_M = ‖w‖²_M − ‖c‖², V being M-orthonormal).
                let lost = (0..b).any(|col| {
                    let c2: f64 = (0..m).map(|r| c[(r, col)] * c[(r, col)]).sum();
                    c2 > 0.5 * self_norms[col]
                });
                if !lost {
                    break;
                }
            }
        }
        coef
    }

    /// M-orthonormalizes the columns of `w` in place (after orthogonalization against `v`): W = Q B.
    /// Directions that vanished (rank deficiency) are replaced by random vectors orthogonal to `v` and the rest;
    /// their rows of B are zero. Returns B.
    fn normalize(&self, v: MatRef<'_, f64>, mut w: MatMut<'_, f64>, rng: &mut Rng, scale: &[f64]) -> Mat<f64> {
        let (n, b) = (w.nrows(), w.ncols());
        let mut mw = Mat::<f64>::zeros(n, b);
        self.apply_m(w.rb(), mw.as_mut());
        let mut g = Mat::<f64>::zeros(b, b);
        matmul(g.as_mut(), Accum::Replace, w.rb().transpose(), mw.as_ref(), 1.0, Par::Seq);
        let g = Mat::from_fn(b, b, |i, j| 0.5 * (g[(i, j)] + g[(j, i)]));
        let evd = g.self_adjoint_eigen(Side::Lower).expect("symmetric eigen of a small Gram matrix");
        let (s, u) = (evd.S(), evd.U());
        let ref_scale = scale.iter().cloned().fold(0.0, f64::max).max(f64::MIN_POSITIVE);
        let mut q = Mat::<f64>::zeros(n, b);
        let mut bmat = Mat::<f64>::zeros(b, b);
        let mut kept = 0;
        // Largest directions first.
        for idx in (0..b).rev() {
            let sv = s[idx];
            if sv > 1e-24 * ref_scale {
                let r = sv.sqrt();
                let col = u.col(idx);
                let mut qc = q.col_mut(kept);
                for i in 0..n {
                    let mut acc = 0.0;
                    for c in 0..b {
                        acc += w[(i, c)] * col[c];
                    }
                    qc[i] = acc / r;
                }
                for c in 0..b {
                    bmat[(kept, c)] = r * col[c];
                }
                kept += 1;
            }
        }
        // Refill vanished directions with random vectors.
        for j in kept..b {
            for _attempt in 0..3 {
                let mut x = Mat::<f64>::from_fn(n, 1, |_, _| rng.next());
                let vv = if v.ncols() > 0 { Some(v) } else { None };
                // `orthogonalize` already reorthogonalizes as needed (DGKS); Q ⊥ V, so one call against each.
                if let Some(vv) = vv {
                    self.orthogonalize(vv, x.as_mut());
                }
                if j > 0 {
                    self.orthogonalize(q.as_ref().subcols(0, j), x.as_mut());
                }
                let mut mx = Mat::<f64>::zeros(n, 1);
                self.apply_m(x.as_ref(), mx.as_mut());
                let nrm = (0..n).map(|i| x[(i, 0)] * mx[(i, 0)]).sum::<f64>().sqrt();
                if nrm > 1e-8 {
                    for i in 0..n {
                        q[(i, j)] = x[(i, 0)] / nrm;
                    }
                    break;
                }
            }
        }
        w.copy_from(q.as_ref());
        bmat
    }
}

pub fn eigs_block_lanczos(
    pair: &SparsePair,
    o: &EigenOptions,
    symbolic: Option<&Symbolic>,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    let t_start = Instant::now();
    let n = pair.n();
    let k = o.k;
    let par = if o.threads == 1 { Par::Seq } else { Par::rayon(o.threads) };
    // Block 8 and a subspace of about 3w for w up to ~50 (2w beyond): measured best on 10k–41k icospheres for
    // k = 10…200 with one thread (block 16 cost 1.4× at k = 50: more solves per converged pair, bigger GEMMs).
    let b = o.block.unwrap_or(8).clamp(1, n.saturating_sub(1).max(1));
    let guard = (b / 2).max(2);
    let want = (k + guard).min(n - 1);
    let default_m = (2 * want).max(want + 6 * b).max((3 * want).min(want + 100));
    let msize = o.subspace.unwrap_or(default_m).max(want + 2 * b).min(n);
    // Block count must fit: expanded part + one waiting block.
    if msize < want + b {
        // Tiny problem relative to the block: fall back to dense.
        return super::dense::eigs_dense(pair, k).map(|mut s| {
            s.stats.sigma = default_sigma(pair);
            s
        });
    }
    // Factor L − σM (symbolic analysis reused when given).
    let t0 = Instant::now();
    let (sym, reused) = match symbolic {
        Some(s) if s.fits(pair) => (s.clone(), true),
        _ => (Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?, false),
    };
    let symbolic_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let mut sigma = o.sigma.unwrap_or_else(|| default_sigma(pair));
    let chol = {
        let mut attempt = 0;
        loop {
            match Cholesky::factor(&sym, &pair.shifted(sigma), par) {
                Ok(c) => break c,
                Err(message) => {
                    attempt += 1;
                    if o.sigma.is_some() || attempt >= 4 {
                        return Err(EigenError::Factorization { message: format!("σ = {sigma:e}: {message}") });
                    }
                    sigma *= 100.0;
                }
            }
        }
    };
    let numeric_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let mdiag = pair.mass_diagonal();
    let mean_mass = mdiag.iter().sum::<f64>() / n as f64;
    let ctx = Ctx { pair, mdiag: pair.mass_is_diagonal.then_some(mdiag), mean_mass };
    let mut rng = Rng(o.seed);

    let mut v = Mat::<f64>::zeros(n, msize);
    let mut h = Mat::<f64>::zeros(msize, msize);
    // Start block.
    {
        let mut q0 = Mat::<f64>::from_fn(n, b, |_, _| rng.next());
        let empty = Mat::<f64>::zeros(n, 0);
        ctx.normalize(empty.as_ref(), q0.as_mut(), &mut rng, &[1.0]);
        v.as_mut().subcols_mut(0, b).copy_from(q0.as_ref());
    }
    let mut m = 0usize; // expanded columns
    let mut locked = 0usize;
    let mut e = Mat::<f64>::zeros(b, 0);
    let (mut steps, mut restarts, mut solves) = (0usize, 0usize, 0usize);
    let mut best_converged = 0;
    control.report("iterating", 0, k);
    loop {
        if control.stopped() {
            return Err(EigenError::Canceled);
        }
        // Expand the waiting block while it fits.
        if m + 2 * b <= msize {
            let mut w = Mat::<f64>::zeros(n, b);
            ctx.apply_m(v.as_ref().subcols(m, b), w.as_mut());
            chol.solve_in_place(w.as_mut(), par);
            solves += b;
            steps += 1;
            // Scale for the rank test: Euclidean norms² times the mean mass (no extra M-product).
            let mscale = ctx.mean_mass;
            let gram: Vec<f64> = (0..b).map(|c| mscale * (0..n).map(|i| w[(i, c)] * w[(i, c)]).sum::<f64>()).collect();
            let coef = ctx.orthogonalize(v.as_ref().subcols(0, m + b), w.as_mut());
            for r in 0..m + b {
                for c in 0..b {
                    let val = if r < locked { 0.0 } else { coef[(r, c)] };
                    h[(r, m + c)] = val;
                    h[(m + c, r)] = val;
                }
            }
            let bm = ctx.normalize(v.as_ref().subcols(0, m + b), w.as_mut(), &mut rng, &gram);
            v.as_mut().subcols_mut(m + b, b).copy_from(w.as_ref());
            m += b;
            e = Mat::<f64>::zeros(b, m);
            for r in 0..b {
                for c in 0..b {
                    e[(r, m - b + c)] = bm[(r, c)];
                }
            }
            if m < want || (m + 2 * b <= msize && steps % 2 == 1) {
                continue;
            }
        }
        // Rayleigh–Ritz on the expanded part.
        let hs = Mat::from_fn(m, m, |i, j| 0.5 * (h[(i, j)] + h[(j, i)]));
        let evd = hs
            .self_adjoint_eigen(Side::Lower)
            .map_err(|err| EigenError::Factorization { message: format!("projected eigenproblem: {err:?}") })?;
        let (theta, s) = (evd.S(), evd.U());
        // Largest θ first.
        let order: Vec<usize> = (0..m).rev().collect();
        let mut es = Mat::<f64>::zeros(b, m);
        matmul(es.as_mut(), Accum::Replace, e.as_ref(), s, 1.0, Par::Seq);
        let resid: Vec<f64> =
            order.iter().map(|&c| (0..b).map(|r| es[(r, c)] * es[(r, c)]).sum::<f64>().sqrt()).collect();
        let conv: Vec<bool> = order.iter().zip(&resid).map(|(&c, &r)| r <= o.tol * theta[c].abs()).collect();
        let leading = conv.iter().take_while(|&&x| x).count();
        if leading.min(k) > best_converged {
            best_converged = leading.min(k);
            control.report("iterating", best_converged, k);
        }
        let done = leading >= want;
        let full = m + 2 * b > msize;
        if !done && !full {
            continue;
        }
        if !done && steps >= o.max_steps {
            return Err(EigenError::NoConvergence { converged: leading.min(k), wanted: k, steps });
        }
        // Ritz vectors of the kept (or final) set.
        let keep = if done { k } else { (want + (msize - want - 2 * b) / 2).min(m - b).max(want.min(m - b)) };
        let sel: Vec<usize> = order[..keep].to_vec();
        let s_keep = Mat::from_fn(m, keep, |i, j| s[(i, sel[j])]);
        let mut x = Mat::<f64>::zeros(n, keep);
        matmul(x.as_mut(), Accum::Replace, v.as_ref().subcols(0, m), s_keep.as_ref(), 1.0, Par::Seq);
        if done {
            let values: Vec<f64> = sel.iter().map(|&c| sigma + 1.0 / theta[c]).collect();
            // Ascending λ = descending θ already; sort defensively.
            let mut idx: Vec<usize> = (0..k).collect();
            idx.sort_by(|&a, &b2| values[a].total_cmp(&values[b2]));
            let vectors = Mat::from_fn(n, k, |i, j| x[(i, idx[j])]);
            let values = idx.iter().map(|&j| values[j]).collect();
            control.report("done", k, k);
            let iteration_s = t2.elapsed().as_secs_f64();
            return Ok(Spectrum {
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
                    factor_nnz: chol.factor_nnz(),
                    symbolic_reused: reused,
                    timings: Timings { symbolic_s, numeric_s, iteration_s, total_s: t_start.elapsed().as_secs_f64() },
                },
            });
        }
        // Thick restart: [Ritz vectors | Q], H = diag(θ), E ← E S; converged leading pairs are locked (E column 0).
        restarts += 1;
        let q = v.as_ref().subcols(m, b).to_owned();
        v.as_mut().subcols_mut(0, keep).copy_from(x.as_ref());
        v.as_mut().subcols_mut(keep, b).copy_from(q.as_ref());
        h.fill(0.0);
        let mut e_new = Mat::<f64>::zeros(b, keep);
        locked = leading.min(keep);
        for (j, &c) in sel.iter().enumerate() {
            h[(j, j)] = theta[c];
            if j >= locked {
                for r in 0..b {
                    e_new[(r, j)] = es[(r, c)];
                }
            }
        }
        // The waiting block's coupling to the kept vectors lives in H's border as well.
        for j in 0..keep {
            for r in 0..b {
                h[(keep + r, j)] = e_new[(r, j)];
                h[(j, keep + r)] = e_new[(r, j)];
            }
        }
        e = e_new;
        m = keep;
    }
}

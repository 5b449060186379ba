//! Completeness: Sylvester's inertia at a shift in a gap above the pairs found counts the eigenvalues below it;
//! a shortfall is repaired by solving again, deflated against what was found, or densely for small blocks.

use super::*;

/// Repair rounds before a spectrum that stays incomplete is an error. Each round finds every pair missed below
/// the check's shift unless the repair solve itself misses one, which the next round sees.
pub(crate) const MAX_REPAIRS: usize = 3;

/// The largest problem (or block) a repair hands to the dense path when too few unknowns are left for the
/// Krylov method.
pub(crate) const DENSE_REPAIR_MAX: usize = 8000;

/// Relative width of a gap between consecutive eigenvalues that the inertia check may put its shift in.
pub(crate) const GAP: f64 = 1e-6;

/// Where to count: τ in the first gap wider than [`GAP`] above the `wanted`-th of the ascending `values` (which
/// may hold converged pairs beyond `wanted`), else in the last such gap below it. Returns τ and the number of
/// `values` below it; `None` when the values have no gap at all.
pub(crate) fn check_shift(values: &[f64], wanted: usize) -> Option<(f64, usize)> {
    let wide = |j: usize| values[j + 1] - values[j] > GAP * values[j + 1].abs().max(values[j].abs()).max(1e-300);
    let last = values.len().checked_sub(1)?;
    let above = (wanted.saturating_sub(1)..last).find(|&j| wide(j));
    let j = above.or_else(|| (0..wanted.saturating_sub(1).min(last)).rev().find(|&j| wide(j)))?;
    Some((0.5 * (values[j] + values[j + 1]), j + 1))
}

/// The gap the check counts in for the ascending `values` and `wanted` pairs: (lo, hi, pairs found below it). With
/// no gap at all (every value found is one cluster), just below the cluster, where nothing may lie.
pub(crate) fn gap_to_count(pair: &SparsePair, values: &[f64], wanted: usize) -> (f64, f64, usize) {
    match check_shift(values, wanted) {
        Some((_, found)) => (values[found - 1], values[found], found),
        None => {
            let v0 = values[0];
            let scale = v0.abs().max(lanczos::default_sigma(pair).abs());
            (v0 - 2.0 * GAP * scale, v0 - GAP * scale, 0)
        }
    }
}

/// A count taken ahead of [`verify_and_repair`]: τ and the eigenvalues below it by inertia, or the count's error,
/// with the seconds it took.
pub(crate) type EarlyCount = (Result<(f64, usize), EigenError>, f64);

/// The first count of [`verify_and_repair`], taken beside [`finish`] at a shift placed from the solver's values
/// (`finish` replaces them by Rayleigh quotients, which moves them by about 10⁻¹¹ relative at most, against gaps
/// of at least [`GAP`]).
pub(crate) fn early_count(
    sym: &factor::Symbolic,
    pair: &SparsePair,
    values: &[f64],
    k: usize,
    control: &Control<'_>,
    par: faer::Par,
) -> EarlyCount {
    let t = Instant::now();
    let (lo, hi, _) = gap_to_count(pair, values, k);
    (inertia_in_gap(sym, pair, (lo, hi), control, par), t.elapsed().as_secs_f64())
}

/// The largest backward error of a test solve accepted from the check's LDLᵀ factor (as for the solver's own
/// factor: [`lanczos`]'s LDLᵀ stability test); beyond it the count may be wrong and τ moves within its gap.
pub(crate) const CHECK_BACKWARD_ERROR: f64 = 1e-10;

/// Sylvester's inertia at τ: the eigenvalues of the problem below τ, from an LDLᵀ factor whose test solve is
/// backward stable; τ is tried at the middle, then at a third and two thirds of the gap (lo, hi). The factorization
/// and the test solve run on `par`'s threads.
pub(crate) fn inertia_in_gap(
    sym: &factor::Symbolic,
    pair: &SparsePair,
    (lo, hi): (f64, f64),
    control: &Control<'_>,
    par: faer::Par,
) -> Result<(f64, usize), EigenError> {
    let mut last = String::new();
    for f in [0.5, 1.0 / 3.0, 2.0 / 3.0] {
        let tau = lo + f * (hi - lo);
        let values = pair.shifted(tau);
        match factor::Cholesky::factor_ldlt_stoppable(sym, &values, par, control.stop) {
            Ok((factor, below)) => {
                let e = lanczos::solve_backward_error(pair, &values, &factor, par);
                if e <= CHECK_BACKWARD_ERROR {
                    return Ok((tau, below));
                }
                last = format!("the LDLᵀ factor of L − {tau:e}·M is not backward stable ({e:.1e})");
            }
            Err(super::numeric::FactorError::Stopped) => return Err(EigenError::Canceled),
            Err(e) => last = format!("LDLᵀ of L − {tau:e}·M failed ({e})"),
        }
    }
    Err(EigenError::Factorization { message: format!("the completeness check could not count: {last}") })
}

/// Checks by inertia that the ascending `values` hold every eigenvalue below the check's shift (see
/// [`Completeness`]), without repairing; `Ok(None)` when the values have no gap to put a shift in.
pub fn check_completeness(
    pair: &SparsePair,
    values: &[f64],
    wanted: usize,
    symbolic: Option<&factor::Symbolic>,
) -> Result<Option<Completeness>, EigenError> {
    let t = Instant::now();
    let Some((_, found)) = check_shift(values, wanted) else { return Ok(None) };
    let owned;
    let sym = match symbolic {
        Some(s) if s.fits(pair) => s,
        _ => {
            owned =
                factor::Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?;
            &owned
        }
    };
    let (tau, below) =
        inertia_in_gap(sym, pair, (values[found - 1], values[found]), &Control::default(), faer::Par::Seq)?;
    Ok(Some(Completeness {
        method: "inertia",
        complete: below == found,
        shift: Some(tau),
        below_shift: Some(below),
        found_below_shift: Some(found),
        repairs: 0,
        repaired_pairs: 0,
        seconds: t.elapsed().as_secs_f64(),
    }))
}

/// The completeness check of a sparse solve, repaired: while the inertia counts more eigenvalues below τ than were
/// found, every found pair is deflated and the iteration runs again (σ below the spectrum, another seed) for the
/// missing ones, which are the smallest of what is left; their pairs join the others and the count is taken
/// again. `s` holds the k wanted pairs and any converged guard pairs, ascending, the first `zeros.len()` the known
/// zero modes. `early` is a first count taken beside [`finish`] ([`early_count`]): it stands where its τ lies in the
/// middle half of the gap this check would count in, and is taken again otherwise.
#[allow(clippy::too_many_arguments)]
pub(crate) fn verify_and_repair(
    pair: &SparsePair,
    sym: &factor::Symbolic,
    options: &EigenOptions,
    control: Control<'_>,
    (zeros, blocks): (&ZeroModes, Option<&Blocks>),
    s: &mut Spectrum,
    k: usize,
    mut early: Option<EarlyCount>,
) -> Result<(), EigenError> {
    let t = Instant::now();
    let z = zeros.len();
    let mut repairs = 0;
    let mut repaired_pairs = 0;
    let mut early_s = 0.0;
    loop {
        let (lo, hi, found) = gap_to_count(pair, &s.values, k);
        control.phase("verifying", k, k)?;
        // A count taken early stands where its τ lies in the middle half of this gap (it was placed in the middle
        // of the same gap of the values before their Rayleigh quotients); otherwise the count is taken again here.
        let (tau, below) = match early.take() {
            Some((Err(EigenError::Canceled), _)) => return Err(EigenError::Canceled),
            Some((Ok((tau, below)), seconds)) if tau > lo + 0.25 * (hi - lo) && tau < hi - 0.25 * (hi - lo) => {
                early_s = seconds;
                (tau, below)
            }
            _ => inertia_in_gap(sym, pair, (lo, hi), &control, options.par())?,
        };
        control.check()?;
        let c = Completeness {
            method: "inertia",
            complete: below == found,
            shift: Some(tau),
            below_shift: Some(below),
            found_below_shift: Some(found),
            repairs,
            repaired_pairs,
            seconds: 0.0,
        };
        if below == found {
            s.stats.completeness = Some(c);
            break;
        }
        if below < found || repairs == MAX_REPAIRS {
            // Fewer eigenvalues than pairs found cannot be (the found vectors are M-orthonormal); more after the
            // repairs means the repair solves keep missing them.
            return Err(EigenError::Incomplete { shift: tau, below, found, repairs });
        }
        if control.stopped() {
            return Err(EigenError::Canceled);
        }
        repairs += 1;
        let missing = below - found;
        let p = s.values.len() - z;
        let found_vectors = s.vectors.as_ref().subcols(z, p).to_owned();
        let m_found = mass_times(pair, found_vectors.as_ref(), options.thread_count());
        let deflation = Deflation { sparse: &zeros.vectors, dense: Some((found_vectors.as_ref(), m_found.as_ref())) };
        let mut deflated_values = vec![0.0; z];
        deflated_values.extend_from_slice(&s.values[z..]);
        let run = lanczos::Run {
            deflation: &deflation,
            deflated_values: &deflated_values,
            interior_shift: false,
            window: None,
            head: None,
        };
        let o = EigenOptions {
            k: missing,
            sigma: Some(lanczos::default_sigma(pair)),
            seed: options.seed.wrapping_add(repairs as u64),
            ..options.clone()
        };
        let Some(mut extra) = lanczos::eigs_block_lanczos(pair, &o, Some(sym), control, &run)? else {
            // Too few unknowns left for the Krylov method: the dense path computes every eigenvalue.
            if blocks.map_or(pair.n(), |b| b.largest) > DENSE_REPAIR_MAX {
                return Err(EigenError::Incomplete { shift: tau, below, found, repairs });
            }
            let stats = std::mem::take(&mut s.stats);
            *s = dense_with_zero_modes(pair, zeros, blocks, k, options.thread_count(), control)?;
            s.stats = Stats { completeness: Some(Completeness { repairs, ..Completeness::by("dense") }), ..stats };
            finish(pair, s, z.min(k), options.thread_count(), usize::MAX, control)?;
            break;
        };
        finish(pair, &mut extra, 0, options.thread_count(), usize::MAX, control)?;
        repaired_pairs += extra.values.len().min(missing);
        merge(s, extra);
    }
    // The seconds of the check's work, an early count's included (it ran beside `finish`).
    let seconds = t.elapsed().as_secs_f64() + early_s;
    if let Some(c) = s.stats.completeness.as_mut() {
        c.seconds = seconds;
    }
    s.stats.timings.verify_s = seconds;
    Ok(())
}

/// M X for a dense block, on `threads` threads.
pub(crate) fn mass_times(pair: &SparsePair, x: MatRef<'_, f64>, threads: usize) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(x.nrows(), x.ncols());
    let mut scratch = Vec::new();
    crate::operators::sparse::spmm(&pair.pattern, &pair.mass, x, out.as_mut(), &mut scratch, threads);
    out
}

/// Adds the pairs of a repair solve to a spectrum, keeping the ascending order.
pub(crate) fn merge(s: &mut Spectrum, extra: Spectrum) {
    let (n, a, b) = (s.vectors.nrows(), s.values.len(), extra.values.len());
    let mut order: Vec<(f64, bool, usize)> = (0..a).map(|j| (s.values[j], false, j)).collect();
    order.extend((0..b).map(|j| (extra.values[j], true, j)));
    // Stable: the known zero modes (exact zeros) stay first.
    order.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut vectors = Mat::<f64>::zeros(n, a + b);
    let (mut values, mut residuals) = (Vec::with_capacity(a + b), Vec::with_capacity(a + b));
    for (j, &(v, from_extra, i)) in order.iter().enumerate() {
        let (src, res) = if from_extra { (&extra.vectors, &extra.residuals) } else { (&s.vectors, &s.residuals) };
        vectors.as_mut().col_mut(j).copy_from(src.col(i));
        values.push(v);
        residuals.push(res.get(i).copied().unwrap_or(0.0));
    }
    s.values = values;
    s.residuals = residuals;
    s.vectors = vectors;
    s.stats.block_steps += extra.stats.block_steps;
    s.stats.solves += extra.stats.solves;
    s.stats.restarts += extra.stats.restarts;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{generate, Shape};
    use crate::operators;

    /// A verified sparse solve of the 642-vertex sphere, its options, and the check run again on the result with
    /// an early count given.
    fn solved() -> (SparsePair, Spectrum, EigenOptions) {
        let shape = Shape::TriangleMesh(generate::icosphere(3));
        let pair = operators::build(&shape, &Default::default()).unwrap().pair;
        let o = EigenOptions { k: 20, method: Method::Sparse, threads: 1, ..Default::default() };
        let s = eigs(&pair, &o, None, Control::default()).unwrap();
        (pair, s, o)
    }

    fn check_again(
        pair: &SparsePair,
        s: &Spectrum,
        o: &EigenOptions,
        early: Option<EarlyCount>,
    ) -> Result<Spectrum, EigenError> {
        let sym = factor::Symbolic::analyze(&pair.pattern).unwrap();
        let zeros = null_space::zero_modes(pair);
        let blocks = Blocks::of(pair);
        let mut s = s.clone();
        s.stats.completeness = None;
        verify_and_repair(pair, &sym, o, Control::default(), (&zeros, blocks.as_ref()), &mut s, o.k, early)?;
        Ok(s)
    }

    /// An early count stands only where its τ lies in the middle half of the final values' gap: one there is taken
    /// as it is (its seconds counted in the check's), one elsewhere, or one that failed, is counted again; a stop
    /// during the early count stops the check.
    #[test]
    fn an_early_count_stands_only_inside_the_gap() {
        let (pair, s, o) = solved();
        // The check of the k pairs returned (the solve's own check also saw its guard pairs), counted now.
        let truth = check_again(&pair, &s, &o, None).unwrap().stats.completeness.unwrap();
        assert!(truth.complete);
        let sym = factor::Symbolic::analyze(&pair.pattern).unwrap();
        let (lo, hi, found) = gap_to_count(&pair, &s.values, o.k);
        assert_eq!((Some(found), truth.shift), (truth.found_below_shift, Some(0.5 * (lo + hi))));

        // Inside: taken as it is, even a count the check would not have made (a τ a little off the middle).
        let tau = lo + 0.4 * (hi - lo);
        let early = early_count(&sym, &pair, &s.values, o.k, &Control::default(), faer::Par::Seq);
        let below = early.0.as_ref().unwrap().1;
        let c = check_again(&pair, &s, &o, Some((Ok((tau, below)), 100.0))).unwrap().stats.completeness.unwrap();
        assert_eq!((c.shift, c.below_shift, c.complete), (Some(tau), Some(below), true));
        assert!(c.seconds >= 100.0, "{}", c.seconds);

        // Outside the middle half, or above the gap: counted again at the gap's middle.
        for tau in [lo + 0.1 * (hi - lo), hi + 1.0] {
            let c = check_again(&pair, &s, &o, Some((Ok((tau, 0)), 100.0))).unwrap().stats.completeness.unwrap();
            assert_eq!((c.shift, c.below_shift, c.complete), (truth.shift, truth.below_shift, true), "τ = {tau}");
            assert!(c.seconds < 100.0);
        }
        // A failed early count is counted again; a stopped one stops the check.
        let failed = Err(EigenError::Factorization { message: "test".into() });
        let c = check_again(&pair, &s, &o, Some((failed, 0.0))).unwrap().stats.completeness.unwrap();
        assert_eq!((c.shift, c.complete), (truth.shift, true));
        assert!(matches!(
            check_again(&pair, &s, &o, Some((Err(EigenError::Canceled), 0.0))),
            Err(EigenError::Canceled)
        ));
    }

    /// In a real solve the early count stands: taken as `eigs` takes it on several threads (from the solver's
    /// values, before `finish`), it is accepted by the check of the finished pairs, which counts nothing again.
    #[test]
    fn a_solves_early_count_stands() {
        let shape = Shape::TriangleMesh(generate::icosphere(4));
        let pair = operators::build(&shape, &Default::default()).unwrap().pair;
        let o = EigenOptions { k: 60, method: Method::Sparse, threads: 1, ..Default::default() };
        let sym = factor::Symbolic::analyze(&pair.pattern).unwrap();
        let zeros = null_space::zero_modes(&pair);
        let z = zeros.len();
        let deflation = Deflation { sparse: &zeros.vectors, dense: None };
        let zero_values = vec![0.0; z];
        let head = zero_mode_spectrum(&pair, &zeros, z);
        let run = lanczos::Run {
            deflation: &deflation,
            deflated_values: &zero_values,
            interior_shift: true,
            window: None,
            head: Some(&head),
        };
        let solve = EigenOptions { k: o.k - z, ..o.clone() };
        let mut s = lanczos::eigs_block_lanczos(&pair, &solve, Some(&sym), Control::default(), &run).unwrap().unwrap();
        let (count, _) = early_count(&sym, &pair, &s.values, o.k, &Control::default(), faer::Par::Seq);
        let before = s.values.clone();
        finish(&pair, &mut s, z, 1, usize::MAX, Control::default()).unwrap();
        assert_ne!(before, s.values, "finish replaced the values by Rayleigh quotients");
        let blocks = Blocks::of(&pair);
        let early = Some((count, 100.0));
        verify_and_repair(&pair, &sym, &o, Control::default(), (&zeros, blocks.as_ref()), &mut s, o.k, early).unwrap();
        let c = s.stats.completeness.unwrap();
        assert!(c.complete && c.seconds >= 100.0, "{c:?}");
    }
}

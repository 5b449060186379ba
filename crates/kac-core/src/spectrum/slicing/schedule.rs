//! Running the slices: on the solve's own threads, on threads a host lends, and as tasks offered to other
//! machines, each slice taken once; the parts then stitched into one spectrum.

use super::edges::stitch;
use super::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A thread lent by a [`Lender`], given back when dropped, and taken off the count of loans out.
struct Returned<'a>(&'a dyn Lender, &'a AtomicUsize);

/// The slice loops running as tasks of the pool, and whether the caller has closed the queue (its own loop found no
/// slice left): a task that starts after that has nothing to do.
#[derive(Default)]
struct Tasks {
    state: std::sync::Mutex<(usize, bool)>,
    ended: std::sync::Condvar,
}

/// A task's loop, counted while it runs (its end signalled when dropped, a panic included).
struct Started<'a>(&'a Tasks);

impl Tasks {
    fn start(&self) -> Option<Started<'_>> {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if st.1 {
            return None;
        }
        st.0 += 1;
        Some(Started(self))
    }
    fn close_and_wait(&self) {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        st.1 = true;
        while st.0 > 0 {
            st = self.ended.wait(st).unwrap_or_else(|e| e.into_inner());
        }
    }
}

impl Drop for Started<'_> {
    fn drop(&mut self) {
        self.0.state.lock().unwrap_or_else(|e| e.into_inner()).0 -= 1;
        self.0.ended.notify_all();
    }
}

impl Drop for Returned<'_> {
    fn drop(&mut self) {
        self.1.fetch_sub(1, Ordering::SeqCst);
        self.0.give_back();
    }
}

/// What [`solve`] did: slicing does not apply (one run is the plan), the slices' pairs, or the plan given up (the
/// caller then solves in one run and reports why).
pub(crate) enum Sliced {
    NotPlanned,
    Solved(Box<Spectrum>),
    GivenUp(String),
}

/// The `o.k` smallest pairs of the deflated problem by slicing, with the guard pairs above them (see [`Sliced`]).
pub(crate) fn solve(
    pair: &SparsePair,
    o: &EigenOptions,
    sym: &factor::Symbolic,
    control: Control<'_>,
    deflation: &null_space::Deflation<'_>,
    deflated_values: &[f64],
    head: Option<&Spectrum>,
) -> Result<Sliced, EigenError> {
    let t0 = Instant::now();
    let Some(slices) = plan(pair, deflation.len(), o.k, o) else { return Ok(Sliced::NotPlanned) };
    let threads = o.thread_count();
    control.phase("factorization", 0, o.k)?;
    // Sylvester's inertia at every edge between two slices: each window's count exactly, so its subspace is
    // sized for what it holds (Weyl's even split meets clustered spectra unevenly: a sphere's window can hold a
    // 57-fold cluster more than planned). An edge moves within ±1 % of its window where its LDLᵀ factor is not
    // backward stable.
    let count_edge = |j: usize| -> Result<(f64, usize), EigenError> {
        let (w0, w1) = (slices[j - 1], slices[j]);
        let e = w1.lo;
        let below = if w0.lo.is_finite() { w0.lo } else { 0.0 };
        let above = if w1.hi.is_finite() { w1.hi } else { w1.sigma };
        let reach = 0.01 * (e - below).min(above - e);
        // Each edge on one thread; the runs of edges below are counted side by side.
        completeness::inertia_in_gap(sym, pair, (e - reach, e + reach), &control, faer::Par::Seq)
    };
    // One run of consecutive edges per thread given (not one task per edge, which idle threads of a shared pool
    // would take, each holding a factor).
    let inner: Vec<usize> = (1..slices.len()).collect();
    let runs: Vec<&[usize]> = inner.chunks(inner.len().div_ceil(threads.max(1)).max(1)).collect();
    let edges: Vec<Result<(f64, usize), EigenError>> = if runs.len() > 1 {
        let counted: Vec<Vec<_>> =
            runs.into_par_iter().with_max_len(1).map(|run| run.iter().map(|&j| count_edge(j)).collect()).collect();
        counted.into_iter().flatten().collect()
    } else {
        inner.iter().map(|&j| count_edge(j)).collect()
    };
    let edges: Vec<(f64, usize)> = match edges.into_iter().collect() {
        Ok(e) => e,
        Err(EigenError::Canceled) => return Err(EigenError::Canceled),
        Err(e) => return Ok(Sliced::GivenUp(format!("the inertia count at a slice edge failed: {e}"))),
    };
    let deflated = deflation.len();
    let total = slices.last().and_then(|s| s.total).unwrap_or(deflated + o.k);
    // Windows with their exact counts; slices past the one that reaches `total` pairs are dropped.
    let mut planned: Vec<(Window, usize)> = Vec::with_capacity(slices.len());
    let mut below = deflated;
    for (j, w) in slices.iter().enumerate() {
        let mut w = *w;
        if j > 0 {
            w.lo = edges[j - 1].0;
        }
        w.below_lo = below;
        let last = j + 1 == slices.len() || edges[j].1 >= total;
        if last {
            w.hi = f64::INFINITY;
            w.total = Some(total);
            if j + 1 < slices.len() {
                // The `total`-th eigenvalue lies below this window's planned top edge: σ halfway to where the count
                // between the edges (linear in λ) reaches it, not at the planned midpoint, which may lie above it.
                let (top, at_top) = edges[j];
                let share = (total - below) as f64 / (at_top - below).max(1) as f64;
                let lam_total = w.lo + share.clamp(0.0, 1.0) * (top - w.lo);
                w.sigma = 0.5 * (w.lo + lam_total);
            }
            if !(w.sigma > w.lo) {
                w.sigma = w.lo + 0.5 * (slices[j].sigma - slices[j].lo).abs().max(w.lo.abs() * 1e-3);
            }
            planned.push((w, total.saturating_sub(below).max(1)));
            break;
        }
        w.hi = edges[j].0;
        w.sigma = if w.lo.is_finite() { 0.5 * (w.lo + w.hi) } else { lanczos::WEYL_FRACTION * w.hi };
        let count = edges[j].1.saturating_sub(below);
        w.count = Some(count);
        below = edges[j].1;
        planned.push((w, count.max(1)));
    }
    let slices = planned;
    if slices.len() < 2 {
        return Ok(Sliced::GivenUp(format!(
            "the counts at the slice edges put all {total} pairs in the first slice (Weyl's law misjudged this spectrum)"
        )));
    }
    // Threads left to each slice's factorization and solves once every slice has one.
    let inner = (threads / slices.len()).max(1);
    let converged: Vec<AtomicUsize> = slices.iter().map(|_| AtomicUsize::new(0)).collect();
    let k = o.k;
    // A slice's run: `pairs` sizes its subspace. The top slice ends at the k-th eigenvalue, not at an edge placed in
    // a gap, and must see whole the cluster that may straddle it: its subspace gets as many more columns as its
    // pairs, at most [`TOP_EXTRA`].
    let options_of = |i: usize| -> EigenOptions {
        let (window, pairs) = slices[i];
        let sub = window.total.and_then(|_| {
            let own = EigenOptions { k: pairs, subspace: None, ..o.clone() };
            let (_, _, msize) = lanczos::plan(pair.n(), deflation.len(), &own)?;
            Some((msize + TOP_EXTRA.min(pairs)).min(pair.n()))
        });
        EigenOptions { k: pairs, threads: inner, subspace: sub, ..o.clone() }
    };
    // (pairs, seconds, pool thread, who solved it elsewhere)
    type Outcome = (Result<Option<Spectrum>, EigenError>, f64, Option<usize>, Option<String>);
    let progress_of = |i: usize, done: usize| {
        converged[i].store(done, Ordering::Relaxed);
        let sum: usize = converged.iter().map(|c| c.load(Ordering::Relaxed)).sum();
        control.report("iterating", sum.min(k), k);
    };
    let run_slice = |i: usize| -> Outcome {
        let t = Instant::now();
        let report = |p: Progress| {
            if p.phase == "iterating" {
                progress_of(i, p.converged);
            }
        };
        let slice_control = Control { progress: Some(&report), stop: control.stop, lender: None, farm: None };
        let run =
            lanczos::Run { deflation, deflated_values, interior_shift: true, window: Some(slices[i].0), head: None };
        let r = lanczos::eigs_block_lanczos(pair, &options_of(i), Some(sym), slice_control, &run);
        (r, t.elapsed().as_secs_f64(), rayon::current_thread_index(), None)
    };
    // The solve's own threads, and the idle threads its host lends for the slices beyond them (the service's idle
    // workers; see [`Lender`]).
    let own = threads.min(slices.len());
    let lender = control.lender.filter(|_| slices.len() > own);
    let lent = lender.map_or(0, |l| l.borrow(slices.len() - own));
    // One queue, the top slice first: it holds the k-th eigenvalue, often inside a cluster it must see whole, and
    // takes the most block steps (about twice the others'). Each thread takes the next slice when it is free, so the
    // longest does not start last, and no thread is handed a fixed half of the slices that may hold the slow ones.
    let order: Vec<usize> = (0..slices.len()).rev().collect();
    // The slices no thread starts at once, offered to the host's other machines ([`Farm`]).
    let farm = control.farm.filter(|_| slices.len() > own + lent);
    let offers: Vec<Option<SliceTask>> = match farm {
        Some(f) => {
            let pencil = pencil_digest(pair);
            let mut offers: Vec<Option<SliceTask>> = vec![None; slices.len()];
            for &i in &order[own + lent..] {
                let task = SliceTask {
                    index: i,
                    window: slices[i].0,
                    options: EigenOptions { threads: 0, ..options_of(i) },
                    pencil: pencil.clone(),
                };
                if f.offer(&task) {
                    offers[i] = Some(task);
                }
            }
            offers
        }
        None => vec![],
    };
    let offered = |i: usize| offers.get(i).and_then(Option::as_ref);
    let results: Vec<Outcome> = if own + lent > 1 || lender.is_some() || farm.is_some() {
        // A lent thread also leaves when its host wants it back, and is given back however it leaves (a panic
        // included).
        let next = AtomicUsize::new(0);
        let failed = std::sync::atomic::AtomicBool::new(false);
        let done: Vec<std::sync::Mutex<Option<Outcome>>> = slices.iter().map(|_| std::sync::Mutex::new(None)).collect();
        // Offered slices another machine started: collected by the solve's own threads once none of theirs is left.
        let elsewhere = std::sync::Mutex::new(Vec::<usize>::new());
        let (order, next, failed, slots, run_slice, elsewhere) =
            (&order, &next, &failed, &done, &run_slice, &elsewhere);
        let keep = |i: usize, r: Outcome| {
            if !matches!(r.0, Ok(Some(_))) {
                failed.store(true, Ordering::Relaxed);
            }
            *slots[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
            !failed.load(Ordering::Relaxed)
        };
        // The offered slices another machine started, collected (or solved here when they come back unsolved).
        let collect_rest = || {
            let Some(f) = farm else { return };
            while !failed.load(Ordering::Relaxed) {
                let Some(i) = elsewhere.lock().unwrap_or_else(|e| e.into_inner()).pop() else { break };
                let Some(task) = offered(i) else { continue };
                let r = match f.collect(task, &control) {
                    // Pairs of this pencil's size, one vector per value (anything else is solved here).
                    Ok(Some(solved))
                        if solved.spectrum.vectors.nrows() == pair.n()
                            && solved.spectrum.vectors.ncols() == solved.spectrum.values.len() =>
                    {
                        progress_of(i, solved.spectrum.values.len());
                        (Ok(Some(solved.spectrum)), solved.seconds, None, Some(solved.by))
                    }
                    // Taken back, or failed or lost where it ran: solved here.
                    Ok(_) => run_slice(i),
                    Err(e) => (Err(e), 0.0, None, None),
                };
                if !keep(i, r) {
                    return;
                }
            }
        };
        let collect_rest = &collect_rest;
        // A thread's loop over the slices waiting, `after` run after each of its slices.
        let looper = |loan: Option<&Returned<'_>>, after: &dyn Fn()| {
            // After a failure the rest is not started (the plan falls back to one run, or the stop ends it).
            while !failed.load(Ordering::Relaxed) {
                let Some(&i) = order.get(next.fetch_add(1, Ordering::Relaxed)) else { break };
                if let (Some(f), Some(task)) = (farm, offered(i)) {
                    if !f.take_back(task) {
                        elsewhere.lock().unwrap_or_else(|e| e.into_inner()).push(i);
                        continue;
                    }
                }
                if !keep(i, run_slice(i)) {
                    return;
                }
                after();
                if loan.is_some_and(|l| l.0.wanted_back()) {
                    return;
                }
            }
            // A lent thread goes back to its host rather than wait for another machine.
            if loan.is_none() {
                collect_rest();
            }
        };
        let tasks = Tasks::default();
        // Loans spawned and not yet ended: the caller asks for more after each of its slices while more slices wait
        // than threads take them (a worker the host could not lend at first, or that came free since, joins then).
        let out = AtomicUsize::new(lent);
        let (looper, tasks, out) = (&looper, &tasks, &out);
        rayon::scope(|scope| {
            let spawn = |lent: bool| {
                let loan = lender.filter(|_| lent).map(|l| Returned(l, out));
                scope.spawn(move |_| {
                    let started = tasks.start();
                    // Declared after `started`, so dropped before it (a panic included): the loan is given back
                    // before the caller may leave its wait.
                    let loan = loan;
                    if started.is_some() {
                        looper(loan.as_ref(), &|| {});
                    }
                });
            };
            // The caller's own loop runs here; the other threads (its own beyond the first, then the lent ones) are
            // tasks of the pool, taken by its idle threads.
            for t in 1..own + lent {
                spawn(t >= own);
            }
            looper(None, &|| {
                if let Some(l) = lender {
                    let left = order.len().saturating_sub(next.load(Ordering::Relaxed));
                    let waiting = left.saturating_sub(own + out.load(Ordering::SeqCst));
                    let more = if waiting > 0 { l.borrow(waiting) } else { 0 };
                    out.fetch_add(more, Ordering::SeqCst);
                    for _ in 0..more {
                        spawn(true);
                    }
                }
            });
            // The caller waits for the tasks that started, blocked: a thread waiting inside the pool runs whatever
            // work the pool has, another job's included, and this solve would end only when that job does. The
            // tasks no thread has started return at once.
            tasks.close_and_wait();
            // A lent thread may have found an offered slice started elsewhere after the caller's own collecting ended.
            collect_rest();
        });
        // Offered slices the solve no longer waits for (after a failure) are released.
        if let Some(f) = farm {
            for (i, slot) in done.iter().enumerate() {
                if let (None, Some(task)) = (&*slot.lock().unwrap_or_else(|e| e.into_inner()), offered(i)) {
                    f.release(task);
                }
            }
        }
        // Slices never started (after a failure) are left out: the failure is in the list, and ends the solve
        // below as in the sequential path.
        done.into_iter().filter_map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner())).collect()
    } else {
        let mut out = Vec::with_capacity(slices.len());
        for i in 0..slices.len() {
            let r = run_slice(i);
            let failed = r.0.is_err();
            out.push(r);
            if failed {
                break;
            }
        }
        out
    };
    let mut parts = Vec::with_capacity(slices.len());
    let mut seconds = Vec::with_capacity(slices.len());
    let which = |i: usize| format!("slice {} of {} ({} pairs)", i + 1, slices.len(), slices[i].1);
    for (i, (r, s, worker, by)) in results.into_iter().enumerate() {
        match r {
            Ok(Some(spectrum)) => parts.push(spectrum),
            Err(EigenError::Canceled) => return Err(EigenError::Canceled),
            // A slice's basis over the limit: one run instead where its basis fits (a top slice that a misjudged
            // plan gave nearly every pair, with its extra columns, can be wider than one run), else the slice's error.
            Err(e @ EigenError::TooLarge { .. }) => {
                let one_run = lanczos::plan(pair.n(), deflation.len(), o).map(|(_, _, m)| pair.n().saturating_mul(m));
                return if one_run.is_some_and(|v| v <= o.max_values) {
                    Ok(Sliced::GivenUp(format!("{}: {e}", which(i))))
                } else {
                    Err(e)
                };
            }
            // The plan did not fit this problem (or too few unknowns): one run instead.
            Ok(None) => return Ok(Sliced::GivenUp(format!("{}: too few unknowns for its Krylov basis", which(i)))),
            Err(e) => return Ok(Sliced::GivenUp(format!("{}: {e}", which(i)))),
        }
        seconds.push((s, worker, by));
    }
    if parts.len() < slices.len() {
        return Ok(Sliced::GivenUp(format!("{} of {} slices were solved", parts.len(), slices.len())));
    }
    control.check()?;
    let reports: Vec<SliceReport> = parts
        .iter()
        .zip(&slices)
        .zip(&seconds)
        .map(|((p, (w, _)), (s, worker, by))| SliceReport {
            lo: w.lo.is_finite().then_some(w.lo),
            hi: w.hi.is_finite().then_some(w.hi),
            // The shift the slice was solved at (another than planned where the planned one's factor was not
            // backward stable).
            sigma: p.stats.sigma,
            below_sigma: p.stats.below_sigma,
            pairs: p.values.len(),
            block_steps: p.stats.block_steps,
            solves: p.stats.solves,
            restarts: p.stats.restarts,
            seconds: *s,
            worker: *worker,
            solved_by: by.clone(),
        })
        .collect();
    let mut s = stitch(pair, parts, head, &slices, &control, threads)?;
    if s.values.len() < k + head.map_or(0, |h| h.values.len()) {
        return Ok(Sliced::GivenUp(format!(
            "the slices held {} pairs together, fewer than the {k} asked",
            s.values.len()
        )));
    }
    s.stats.slices = reports;
    s.stats.timings.iteration_s = t0.elapsed().as_secs_f64();
    Ok(Sliced::Solved(Box::new(s)))
}

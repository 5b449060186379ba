//! Spectrum slicing against the solve in one run and against closed forms: the same eigenvalues (10⁻¹⁰ relative),
//! M-orthonormal eigenvectors across the slices' edges, full multiplicities where an edge cuts a cluster, the same
//! answer on one thread and on two, completeness proven, a plan the spectrum does not fit given up for one run, and a
//! stop honoured inside a slice.

use kac_core::geometry::{generate, Shape};
use kac_core::operators::{self, Boundary, Mass, OperatorOptions};
use kac_core::spectrum::{eigs, slicing, Control, EigenError, EigenOptions, Method, Spectrum};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

fn pair_of(shape: &Shape, boundary: Boundary) -> operators::sparse::SparsePair {
    let op = OperatorOptions { mass: Some(Mass::Consistent), boundary, ..Default::default() };
    operators::build(shape, &op).unwrap().pair
}

fn solve(pair: &operators::sparse::SparsePair, k: usize, slices: usize, threads: usize) -> Spectrum {
    let o = EigenOptions { k, slices: Some(slices), threads, method: Method::Sparse, ..Default::default() };
    eigs(pair, &o, None, Control::default()).unwrap()
}

/// max |ΦᵀMΦ − I|.
fn orthonormality_defect(pair: &operators::sparse::SparsePair, s: &Spectrum) -> f64 {
    let n = pair.n();
    let k = s.values.len();
    let mut worst = 0.0f64;
    let mut mx = vec![0.0; n];
    for a in 0..k {
        let xa: Vec<f64> = (0..n).map(|i| s.vectors[(i, a)]).collect();
        operators::sparse::matvec(&pair.pattern, &pair.mass, &xa, &mut mx);
        for b in 0..k {
            let d: f64 = (0..n).map(|i| s.vectors[(i, b)] * mx[i]).sum();
            worst = worst.max((d - if a == b { 1.0 } else { 0.0 }).abs());
        }
    }
    worst
}

fn assert_same_values(sliced: &Spectrum, whole: &Spectrum) {
    assert_eq!(sliced.values.len(), whole.values.len());
    for (j, (a, b)) in sliced.values.iter().zip(&whole.values).enumerate() {
        assert!((a - b).abs() <= 1e-10 * b.abs().max(1.0), "λ{j}: sliced {a}, one run {b}");
    }
}

/// The unit sphere: eigenvalues l(l + 1) with multiplicity 2l + 1, so every edge Weyl's law puts between slices
/// falls inside or beside a cluster. Four slices return the 150 smallest pairs of the one-run solve, the clusters
/// whole, the vectors M-orthonormal across the edges; the slices' windows are contiguous and the completeness check
/// confirms the count.
#[test]
fn sliced_sphere_matches_one_run_with_whole_clusters() {
    let pair = pair_of(&Shape::TriangleMesh(generate::icosphere(4)), Boundary::Neumann);
    let k = 150;
    let whole = solve(&pair, k, 1, 1);
    assert!(whole.stats.slices.is_empty());
    let sliced = solve(&pair, k, 4, 1);
    let st = &sliced.stats;
    assert_eq!(st.slices.len(), 4, "{:?}", st.slices);
    assert_same_values(&sliced, &whole);
    let defect = orthonormality_defect(&pair, &sliced);
    assert!(defect < 1e-8, "ΦᵀMΦ − I reaches {defect:e}");
    let c = st.completeness.as_ref().unwrap();
    assert!(c.complete && c.below_shift == c.found_below_shift && c.repairs == 0, "{c:?}");
    // The windows tile the spectrum: each slice's upper end is the next one's lower end.
    for w in st.slices.windows(2) {
        assert_eq!(w[0].hi, w[1].lo);
        assert!(w[0].sigma < w[1].sigma);
    }
    assert!(st.slices[0].lo.is_none() && st.slices[3].hi.is_none());
    // l(l + 1) with 2l + 1 members, l = 0..11 (144 pairs): on 2,562 vertices the P1 error grows like l⁴h² (3.2% at
    // l = 9, measured), and each cluster stays apart from the next.
    let mut j = 0;
    for l in 0..12usize {
        let exact = (l * (l + 1)) as f64;
        for _ in 0..2 * l + 1 {
            let v = sliced.values[j];
            assert!((v - exact).abs() <= 0.08 * exact, "λ{j} = {v}, l = {l}: {exact}");
            assert!(v < ((l + 1) * (l + 2)) as f64, "λ{j} = {v} reaches the cluster of l = {}", l + 1);
            j += 1;
        }
    }
}

/// The Dirichlet unit square, π²(a² + b²) for a, b ≥ 1 (no zero modes): three slices give the one run's 100 pairs,
/// and so does the same plan on two threads (the slices in parallel).
#[test]
fn dirichlet_square_sliced_on_one_and_two_threads() {
    let pair = pair_of(&Shape::TriangleMesh(generate::unit_square(40)), Boundary::Dirichlet);
    let k = 100;
    let whole = solve(&pair, k, 1, 1);
    let one = solve(&pair, k, 3, 1);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let two = pool.install(|| solve(&pair, k, 3, 2));
    assert_eq!(one.stats.slices.len(), 3);
    assert_eq!(two.stats.slices.len(), 3);
    assert_same_values(&one, &whole);
    assert_same_values(&two, &whole);
    for s in [&one, &two] {
        let defect = orthonormality_defect(&pair, s);
        assert!(defect < 1e-8, "ΦᵀMΦ − I reaches {defect:e}");
    }
    let pi2 = std::f64::consts::PI.powi(2);
    let mut exact: Vec<f64> = (1..30).flat_map(|a| (1..30).map(move |b| pi2 * (a * a + b * b) as f64)).collect();
    exact.sort_by(f64::total_cmp);
    // P1 on a 40 × 40 grid: 2.2% at λ₂₀ ≈ 316 (measured), the error growing like λ²h².
    for (j, (v, e)) in one.values.iter().zip(&exact).enumerate().take(40) {
        assert!((v - e).abs() <= 0.05 * e, "λ{j} = {v}, exact {e}");
    }
}

/// A thin strip's low spectrum grows like a segment's (N ∝ √λ), so Weyl's two-dimensional law puts the edges far
/// too high: the inertia at the second edge already counts more than the k pairs, the windows above it are dropped,
/// and the lowest window holds three times its share, sized by its count; the pairs are the one run's.
#[test]
fn thin_strip_keeps_the_windows_its_spectrum_fills() {
    let pair = pair_of(&Shape::TriangleMesh(generate::grid(600, 4, 150.0, 1.0)), Boundary::Neumann);
    let k = 80;
    let sliced = solve(&pair, k, 4, 1);
    let sl = &sliced.stats.slices;
    assert_eq!(sl.len(), 2, "{sl:?}");
    assert!(sl[0].pairs > 50, "{sl:?}");
    let whole = solve(&pair, k, 1, 1);
    assert_same_values(&sliced, &whole);
    for (m, v) in whole.values.iter().enumerate().take(40) {
        let e = (std::f64::consts::PI * m as f64 / 150.0).powi(2);
        assert!((v - e).abs() <= 1e-2 * e.max(1e-3), "λ{m} = {v}, exact {e}");
    }
}

/// A strip thinner still: its first edge by Weyl's law already holds every pair asked for, so the plan is given up
/// for one run, and the result says so (`plan`: planned slices, taken one run, why) instead of switching silently.
#[test]
fn a_plan_given_up_is_reported() {
    let pair = pair_of(&Shape::TriangleMesh(generate::grid(1200, 2, 300.0, 0.5)), Boundary::Neumann);
    let k = 80;
    let sliced = solve(&pair, k, 4, 1);
    let plan = sliced.stats.plan.as_ref().expect("the change of path is reported");
    assert_eq!((plan.planned, plan.taken), ("slices", "one-run"), "{plan:?}");
    assert!(plan.reason.contains("first slice"), "{plan:?}");
    assert!(sliced.stats.slices.is_empty());
    let whole = solve(&pair, k, 1, 1);
    assert_eq!(whole.stats.plan, None, "one run asked for is the plan");
    assert_same_values(&sliced, &whole);
}

/// The same mesh in another vertex and face order (a random permutation, as another program would write it) is cut
/// into the same slices, holding the same pairs, and gives the same eigenvalues, on one thread and on two: the plan
/// and its edges depend on the spectrum, not on the numbering.
#[test]
fn a_permuted_mesh_gives_the_same_slices_and_eigenvalues() {
    let mesh = generate::icosphere(4);
    let n = mesh.vertices.len();
    let mut x = 0x853C_49E6_748F_EA9Bu64;
    let mut rnd = move |m: usize| {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as usize % m
    };
    // Fisher–Yates: new index of each old vertex, then the faces in another order and rotated.
    let mut perm: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        perm.swap(i, rnd(i + 1));
    }
    let mut vertices = vec![[0.0; 3]; n];
    for (old, &new) in perm.iter().enumerate() {
        vertices[new] = mesh.vertices[old];
    }
    let mut faces: Vec<[u32; 3]> = mesh
        .faces
        .iter()
        .map(|f| [perm[f[0] as usize] as u32, perm[f[1] as usize] as u32, perm[f[2] as usize] as u32])
        .collect();
    for i in (1..faces.len()).rev() {
        let j = rnd(i + 1);
        faces.swap(i, j);
        faces[i].rotate_left(rnd(3));
    }
    let permuted = kac_core::geometry::TriangleMesh { vertices, faces };
    let (a, b) = (
        pair_of(&Shape::TriangleMesh(mesh), Boundary::Neumann),
        pair_of(&Shape::TriangleMesh(permuted), Boundary::Neumann),
    );
    let k = 150;
    for threads in [1, 2] {
        let (sa, sb) = (solve(&a, k, 4, threads), solve(&b, k, 4, threads));
        assert_eq!((sa.stats.plan.as_ref(), sb.stats.plan.as_ref()), (None, None));
        let pairs = |s: &Spectrum| s.stats.slices.iter().map(|r| r.pairs).collect::<Vec<_>>();
        assert_eq!(sa.stats.slices.len(), 4);
        assert_eq!(pairs(&sa), pairs(&sb), "the same slices hold the same pairs");
        for (x, y) in sa.stats.slices.iter().zip(&sb.stats.slices) {
            for (p, q) in [(x.lo, y.lo), (x.hi, y.hi)] {
                if let (Some(p), Some(q)) = (p, q) {
                    assert!((p - q).abs() <= 1e-9 * p.abs(), "edges {p} and {q}");
                }
            }
        }
        assert_same_values(&sb, &sa);
    }
}

/// A stop set while the slices iterate ends the solve with `Canceled`, not a result.
#[test]
fn a_stop_inside_a_slice_cancels() {
    let pair = pair_of(&Shape::TriangleMesh(generate::icosphere(4)), Boundary::Neumann);
    let stop = AtomicBool::new(false);
    let progress = |p: kac_core::spectrum::Progress| {
        if p.phase == "iterating" && p.converged > 0 {
            stop.store(true, Ordering::Relaxed);
        }
    };
    let o = EigenOptions { k: 150, slices: Some(4), threads: 1, method: Method::Sparse, ..Default::default() };
    let r = eigs(&pair, &o, None, Control { progress: Some(&progress), stop: Some(&stop), lender: None, farm: None });
    assert!(matches!(r, Err(EigenError::Canceled)), "{:?}", r.map(|s| s.values.len()));
    assert!(stop.load(Ordering::Relaxed));
}

/// A limit on one array's values (`max_values`, the service's --max-output-values) is checked against each Krylov
/// basis before it is allocated: a sliced solve holds its slices' bases, each sized for a share of the pairs, where one
/// run of the same k holds a basis of twice k columns. `widest_basis` predicts both.
#[test]
fn the_values_limit_counts_each_slice_basis() {
    let pair = pair_of(&Shape::TriangleMesh(generate::icosphere(4)), Boundary::Neumann);
    let n = pair.n();
    // The zero mode aside, 400 pairs: the fewest the automatic plan slices.
    let k = 401;
    let o = EigenOptions { k, threads: 2, method: Method::Sparse, ..Default::default() };
    let one_run = EigenOptions { slices: Some(1), ..o.clone() };
    let (sliced, one) = (slicing::widest_basis(n, 1, &o).unwrap(), slicing::widest_basis(n, 1, &one_run).unwrap());
    assert!(sliced < k && one > 2 * k, "widest basis sliced {sliced}, one run {one}");
    // Above the slices' bases, sized at run time for the pairs each window holds (a cluster more than the even share:
    // up to 364 columns here), below one run's.
    let limit = n * 450;
    let s = eigs(&pair, &EigenOptions { max_values: limit, ..o }, None, Control::default()).unwrap();
    assert!(s.stats.slices.len() >= 2, "{:?}", s.stats.slices);
    assert_eq!(s.values.len(), k);
    assert_eq!(s.stats.completeness.as_ref().map(|c| c.complete), Some(true));
    let e = eigs(&pair, &EigenOptions { max_values: limit, ..one_run }, None, Control::default()).unwrap_err();
    assert!(matches!(e, EigenError::TooLarge { .. }) && e.to_string().contains("× 808 columns"), "{e}");
    // Below the slices' own bases: the slice that meets the limit says so (one run's basis would be wider still).
    let e = eigs(&pair, &EigenOptions { max_values: n * 250, ..o }, None, Control::default()).unwrap_err();
    let text = e.to_string();
    let one_run = text.contains("× 808 columns");
    assert!(matches!(e, EigenError::TooLarge { .. }) && text.contains("Krylov basis") && !one_run, "{e}");
}

/// Where the zero modes are not known yet (at submission) but at most `most`, the prediction bounds the widest basis
/// for every number of them up to that: for the automatic plan (one run below 400 pairs beyond the zero modes), an
/// asked slice count, a fixed shift, a chosen subspace and another block, on problems from far larger than k to
/// barely larger.
#[test]
fn the_widest_basis_for_unknown_zero_modes_bounds_every_count() {
    use kac_core::spectrum::slicing::{widest_basis, widest_basis_for_zero_modes};
    let variants = [
        EigenOptions::default(),
        EigenOptions { slices: Some(3), ..Default::default() },
        EigenOptions { sigma: Some(-0.5), ..Default::default() },
        EigenOptions { subspace: Some(700), ..Default::default() },
        EigenOptions { block: Some(16), ..Default::default() },
    ];
    for n in [1_000_000, 5_000, 1_300] {
        for o in &variants {
            for k in (1..=1_200.min(n - 2)).step_by(7) {
                let o = EigenOptions { k, ..o.clone() };
                for most in [0, 1, 3, 50, k] {
                    let bound = widest_basis_for_zero_modes(n, &o, most).unwrap_or(0);
                    let every = (0..=most.min(k)).filter_map(|z| widest_basis(n, z, &o)).max().unwrap_or(0);
                    assert!(bound >= every, "n = {n}, k = {k}, at most {most}: {bound} < {every} for {o:?}");
                }
            }
        }
    }
    // The automatic plan around its threshold, on a surface of one component: 400 pairs with its zero mode are one
    // run of 399 (822 columns with the block vectors); 401 are sliced, and stay sliced without the zero mode.
    let o = EigenOptions { k: 400, ..Default::default() };
    assert_eq!(widest_basis(1_000_000, 1, &o), Some(822));
    assert_eq!(widest_basis_for_zero_modes(1_000_000, &o, 1), Some(822));
    assert!(widest_basis_for_zero_modes(1_000_000, &EigenOptions { k: 401, ..o }, 1).unwrap() < 400);
}

/// Options queued with a slice task by a build from before `max_values` was named so still parse, their limit kept.
#[test]
fn options_from_before_the_limit_was_renamed_keep_it() {
    let mut v = serde_json::to_value(EigenOptions { max_values: 12_345, ..Default::default() }).unwrap();
    let fields = v.as_object_mut().unwrap();
    let limit = fields.remove("max_values").unwrap();
    fields.insert("max_factor_values".into(), limit);
    let o: EigenOptions = serde_json::from_value(v).unwrap();
    assert_eq!(o.max_values, 12_345);
}

#[test]
fn slice_count_by_k_and_threads() {
    use kac_core::spectrum::slicing::slice_count;
    assert_eq!(slice_count(50, 1, None), 1);
    assert_eq!(slice_count(200, 1, None), 1);
    assert_eq!(slice_count(200, 2, None), 1);
    assert_eq!(slice_count(400, 1, None), 4);
    assert_eq!(slice_count(1000, 1, None), 8);
    assert_eq!(slice_count(1000, 16, None), 8);
    assert_eq!(slice_count(100, 1, Some(4)), 4);
    assert_eq!(slice_count(16, 1, Some(4)), 2);
}

/// The basis products split by rows over two threads give the single thread's results (the partial Gram products
/// summed in another order: equal to rounding).
#[test]
fn threaded_basis_products_match_one_thread() {
    use kac_core::spectrum::basis_products::{gram, gram_par, update, update_par};
    let (n, m, b) = (20_000, 37, 8);
    let v = faer::Mat::<f64>::from_fn(n, m, |i, j| ((i * 7 + j * 13) % 101) as f64 / 101.0 - 0.5);
    let y: Vec<f64> = (0..n * b).map(|p| ((p * 31) % 97) as f64 / 97.0 - 0.5).collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let (one, two) = (gram(v.as_ref(), &y, b), pool.install(|| gram_par(v.as_ref(), &y, b, 2)));
    for r in 0..m {
        for c in 0..b {
            assert!((one[(r, c)] - two[(r, c)]).abs() <= 1e-9 * one[(r, c)].abs().max(1.0), "({r}, {c})");
        }
    }
    let (mut w1, mut w2) = (y.clone(), y.clone());
    update(&mut w1, b, v.as_ref(), one.as_ref(), -0.5);
    pool.install(|| update_par(&mut w2, b, v.as_ref(), one.as_ref(), -0.5, 2));
    assert_eq!(w1, w2, "each row is updated by the same kernel on either thread");
}

/// A host lending threads: grants up to `grant`, counts what was borrowed, asked back and given back, and wants a
/// thread back after each slice when `back` is set.
struct Host {
    grant: usize,
    back: bool,
    /// Calls of `borrow` answered with nothing first (a host whose workers are all busy when the solve asks).
    refuse: AtomicUsize,
    borrowed: std::sync::atomic::AtomicUsize,
    asked: std::sync::atomic::AtomicUsize,
    returned: std::sync::atomic::AtomicUsize,
}

impl kac_core::spectrum::Lender for Host {
    fn borrow(&self, wanted: usize) -> usize {
        if self.refuse.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |r| r.checked_sub(1)).is_ok() {
            return 0;
        }
        let n = wanted.min(self.grant);
        self.borrowed.fetch_add(n, Ordering::SeqCst);
        n
    }
    fn wanted_back(&self) -> bool {
        self.asked.fetch_add(1, Ordering::SeqCst);
        self.back
    }
    fn give_back(&self) {
        self.returned.fetch_add(1, Ordering::SeqCst);
    }
}

/// A solve of one thread in a pool of two, cut into four slices, with a host lending its idle thread: both threads
/// solve slices (the first slice's progress waits, at most 20 s, until a second thread has started one), the
/// eigenvalues are the one run's, and every lent thread is given back. A host that wants its thread back after each
/// slice gets it after each (the solve's own thread goes on with the rest).
#[test]
fn lent_threads_solve_slices_and_are_given_back() {
    use std::sync::Mutex;
    let pair = pair_of(&Shape::TriangleMesh(generate::icosphere(5)), Boundary::Neumann);
    let k = 150;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let whole = pool.install(|| solve(&pair, k, 1, 1));
    for back in [false, true] {
        let host = Host {
            grant: 3,
            back,
            refuse: AtomicUsize::new(0),
            borrowed: AtomicUsize::new(0),
            asked: AtomicUsize::new(0),
            returned: AtomicUsize::new(0),
        };
        let seen = Mutex::new(std::collections::HashSet::new());
        let t0 = std::time::Instant::now();
        let progress = |p: kac_core::spectrum::Progress| {
            if p.phase != "iterating" {
                return;
            }
            seen.lock().unwrap().insert(rayon::current_thread_index());
            while seen.lock().unwrap().len() < 2 && t0.elapsed() < std::time::Duration::from_secs(20) {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        };
        let o = EigenOptions { k, slices: Some(4), threads: 1, method: Method::Sparse, ..Default::default() };
        let control = Control { progress: Some(&progress), lender: Some(&host), ..Control::default() };
        let sliced = pool.install(|| eigs(&pair, &o, None, control).unwrap());
        assert_eq!(sliced.stats.slices.len(), 4, "{:?}", sliced.stats.slices);
        assert_same_values(&sliced, &whole);
        // Three slices beyond the solve's own thread: three asked for and granted at first (more later only when a
        // loan went back early with slices left), every one given back; a lent thread solved at least one slice (it
        // is asked after each).
        let borrowed = host.borrowed.load(Ordering::SeqCst);
        assert!(if back { borrowed >= 3 } else { borrowed == 3 }, "borrowed {borrowed}");
        assert_eq!(host.returned.load(Ordering::SeqCst), borrowed);
        let asked = host.asked.load(Ordering::SeqCst);
        assert!(asked >= 1 && asked <= borrowed, "asked back {asked} times for {borrowed} loans");
        let mut workers: Vec<usize> = sliced.stats.slices.iter().map(|s| s.worker.unwrap()).collect();
        workers.sort_unstable();
        workers.dedup();
        assert_eq!(workers, vec![0, 1], "{:?}", sliced.stats.slices);
    }
    // Without a host, one thread solves every slice.
    let alone = pool.install(|| solve(&pair, k, 4, 1));
    let workers: std::collections::HashSet<_> = alone.stats.slices.iter().map(|s| s.worker).collect();
    assert_eq!(workers.len(), 1, "{:?}", alone.stats.slices);
}

/// A host with no idle thread when the slices are planned, and one after: the solve asks again after its first slice,
/// and the thread lent then solves slices.
#[test]
fn a_thread_that_comes_free_mid_solve_joins() {
    let pair = pair_of(&Shape::TriangleMesh(generate::icosphere(5)), Boundary::Neumann);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let host = Host {
        grant: 1,
        back: false,
        refuse: AtomicUsize::new(1),
        borrowed: AtomicUsize::new(0),
        asked: AtomicUsize::new(0),
        returned: AtomicUsize::new(0),
    };
    // Once the thread is lent, the solve's own thread waits (at most 20 s) until it has started a slice.
    let seen = std::sync::Mutex::new(std::collections::HashSet::new());
    let t0 = std::time::Instant::now();
    let progress = |p: kac_core::spectrum::Progress| {
        if p.phase != "iterating" {
            return;
        }
        seen.lock().unwrap().insert(rayon::current_thread_index());
        while host.borrowed.load(Ordering::SeqCst) > 0
            && seen.lock().unwrap().len() < 2
            && t0.elapsed() < std::time::Duration::from_secs(20)
        {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    };
    let o = EigenOptions { k: 150, slices: Some(4), threads: 1, method: Method::Sparse, ..Default::default() };
    let control = Control { progress: Some(&progress), lender: Some(&host), ..Control::default() };
    let sliced = pool.install(|| eigs(&pair, &o, None, control).unwrap());
    assert_eq!(sliced.stats.slices.len(), 4);
    assert_eq!((host.borrowed.load(Ordering::SeqCst), host.returned.load(Ordering::SeqCst)), (1, 1));
    assert!(host.asked.load(Ordering::SeqCst) >= 1, "the thread lent after the first slice solved one");
    let workers: std::collections::HashSet<_> = sliced.stats.slices.iter().map(|s| s.worker).collect();
    assert_eq!(workers.len(), 2, "{:?}", sliced.stats.slices);
}

/// Another machine for a sliced solve ([`kac_core::spectrum::Farm`]): it holds a pencil it built itself from the same
/// shape, starts the slices `starts` names as soon as they are offered (each on a thread of its own, by
/// `solve_slice`), and leaves the others to be taken back. A slice in `corrupt` reaches it with a wrong pencil digest,
/// so it refuses it and the solve must solve that slice itself.
struct Machine {
    pair: std::sync::Arc<operators::sparse::SparsePair>,
    starts: Vec<usize>,
    corrupt: Vec<usize>,
    offered: std::sync::Mutex<Vec<usize>>,
    running: std::sync::Mutex<Vec<(usize, Solving)>>,
}

/// A slice being solved on the other machine.
type Solving = std::thread::JoinHandle<Result<Spectrum, EigenError>>;

/// The other machine's answer for slice `index`, taken from those it runs (each is collected once).
fn join(running: &std::sync::Mutex<Vec<(usize, Solving)>>, index: usize) -> Result<Spectrum, EigenError> {
    let mut running = running.lock().unwrap();
    let at = running.iter().position(|(i, _)| *i == index).expect("collected once, after being started");
    running.remove(at).1.join().unwrap()
}

/// A window's open ends travel as JSON null and come back infinite.
#[test]
fn a_slice_task_keeps_its_open_ends_through_json() {
    for (lo, hi) in [(f64::NEG_INFINITY, 3.5), (2.0, f64::INFINITY), (1.0, 2.0)] {
        let window =
            kac_core::spectrum::lanczos::Window { lo, hi, sigma: 1.5, total: None, count: Some(4), below_lo: 7 };
        let task = kac_core::spectrum::slicing::SliceTask {
            index: 0,
            window,
            options: EigenOptions::default(),
            pencil: "p".into(),
        };
        let text = serde_json::to_string(&task).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(
            (json["window"]["lo"].is_null(), json["window"]["hi"].is_null()),
            (!lo.is_finite(), !hi.is_finite())
        );
        let back: kac_core::spectrum::slicing::SliceTask = serde_json::from_str(&text).unwrap();
        assert_eq!(back, task);
    }
}

impl kac_core::spectrum::Farm for Machine {
    fn offer(&self, task: &kac_core::spectrum::slicing::SliceTask) -> bool {
        self.offered.lock().unwrap().push(task.index);
        if self.starts.contains(&task.index) {
            let (pair, index, mut task) = (self.pair.clone(), task.index, task.clone());
            if self.corrupt.contains(&task.index) {
                task.pencil = "0".repeat(64);
            }
            let handle = std::thread::spawn(move || {
                kac_core::spectrum::slicing::solve_slice(&pair, &task, 1, Control::default())
            });
            self.running.lock().unwrap().push((index, handle));
        }
        true
    }
    fn take_back(&self, task: &kac_core::spectrum::slicing::SliceTask) -> bool {
        !self.starts.contains(&task.index)
    }
    fn collect(
        &self,
        task: &kac_core::spectrum::slicing::SliceTask,
        _: &Control<'_>,
    ) -> Result<Option<kac_core::spectrum::slicing::Solved>, EigenError> {
        Ok(match join(&self.running, task.index) {
            Ok(spectrum) => Some(kac_core::spectrum::slicing::Solved { spectrum, seconds: 0.0, by: "b".into() }),
            Err(EigenError::InvalidOption { name: "pencil", .. }) => None,
            Err(e) => panic!("slice {} failed elsewhere: {e}", task.index),
        })
    }
    fn release(&self, task: &kac_core::spectrum::slicing::SliceTask) {
        panic!("slice {} released: no slice fails here", task.index);
    }
}

/// One thread and another machine: the slices the thread does not start at once (2, 1 and 0; the top one first is its
/// own) are offered; the machine solves slice 2, slice 1 is taken back, and slice 0, which the machine refuses (its
/// pencil's digest differs), is solved here. The result is the one run's, M-orthonormal across every edge, and says
/// who solved each slice.
#[test]
fn slices_solved_on_another_machine_are_stitched_in() {
    let shape = Shape::TriangleMesh(generate::icosphere(4));
    let pair = pair_of(&shape, Boundary::Neumann);
    let k = 150;
    let whole = solve(&pair, k, 1, 1);
    let machine = Machine {
        pair: std::sync::Arc::new(pair_of(&shape, Boundary::Neumann)),
        starts: vec![2, 0],
        corrupt: vec![0],
        offered: Default::default(),
        running: Default::default(),
    };
    let o = EigenOptions { k, slices: Some(4), threads: 1, method: Method::Sparse, ..Default::default() };
    let sliced = eigs(&pair, &o, None, Control { farm: Some(&machine), ..Control::default() }).unwrap();
    assert_eq!(*machine.offered.lock().unwrap(), vec![2, 1, 0]);
    assert!(machine.running.lock().unwrap().is_empty(), "every slice started elsewhere was collected");
    let by: Vec<Option<&str>> = sliced.stats.slices.iter().map(|s| s.solved_by.as_deref()).collect();
    assert_eq!(by, vec![None, None, Some("b"), None]);
    assert!(sliced.stats.slices[2].block_steps > 0, "the other machine's statistics");
    assert_same_values(&sliced, &whole);
    let defect = orthonormality_defect(&pair, &sliced);
    assert!(defect < 1e-8, "ΦᵀMΦ − I reaches {defect:e}");
    assert!(sliced.stats.completeness.as_ref().is_some_and(|c| c.complete));
    // A pencil of another problem is refused outright.
    let other = pair_of(&Shape::TriangleMesh(generate::icosphere(3)), Boundary::Neumann);
    let window = kac_core::spectrum::lanczos::Window {
        lo: 10.0,
        hi: 20.0,
        sigma: 15.0,
        total: None,
        count: Some(10),
        below_lo: 20,
    };
    let task = kac_core::spectrum::slicing::SliceTask {
        index: 1,
        window,
        options: EigenOptions { k: 10, ..Default::default() },
        pencil: kac_core::spectrum::slicing::pencil_digest(&pair),
    };
    let refused = kac_core::spectrum::slicing::solve_slice(&other, &task, 1, Control::default());
    assert!(matches!(refused, Err(EigenError::InvalidOption { name: "pencil", .. })), "{:?}", refused.err());
}

/// Another machine that starts every offered slice at once and answers `take_back` slowly (1.5 s) on any thread but
/// the solve's own: a lent thread comes to an offered slice, finds it started elsewhere, and hands it on only after
/// the solve's own thread has run out of slices and collected what it knew of.
struct LateMachine {
    pair: std::sync::Arc<operators::sparse::SparsePair>,
    caller: std::sync::Mutex<Option<std::thread::ThreadId>>,
    entered: AtomicBool,
    running: std::sync::Mutex<Vec<(usize, Solving)>>,
    released: AtomicUsize,
}

impl kac_core::spectrum::Farm for LateMachine {
    fn offer(&self, task: &kac_core::spectrum::slicing::SliceTask) -> bool {
        let (pair, index, task) = (self.pair.clone(), task.index, task.clone());
        let handle =
            std::thread::spawn(move || kac_core::spectrum::slicing::solve_slice(&pair, &task, 1, Control::default()));
        self.running.lock().unwrap().push((index, handle));
        true
    }
    fn take_back(&self, _: &kac_core::spectrum::slicing::SliceTask) -> bool {
        if *self.caller.lock().unwrap() != Some(std::thread::current().id()) {
            self.entered.store(true, Ordering::SeqCst);
            std::thread::sleep(std::time::Duration::from_millis(1500));
        }
        false
    }
    fn collect(
        &self,
        task: &kac_core::spectrum::slicing::SliceTask,
        _: &Control<'_>,
    ) -> Result<Option<kac_core::spectrum::slicing::Solved>, EigenError> {
        let spectrum = join(&self.running, task.index)?;
        Ok(Some(kac_core::spectrum::slicing::Solved { spectrum, seconds: 0.0, by: "late".into() }))
    }
    fn release(&self, _: &kac_core::spectrum::slicing::SliceTask) {
        self.released.fetch_add(1, Ordering::SeqCst);
    }
}

/// A lent thread that finds an offered slice started elsewhere only after the solve's own thread has collected and
/// ended its loop: the solve still collects it (it is not lost, and the slices are not given up for one run).
#[test]
fn a_slice_a_lent_thread_hands_on_late_is_collected() {
    let shape = Shape::TriangleMesh(generate::icosphere(4));
    let pair = pair_of(&shape, Boundary::Neumann);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let whole = pool.install(|| solve(&pair, 150, 1, 1));
    let machine = LateMachine {
        pair: std::sync::Arc::new(pair_of(&shape, Boundary::Neumann)),
        caller: Default::default(),
        entered: AtomicBool::new(false),
        running: Default::default(),
        released: AtomicUsize::new(0),
    };
    let host = Host {
        grant: 1,
        back: false,
        refuse: AtomicUsize::new(0),
        borrowed: AtomicUsize::new(0),
        asked: AtomicUsize::new(0),
        returned: AtomicUsize::new(0),
    };
    // The solve's own thread holds its first slice until the lent thread is in `take_back` (at most 20 s).
    let t0 = std::time::Instant::now();
    let progress = |p: kac_core::spectrum::Progress| {
        if p.phase == "iterating" && *machine.caller.lock().unwrap() == Some(std::thread::current().id()) {
            while !machine.entered.load(Ordering::SeqCst) && t0.elapsed() < std::time::Duration::from_secs(20) {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        }
    };
    let o = EigenOptions { k: 150, slices: Some(3), threads: 1, method: Method::Sparse, ..Default::default() };
    let control =
        Control { progress: Some(&progress), lender: Some(&host), farm: Some(&machine), ..Control::default() };
    let sliced = pool.install(|| {
        *machine.caller.lock().unwrap() = Some(std::thread::current().id());
        eigs(&pair, &o, None, control).unwrap()
    });
    assert!(machine.entered.load(Ordering::SeqCst));
    assert_eq!(sliced.stats.slices.len(), 3, "the sliced solve was given up");
    let by: Vec<Option<&str>> = sliced.stats.slices.iter().map(|s| s.solved_by.as_deref()).collect();
    assert_eq!(by, vec![Some("late"), None, None]);
    assert_same_values(&sliced, &whole);
    assert_eq!(machine.released.load(Ordering::SeqCst), 0);
    assert_eq!(host.returned.load(Ordering::SeqCst), host.borrowed.load(Ordering::SeqCst));
}

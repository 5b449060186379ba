//! Eigensolver against mathematics: exact spectra of the sphere (l(l+1), multiplicity 2l+1), unit square,
//! disk (Bessel zeros), segment ((πk/ℓ)²), eq. (9.3), graphs, the tetrahedral cube; and agreement with the
//! dense path to 1e-10.

use kac_core::geometry::generate;
use kac_core::geometry::{Shape, TriangleMesh};
use kac_core::operators::{self, Boundary, Mass, OperatorKind, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions, Method, Spectrum};

fn solve(shape: &Shape, op: OperatorOptions, k: usize, method: Method) -> Spectrum {
    let o = operators::build(shape, &op).unwrap();
    eigs(&o.pair, &EigenOptions { k, method, ..Default::default() }, None, Control::default()).unwrap()
}

fn mesh(m: TriangleMesh) -> Shape {
    Shape::TriangleMesh(m)
}

fn opts(mass: Mass, boundary: Boundary) -> OperatorOptions {
    OperatorOptions { mass: Some(mass), boundary, ..Default::default() }
}

/// M-orthonormality: ΦᵀMΦ = I.
fn check_m_orthonormal(shape: &Shape, op: &OperatorOptions, s: &Spectrum, tol: f64) {
    let o = operators::build(shape, op).unwrap();
    let n = o.pair.n();
    let k = s.values.len();
    let mut mx = vec![0.0; n];
    for a in 0..k {
        let xa: Vec<f64> = (0..n).map(|i| s.vectors[(i, a)]).collect();
        operators::sparse::matvec(&o.pair.pattern, &o.pair.mass, &xa, &mut mx);
        for b in 0..k {
            let d: f64 = (0..n).map(|i| s.vectors[(i, b)] * mx[i]).sum();
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((d - want).abs() < tol, "φ{a}ᵀMφ{b} = {d}");
        }
    }
}

#[test]
fn sparse_agrees_with_dense_on_a_small_sphere() {
    let s = mesh(generate::icosphere(3));
    for mass in [Mass::Consistent, Mass::Lumped] {
        let o = opts(mass, Boundary::Neumann);
        let d = solve(&s, o.clone(), 30, Method::Dense);
        let sp = solve(&s, o.clone(), 30, Method::Sparse);
        for (a, b) in d.values.iter().zip(&sp.values) {
            assert!((a - b).abs() <= 1e-10 * a.abs().max(1.0), "{a} vs {b}");
        }
        assert!(sp.residuals.iter().all(|&r| r < 1e-8), "{:?}", sp.residuals);
        check_m_orthonormal(&s, &o, &sp, 1e-9);
    }
}

#[test]
fn sphere_spectrum_has_full_multiplicities_and_second_order_convergence() {
    // Unit sphere: λ = l(l+1) with multiplicity 2l+1. First 25 eigenvalues: l = 0..4.
    let exact: Vec<f64> = (0..5).flat_map(|l| std::iter::repeat_n((l * (l + 1)) as f64, 2 * l + 1)).collect();
    let mut errors = Vec::new();
    for level in [3, 4, 5] {
        let s = solve(&mesh(generate::icosphere(level)), opts(Mass::Consistent, Boundary::Neumann), 25, Method::Sparse);
        assert!(s.values[0].abs() < 1e-8);
        let err = s.values.iter().zip(&exact).skip(1).map(|(a, e)| ((a - e) / e).abs()).fold(0.0, f64::max);
        errors.push(err);
        // Every cluster member present: the nearest l(l+1) of each computed value is the expected one, so no
        // member of a (2l+1)-cluster is missing (a missing one would pull in a value of the next cluster).
        for (a, e) in s.values.iter().zip(&exact).skip(1) {
            let l = ((1.0 + 4.0 * a).sqrt() - 1.0) / 2.0;
            let nearest = l.round();
            assert_eq!(nearest * (nearest + 1.0), *e, "level {level}: {a} is not near {e}");
        }
    }
    let order1 = (errors[0] / errors[1]).log2();
    let order2 = (errors[1] / errors[2]).log2();
    assert!(order1 > 1.8 && order2 > 1.8, "observed orders {order1}, {order2} (errors {errors:?})");
}

fn assert_close(got: &[f64], want: &[f64], rel: f64, what: &str) {
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let err = if *w == 0.0 { g.abs() } else { ((g - w) / w).abs() };
        assert!(err <= rel, "{what}: eigenvalue {i}: {g} vs {w} (error {err:e})");
    }
}

#[test]
fn unit_square_dirichlet_and_neumann() {
    let pi2 = std::f64::consts::PI.powi(2);
    let sq = mesh(generate::unit_square(48));
    // Dirichlet: π²(m² + n²), m, n ≥ 1.
    let d = solve(&sq, opts(Mass::Consistent, Boundary::Dirichlet), 6, Method::Sparse);
    assert_close(&d.values, &[2.0, 5.0, 5.0, 8.0, 10.0, 10.0].map(|x| x * pi2), 4e-3, "square Dirichlet");
    // Neumann: m, n ≥ 0.
    let nm = solve(&sq, opts(Mass::Consistent, Boundary::Neumann), 6, Method::Sparse);
    assert_close(&nm.values, &[0.0, 1.0, 1.0, 2.0, 4.0, 4.0].map(|x| x * pi2), 4e-3, "square Neumann");
    assert!(nm.values[0].abs() < 1e-8);
}

#[test]
fn unit_disk_dirichlet_is_bessel_zeros_squared() {
    // j₀₁², j₁₁² (×2), j₂₁² (×2), j₀₂².
    let exact = [5.783185962947, 14.681970642124, 14.681970642124, 26.374616427163, 26.374616427163, 30.471262343662];
    let disk = mesh(generate::unit_disk(40));
    let s = solve(&disk, opts(Mass::Consistent, Boundary::Dirichlet), 6, Method::Sparse);
    assert_close(&s.values, &exact, 3e-3, "disk Dirichlet");
}

#[test]
fn string_and_equation_9_3() {
    // Eq. (9.3): unit spacing, Dirichlet ends, lumped mass: exactly 2 − 2cos(kπ/n).
    let n = 40;
    let seg = Shape::Polyline(generate::segment(n, n as f64));
    let o = OperatorOptions { mass: Some(Mass::Lumped), boundary: Boundary::Dirichlet, ..Default::default() };
    let s = solve(&seg, o, 10, Method::Sparse);
    let exact: Vec<f64> = (1..=10).map(|k| 2.0 - 2.0 * (k as f64 * std::f64::consts::PI / n as f64).cos()).collect();
    assert_close(&s.values, &exact, 1e-11, "eq. (9.3)");
    // "Hear the length of a string": P1 FEM with real lengths on [0, ℓ] converges to (πk/ℓ)².
    let l = 2.5;
    let seg = Shape::Polyline(generate::segment(400, l));
    let s = solve(&seg, opts(Mass::Consistent, Boundary::Dirichlet), 5, Method::Sparse);
    let exact: Vec<f64> = (1..=5).map(|k| (k as f64 * std::f64::consts::PI / l).powi(2)).collect();
    assert_close(&s.values, &exact, 3e-4, "string Dirichlet");
    // And exactly the discrete P1 spectrum on a uniform mesh: λ_h = (6/h²)(1 − cos θ)/(2 + cos θ), θ = πkh/ℓ.
    let h = l / 400.0;
    let p1: Vec<f64> = (1..=5)
        .map(|k| {
            let th = std::f64::consts::PI * k as f64 * h / l;
            6.0 / (h * h) * (1.0 - th.cos()) / (2.0 + th.cos())
        })
        .collect();
    assert_close(&s.values, &p1, 1e-10, "string Dirichlet, discrete P1 spectrum");
    let s = solve(&seg, opts(Mass::Consistent, Boundary::Neumann), 5, Method::Sparse);
    let exact: Vec<f64> = (0..5).map(|k| (k as f64 * std::f64::consts::PI / l).powi(2)).collect();
    assert_close(&s.values, &exact, 3e-4, "string Neumann");
}

#[test]
fn graph_spectra() {
    let graph = |g| Shape::Graph(g);
    let o = OperatorOptions::default();
    // K_n: 0 and n with multiplicity n − 1.
    let s = solve(&graph(generate::complete_graph(12)), o.clone(), 12, Method::Dense);
    let mut want = vec![12.0; 12];
    want[0] = 0.0;
    assert_close(&s.values, &want, 1e-12, "K_12");
    // Cycle C_n: 2 − 2cos(2πj/n); path P_n: 2 − 2cos(πj/n).
    let n = 300;
    let mut cyc: Vec<f64> =
        (0..n).map(|j| 2.0 - 2.0 * (2.0 * std::f64::consts::PI * j as f64 / n as f64).cos()).collect();
    cyc.sort_by(f64::total_cmp);
    let s = solve(&graph(generate::cycle_graph(n)), o.clone(), 9, Method::Sparse);
    assert_close(&s.values[1..], &cyc[1..9], 1e-9, "C_300");
    let path: Vec<f64> = (0..9).map(|j| 2.0 - 2.0 * (std::f64::consts::PI * j as f64 / n as f64).cos()).collect();
    let s = solve(&graph(generate::path_graph(n)), o.clone(), 9, Method::Sparse);
    assert_close(&s.values[1..], &path[1..], 1e-9, "P_300");
    // Petersen: 0, 2 (×5), 5 (×4).
    let s = solve(&graph(generate::petersen_graph()), o, 10, Method::Dense);
    assert_close(&s.values, &[0.0, 2.0, 2.0, 2.0, 2.0, 2.0, 5.0, 5.0, 5.0, 5.0], 1e-12, "Petersen");
}

#[test]
fn tetrahedral_unit_cube_neumann_pi_squared_three_times() {
    let cube = Shape::TetMesh(generate::unit_cube_tets(10));
    let s = solve(&cube, OperatorOptions::default(), 4, Method::Sparse);
    let pi2 = std::f64::consts::PI.powi(2);
    assert!(s.values[0].abs() < 1e-8);
    assert_close(&s.values[1..], &[pi2; 3], 2e-2, "cube Neumann");
}

#[test]
fn disconnected_shape_has_one_zero_per_component() {
    // 30 separate triangles: 30 zero eigenvalues, more than the block size, then positive ones.
    let mut m = TriangleMesh::default();
    for t in 0..30u32 {
        let x = t as f64 * 3.0;
        m.vertices.extend([[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]);
        m.faces.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    let s = solve(&mesh(m.clone()), OperatorOptions::default(), 40, Method::Sparse);
    assert!(s.values[..30].iter().all(|v| v.abs() < 1e-8), "{:?}", &s.values[..31]);
    assert!(s.values[30] > 1.0);
    let d = solve(&mesh(m), OperatorOptions::default(), 40, Method::Dense);
    assert_close(&s.values[30..], &d.values[30..], 1e-10, "sparse vs dense");
}

#[test]
fn every_operator_solves() {
    let sphere = mesh(generate::icosphere(3));
    for (op, mass) in [
        (OperatorKind::Cotan, Mass::Voronoi),
        (OperatorKind::IntrinsicDelaunay, Mass::Lumped),
        (OperatorKind::Robust, Mass::Lumped),
        (OperatorKind::Graph, Mass::Identity),
        (OperatorKind::GraphNormalized, Mass::Identity),
        (OperatorKind::GraphRandomWalk, Mass::Degree),
        (OperatorKind::PointCloud, Mass::Lumped),
    ] {
        let o = OperatorOptions { operator: Some(op), mass: Some(mass), ..Default::default() };
        // What the service plans by before it builds the operator.
        let dimension = operators::build(&sphere, &o).unwrap().pair.dimension;
        assert_eq!(dimension.is_some(), op.has_weyl_dimension(), "{op:?}: {dimension:?}");
        let s = solve(&sphere, o, 10, Method::Sparse);
        assert!(s.values[0].abs() < 1e-8, "{op:?}: {:?}", s.values);
        assert!(s.values.windows(2).all(|w| w[0] <= w[1] + 1e-12), "{op:?} ascending");
        assert!(s.residuals.iter().all(|r| *r < 1e-6), "{op:?}: {:?}", s.residuals);
    }
}

#[test]
fn band_mode_returns_every_eigenvalue_in_the_interval() {
    // Unit square, Dirichlet: π²(m² + n²) in [40, 110] are 5π² (×2), 8π², 10π² (×2), i.e. 49.3, 79.0, 98.7.
    let sq = mesh(generate::unit_square(40));
    let o = operators::build(&sq, &opts(Mass::Consistent, Boundary::Dirichlet)).unwrap();
    let s = kac_core::spectrum::eigs_band(
        &o.pair,
        40.0,
        110.0,
        usize::MAX,
        &EigenOptions { method: Method::Sparse, ..Default::default() },
        Control::default(),
    )
    .unwrap();
    let pi2 = std::f64::consts::PI.powi(2);
    assert_close(&s.values, &[5.0, 5.0, 8.0, 10.0, 10.0].map(|x| x * pi2), 1e-2, "band");
    assert_eq!(s.vectors.ncols(), 5);
    // The same values as the first k of an ordinary solve.
    let all = solve(&sq, opts(Mass::Consistent, Boundary::Dirichlet), 6, Method::Sparse);
    assert_close(&s.values, &all.values[1..6], 1e-10, "band vs k smallest");
}

#[test]
fn band_that_needs_more_pairs_than_allowed_is_refused() {
    // Reaching [40, 110] takes the 6 eigenvalues below 110 (2π² is below the band) and a 7th (13π²) to show
    // that the band ends: 6 pairs are not enough, 7 are.
    let sq = mesh(generate::unit_square(40));
    let o = operators::build(&sq, &opts(Mass::Consistent, Boundary::Dirichlet)).unwrap();
    let band =
        |max| kac_core::spectrum::eigs_band(&o.pair, 40.0, 110.0, max, &EigenOptions::default(), Control::default());
    match band(6) {
        Err(kac_core::spectrum::EigenError::InvalidOption { name: "band", message }) => {
            assert!(message.contains("limit of 6"), "{message}")
        }
        other => panic!("expected a refused band, got {:?}", other.map(|s| s.values)),
    }
    assert_eq!(band(7).unwrap().values.len(), 5);
}

#[test]
fn flat_torus_has_fourfold_clusters() {
    // The flat square torus [0,1)² (intrinsic: built from edge lengths, it has no embedding in R³):
    // λ = 4π²(m² + n²): 0, then 4π² with multiplicity 4, then 8π² with multiplicity 4.
    use kac_core::operators::intrinsic_delaunay::IntrinsicTriangulation;
    let n = 40usize;
    let h = 1.0 / n as f64;
    let idx = |i: usize, j: usize| ((j % n) * n + i % n) as u32;
    let mut faces = Vec::new();
    let mut lengths = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            // Half-edge k of a face runs from corner k to k+1: legs h, diagonal h√2.
            faces.push([a, b, c]);
            lengths.extend([h, h, h * 2f64.sqrt()]);
            faces.push([a, c, d]);
            lengths.extend([h * 2f64.sqrt(), h, h]);
        }
    }
    let t = IntrinsicTriangulation::new(faces, lengths).unwrap();
    assert!(t.twin.iter().all(|&x| x != u32::MAX), "closed: every edge glued");
    let pair = t.pair(n * n, Mass::Consistent).unwrap();
    let s = eigs(&pair, &EigenOptions { k: 9, method: Method::Sparse, ..Default::default() }, None, Control::default())
        .unwrap();
    let c = 4.0 * std::f64::consts::PI.powi(2);
    assert!(s.values[0].abs() < 1e-8);
    assert_close(&s.values[1..5], &[c; 4], 4e-3, "4π² cluster");
    // The uniform diagonals distinguish the (1, 1) and (1, −1) modes: the 8π² cluster splits 2 + 2 at O(h²).
    assert_close(&s.values[5..9], &[2.0 * c; 4], 1.5e-2, "8π² cluster");
    // Members of a cluster agree far better than the discretization error: the cluster is complete.
    assert!((s.values[4] - s.values[1]).abs() < 1e-8 * c, "{:?}", &s.values[1..5]);
}

/// The block solve (own supernodal kernel for 1, 2, 4, 8 and 16 columns, faer's otherwise; column-major and
/// row-major right-hand sides; the kernels of every instruction set the CPU has) against K X = B through
/// column-by-column products, and the block product with K against single columns.
fn check_block_solve(
    pair: &operators::sparse::SparsePair,
    k_values: &[f64],
    chol: &kac_core::spectrum::factor::Cholesky,
) {
    use kac_core::simd::Isa;
    let n = pair.n();
    assert!(chol.solves_in_parallel(2), "the factor's tree splits for two threads: the parallel solve is tested");
    for isa in Isa::available() {
        for b in [1usize, 2, 3, 4, 8, 16] {
            let rhs = faer::Mat::<f64>::from_fn(n, b, |i, j| ((i * 31 + j * 17) % 23) as f64 - 11.0);
            let mut x = rhs.clone();
            chol.solve_in_place_with(x.as_mut(), faer::Par::Seq, isa);
            let mut y = faer::Mat::<f64>::zeros(n, b);
            let mut scratch = Vec::new();
            operators::sparse::spmm(&pair.pattern, k_values, x.as_ref(), y.as_mut(), &mut scratch, 2);
            let mut single = vec![0.0; n];
            for c in 0..b {
                let xc: Vec<f64> = (0..n).map(|i| x[(i, c)]).collect();
                operators::sparse::matvec(&pair.pattern, k_values, &xc, &mut single);
                let scale = (0..n).map(|i| rhs[(i, c)].abs()).fold(0.0, f64::max);
                for i in 0..n {
                    assert!(
                        (single[i] - y[(i, c)]).abs() <= 1e-12 * scale.max(1.0),
                        "{isa:?} b = {b}: block product row {i}"
                    );
                    assert!(
                        (y[(i, c)] - rhs[(i, c)]).abs() <= 1e-9 * scale,
                        "{isa:?} b = {b}: residual at row {i}, column {c}"
                    );
                }
            }
            // The same solve and product on row-major blocks (the eigensolver's layout, no transposes inside).
            let mut xr: Vec<f64> = (0..n * b).map(|t| rhs[(t / b, t % b)]).collect();
            chol.solve_in_place_with(faer::MatMut::from_row_major_slice_mut(&mut xr, n, b), faer::Par::Seq, isa);
            let mut yr = vec![0.0; n * b];
            let xv = faer::MatRef::from_row_major_slice(&xr, n, b);
            operators::sparse::spmm(
                &pair.pattern,
                k_values,
                xv,
                faer::MatMut::from_row_major_slice_mut(&mut yr, n, b),
                &mut scratch,
                1,
            );
            for i in 0..n {
                for c in 0..b {
                    assert!(
                        (xr[i * b + c] - x[(i, c)]).abs() <= 1e-13 * x[(i, c)].abs().max(1.0),
                        "{isa:?} b = {b}: row-major solve"
                    );
                    assert!(
                        (yr[i * b + c] - y[(i, c)]).abs() <= 1e-13 * y[(i, c)].abs().max(1.0),
                        "{isa:?} b = {b}: row-major product"
                    );
                }
            }
            // On several threads (the factor's tree split into subtrees solved side by side, where the kernels
            // apply): the same solution up to the order of the sums into the rows above the subtrees, which an
            // indefinite K (σ inside the spectrum) amplifies by its condition: compared norm-wise.
            let largest = xr.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for threads in [2, 3] {
                let mut xp: Vec<f64> = (0..n * b).map(|t| rhs[(t / b, t % b)]).collect();
                let m = faer::MatMut::from_row_major_slice_mut(&mut xp, n, b);
                chol.solve_in_place_with(m, faer::Par::rayon(threads), isa);
                let diff = xp.iter().zip(&xr).fold(0.0f64, |m, (a, e)| m.max((a - e).abs()));
                assert!(diff <= 1e-10 * largest, "{isa:?} b = {b}, {threads} threads: {diff:e} of {largest:e}");
                // Column-major right-hand sides take the same parallel sweeps after a serial permutation.
                let mut xc = rhs.clone();
                chol.solve_in_place_with(xc.as_mut(), faer::Par::rayon(threads), isa);
                let diff = (&xc - &x).norm_max();
                assert!(diff <= 1e-10 * largest, "{isa:?} b = {b}, {threads} threads, column-major: {diff:e}");
            }
        }
    }
}

#[test]
fn block_solve_and_block_product_match_single_columns() {
    use kac_core::spectrum::factor::{Cholesky, Symbolic};
    let s = mesh(generate::icosphere(5));
    let o = operators::build(&s, &opts(Mass::Consistent, Boundary::Neumann)).unwrap();
    let pair = &o.pair;
    let k_values = pair.shifted(-0.5);
    let sym = Symbolic::analyze(&pair.pattern).unwrap();
    let chol = Cholesky::factor(&sym, &k_values, faer::Par::Seq).unwrap();
    assert!(chol.is_supernodal(), "10k vertices: faer picks the supernodal factorization, whose solve is kac's own");
    check_block_solve(pair, &k_values, &chol);
}

/// L − σM with σ = 7 inside the sphere's spectrum (between l = 2 at 6 and l = 3 at 12): the LDLᵀ factor's inertia
/// counts the 1 + 3 + 5 = 9 eigenvalues below σ (Sylvester), and its block solve (unit diagonal, D between the
/// sweeps) solves the indefinite system.
#[test]
fn ldlt_factor_counts_eigenvalues_below_an_interior_shift_and_solves() {
    use kac_core::spectrum::factor::{Cholesky, Symbolic};
    let s = mesh(generate::icosphere(5));
    let o = operators::build(&s, &opts(Mass::Consistent, Boundary::Neumann)).unwrap();
    let pair = &o.pair;
    let k_values = pair.shifted(7.0);
    let sym = Symbolic::analyze(&pair.pattern).unwrap();
    assert!(Cholesky::factor(&sym, &k_values, faer::Par::Seq).is_err(), "L − 7M is indefinite");
    let (ldlt, below) = Cholesky::factor_ldlt(&sym, &k_values, faer::Par::Seq).unwrap();
    assert!(ldlt.is_ldlt() && ldlt.is_supernodal());
    assert_eq!(below, 9);
    check_block_solve(pair, &k_values, &ldlt);
}

/// The automatic shift goes inside the spectrum (Weyl's law: σ = 0.7·4πk/area = 35 for k = 50 on the unit
/// sphere, where λ_50 = 56): an LDLᵀ factor whose inertia the solver matches, and the same eigenpairs as with a
/// shift below the spectrum (Cholesky) to 10⁻¹⁰ (the returned eigenvalues are Rayleigh quotients).
#[test]
fn shift_inside_the_spectrum_by_weyls_law_gives_the_same_spectrum() {
    let s = mesh(generate::icosphere(5));
    let op = opts(Mass::Consistent, Boundary::Neumann);
    let o = operators::build(&s, &op).unwrap();
    let k = 50;
    let auto =
        eigs(&o.pair, &EigenOptions { k, method: Method::Sparse, ..Default::default() }, None, Control::default())
            .unwrap();
    let below = eigs(
        &o.pair,
        &EigenOptions { k, method: Method::Sparse, sigma: Some(-0.5), ..Default::default() },
        None,
        Control::default(),
    )
    .unwrap();
    let st = &auto.stats;
    assert_eq!(st.factorization, "ldlt");
    assert_eq!(below.stats.factorization, "cholesky");
    let area = 4.0 * std::f64::consts::PI;
    assert!(
        (st.sigma - 0.7 * 4.0 * std::f64::consts::PI * k as f64 / area).abs() < 0.05 * st.sigma,
        "σ = {}",
        st.sigma
    );
    let nu = st.below_sigma.expect("an interior shift reports its inertia");
    assert_eq!(nu, auto.values.iter().filter(|&&l| l < st.sigma).count());
    assert_eq!(nu, 36, "l = 0..5 (λ ≤ 30) lie below σ ≈ 35, l = 6 (λ = 42) above");
    for (a, b) in auto.values.iter().zip(&below.values) {
        assert!((a - b).abs() <= 1e-10 * a.abs().max(1.0), "{a} vs {b}");
    }
    assert!(auto.residuals.iter().all(|&r| r < 1e-7), "{:?}", auto.residuals);
    check_m_orthonormal(&s, &op, &auto, 1e-9);
}

/// A 100 × 1 strip: Weyl's two-dimensional law overestimates its low spectrum, which is one-dimensional
/// ((πm/100)², m = 0, 1, …, below (π)² where the first transverse mode starts), so the first interior shift has
/// more than k eigenvalues below it; the solver lowers it and still returns the exact low spectrum.
#[test]
fn thin_strip_lowers_an_overestimated_shift() {
    let s = mesh(generate::grid(400, 4, 100.0, 1.0));
    let op = opts(Mass::Consistent, Boundary::Neumann);
    let o = operators::build(&s, &op).unwrap();
    let k = 20;
    let first = kac_core::spectrum::lanczos::weyl_shift(&o.pair, k).unwrap();
    let exact: Vec<f64> = (0..k).map(|m| (std::f64::consts::PI * m as f64 / 100.0).powi(2)).collect();
    assert!(exact.iter().filter(|&&l| l < first).count() > k - 1, "the first guess is too high here");
    let sp = eigs(&o.pair, &EigenOptions { k, method: Method::Sparse, ..Default::default() }, None, Control::default())
        .unwrap();
    let st = &sp.stats;
    assert!(st.sigma < first, "σ lowered from {first} to {}", st.sigma);
    if let Some(nu) = st.below_sigma {
        assert!(nu <= k);
        assert_eq!(nu, sp.values.iter().filter(|&&l| l < st.sigma).count());
    }
    let dense =
        eigs(&o.pair, &EigenOptions { k, method: Method::Dense, ..Default::default() }, None, Control::default())
            .unwrap();
    for ((a, b), e) in sp.values.iter().zip(&dense.values).zip(&exact) {
        assert!((a - b).abs() <= 1e-10 * a.abs().max(1.0), "{a} vs dense {b}");
        // P1 elements, h = 1/4 along the strip: 1% on these smooth modes.
        assert!((a - e).abs() <= 1e-2 * e.max(1e-3), "{a} vs exact {e}");
    }
}

/// Completeness by Sylvester's inertia: k = 50 cuts the sphere's l = 7 cluster (indices 49–63, which the
/// icosahedral mesh splits into sub-clusters), and the check counts below a shift in the first gap above λ₅₀
/// among the converged pairs, so every returned eigenvalue is covered; 30 separate triangles have 30 zero
/// eigenvalues below τ. A spectrum with one eigenvalue removed is reported incomplete.
#[test]
fn inertia_check_confirms_clusters_and_catches_a_missing_eigenvalue() {
    use kac_core::spectrum::check_completeness;
    let s = mesh(generate::icosphere(4));
    let o = operators::build(&s, &OperatorOptions::default()).unwrap();
    let options = EigenOptions { k: 50, method: Method::Sparse, verify: true, ..Default::default() };
    let sp = eigs(&o.pair, &options, None, Control::default()).unwrap();
    let c = sp.stats.completeness.clone().expect("the found values have a gap");
    assert!(c.complete && c.below_shift == c.found_below_shift && c.found_below_shift >= Some(50), "{c:?}");
    let shift = c.shift.expect("an inertia count");
    assert!(shift > sp.values[49], "{c:?}");

    let mut missing = sp.values[..40].to_vec();
    missing.remove(10);
    let c = check_completeness(&o.pair, &missing, missing.len(), None).unwrap().unwrap();
    assert!(!c.complete && c.below_shift == c.found_below_shift.map(|f| f + 1), "{c:?}");

    let mut m = TriangleMesh::default();
    for t in 0..30u32 {
        let x = t as f64 * 3.0;
        m.vertices.extend([[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]);
        m.faces.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    let o = operators::build(&mesh(m), &OperatorOptions::default()).unwrap();
    let options = EigenOptions { k: 40, method: Method::Sparse, verify: true, ..Default::default() };
    let sp = eigs(&o.pair, &options, None, Control::default()).unwrap();
    let c = sp.stats.completeness.expect("a gap above the zeros");
    // The 30 congruent triangles' eigenvalues come in clusters of 30, more than the block: either the inertia
    // confirms the count, or the repairs ran out of Krylov room and the dense path computed everything.
    assert!(c.complete && (c.below_shift >= Some(30) || c.method == "dense"), "{c:?}");
}

/// Kac's question answered "no" by kac: the Gordon–Webb–Wolpert drums are not congruent (different shape ids),
/// yet their Dirichlet spectra agree (on these conforming meshes to rounding: transplantation holds for the
/// discrete problem too), and the first eigenvalue approaches Driscoll's 2.53794399980 for the drums at twice
/// this size (Driscoll 1997, SIAM Review 39: λ scales as 1/size², so ours is 4×) under refinement.
#[test]
fn isospectral_drums_sound_the_same() {
    let spectrum = |which: usize, n: usize| {
        let off = kac_core::io::write::off(&generate::gww_drum(which, n));
        let v = kac_core::load_bytes(off.as_bytes(), kac_core::Format::Off, &Default::default(), &Default::default())
            .unwrap();
        let o = operators::build(&v.shape, &opts(Mass::Consistent, Boundary::Dirichlet)).unwrap();
        let s =
            kac_core::spectrum::eigs(&o.pair, &EigenOptions { k: 10, ..Default::default() }, None, Control::default())
                .unwrap();
        (v.id.hex(), s.values)
    };
    let (id1, l1) = spectrum(1, 12);
    let (id2, l2) = spectrum(2, 12);
    assert_ne!(id1, id2, "two different drums");
    assert_close(&l1, &l2, 1e-9, "the two drums' spectra");
    let driscoll = 4.0 * 2.53794399980;
    let errors: Vec<f64> = [6, 12, 24].iter().map(|&n| (spectrum(1, n).1[0] - driscoll) / driscoll).collect();
    assert!(errors.iter().all(|e| *e > 0.0), "P1 eigenvalues lie above: {errors:?}");
    assert!(errors[1] < errors[0] && errors[2] < errors[1] && errors[2] < 0.005, "{errors:?}");
}

/// The graphs' counterpart: two non-isomorphic graphs (different degree sequences) with one combinatorial
/// Laplacian spectrum, and different shape ids.
#[test]
fn cospectral_graphs_sound_the_same() {
    let mut spectra = vec![];
    let mut degrees = vec![];
    let mut ids = vec![];
    for which in [1, 2] {
        let g = generate::cospectral_graph(which);
        let mut d = vec![0; g.vertex_count];
        for e in &g.edges {
            d[e[0] as usize] += 1;
            d[e[1] as usize] += 1;
        }
        d.sort_unstable();
        degrees.push(d);
        let text = serde_json::to_vec(&kac_core::io::write::json(&Shape::Graph(g.clone()))).unwrap();
        let v = kac_core::load_bytes(&text, kac_core::Format::Json, &Default::default(), &Default::default()).unwrap();
        ids.push(v.id.hex());
        let o = OperatorOptions { operator: Some(OperatorKind::Graph), ..Default::default() };
        spectra.push(solve(&Shape::Graph(g), o, 6, Method::Dense).values);
    }
    assert_ne!(degrees[0], degrees[1], "not isomorphic");
    assert_ne!(ids[0], ids[1]);
    assert_close(&spectra[0], &spectra[1], 1e-12, "one spectrum");
}

/// One run on two threads against one thread, with thick restarts whose Ritz vectors are formed by row ranges on
/// both threads (10,242 vertices: five chunks of the in-place product): the same eigenvalues to 10⁻¹⁰,
/// M-orthonormal eigenvectors with the sphere's residuals, the same sign convention and a proven count.
#[test]
fn one_run_with_restarts_on_two_threads_matches_one_thread() {
    let shape = mesh(generate::icosphere(5));
    let op = opts(Mass::Consistent, Boundary::Neumann);
    let pair = operators::build(&shape, &op).unwrap().pair;
    let run = |threads: usize| {
        let o = EigenOptions { k: 50, threads, slices: Some(1), method: Method::Sparse, ..Default::default() };
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        pool.install(|| eigs(&pair, &o, None, Control::default()).unwrap())
    };
    let (one, two) = (run(1), run(2));
    assert!(two.stats.restarts >= 1, "the run restarts: {:?}", two.stats.restarts);
    // Both proven complete (on two threads the check's factorization ran beside the residuals), and every vector
    // signed with its largest-magnitude entry positive (on two threads the columns are negated side by side).
    for s in [&one, &two] {
        assert!(s.stats.completeness.as_ref().is_some_and(|c| c.complete), "{:?}", s.stats.completeness);
        for j in 0..s.values.len() {
            let col = s.vectors.col(j);
            let big = col.iter().copied().fold(0.0f64, |a, x| if x.abs() > a.abs() { x } else { a });
            assert!(big > 0.0, "pair {j}: largest-magnitude entry {big}");
        }
    }
    assert_close(&two.values, &one.values, 1e-10, "two threads against one");
    check_m_orthonormal(&shape, &op, &two, 1e-8);
    let worst = two.residuals.iter().copied().fold(0.0f64, f64::max);
    assert!(worst < 1e-7, "largest residual {worst:e}");
}

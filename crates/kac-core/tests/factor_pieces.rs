//! The numeric factorization in pieces (`spectrum::numeric`) against faer's own numeric factorization on the same
//! symbolic analysis: the same factor to rounding, LLᵀ and LDLᵀ (with the same inertia), on surface, P2 and tet
//! operators, on one thread and on several (subtrees side by side); solves with it as accurate; and a stop flag
//! raised in the middle ends it with `Stopped`.

use faer::{Mat, Par};
use kac_core::geometry::{generate, Shape};
use kac_core::operators::sparse::SparsePair;
use kac_core::operators::{self, OperatorOptions};
use kac_core::spectrum::factor::{Cholesky, Symbolic};
use kac_core::spectrum::numeric::FactorError;
use std::sync::atomic::{AtomicBool, Ordering};

fn pair(shape: Shape, order: u8) -> SparsePair {
    operators::build(&shape, &OperatorOptions { order, ..Default::default() }).unwrap().pair
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// A factor's values with the strict upper triangle of every diagonal block cleared: faer's dense LLᵀ leaves
/// scratch there, which no solve reads.
fn lower(sym: &Symbolic, values: &[f64]) -> Vec<f64> {
    let faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Supernodal(sn) = sym.inner.raw() else {
        return values.to_vec();
    };
    let mut v = values.to_vec();
    let vp = sn.col_ptr_for_val();
    for s in 0..sn.n_supernodes() {
        let nc = sn.supernode_end()[s] - sn.supernode_begin()[s];
        let nr = nc + sn.supernode(s).pattern().len();
        for j in 0..nc {
            for i in 0..j {
                v[vp[s] + j * nr + i] = 0.0;
            }
        }
    }
    v
}

/// Factors L − σM both ways and compares values, inertia and a solve.
fn same_factor(p: &SparsePair, sigma: f64, ldlt: bool, par: Par) {
    let sym = Symbolic::analyze(&p.pattern).unwrap();
    assert!(
        matches!(sym.inner.raw(), faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Supernodal(_)),
        "the test needs a supernodal analysis"
    );
    let values = p.shifted(sigma);
    let (mine, whole, below) = if ldlt {
        let (a, na) = Cholesky::factor_ldlt_pieces(&sym, &values, par, None).unwrap();
        let (b, nb) = Cholesky::factor_ldlt_whole(&sym, &values, par).unwrap();
        assert_eq!(na, nb, "inertia at σ = {sigma}");
        (a, b, na)
    } else {
        (
            Cholesky::factor_pieces(&sym, &values, par, None).unwrap(),
            Cholesky::factor_whole(&sym, &values, par).unwrap(),
            0,
        )
    };
    let (mine_l, whole_l) = (lower(&sym, mine.values()), lower(&sym, whole.values()));
    let scale = max_abs(&whole_l);
    let diff = mine_l.iter().zip(&whole_l).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff <= 1e-9 * scale, "σ = {sigma}, ldlt {ldlt}: max difference {diff:e} of {scale:e}");
    let n = p.n();
    let rhs = Mat::from_fn(n, 3, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
    let (mut x, mut y) = (rhs.clone(), rhs.clone());
    mine.solve_in_place(x.as_mut(), Par::Seq);
    whole.solve_in_place(y.as_mut(), Par::Seq);
    let e = (&x - &y).norm_max() / y.norm_max();
    assert!(e < 1e-8, "σ = {sigma}, ldlt {ldlt}: solves differ by {e:e}");
    if ldlt {
        assert!(below > 0 || sigma < 0.0, "σ = {sigma} inside the spectrum has eigenvalues below it");
    }
}

#[test]
fn the_pieces_make_faers_factor_on_surfaces_p2_and_tets() {
    let sphere = pair(Shape::TriangleMesh(generate::icosphere(5)), 1);
    same_factor(&sphere, -0.5, false, Par::Seq);
    same_factor(&sphere, 30.0, true, Par::Seq);
    // Several threads: the tree's subtrees factored side by side, the top after them.
    same_factor(&sphere, -0.5, true, Par::rayon(2));
    same_factor(&sphere, -0.5, false, Par::rayon(3));
    same_factor(&sphere, 30.0, true, Par::rayon(4));
    let p2 = pair(Shape::TriangleMesh(generate::icosphere(4)), 2);
    same_factor(&p2, -1.0, false, Par::Seq);
    same_factor(&p2, 50.0, true, Par::Seq);
    same_factor(&p2, 50.0, true, Par::rayon(2));
    // Tets: wide supernodes near the root, factored in several panels.
    let cube = pair(Shape::TetMesh(generate::unit_cube_tets(14)), 1);
    same_factor(&cube, -1.0, false, Par::Seq);
    same_factor(&cube, 200.0, true, Par::rayon(2));
    let cube2 = pair(Shape::TetMesh(generate::unit_cube_tets(9)), 2);
    same_factor(&cube2, -1.0, false, Par::Seq);
    same_factor(&cube2, 300.0, true, Par::Seq);
}

#[test]
fn a_matrix_that_is_not_positive_definite_is_refused_by_cholesky() {
    let sphere = pair(Shape::TriangleMesh(generate::icosphere(4)), 1);
    let sym = Symbolic::analyze(&sphere.pattern).unwrap();
    let r = Cholesky::factor_pieces(&sym, &sphere.shifted(30.0), Par::Seq, None);
    assert!(matches!(&r, Err(FactorError::Failed(m)) if m.contains("not positive definite")), "{:?}", r.err());
    // On several threads (subtrees side by side; a sphere of 10k vertices, whose tree splits): the failure, not
    // the stops it causes in the other threads.
    let sphere = pair(Shape::TriangleMesh(generate::icosphere(5)), 1);
    let sym = Symbolic::analyze(&sphere.pattern).unwrap();
    for threads in [2, 3] {
        let r = Cholesky::factor_pieces(&sym, &sphere.shifted(30.0), Par::rayon(threads), None);
        assert!(matches!(&r, Err(FactorError::Failed(m)) if m.contains("not positive definite")), "{:?}", r.err());
    }
}

#[test]
fn a_raised_flag_stops_the_factorization() {
    // A P2 tet operator (about 30k unknowns, wide separators): its factorization takes long enough to be stopped
    // in the middle.
    let p = pair(Shape::TetMesh(generate::unit_cube_tets(15)), 2);
    let sym = Symbolic::analyze(&p.pattern).unwrap();
    let values = p.shifted(-1.0);
    let raised = AtomicBool::new(true);
    assert_eq!(Cholesky::factor_pieces(&sym, &values, Par::Seq, Some(&raised)).err(), Some(FactorError::Stopped));
    // On several threads the raised flag ends it too (before the subtrees start).
    assert_eq!(Cholesky::factor_pieces(&sym, &values, Par::rayon(2), Some(&raised)).err(), Some(FactorError::Stopped));
    let stop = AtomicBool::new(false);
    let t = std::time::Instant::now();
    let r = std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(std::time::Duration::from_millis(30));
            stop.store(true, Ordering::SeqCst);
        });
        Cholesky::factor_ldlt_pieces(&sym, &values, Par::Seq, Some(&stop)).map(|_| ())
    });
    // The same on two threads (subtrees side by side where the tree splits), the flag raised during the work.
    let stop2 = AtomicBool::new(false);
    let r2 = std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(std::time::Duration::from_millis(30));
            stop2.store(true, Ordering::SeqCst);
        });
        Cholesky::factor_ldlt_pieces(&sym, &values, Par::rayon(2), Some(&stop2)).map(|_| ())
    });
    let whole = std::time::Instant::now();
    let done = Cholesky::factor_whole(&sym, &values, Par::Seq);
    assert!(done.is_ok());
    // Only meaningful when the whole factorization takes longer than the flag's delay (on two threads, twice that).
    let took = whole.elapsed();
    if took > std::time::Duration::from_millis(300) {
        assert_eq!(r.err(), Some(FactorError::Stopped), "after {:?}", t.elapsed());
    }
    if took > std::time::Duration::from_millis(600) {
        assert_eq!(r2.err(), Some(FactorError::Stopped), "two threads");
    }
}

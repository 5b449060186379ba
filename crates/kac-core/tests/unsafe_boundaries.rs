//! The safe public entry points that reach unsafe code — the supernodal block solve
//! ([`Cholesky::solve_in_place_with`]), the basis products ([`gram_with`], [`update_with`]) and the sparse block
//! product ([`sparse::spmm`]) — fed wrong sizes and every kind of view faer can make safely: reversed rows and
//! columns, row- and column-strided, transposed, a block inside a larger matrix. Each call must panic, or give
//! the result of a plain computation and leave every value outside the view it was handed as it was: never a
//! write (or read) out of bounds. `scripts/sanitize.sh` runs this file under AddressSanitizer (or valgrind), which
//! also catches an out-of-bounds access that happens to leave the values alone.

use faer::prelude::IntoConst;
use faer::{Mat, MatMut, MatRef, Par};
use kac_core::geometry::{generate, Shape};
use kac_core::operators::sparse::{self, SparsePair};
use kac_core::operators::{self, OperatorOptions};
use kac_core::simd::Isa;
use kac_core::spectrum::basis_products::{gram_with, update_with};
use kac_core::spectrum::factor::{Cholesky, Symbolic};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::OnceLock;

/// Whether `f` panics.
fn panics(f: impl FnOnce()) -> bool {
    catch_unwind(AssertUnwindSafe(f)).is_err()
}

/// Fills every buffer before a view is cut from it; the values written through views never equal it.
const SENTINEL: f64 = -7777.25;

/// How an n × b block sits in its buffer: every layout faer builds from a slice without `unsafe`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Layout {
    ColMajor,
    RowMajor,
    ReversedRows,
    ReversedCols,
    ReversedRowMajor,
    /// Row-major with three unused values after each row (row stride b + 3, column stride 1). Built as the
    /// transpose of a column-major view: faer 0.24.4's `MatMut::from_row_major_slice_with_stride_mut` swaps the
    /// strides (a column-major view, which for more columns than rows reaches past its slice; faer-rs PR #267).
    RowStrided,
    /// Every other column of a column-major matrix (column stride 2n).
    EveryOtherCol,
    /// The interior of an (n + 3) × (b + 2) column-major matrix (column stride n + 3, offset (1, 1)).
    Interior,
    /// The transpose of the interior of a (b + 2) × (n + 3) column-major matrix (row stride b + 2, column stride
    /// 1, offset (1, 1)).
    TransposedInterior,
}

const LAYOUTS: [Layout; 9] = [
    Layout::ColMajor,
    Layout::RowMajor,
    Layout::ReversedRows,
    Layout::ReversedCols,
    Layout::ReversedRowMajor,
    Layout::RowStrided,
    Layout::EveryOtherCol,
    Layout::Interior,
    Layout::TransposedInterior,
];

impl Layout {
    fn buffer(self, n: usize, b: usize) -> Vec<f64> {
        let len = match self {
            Layout::RowStrided => n * (b + 3),
            Layout::EveryOtherCol => 2 * n * b,
            Layout::Interior => (n + 3) * (b + 2),
            Layout::TransposedInterior => (b + 2) * (n + 3),
            _ => n * b,
        };
        vec![SENTINEL; len]
    }

    fn view(self, buf: &mut [f64], n: usize, b: usize) -> MatMut<'_, f64> {
        match self {
            Layout::ColMajor => MatMut::from_column_major_slice_mut(buf, n, b),
            Layout::RowMajor => MatMut::from_row_major_slice_mut(buf, n, b),
            Layout::ReversedRows => MatMut::from_column_major_slice_mut(buf, n, b).reverse_rows_mut(),
            Layout::ReversedCols => MatMut::from_column_major_slice_mut(buf, n, b).reverse_cols_mut(),
            Layout::ReversedRowMajor => MatMut::from_row_major_slice_mut(buf, n, b).reverse_rows_mut(),
            Layout::RowStrided => MatMut::from_column_major_slice_with_stride_mut(buf, b, n, b + 3).transpose_mut(),
            Layout::EveryOtherCol => MatMut::from_column_major_slice_with_stride_mut(buf, n, b, 2 * n),
            Layout::Interior => MatMut::from_column_major_slice_mut(buf, n + 3, b + 2).submatrix_mut(1, 1, n, b),
            Layout::TransposedInterior => {
                MatMut::from_column_major_slice_mut(buf, b + 2, n + 3).submatrix_mut(1, 1, b, n).transpose_mut()
            }
        }
    }

    /// A buffer holding `a` in this layout, SENTINEL everywhere else.
    fn holding(self, a: MatRef<'_, f64>) -> Vec<f64> {
        let (n, b) = (a.nrows(), a.ncols());
        let mut buf = self.buffer(n, b);
        let mut v = self.view(&mut buf, n, b);
        for c in 0..b {
            for i in 0..n {
                v[(i, c)] = a[(i, c)];
            }
        }
        buf
    }

    /// The block held in `buf`, after asserting that every value outside the view is still SENTINEL.
    fn read(self, buf: &mut [f64], n: usize, b: usize, what: &str) -> Mat<f64> {
        let mut inside = vec![false; buf.len()];
        let start = buf.as_ptr() as usize;
        {
            let v = self.view(buf, n, b).into_const();
            for c in 0..b {
                for i in 0..n {
                    inside[(v.ptr_at(i, c) as usize - start) / size_of::<f64>()] = true;
                }
            }
        }
        for (t, (&x, &inn)) in buf.iter().zip(&inside).enumerate() {
            assert!(inn || x == SENTINEL, "{what} {self:?}: value {t} outside the view changed to {x}");
        }
        let v = self.view(buf, n, b);
        Mat::from_fn(n, b, |i, c| v[(i, c)])
    }
}

fn max_abs(a: MatRef<'_, f64>) -> f64 {
    let mut m = 0.0f64;
    for c in 0..a.ncols() {
        for i in 0..a.nrows() {
            m = m.max(a[(i, c)].abs());
        }
    }
    m
}

fn assert_close(got: MatRef<'_, f64>, want: MatRef<'_, f64>, tol: f64, what: &str) {
    assert_eq!((got.nrows(), got.ncols()), (want.nrows(), want.ncols()), "{what}: shape");
    let scale = max_abs(want).max(1.0);
    for c in 0..want.ncols() {
        for i in 0..want.nrows() {
            let (g, w) = (got[(i, c)], want[(i, c)]);
            assert!((g - w).abs() <= tol * scale, "{what}: entry ({i}, {c}) is {g}, expected {w}");
        }
    }
}

fn block(n: usize, b: usize, seed: usize) -> Mat<f64> {
    Mat::from_fn(n, b, |i, c| ((i * 31 + c * 17 + seed * 7) % 23) as f64 - 11.0)
}

struct Fixture {
    pair: SparsePair,
    k: Vec<f64>,
    /// Cholesky of K = L + 0.5 M and LDLᵀ of L − 7 M (indefinite), both supernodal.
    factors: [Cholesky; 2],
}

/// A 10242-vertex sphere: large enough for faer's supernodal factorization (the one with kac's own kernels), small
/// enough for a sanitizer.
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let shape = Shape::TriangleMesh(generate::icosphere(5));
        let pair = operators::build(&shape, &OperatorOptions::default()).unwrap().pair;
        let k = pair.shifted(-0.5);
        let sym = Symbolic::analyze(&pair.pattern).unwrap();
        let chol = Cholesky::factor(&sym, &k, Par::Seq).unwrap();
        let (ldlt, _) = Cholesky::factor_ldlt(&sym, &pair.shifted(7.0), Par::Seq).unwrap();
        assert!(chol.is_supernodal() && ldlt.is_supernodal(), "the fixture must reach the supernodal kernels");
        Fixture { pair, k, factors: [chol, ldlt] }
    })
}

const WIDTHS: [usize; 7] = [1, 2, 3, 4, 8, 16, 5];

/// Too few or too many rows, column- or row-major: the SIMD solve used to trust `rhs.nrows()` and write past a
/// short row-major block in a release build.
#[test]
fn solve_panics_on_a_wrong_row_count() {
    let f = fixture();
    let n = f.pair.n();
    for fac in &f.factors {
        for isa in Isa::available() {
            for b in WIDTHS {
                for rows in [0, 1, n - 1, n + 1] {
                    let mut col = Mat::<f64>::zeros(rows, b);
                    assert!(
                        panics(|| fac.solve_in_place_with(col.as_mut(), Par::Seq, isa)),
                        "{isa:?} b={b} rows={rows}"
                    );
                    let mut buf = vec![1.0; rows * b];
                    let rm = MatMut::from_row_major_slice_mut(&mut buf, rows, b);
                    assert!(
                        panics(|| fac.solve_in_place_with(rm, Par::Seq, isa)),
                        "row-major {isa:?} b={b} rows={rows}"
                    );
                }
            }
        }
        assert!(panics(|| fac.solve_in_place(Mat::<f64>::zeros(n - 1, 8).as_mut(), Par::Seq)));
    }
}

/// Every layout, width, factor and instruction set against the portable solve of a plain column-major block.
#[test]
fn solve_takes_reversed_strided_and_transposed_views() {
    let f = fixture();
    let n = f.pair.n();
    for (which, fac) in f.factors.iter().enumerate() {
        for b in WIDTHS {
            let rhs = block(n, b, which);
            let mut want = rhs.clone();
            fac.solve_in_place_with(want.as_mut(), Par::Seq, Isa::Scalar);
            for isa in Isa::available() {
                for layout in LAYOUTS {
                    let mut buf = layout.holding(rhs.as_ref());
                    fac.solve_in_place_with(layout.view(&mut buf, n, b), Par::Seq, isa);
                    let what = format!("solve factor {which} {isa:?} b={b}");
                    let got = layout.read(&mut buf, n, b, &what);
                    assert_close(got.as_ref(), want.as_ref(), 1e-10, &what);
                }
            }
        }
    }
}

/// Y, W and C of the wrong size, and a width whose n·b overflows, panic for every instruction set.
#[test]
fn basis_products_panic_on_wrong_sizes() {
    let v = block(300, 9, 1);
    for isa in Isa::available() {
        for b in [1usize, 3, 4, 8, 16] {
            let (n, m) = (300, 9);
            for len in [n * b - 1, n * b + 1, 0] {
                let y = vec![1.0; len];
                assert!(panics(|| drop(gram_with(v.as_ref(), &y, b, isa))), "gram {isa:?} b={b} len={len}");
                let mut w = vec![1.0; len];
                let c = Mat::<f64>::zeros(m, b);
                assert!(panics(|| update_with(&mut w, b, v.as_ref(), c.as_ref(), 1.0, isa)), "update {isa:?} b={b}");
            }
            let mut w = vec![1.0; n * b];
            for (cr, cc) in [(m + 1, b), (m - 1, b), (m, b + 1)] {
                let c = Mat::<f64>::zeros(cr, cc);
                assert!(panics(|| update_with(&mut w, b, v.as_ref(), c.as_ref(), 1.0, isa)), "C {cr}×{cc} {isa:?}");
            }
        }
        // n·b wraps to a small number in release arithmetic: a panic, not a short block.
        let huge = usize::MAX / 150 + 1;
        assert!(panics(|| drop(gram_with(v.as_ref(), &[1.0; 8], huge, isa))));
        assert!(panics(|| update_with(&mut [1.0; 8], huge, v.as_ref(), Mat::<f64>::zeros(9, 0).as_ref(), 1.0, isa)));
    }
}

/// V in every layout (the reversed-column view is the one whose column stride `Columns` used to cast to a huge
/// usize), C in several, against the definitions C = Vᵀ Y and W + α V C.
#[test]
fn basis_products_take_any_view_of_v_and_c() {
    for isa in Isa::available() {
        for b in [1usize, 3, 4, 8, 16] {
            for (n, m) in [(300usize, 9usize), (2100, 11), (7, 1), (1, 5), (257, 4)] {
                let vm = block(n, m, 3);
                let y: Vec<f64> = (0..n * b).map(|p| ((p * 13) % 17) as f64 / 5.0 - 1.5).collect();
                let want_c = Mat::from_fn(m, b, |j, t| (0..n).map(|i| vm[(i, j)] * y[i * b + t]).sum::<f64>());
                let want_w: Vec<f64> = (0..n * b)
                    .map(|p| y[p] - 0.5 * (0..m).map(|j| vm[(p / b, j)] * want_c[(j, p % b)]).sum::<f64>())
                    .collect();
                for layout in LAYOUTS {
                    let mut vbuf = layout.holding(vm.as_ref());
                    let v = layout.view(&mut vbuf, n, m).into_const();
                    let what = format!("{isa:?} b={b} n={n} m={m} V {layout:?}");
                    let c = gram_with(v, &y, b, isa);
                    assert_close(c.as_ref(), want_c.as_ref(), 1e-12, &format!("gram {what}"));
                    for c_layout in [Layout::ColMajor, Layout::ReversedCols, Layout::ReversedRows, Layout::RowStrided] {
                        let mut cbuf = c_layout.holding(c.as_ref());
                        let cv = c_layout.view(&mut cbuf, m, b).into_const();
                        let mut w = y.clone();
                        update_with(&mut w, b, v, cv, -0.5, isa);
                        let got = MatRef::from_row_major_slice(&w, n, b);
                        let want = MatRef::from_row_major_slice(&want_w, n, b);
                        assert_close(got, want, 1e-11, &format!("update {what} C {c_layout:?}"));
                    }
                    layout.read(&mut vbuf, n, m, &what);
                }
            }
        }
    }
}

/// Y with fewer rows than X (the row-major fast path used to write n·b values through Y's pointer), Y of another
/// width, X not matching A, values not matching the pattern.
#[test]
fn spmm_panics_on_wrong_sizes() {
    let f = fixture();
    let (p, n) = (&f.pair.pattern, f.pair.n());
    let mut scratch = Vec::new();
    for b in [1usize, 3, 8, 16] {
        let x = block(n, b, 5);
        let xr: Vec<f64> = (0..n * b).map(|t| x[(t / b, t % b)]).collect();
        let xr = MatRef::from_row_major_slice(&xr, n, b);
        for (yr, yc) in [(n - 1, b), (n + 1, b), (0, b), (n, b + 1), (n, b - 1)] {
            let mut ybuf = vec![0.0; yr * yc];
            let y = MatMut::from_row_major_slice_mut(&mut ybuf, yr, yc);
            assert!(panics(|| sparse::spmm(p, &f.k, xr, y, &mut scratch, 2)), "b={b} Y {yr}×{yc}");
            let mut y = Mat::<f64>::zeros(yr, yc);
            assert!(panics(|| sparse::spmm(p, &f.k, x.as_ref(), y.as_mut(), &mut scratch, 2)), "col-major Y {yr}×{yc}");
        }
        let short = block(n - 1, b, 5);
        let mut y = Mat::<f64>::zeros(n - 1, b);
        assert!(panics(|| sparse::spmm(p, &f.k, short.as_ref(), y.as_mut(), &mut scratch, 2)), "X of n − 1 rows");
        let mut y = Mat::<f64>::zeros(n, b);
        assert!(panics(|| sparse::spmm(p, &f.k[1..], x.as_ref(), y.as_mut(), &mut scratch, 2)), "values too short");
    }
}

/// X and Y in every pair of layouts against one matrix-vector product per column; Y's buffer is untouched
/// outside its view.
#[test]
fn spmm_takes_any_views() {
    let f = fixture();
    let (p, n) = (&f.pair.pattern, f.pair.n());
    let mut scratch = Vec::new();
    for b in [1usize, 3, 8, 16] {
        let x = block(n, b, 6);
        let mut want = Mat::<f64>::zeros(n, b);
        let mut col = vec![0.0; n];
        for c in 0..b {
            let xc: Vec<f64> = (0..n).map(|i| x[(i, c)]).collect();
            sparse::matvec(p, &f.k, &xc, &mut col);
            for i in 0..n {
                want[(i, c)] = col[i];
            }
        }
        for xl in LAYOUTS {
            let mut xbuf = xl.holding(x.as_ref());
            for yl in LAYOUTS {
                let mut ybuf = yl.buffer(n, b);
                let xv = xl.view(&mut xbuf, n, b).into_const();
                sparse::spmm(p, &f.k, xv, yl.view(&mut ybuf, n, b), &mut scratch, 2);
                let what = format!("spmm b={b} X {xl:?} Y {yl:?}");
                let got = yl.read(&mut ybuf, n, b, &what);
                assert_close(got.as_ref(), want.as_ref(), 1e-12, &what);
            }
            xl.read(&mut xbuf, n, b, "spmm X");
        }
    }
}

//! The polygon Laplacian (Bunge et al. 2020) on meshes read with their polygons: a regular quad grid's spectrum
//! converges to the unit square's (π²(a² + b²)) at order 2; on planar non-convex polygons it has linear
//! precision; on non-planar quads it is symmetric, positive semidefinite with the constants in its kernel; and as
//! a curved quad mesh refines its spectrum and the triangulated mesh's cotan spectrum approach each other.

use kac_core::operators::{self, properties, Boundary, OperatorKind, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};
use kac_core::{io::Format, ReadOptions, ValidateOptions, Validated};
use std::f64::consts::PI;

fn read_obj(text: &str) -> Validated {
    kac_core::load_bytes(text.as_bytes(), Format::Obj, &ReadOptions::default(), &ValidateOptions::default()).unwrap()
}

fn polygon_operator(v: &Validated, boundary: Boundary) -> operators::Operator {
    let o = OperatorOptions {
        operator: Some(OperatorKind::Polygon),
        boundary,
        polygons: v.polygons.clone(),
        ..Default::default()
    };
    operators::build(&v.shape, &o).unwrap_or_else(|e| panic!("{e}"))
}

/// An n × n grid of quads on [0, 1]², with heights z = f(x, y).
fn quad_grid(n: usize, f: impl Fn(f64, f64) -> f64) -> String {
    let mut s = String::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            s += &format!("v {x} {y} {}\n", f(x, y));
        }
    }
    let idx = |i: usize, j: usize| j * (n + 1) + i + 1;
    for j in 0..n {
        for i in 0..n {
            s += &format!("f {} {} {} {}\n", idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
        }
    }
    s
}

fn smallest(o: &operators::Operator, k: usize) -> Vec<f64> {
    eigs(&o.pair, &EigenOptions { k, ..Default::default() }, None, Control::default()).unwrap().values
}

#[test]
fn a_regular_quad_grid_converges_to_the_square() {
    let exact = [2.0, 5.0, 5.0, 8.0].map(|x| x * PI * PI);
    let mut errors = vec![];
    for n in [8, 16, 32] {
        let v = read_obj(&quad_grid(n, |_, _| 0.0));
        assert_eq!(v.polygons.as_ref().map(|p| p.len()), Some(n * n), "the quads are kept");
        let l = smallest(&polygon_operator(&v, Boundary::Dirichlet), 4);
        errors.push(l.iter().zip(&exact).map(|(a, b)| (a - b).abs() / b).fold(0.0, f64::max));
    }
    let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    eprintln!("quad grid: {errors:?}, orders {orders:?}");
    assert!(orders.iter().all(|&o| (o - 2.0).abs() < 0.3) && errors[2] < 6e-3, "{errors:?} {orders:?}");
}

#[test]
fn planar_non_convex_polygons_have_linear_precision() {
    // An L-shaped hexagon and a square beside it, sharing an edge, and a triangle: mixed, non-convex, planar.
    let obj = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nv 3 0 0\nv 3 1 0\nv 3 2 0\nv 2 2 0\n\
               f 1 2 3 4 5 6\nf 2 7 8 3\nf 3 8 9 10\nf 3 10 4\nf 4 10 5\n";
    let v = read_obj(obj);
    let o = polygon_operator(&v, Boundary::Neumann);
    let r = properties::report(&v.shape, &o);
    assert!(r.linear_precision.as_ref().unwrap().holds, "{:?}", r.linear_precision);
    assert!(r.symmetric.holds && r.positive_semidefinite.holds && r.constants_in_kernel.unwrap().holds);
    assert!((r.total_mass - 6.0).abs() < 1e-12, "the mass sums to the area: {}", r.total_mass);
}

#[test]
fn non_planar_quads_give_a_symmetric_semidefinite_operator_that_approaches_the_triangulated_one() {
    // A saddle z = (x − ½)(y − ½) of quads: every quad is non-planar.
    let saddle = |x: f64, y: f64| (x - 0.5) * (y - 0.5);
    let mut gaps = vec![];
    for n in [8, 16, 32] {
        let v = read_obj(&quad_grid(n, saddle));
        let o = polygon_operator(&v, Boundary::Neumann);
        if n == 8 {
            let r = properties::report(&v.shape, &o);
            assert!(
                r.symmetric.holds && r.positive_semidefinite.holds && r.constants_in_kernel.as_ref().unwrap().holds,
                "{r:?}"
            );
        }
        let cotan = operators::build(&v.shape, &OperatorOptions::default()).unwrap();
        let (a, b) = (smallest(&o, 6), smallest(&cotan, 6));
        gaps.push(a.iter().zip(&b).skip(1).map(|(x, y)| (x - y).abs() / y).fold(0.0, f64::max));
    }
    eprintln!("saddle: polygon vs triangulated {gaps:?}");
    assert!(gaps[2] < gaps[0] / 3.0 && gaps[2] < 5e-3, "{gaps:?}");
}

/// The polygons are part of the shape's identity (the polygon operator reads them): a quad mesh and the same
/// triangles uploaded as triangles are two shapes; a polygon with more corners than the operator takes is refused.
#[test]
fn polygons_are_part_of_the_id_and_bounded() {
    let quads = read_obj(&quad_grid(2, |_, _| 0.0));
    let v = |i: usize, j: usize| j * 3 + i + 1;
    let mut tris = String::new();
    for j in 0..=2 {
        for i in 0..=2 {
            tris += &format!("v {} {} 0\n", i as f64 / 2.0, j as f64 / 2.0);
        }
    }
    for j in 0..2 {
        for i in 0..2 {
            tris += &format!(
                "f {} {} {}\nf {} {} {}\n",
                v(i, j),
                v(i + 1, j),
                v(i + 1, j + 1),
                v(i, j),
                v(i + 1, j + 1),
                v(i, j + 1)
            );
        }
    }
    let tris = read_obj(&tris);
    assert!(quads.polygons.is_some() && tris.polygons.is_none());
    assert_ne!(quads.id, tris.id);
    let n = operators::polygon::MAX_CORNERS + 1;
    let mut big = String::new();
    for i in 0..n {
        let a = 2.0 * PI * i as f64 / n as f64;
        big += &format!("v {} {} 0\n", a.cos(), a.sin());
    }
    big += "f";
    for i in 1..=n {
        big += &format!(" {i}");
    }
    big += "\n";
    let v = read_obj(&big);
    let o =
        OperatorOptions { operator: Some(OperatorKind::Polygon), polygons: v.polygons.clone(), ..Default::default() };
    assert!(operators::build(&v.shape, &o).is_err());
}

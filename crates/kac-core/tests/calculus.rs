//! Gradient and divergence (issue 29, item 5) against closed forms: exact on linear functions (triangles in the
//! plane and on a tilted plane, tetrahedra), convergent at first order on x² + y², and div ∇u = −L u to rounding
//! for any u on surface and tet meshes.

use kac_core::geometry::{generate, Shape};
use kac_core::operators::sparse::matvec;
use kac_core::operators::{self, OperatorOptions};
use kac_core::pde::calculus::{divergence, gradient};

/// The few 3-vector operations the checks need.
mod vec3 {
    pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }
    pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }
    pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
        [a[0] * s, a[1] * s, a[2] * s]
    }
    pub fn norm(a: [f64; 3]) -> f64 {
        dot(a, a).sqrt()
    }
}

fn elements(shape: &Shape) -> Vec<Vec<usize>> {
    match shape {
        Shape::TriangleMesh(m) => m.faces.iter().map(|f| f.iter().map(|&i| i as usize).collect()).collect(),
        Shape::TetMesh(m) => m.tets.iter().map(|t| t.iter().map(|&i| i as usize).collect()).collect(),
        _ => unreachable!(),
    }
}

fn positions(shape: &Shape) -> &[[f64; 3]] {
    match shape {
        Shape::TriangleMesh(m) => &m.vertices,
        Shape::TetMesh(m) => &m.vertices,
        _ => unreachable!(),
    }
}

#[test]
fn gradients_of_linear_functions_are_exact() {
    let a = [0.3, -1.7, 2.2];
    // The unit square in the plane z = 0: the in-plane part of a; a tilted copy (z = x): a projected on its plane.
    let square = generate::unit_square(9);
    let mut tilted = square.clone();
    tilted.vertices.iter_mut().for_each(|p| p[2] = p[0]);
    let cube = generate::unit_cube_tets(5);
    for shape in [Shape::TriangleMesh(square), Shape::TriangleMesh(tilted), Shape::TetMesh(cube)] {
        let p = positions(&shape);
        let u: Vec<f64> = p.iter().map(|x| vec3::dot(a, *x)).collect();
        let g = gradient(&shape, &u).unwrap();
        let want = match &shape {
            Shape::TetMesh(_) => a,
            Shape::TriangleMesh(m) if m.vertices.iter().any(|x| x[2] != 0.0) => {
                let n = [-std::f64::consts::FRAC_1_SQRT_2, 0.0, std::f64::consts::FRAC_1_SQRT_2];
                vec3::sub(a, vec3::scale(n, vec3::dot(a, n)))
            }
            _ => [a[0], a[1], 0.0],
        };
        for gf in &g {
            assert!(vec3::norm(vec3::sub(*gf, want)) < 1e-12, "{gf:?} vs {want:?}");
        }
    }
}

#[test]
fn the_gradient_of_x2_plus_y2_converges_at_first_order() {
    let error = |n: usize| {
        let m = generate::unit_square(n);
        let u: Vec<f64> = m.vertices.iter().map(|p| p[0] * p[0] + p[1] * p[1]).collect();
        let shape = Shape::TriangleMesh(m);
        let g = gradient(&shape, &u).unwrap();
        let p = positions(&shape);
        elements(&shape)
            .iter()
            .zip(&g)
            .map(|(f, gf)| {
                let c = f.iter().fold([0.0; 3], |acc, &i| vec3::add(acc, vec3::scale(p[i], 1.0 / 3.0)));
                vec3::norm(vec3::sub(*gf, [2.0 * c[0], 2.0 * c[1], 0.0]))
            })
            .fold(0.0f64, f64::max)
    };
    let (e16, e32, e64) = (error(16), error(32), error(64));
    let order = (e16 / e32).log2();
    assert!(e64 < 0.05 && (order - 1.0).abs() < 0.2 && (e32 / e64).log2() > 0.8, "{e16} {e32} {e64}: order {order}");
}

#[test]
fn the_divergence_of_a_gradient_is_minus_the_laplacian() {
    let mut sphere = generate::icosphere(3);
    sphere.vertices.iter_mut().for_each(|p| p[0] *= 1.3);
    for shape in [Shape::TriangleMesh(sphere), Shape::TetMesh(generate::unit_cube_tets(6))] {
        let p = positions(&shape);
        let u: Vec<f64> = p.iter().map(|x| (3.0 * x[0]).sin() + x[1] * x[2]).collect();
        let d = divergence(&shape, &gradient(&shape, &u).unwrap()).unwrap();
        let op = operators::build(&shape, &OperatorOptions::default()).unwrap();
        let mut lu = vec![0.0; u.len()];
        matvec(&op.pair.pattern, &op.pair.stiffness, &u, &mut lu);
        let scale = lu.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let diff = d.iter().zip(&lu).fold(0.0f64, |m, (a, b)| m.max((a + b).abs()));
        assert!(diff < 1e-12 * scale.max(1.0), "div ∇u + L u = {diff:e} of {scale:e}");
    }
}

#[test]
fn shapes_without_elements_are_refused() {
    let graph = Shape::Graph(generate::petersen_graph());
    assert!(gradient(&graph, &[0.0; 10]).is_err());
    let square = Shape::TriangleMesh(generate::unit_square(3));
    assert!(gradient(&square, &[0.0; 3]).is_err(), "a function of the wrong length");
    assert!(divergence(&square, &[[0.0; 3]; 2]).is_err(), "a field of the wrong length");
}

//! Quadratic (P2) elements against closed forms: the observed order of convergence of eigenvalues under
//! uniform refinement is about 4 (P1: 2) on the unit square (Dirichlet and Neumann), the flat torus (given by
//! edge lengths alone) and the unit cube (tets); on the unit disk it is 4 only when the boundary edges are
//! curved onto the circle (isoparametric), and 2 with straight ones (the polygon's own error); a second-order
//! Gmsh file (6-node triangles, 10-node tets) gives those curved edges through the reader.

use kac_core::geometry::{generate, Shape};
use kac_core::operators::sparse::SparsePair;
use kac_core::operators::{self, boundary, p2, Boundary, OperatorKind, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};
use std::f64::consts::PI;

fn smallest(pair: &SparsePair, k: usize) -> Vec<f64> {
    eigs(pair, &EigenOptions { k, ..Default::default() }, None, Control::default()).unwrap().values
}

fn build(shape: &Shape, order: u8, boundary: Boundary) -> SparsePair {
    let o = OperatorOptions { order, boundary, ..Default::default() };
    operators::build(shape, &o).unwrap_or_else(|e| panic!("{e}")).pair
}

/// Relative errors of eigenvalues `index` at each refinement, and the observed orders log₂(e_h / e_{h/2}).
fn orders(errors: &[f64]) -> Vec<f64> {
    errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
}

fn sci(v: &[f64]) -> String {
    v.iter().map(|x| format!("{x:.2e}")).collect::<Vec<_>>().join(", ")
}

fn rel(got: &[f64], exact: &[f64], skip: usize) -> f64 {
    got.iter().zip(exact).skip(skip).map(|(g, e)| (g - e).abs() / e).fold(0.0, f64::max)
}

#[test]
fn unit_square_converges_at_order_four() {
    let dirichlet = [2.0, 5.0, 5.0, 8.0, 10.0, 10.0].map(|x| x * PI * PI);
    let neumann = [0.0, 1.0, 1.0, 2.0, 4.0, 4.0].map(|x| x * PI * PI);
    for (exact, bc) in [(dirichlet, Boundary::Dirichlet), (neumann, Boundary::Neumann)] {
        let skip = usize::from(bc == Boundary::Neumann);
        let (mut e1, mut e2) = (vec![], vec![]);
        for n in [4, 8, 16] {
            let s = Shape::TriangleMesh(generate::unit_square(n));
            e1.push(rel(&smallest(&build(&s, 1, bc.clone()), 6), &exact, skip));
            e2.push(rel(&smallest(&build(&s, 2, bc.clone()), 6), &exact, skip));
        }
        let (o1, o2) = (orders(&e1), orders(&e2));
        eprintln!("square {bc:?}: P1 {} orders {o1:.2?}; P2 {} orders {o2:.2?}", sci(&e1), sci(&e2));
        assert!(o2.iter().all(|&o| o > 3.6), "P2 orders {o2:?}");
        assert!(o1[1] < 2.5, "P1 orders {o1:?}");
        assert!(e2[2] < 1e-2 * e1[2], "{e1:?} {e2:?}");
    }
}

/// The flat torus [0, 1)² with periodic identification has no embedding in R³ with flat triangles; it is given
/// by its edge lengths. λ = 4π²(a² + b²): 0, 4π² ×4, 8π² ×4.
#[test]
fn flat_torus_by_lengths_converges_at_order_four() {
    let exact = [0.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0].map(|x| 4.0 * PI * PI * x);
    let mut errors = vec![];
    for n in [4usize, 8, 16] {
        let idx = |i: usize, j: usize| ((j % n) * n + i % n) as u32;
        let faces: Vec<[u32; 3]> = (0..n)
            .flat_map(|j| {
                (0..n).flat_map(move |i| {
                    [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)], [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
                })
            })
            .collect();
        let h = 1.0 / n as f64;
        // Lengths opposite corners 0, 1, 2: the hypotenuse is opposite the right angle.
        let lengths = |f: usize| if f.is_multiple_of(2) { [h, h * 2f64.sqrt(), h] } else { [h, h, h * 2f64.sqrt()] };
        let (pair, edges) = p2::triangle_p2_pair_intrinsic(n * n, &faces, lengths).unwrap();
        assert_eq!(edges.len(), 3 * n * n);
        errors.push(rel(&smallest(&pair, 9), &exact, 1));
    }
    let o = orders(&errors);
    eprintln!("flat torus P2: {} orders {o:.2?}", sci(&errors));
    assert!(o.iter().all(|&x| x > 3.6), "{o:?}");
}

#[test]
fn unit_cube_tets_converge_at_order_four() {
    let exact = [3.0, 6.0, 6.0, 6.0].map(|x| x * PI * PI);
    let (mut e1, mut e2) = (vec![], vec![]);
    for n in [3, 6, 12] {
        let s = Shape::TetMesh(generate::unit_cube_tets(n));
        e1.push(rel(&smallest(&build(&s, 1, Boundary::Dirichlet), 4), &exact, 0));
        e2.push(rel(&smallest(&build(&s, 2, Boundary::Dirichlet), 4), &exact, 0));
    }
    let (o1, o2) = (orders(&e1), orders(&e2));
    eprintln!("cube: P1 {} orders {o1:.2?}; P2 {} orders {o2:.2?}", sci(&e1), sci(&e2));
    assert!(o2[1] > 3.5 && e2[2] < 1e-3, "P2 {e2:?} orders {o2:?}");
    assert!(e2[2] < 0.02 * e1[2]);
}

/// The unit disk, Dirichlet: λ₁ = j₀,₁² (j₀,₁ = 2.404825557695773, the first zero of J₀; Abramowitz & Stegun
/// table 9.5), λ₂ = λ₃ = j₁,₁² (j₁,₁ = 3.831705970207512). Straight boundary edges cut the disk to a polygon
/// whose own eigenvalues differ by O(h²); midpoints on the circle restore order 4.
#[test]
fn disk_needs_curved_boundary_edges() {
    let (j01, j11) = (2.404_825_557_695_773_f64, 3.831_705_970_207_512_f64);
    let exact = [j01 * j01, j11 * j11, j11 * j11];
    let (mut flat, mut curved) = (vec![], vec![]);
    for rings in [4, 8, 16] {
        let m = generate::unit_disk(rings);
        let s = Shape::TriangleMesh(m.clone());
        flat.push(rel(&smallest(&build(&s, 2, Boundary::Dirichlet), 3), &exact, 0));
        let on_circle = |e: [u32; 2]| {
            let (a, b) = (m.vertices[e[0] as usize], m.vertices[e[1] as usize]);
            let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.0];
            let boundary = |p: [f64; 3]| (p[0].hypot(p[1]) - 1.0).abs() < 1e-12;
            if boundary(a) && boundary(b) {
                let r = mid[0].hypot(mid[1]);
                [mid[0] / r, mid[1] / r, 0.0]
            } else {
                mid
            }
        };
        let (pair, edges) = p2::triangle_p2_pair(&m.vertices, &m.faces, Some(&on_circle)).unwrap();
        let (pair, _) = boundary::apply_p2(&s, pair, &edges, &Boundary::Dirichlet).unwrap();
        curved.push(rel(&smallest(&pair, 3), &exact, 0));
    }
    let (of, oc) = (orders(&flat), orders(&curved));
    eprintln!("disk: straight {} orders {of:.2?}; curved {} orders {oc:.2?}", sci(&flat), sci(&curved));
    assert!(of.iter().all(|&o| o < 2.5), "straight edges: {of:?}");
    assert!(oc[1] > 3.5 && curved[2] < 0.01 * flat[2], "curved: {curved:?} {oc:?}");
}

#[test]
fn p2_needs_the_consistent_mass_and_a_fem_operator() {
    let s = Shape::TriangleMesh(generate::unit_square(2));
    let lumped = OperatorOptions { order: 2, mass: Some(operators::Mass::Lumped), ..Default::default() };
    assert!(operators::build(&s, &lumped).is_err());
    let graph = OperatorOptions { order: 2, operator: Some(OperatorKind::Graph), ..Default::default() };
    assert!(operators::build(&s, &graph).is_err());
    let o = operators::build(&s, &OperatorOptions { order: 2, ..Default::default() }).unwrap();
    // 9 vertices and 16 edges; the vertex values of a P2 vector are its first 9 unknowns.
    assert_eq!((o.pair.n(), o.unknowns(), o.expand(&[1.0; 25]).len()), (25, 25, 9));
    let r = operators::properties::report(&s, &o);
    assert!(r.symmetric.holds && r.local_support.holds && r.positive_semidefinite.holds, "{r:?}");
    assert!(r.linear_precision.unwrap().holds && r.constants_in_kernel.unwrap().holds);
}

/// A Gmsh 2.2 ASCII file of second-order elements: `corners` per element (triangles or tets) and the middle node
/// of each edge in Gmsh's order (triangles 01 12 20; tets 01 12 20 30 32 31) placed by `mid`.
fn second_order_msh(vertices: &[[f64; 3]], elements: &[Vec<u32>], mid: &dyn Fn([u32; 2]) -> [f64; 3]) -> String {
    let tri: &[[usize; 2]] = &[[0, 1], [1, 2], [2, 0]];
    let tet: &[[usize; 2]] = &[[0, 1], [1, 2], [2, 0], [3, 0], [3, 2], [3, 1]];
    let mut nodes: Vec<[f64; 3]> = vertices.to_vec();
    let mut index = std::collections::HashMap::new();
    let mut lines = vec![];
    for (i, el) in elements.iter().enumerate() {
        let (ty, edges) = if el.len() == 3 { (9, tri) } else { (11, tet) };
        let mut tags: Vec<usize> = el.iter().map(|&v| v as usize + 1).collect();
        for &[a, b] in edges {
            let e = [el[a].min(el[b]), el[a].max(el[b])];
            let n = *index.entry(e).or_insert_with(|| {
                nodes.push(mid(e));
                nodes.len()
            });
            tags.push(n);
        }
        let tags: Vec<String> = tags.iter().map(|t| t.to_string()).collect();
        lines.push(format!("{} {ty} 2 0 1 {}", i + 1, tags.join(" ")));
    }
    let mut out = String::from("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n");
    out += &format!("{}\n", nodes.len());
    for (i, p) in nodes.iter().enumerate() {
        out += &format!("{} {:.17} {:.17} {:.17}\n", i + 1, p[0], p[1], p[2]);
    }
    out += &format!("$EndNodes\n$Elements\n{}\n{}\n$EndElements\n", lines.len(), lines.join("\n"));
    out
}

/// The same disk as above, now read from second-order Gmsh files whose boundary edges' middle nodes lie on the
/// circle: P2 converges at order ≈ 4 (the reader carries the nodes to the operator); the same corners with
/// straight middle nodes are the polygon (order 2, the same operator as the OFF file of the corners, and another
/// shape id than the curved file; `midpoints: straight` gives it from the curved file too), and P1 ignores the nodes. A 10-node tet file with straight middle nodes in Gmsh's edge order is read without a warning.
#[test]
fn second_order_gmsh_files_curve_the_elements() {
    use kac_core::{load_bytes, Format, ReadOptions, ValidateOptions};
    let read = |text: &str| {
        load_bytes(text.as_bytes(), Format::Gmsh, &ReadOptions::default(), &ValidateOptions::default()).unwrap()
    };
    let dirichlet = |v: &kac_core::Validated, order: u8| {
        let o = OperatorOptions {
            order,
            boundary: Boundary::Dirichlet,
            edge_nodes: v.edge_nodes.clone(),
            ..Default::default()
        };
        smallest(&operators::build(&v.shape, &o).unwrap_or_else(|e| panic!("{e}")).pair, 3)
    };
    let (j01, j11) = (2.404_825_557_695_773_f64, 3.831_705_970_207_512_f64);
    let exact = [j01 * j01, j11 * j11, j11 * j11];
    let (mut curved, mut flat) = (vec![], vec![]);
    for rings in [4, 8, 16] {
        let m = generate::unit_disk(rings);
        let elements: Vec<Vec<u32>> = m.faces.iter().map(|f| f.to_vec()).collect();
        let straight = |e: [u32; 2]| {
            let (a, b) = (m.vertices[e[0] as usize], m.vertices[e[1] as usize]);
            [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.0]
        };
        let on_circle = |e: [u32; 2]| {
            let mid = straight(e);
            let boundary = |i: u32| (m.vertices[i as usize][0].hypot(m.vertices[i as usize][1]) - 1.0).abs() < 1e-12;
            if boundary(e[0]) && boundary(e[1]) {
                let r = mid[0].hypot(mid[1]);
                [mid[0] / r, mid[1] / r, 0.0]
            } else {
                mid
            }
        };
        let v = read(&second_order_msh(&m.vertices, &elements, &on_circle));
        let nodes = v.edge_nodes.as_ref().expect("curved edges kept");
        assert!(v.report.notes.iter().any(|n| n.contains("edges curved")), "{:?}", v.report.notes);
        assert!(nodes.len() >= 6 * rings, "{} curved edge nodes", nodes.len());
        let p2 = dirichlet(&v, 2);
        curved.push(rel(&p2, &exact, 0));
        let plain = load_bytes(
            kac_core::io::write::off(&m).as_bytes(),
            Format::Off,
            &ReadOptions::default(),
            &ValidateOptions::default(),
        )
        .unwrap();
        let s = read(&second_order_msh(&m.vertices, &elements, &straight));
        assert!(s.edge_nodes.is_none(), "straight middle nodes change nothing");
        let (a, b) = (dirichlet(&s, 2), dirichlet(&plain, 2));
        assert!(rel(&a, &b, 0) < 1e-12, "{a:?} {b:?}");
        assert_eq!(dirichlet(&v, 1), dirichlet(&s, 1), "P1 ignores the middle nodes");
        assert_ne!(v.id, s.id, "curved edges are part of the shape");
        // `midpoints: straight` sets the file's middle nodes aside: the polygon's operator again.
        let o = OperatorOptions {
            order: 2,
            boundary: Boundary::Dirichlet,
            edge_nodes: v.edge_nodes.clone(),
            midpoints: p2::Midpoints::Straight,
            ..Default::default()
        };
        let asked = operators::build(&v.shape, &o).unwrap();
        assert!(asked.parameters["midpoints"].as_str().unwrap().contains("not used"), "{:?}", asked.parameters);
        assert!(rel(&smallest(&asked.pair, 3), &b, 0) < 1e-12, "straight as asked");
        flat.push(rel(&dirichlet(&s, 2), &exact, 0));
    }
    let (oc, of) = (orders(&curved), orders(&flat));
    eprintln!("Gmsh disk: curved {} orders {oc:.2?}; straight {} orders {of:.2?}", sci(&curved), sci(&flat));
    assert!(oc[1] > 3.5 && curved[2] < 0.01 * flat[2], "curved: {curved:?} {oc:?}");
    assert!(of.iter().all(|&o| o < 2.5), "straight: {of:?}");
    let cube = generate::unit_cube_tets(2);
    let elements: Vec<Vec<u32>> = cube.tets.iter().map(|t| t.to_vec()).collect();
    let mid = |e: [u32; 2]| {
        let (a, b) = (cube.vertices[e[0] as usize], cube.vertices[e[1] as usize]);
        [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])]
    };
    let v = read(&second_order_msh(&cube.vertices, &elements, &mid));
    assert!(v.report.warnings.is_empty() && v.edge_nodes.is_none(), "{:?}", v.report.warnings);
    // A middle node far off its edge (as a wrong node order would put it) is refused with a warning.
    let off = |e: [u32; 2]| if e == [0, 1] { [9.0, 9.0, 9.0] } else { mid(e) };
    let v = read(&second_order_msh(&cube.vertices, &elements, &off));
    assert!(v.edge_nodes.is_none() && v.report.warnings.iter().any(|w| w.contains("quarter")), "{:?}", v.report);
}

/// On a curved surface without file geometry, `midpoints: normals` curves the edges by the vertex normals: on a
/// unit icosphere whose vertices were jittered along the sphere (no symmetry to help), λ₂..₉ (exactly 2 and 6)
/// with P2 converge at order about 2.6–3 instead of the flat elements' 2 (the normals are estimated to O(h²)) and
/// land 49× nearer at 2,562 vertices (measured 2.6·10⁻⁵ against 1.2·10⁻³). With order 1 or on tets it is refused.
#[test]
fn sphere_edges_curved_by_vertex_normals() {
    let exact: Vec<f64> = [2.0; 3].into_iter().chain([6.0; 5]).collect();
    let (mut flat, mut curved) = (vec![], vec![]);
    for level in 1..=4 {
        let mut m = generate::icosphere(level);
        let mut state = 7u64 + level as u64;
        let mut rnd = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64) / (1u64 << 53) as f64 - 0.5
        };
        let h = 1.0 / f64::from(1u32 << level);
        for p in &mut m.vertices {
            let q = p.map(|x| x + 0.3 * h * rnd());
            let r = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
            *p = q.map(|x| x / r);
        }
        let s = Shape::TriangleMesh(m);
        flat.push(rel(&smallest(&build(&s, 2, Boundary::Neumann), 9)[1..], &exact, 0));
        let o = OperatorOptions { order: 2, midpoints: p2::Midpoints::Normals, ..Default::default() };
        let op = operators::build(&s, &o).unwrap();
        assert!(op.parameters["midpoints"].as_str().unwrap().contains("normals"), "{:?}", op.parameters);
        curved.push(rel(&smallest(&op.pair, 9)[1..], &exact, 0));
    }
    let (of, oc) = (orders(&flat), orders(&curved));
    eprintln!("jittered sphere: flat {} orders {of:.2?}; normals {} orders {oc:.2?}", sci(&flat), sci(&curved));
    assert!(of.iter().all(|&o| o < 2.3), "flat: {of:?}");
    assert!(oc[1] > 2.4 && oc[2] > 2.4 && curved[3] < 0.05 * flat[3], "normals: {curved:?} {oc:?}");
    let sq = Shape::TriangleMesh(generate::unit_square(4));
    let o = OperatorOptions { order: 1, midpoints: p2::Midpoints::Normals, ..Default::default() };
    assert!(operators::build(&sq, &o).is_err(), "order 1 has no edge nodes");
    let cube = Shape::TetMesh(generate::unit_cube_tets(2));
    let o = OperatorOptions { order: 2, midpoints: p2::Midpoints::Normals, ..Default::default() };
    assert!(operators::build(&cube, &o).is_err(), "tets take curved edges from files");
}

/// A curved element that turns over is refused, not assembled: the metric's determinant cannot see a fold, the
/// orientation check can. A moderately curved edge is accepted.
#[test]
fn a_folded_curved_element_is_refused() {
    let vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let faces = [[0u32, 1, 2]];
    let bend = |y: f64| {
        move |e: [u32; 2]| {
            let (a, b) = (vertices[e[0] as usize], vertices[e[1] as usize]);
            let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.0];
            if e == [0, 1] {
                [mid[0], y, 0.0]
            } else {
                mid
            }
        }
    };
    let mild = bend(-0.1);
    assert!(p2::triangle_p2_pair(&vertices, &faces, Some(&mild)).is_ok());
    let folded = bend(0.6);
    let Err(e) = p2::triangle_p2_pair(&vertices, &faces, Some(&folded)) else {
        panic!("a folded element was assembled")
    };
    assert!(e.to_string().contains("inverted"), "{e}");
}

/// Gmsh's node order of the 10-node tetrahedron, written out by hand from its documentation (not by the writer
/// above): nodes 5–10 on edges 1–2, 2–3, 3–1, 4–1, 4–3, 4–2 (one-based). Node 9 is moved off edge 4–3 and node 10
/// off edge 4–2: each must land on its own edge.
#[test]
fn gmsh_tet10_node_order_by_hand() {
    use kac_core::{load_bytes, Format, ReadOptions, ValidateOptions};
    let text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n10\n\
                1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n\
                5 0.5 0 0\n6 0.5 0.5 0\n7 0 0.5 0\n8 0 0 0.5\n9 0.05 0.5 0.5\n10 0.5 0.05 0.5\n\
                $EndNodes\n$Elements\n1\n1 11 2 0 1 1 2 3 4 5 6 7 8 9 10\n$EndElements\n";
    let v = load_bytes(text.as_bytes(), Format::Gmsh, &ReadOptions::default(), &ValidateOptions::default()).unwrap();
    let nodes = v.edge_nodes.as_ref().expect("two curved edges");
    let at = |a: usize, b: usize| {
        let (x, y) = (v.vertex_map[a], v.vertex_map[b]);
        nodes.get([x, y])
    };
    assert_eq!(at(3, 2), Some([0.05, 0.5, 0.5]), "node 9 on edge 4–3");
    assert_eq!(at(3, 1), Some([0.5, 0.05, 0.5]), "node 10 on edge 4–2");
    assert_eq!(at(0, 1), Some([0.5, 0.0, 0.0]), "node 5 on edge 1–2");
}

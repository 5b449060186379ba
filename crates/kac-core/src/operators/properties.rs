//! The "no free lunch" report (§9.5): which properties of the smooth Laplacian a built discrete operator has
//! on the user's shape. No discrete Laplacian has all of them on every mesh (Wardetzky, Mathur, Kälberer &
//! Grinspun 2007); this says which ones hold here.
//!
//! - symmetry: max |L_ij − L_ji| relative to max |L_ij|;
//! - local support: every non-zero joins vertices that are neighbours in the input (mesh edges, graph edges;
//!   for point clouds the kernel radius) — intrinsic Delaunay edges may join vertices that are not;
//! - linear precision: (L u)_i = 0 at interior vertices for linear u, where the shape is flat (planar surfaces,
//!   straight polylines, every tet mesh);
//! - maximum principle: no negative edge weight (no positive off-diagonal entry of L);
//! - positive semidefiniteness: L + εM (ε = 10⁻¹⁰ · mean L_jj/M_jj) has a Cholesky factorization;
//! - null space: eigenvalues below 10⁻⁸ · mean L_jj/M_jj among the smallest ones, against connected components;
//! - constants in the kernel (Neumann): max |L·1| relative to max |L_ii|; the mass is positive and its total.

use super::sparse::matvec;
use super::{edge_graph, Operator, OperatorKind};
use crate::cholesky::factor::{self, Symbolic};
use crate::geometry::{vec3, Shape};
use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Check {
    pub holds: bool,
    /// The measured quantity behind the verdict.
    pub value: f64,
    pub note: String,
}

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PropertyReport {
    pub symmetric: Check,
    pub local_support: Check,
    /// `None` where the shape is not flat, so linear functions are not harmonic.
    pub linear_precision: Option<Check>,
    pub maximum_principle: Check,
    pub positive_semidefinite: Check,
    pub null_space: Check,
    pub constants_in_kernel: Option<Check>,
    pub mass_positive: Check,
    pub total_mass: f64,
}

fn check(holds: bool, value: f64, note: impl Into<String>) -> Check {
    Check { holds, value, note: note.into() }
}

/// Connected components of the operator's graph (non-zero off-diagonal entries).
fn components(op: &Operator) -> usize {
    op.pair.components().1
}

pub fn report(shape: &Shape, op: &Operator) -> PropertyReport {
    let p = &op.pair.pattern;
    let (l, m) = (&op.pair.stiffness, &op.pair.mass);
    let n = p.n;
    let maxabs = l.iter().fold(0.0f64, |a, b| a.max(b.abs())).max(f64::MIN_POSITIVE);
    // Symmetry.
    let mut asym = 0.0f64;
    for j in 0..n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            let i = p.row_idx[pos];
            let col_i = p.col(i);
            let other = col_i.binary_search(&j).map(|k| l[p.col_ptr[i] + k]).unwrap_or(0.0);
            asym = asym.max((l[pos] - other).abs());
        }
    }
    let symmetric = check(asym <= 1e-14 * maxabs, asym / maxabs, "max |L_ij − L_ji| / max |L_ij|");
    // Maximum principle: positive off-diagonal entries are negative weights.
    let mut negative = 0usize;
    for j in 0..n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            if p.row_idx[pos] < j && l[pos] > 1e-14 * maxabs {
                negative += 1;
            }
        }
    }
    let maximum_principle =
        check(negative == 0, negative as f64, "number of negative edge weights (positive off-diagonal entries of L)");
    // Local support against the input's own neighbourhoods.
    let index = |k: usize| op.interior.as_ref().map_or(k, |keep| keep[k] as usize);
    // The vertices an unknown stands for: itself, or a P2 edge unknown's two endpoints.
    let nv = shape.vertex_count();
    let members = |u: usize| -> [u32; 2] {
        match &op.edge_unknowns {
            Some(e) if u >= nv => e[u - nv],
            _ => [u as u32, u as u32],
        }
    };
    let local_support = match (op.kind, edge_graph(shape)) {
        (OperatorKind::PointCloud, _) | (_, None) => {
            check(true, 0.0, "entries join points within the kernel radius or local Delaunay neighbourhoods")
        }
        (_, Some((edges, _))) => {
            let mut set: rustc_hash::FxHashSet<(u32, u32)> = edges.iter().map(|e| (e[0], e[1])).collect();
            set.shrink_to_fit();
            let mut outside = 0usize;
            for j in 0..n {
                for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
                    let i = p.row_idx[pos];
                    if i < j && l[pos] != 0.0 {
                        let (ma, mb) = (members(index(i)), members(index(j)));
                        let joined =
                            ma.iter().all(|&a| mb.iter().all(|&b| a == b || set.contains(&(a.min(b), a.max(b)))));
                        if !joined {
                            outside += 1;
                        }
                    }
                }
            }
            check(
                outside == 0,
                outside as f64,
                "non-zero entries joining vertices that are not neighbours in the input",
            )
        }
    };
    // Linear precision where linear functions are harmonic.
    let linear_precision = flat_frame(shape).map(|axes| {
        let boundary = super::boundary::boundary_vertices(shape);
        let pos = shape.positions().unwrap_or(&[]);
        let diam = crate::geometry::topology::BoundingBox::of(pos).map_or(1.0, |b| b.diagonal()).max(f64::MIN_POSITIVE);
        let mut worst = 0.0f64;
        let mut y = vec![0.0; n];
        // A linear function at an unknown: at its vertex, or at its edge's midpoint (P2).
        let at = |k: usize, axis: [f64; 3]| {
            let [a, b] = members(index(k));
            0.5 * (vec3::dot(pos[a as usize], axis) + vec3::dot(pos[b as usize], axis))
        };
        for axis in axes {
            let u: Vec<f64> = (0..n).map(|k| at(k, axis)).collect();
            matvec(p, l, &u, &mut y);
            for (k, v) in y.iter().enumerate() {
                let [a, b] = members(index(k));
                if !(boundary[a as usize] && boundary[b as usize]) {
                    worst = worst.max(v.abs());
                }
            }
        }
        let rel = worst / (maxabs * diam);
        check(rel <= 1e-10, rel, "max |(L u)_i| at interior vertices for linear u, relative to max |L_ij| · diameter")
    });
    // Constants in the kernel (Neumann only: Dirichlet elimination removes them).
    let constants_in_kernel = (!op.dirichlet()).then(|| {
        let ones = vec![1.0; n];
        let mut y = vec![0.0; n];
        matvec(p, l, &ones, &mut y);
        let worst = y.iter().fold(0.0f64, |a, b| a.max(b.abs())) / maxabs;
        let normalized = op.kind == OperatorKind::GraphNormalized;
        check(
            worst <= 1e-12 || normalized,
            worst,
            if normalized {
                "the normalized Laplacian's kernel is D^{1/2}·1, not constants"
            } else {
                "max |L·1| / max |L_ij|"
            },
        )
    });
    // Mass.
    let mdiag = op.pair.mass_diagonal();
    let total_mass: f64 = m.iter().sum();
    let mass_positive = check(
        mdiag.iter().all(|&d| d > 0.0),
        mdiag.iter().cloned().fold(f64::INFINITY, f64::min),
        "smallest diagonal entry of M",
    );
    // PSD via Cholesky of L + εM.
    let scale = (0..n).map(|j| l[p.diag_pos(j)].abs() / mdiag[j].max(f64::MIN_POSITIVE)).sum::<f64>() / n.max(1) as f64;
    let eps = 1e-10 * scale.max(f64::MIN_POSITIVE);
    let symbolic = Symbolic::analyze(&op.pair.pattern).ok();
    let psd = symbolic
        .as_ref()
        .map(|s| factor::Cholesky::factor(s, &op.pair.shifted(-eps), faer::Par::Seq).is_ok())
        .unwrap_or(false);
    let positive_semidefinite = check(psd, eps, "ε for which L + εM has a Cholesky factorization");
    // Null space against components.
    let comps = components(op);
    // Sylvester's inertia of L − τM at a τ just above 0 counts the zero eigenvalues without an eigensolve (and
    // without the solver's exact zero modes, so the count is measured, not assumed).
    let null_space = if !psd {
        check(false, f64::NAN, "not computed: L is not positive semidefinite")
    } else {
        let zero = 1e-8 * scale;
        let expected = if op.dirichlet() { 0 } else { comps };
        match symbolic.as_ref().map(|s| factor::count_below(s, &op.pair, zero)) {
            Some(Ok(dim)) => check(
                dim == expected,
                dim as f64,
                format!(
                    "eigenvalues below {zero:e} (inertia of L − τM); connected components: {comps}{}",
                    if op.dirichlet() { " (Dirichlet: none expected)" } else { "" }
                ),
            ),
            Some(Err(e)) => check(false, f64::NAN, format!("the inertia count failed: {e}")),
            None => check(false, f64::NAN, "the symbolic analysis failed"),
        }
    };
    PropertyReport {
        symmetric,
        local_support,
        linear_precision,
        maximum_principle,
        positive_semidefinite,
        null_space,
        constants_in_kernel,
        mass_positive,
        total_mass,
    }
}

/// Orthonormal axes spanning the shape where it is flat (linear functions on them are harmonic): a planar
/// surface (2 axes), a straight polyline (1), any tet mesh (3).
fn flat_frame(shape: &Shape) -> Option<Vec<[f64; 3]>> {
    match shape {
        Shape::TetMesh(_) => Some(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        Shape::TriangleMesh(m) => {
            let n =
                m.faces.iter().map(|f| crate::geometry::topology::tri_area2(&m.vertices, f)).fold([0.0; 3], vec3::add);
            let len = vec3::norm(n);
            if len == 0.0 {
                return None;
            }
            let n = vec3::scale(n, 1.0 / len);
            let o = m.vertices[0];
            let diam = crate::geometry::topology::BoundingBox::of(&m.vertices)?.diagonal();
            let planar = m.vertices.iter().all(|p| vec3::dot(vec3::sub(*p, o), n).abs() <= 1e-12 * diam);
            planar.then(|| {
                let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
                let u = vec3::cross(n, helper);
                let u = vec3::scale(u, 1.0 / vec3::norm(u));
                vec![u, vec3::cross(n, u)]
            })
        }
        Shape::Polyline(p) => {
            let (a, b) = (
                p.vertices.first()?,
                p.vertices.iter().max_by(|x, y| {
                    vec3::norm(vec3::sub(**x, p.vertices[0])).total_cmp(&vec3::norm(vec3::sub(**y, p.vertices[0])))
                })?,
            );
            let d = vec3::sub(*b, *a);
            let len = vec3::norm(d);
            if len == 0.0 {
                return None;
            }
            let d = vec3::scale(d, 1.0 / len);
            let straight = p.vertices.iter().all(|q| vec3::norm(vec3::cross(vec3::sub(*q, *a), d)) <= 1e-12 * len);
            straight.then(|| vec![d])
        }
        _ => None,
    }
}

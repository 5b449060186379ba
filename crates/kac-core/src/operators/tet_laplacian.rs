//! P1 finite elements on a tetrahedral mesh. Shapes: #V × #V. Sign: L positive semidefinite,
//! `L_ij = Σ_T V_T ∇φ_i·∇φ_j` — equal to `−(1/6) Σ ℓ_kl cot θ_kl` over the tets sharing edge ij, with θ_kl the
//! dihedral angle at the opposite edge kl. Units: L has units of length, M of volume; eigenvalues 1/length².
//! Masses: `consistent` V/10 on the diagonal and V/20 off it per tet; `lumped` V/4 per corner.

use super::sparse::{assemble, Kernel, SparsePair};
use super::{Mass, OperatorError};
use crate::geometry::{vec3, Point};
use std::sync::Arc;

pub fn tet_pair(v: &[Point], tets: &[[u32; 4]], mass: Mass) -> Result<SparsePair, OperatorError> {
    let n = v.len();
    let consistent = mass == Mass::Consistent;
    let mut off: Vec<(u32, u32, [f64; 2])> = Vec::with_capacity(6 * tets.len());
    let (mut dl, mut dm) = (vec![0.0; n], vec![0.0; n]);
    for (ti, t) in tets.iter().enumerate() {
        let p = t.map(|i| v[i as usize]);
        let e = [vec3::sub(p[1], p[0]), vec3::sub(p[2], p[0]), vec3::sub(p[3], p[0])];
        let det = vec3::dot(e[0], vec3::cross(e[1], e[2]));
        let vol = det.abs() / 6.0;
        if !(vol > 0.0) || !vol.is_finite() {
            return Err(OperatorError::DegenerateElement {
                element: "tetrahedron",
                index: ti,
                message: "zero volume".into(),
            });
        }
        // Rows of J⁻¹ (J = [e1 e2 e3]) are the gradients of φ1..φ3; φ0's is minus their sum.
        let mut g = [[0.0; 3]; 4];
        g[1] = vec3::scale(vec3::cross(e[1], e[2]), 1.0 / det);
        g[2] = vec3::scale(vec3::cross(e[2], e[0]), 1.0 / det);
        g[3] = vec3::scale(vec3::cross(e[0], e[1]), 1.0 / det);
        g[0] = vec3::scale(vec3::add(vec3::add(g[1], g[2]), g[3]), -1.0);
        let (m_diag, m_off) = super::mass::tetrahedron(mass, vol);
        for a in 0..4 {
            dl[t[a] as usize] += vol * vec3::dot(g[a], g[a]);
            dm[t[a] as usize] += m_diag;
            for b in a + 1..4 {
                off.push((t[a], t[b], [vol * vec3::dot(g[a], g[b]), m_off]));
            }
        }
    }
    let (pattern, [stiffness, m]) = assemble(n, &off, [&dl, &dm]);
    Ok(SparsePair {
        pattern: Arc::new(pattern),
        stiffness,
        mass: m,
        mass_is_diagonal: !consistent,
        dimension: Some(3),
        kernel: Kernel::CONSTANTS,
    })
}

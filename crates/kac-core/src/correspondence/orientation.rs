//! The orientation term's operators (Ren et al. 2018) and the outward sign of a surface they need.

use super::options::CorrespondenceOptions;
use super::SpectralShape;
use crate::geometry::vec3::{add, cross, dot, sub};
use crate::geometry::TriangleMesh;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// The orientation operators of one side in its first k eigenfunctions: for a probe f, O_f g = ⟨n × ∇f, ∇g⟩ (a
/// rotated gradient of f acting as a derivative), projected as Φᵀ M O_f Φ with the lumped mass:
/// Σ_T (A_T / 3) (Σ_{v ∈ T} φ_i(v)) ⟨n_T × ∇f_T, ∇φ_j,T⟩. The operator is antisymmetric (n × ∇f is divergence-free),
/// and a map onto a mirror image turns its sign, so commuting with it keeps orientation (Ren et al. 2018). The
/// normals are turned outward ([`outward_sign`]) so that two inputs wound oppositely agree.
pub(super) struct Orienter<'a> {
    mesh: &'a TriangleMesh,
    /// Per face (row): (A_T / 3) Σ_{v ∈ T} φ_i(v), i < k.
    lumped: Mat<f64>,
    /// Per face: the gradients ∇λ_a of its three hat functions.
    grads: Vec<[[f64; 3]; 3]>,
    /// Per face: the outward unit normal (zero for a degenerate face).
    normals: Vec<[f64; 3]>,
    phi: MatRef<'a, f64>,
    k: usize,
}

/// The largest ratio of [`outward_sign`]'s bound to the signed volume for which a surface counts as enclosing a volume.
/// Measured: 10⁻¹⁵ for closed meshes, 0.010 to 0.014 for TOSCA's cat and dog (small holes at the paws), infinite
/// for a flat sheet, about 1.5 for a hemisphere.
const ENCLOSURE_RATIO: f64 = 0.1;

/// The sign that turns the surface's normals outward (±1), when it encloses a volume: the signed volume
/// V(p) = Σ_T (a − p)·((b − p) × (c − p)) / 6 about a point p does not depend on p for a closed surface, and for an
/// open one changes as −p·N/3, N the surface's vector area (the area its holes would need to close them). The
/// surface counts as enclosing when that change across its bounding box, |N|·diagonal/3, is within
/// [`ENCLOSURE_RATIO`] of |V| about the centroid: closed meshes, and scans with small holes. An open sheet or a
/// partial scan, which may be wound either way, has no outward side (None), and the orientation term is left out:
/// it would otherwise favour the mirror map.
pub(super) fn outward_sign(mesh: &TriangleMesh) -> Option<f64> {
    let p = &mesh.vertices;
    if p.is_empty() {
        return None;
    }
    // About the centroid: about the origin, coordinates far from it would drown the volume in rounding.
    let centre = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).sum::<f64>() / p.len() as f64);
    let at = |v: u32| sub(p[v as usize], centre);
    let (mut volume6, mut area2) = (0.0, [0.0; 3]);
    for f in &mesh.faces {
        let (a, b, c) = (at(f[0]), at(f[1]), at(f[2]));
        volume6 += dot(a, cross(b, c));
        let n = cross(sub(b, a), sub(c, a));
        area2 = add(area2, n);
    }
    let lo = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).fold(f64::INFINITY, f64::min));
    let hi = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).fold(f64::NEG_INFINITY, f64::max));
    let diagonal = dot(sub(hi, lo), sub(hi, lo)).sqrt();
    // |N| D / 3 against |V|, both times 6 (N = area2 / 2).
    let drift6 = dot(area2, area2).sqrt() * diagonal;
    (volume6 != 0.0 && drift6 <= ENCLOSURE_RATIO * volume6.abs()).then_some(volume6.signum())
}

/// The two surfaces the orientation term is built on, each with its outward sign, when it applies: a weight, and
/// triangle meshes enclosing a volume on both sides.
#[allow(clippy::type_complexity)]
pub(super) fn oriented<'a>(
    s: &SpectralShape<'a>,
    t: &SpectralShape<'a>,
    o: &CorrespondenceOptions,
) -> Option<((&'a TriangleMesh, f64), (&'a TriangleMesh, f64))> {
    match (s.surface, t.surface) {
        (Some(a), Some(b)) if o.orientation_weight != 0.0 => Some(((a, outward_sign(a)?), (b, outward_sign(b)?))),
        _ => None,
    }
}

impl<'a> Orienter<'a> {
    pub(super) fn new(mesh: &'a TriangleMesh, sign: f64, side: &SpectralShape<'a>, k: usize) -> Self {
        let p = &mesh.vertices;
        let phi = side.basis.vectors.subcols(0, k);
        let (mut lumped, mut grads, mut normals) = (Mat::<f64>::zeros(mesh.faces.len(), k), vec![], vec![]);
        for (t, f) in mesh.faces.iter().enumerate() {
            let [a, b, c] = [p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]];
            let n2 = cross(sub(b, a), sub(c, a));
            let twice = dot(n2, n2).sqrt();
            if twice == 0.0 {
                grads.push([[0.0; 3]; 3]);
                normals.push([0.0; 3]);
                continue;
            }
            let n = [n2[0] / twice, n2[1] / twice, n2[2] / twice];
            // ∇λ_a = n × e_a / (2A), e_a the edge opposite a, run counter-clockwise about n.
            let opposite = [sub(c, b), sub(a, c), sub(b, a)];
            let g = opposite.map(|e| cross(n, e).map(|x| x / twice));
            grads.push(g);
            normals.push(n.map(|x| sign * x));
            let w = twice / 6.0;
            for i in 0..k {
                lumped[(t, i)] = w * (0..3).map(|q| phi[(f[q] as usize, i)]).sum::<f64>();
            }
        }
        Orienter { mesh, lumped, grads, normals, phi, k }
    }

    /// Φᵀ M O_f Φ (k × k) for the probe f (one column). With w_T,q = ⟨n_T × ∇f_T, ∇λ_q⟩ the derivative of the hat
    /// function of the face's corner q, the operator is Σ_T Σ_q lumped_Tᵀ w_T,q φ(v_T,q) = Hᵀ Φ, where row v of
    /// H gathers w_T,q lumped_T over the faces at v (one product of n × k, not of faces × k).
    pub(super) fn op(&self, f: MatRef<'_, f64>) -> Mat<f64> {
        let k = self.k;
        let n = self.phi.nrows();
        // Row-major n × k, gathered face by face.
        let mut h = vec![0.0f64; n * k];
        for (t, face) in self.mesh.faces.iter().enumerate() {
            let grad = &self.grads[t];
            let mut gf = [0.0; 3];
            for q in 0..3 {
                let v = f[(face[q] as usize, 0)];
                for c in 0..3 {
                    gf[c] += v * grad[q][c];
                }
            }
            let rotated = cross(self.normals[t], gf);
            let lumped = self.lumped.row(t);
            for q in 0..3 {
                let w = dot(rotated, grad[q]);
                let row = &mut h[face[q] as usize * k..(face[q] as usize + 1) * k];
                for (i, x) in row.iter_mut().enumerate() {
                    *x += w * lumped[i];
                }
            }
        }
        let h = MatRef::from_row_major_slice(&h, n, k);
        let mut out = Mat::<f64>::zeros(k, k);
        matmul(out.as_mut(), Accum::Replace, h.transpose(), self.phi, 1.0, Par::Seq);
        out
    }
}

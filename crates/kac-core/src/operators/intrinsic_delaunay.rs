//! Intrinsic triangulations and the intrinsic Delaunay cotangent Laplacian (Bobenko & Springborn 2007; Fisher,
//! Springborn, Schröder & Bobenko 2007). The triangulation is kept as edge lengths only; an interior edge whose
//! opposite angles sum to more than π (cot α + cot β < 0) is flipped, the new diagonal's length found by laying
//! the two triangles out in the plane, until every interior edge is Delaunay. The surface's geometry does not
//! change, so L and M discretize the same smooth operator, and on a closed surface every cotangent weight is
//! non-negative (the discrete maximum principle holds). Boundary edges cannot flip; their single weight
//! ½ cot α is negative where the angle opposite them is obtuse.
//!
//! Sign and units as in [`super::cotan_laplacian`]. The pattern of L follows the intrinsic edges, which need not
//! be edges of the input mesh (a flipped edge joins vertices that were not neighbours).

use super::cotan_laplacian::{area_from_lengths, corner_cotangents, cotan_pair, face_lengths};
use super::sparse::SparsePair;
use super::{Mass, OperatorError};
use crate::geometry::TriangleMesh;
use rustc_hash::FxHashMap;

pub const NONE: u32 = u32::MAX;

/// A triangulation by edge lengths: half-edge `3f + k` runs from `faces[f][k]` to `faces[f][(k + 1) % 3]`.
#[derive(Debug, Clone)]
pub struct IntrinsicTriangulation {
    pub faces: Vec<[u32; 3]>,
    pub twin: Vec<u32>,
    pub length: Vec<f64>,
}

impl IntrinsicTriangulation {
    /// From faces and per-half-edge lengths; twins are matched by opposite direction. Fails on an edge used
    /// twice in the same direction (non-manifold or inconsistently oriented).
    pub fn new(faces: Vec<[u32; 3]>, length: Vec<f64>) -> Result<Self, String> {
        let mut by_dir: FxHashMap<(u32, u32), u32> =
            FxHashMap::with_capacity_and_hasher(3 * faces.len(), Default::default());
        for (f, t) in faces.iter().enumerate() {
            for k in 0..3 {
                if by_dir.insert((t[k], t[(k + 1) % 3]), (3 * f + k) as u32).is_some() {
                    return Err(format!("edge ({}, {}) is used twice in the same direction (non-manifold edge or inconsistent orientation)", t[k], t[(k + 1) % 3]));
                }
            }
        }
        let mut twin = vec![NONE; 3 * faces.len()];
        for (f, t) in faces.iter().enumerate() {
            for k in 0..3 {
                if let Some(&h) = by_dir.get(&(t[(k + 1) % 3], t[k])) {
                    twin[3 * f + k] = h;
                }
            }
        }
        Ok(IntrinsicTriangulation { faces, twin, length })
    }

    pub fn from_mesh(m: &TriangleMesh) -> Result<Self, String> {
        let length = m
            .faces
            .iter()
            .flat_map(|f| {
                let l = face_lengths(&m.vertices, f);
                // Half-edge k is opposite corner k + 2.
                [l[2], l[0], l[1]]
            })
            .collect();
        Self::new(m.faces.clone(), length)
    }

    /// Edge lengths of face f, opposite its corners.
    pub fn face_lengths(&self, f: usize) -> [f64; 3] {
        [self.length[3 * f + 1], self.length[3 * f + 2], self.length[3 * f]]
    }

    /// Cotangent of the angle opposite half-edge h.
    fn cot_opposite(&self, h: usize) -> f64 {
        let f = h / 3;
        let (cot, _) = corner_cotangents(self.face_lengths(f));
        cot[(h % 3 + 2) % 3]
    }

    /// Whether the edge of h is Delaunay (a boundary edge always is).
    pub fn is_delaunay(&self, h: usize) -> bool {
        let t = self.twin[h];
        t == NONE || self.cot_opposite(h) + self.cot_opposite(t as usize) >= -1e-12
    }

    /// Flips the edge of h; false (nothing changed) when the new triangles would be degenerate.
    fn flip(&mut self, h: usize) -> bool {
        let t = self.twin[h] as usize;
        let (f1, f2, k1, k2) = (h / 3, t / 3, h % 3, t % 3);
        let [a, b, c] = [self.faces[f1][k1], self.faces[f1][(k1 + 1) % 3], self.faces[f1][(k1 + 2) % 3]];
        let d = self.faces[f2][(k2 + 2) % 3];
        let (h_bc, h_ca) = (3 * f1 + (k1 + 1) % 3, 3 * f1 + (k1 + 2) % 3);
        let (h_ad, h_db) = (3 * f2 + (k2 + 1) % 3, 3 * f2 + (k2 + 2) % 3);
        let (l_ab, l_bc, l_ca, l_ad, l_db) =
            (self.length[h], self.length[h_bc], self.length[h_ca], self.length[h_ad], self.length[h_db]);
        let (t_bc, t_ca, t_ad, t_db) = (self.twin[h_bc], self.twin[h_ca], self.twin[h_ad], self.twin[h_db]);
        // Layout: a = (0, 0), b = (l_ab, 0), c above the axis, d below.
        let cx = (l_ab * l_ab + l_ca * l_ca - l_bc * l_bc) / (2.0 * l_ab);
        let cy = (l_ca * l_ca - cx * cx).max(0.0).sqrt();
        let dx = (l_ab * l_ab + l_ad * l_ad - l_db * l_db) / (2.0 * l_ab);
        let dy = -(l_ad * l_ad - dx * dx).max(0.0).sqrt();
        let l_cd = ((cx - dx).powi(2) + (cy - dy).powi(2)).sqrt();
        if !(area_from_lengths([l_cd, l_ad, l_ca]) > 0.0 && area_from_lengths([l_cd, l_bc, l_db]) > 0.0) {
            return false; // rounding left no room for the new triangles: keep the edge
        }
        // Old outer half-edges → new slots; twins that point into the two faces are remapped too (the faces
        // may share more than one edge in a tufted cover).
        let moves = [(h_ca, 3 * f1), (h_ad, 3 * f1 + 1), (h_db, 3 * f2), (h_bc, 3 * f2 + 1)];
        let remap = |x: u32| moves.iter().find(|m| m.0 as u32 == x).map_or(x, |m| m.1 as u32);
        let new_twins = [t_ca, t_ad, t_db, t_bc].map(|t| if t == NONE { NONE } else { remap(t) });
        self.faces[f1] = [c, a, d];
        self.faces[f2] = [d, b, c];
        for (k, (&(_, slot), len)) in moves.iter().zip([l_ca, l_ad, l_db, l_bc]).enumerate() {
            self.length[slot] = len;
            self.twin[slot] = new_twins[k];
            if new_twins[k] != NONE {
                self.twin[new_twins[k] as usize] = slot as u32;
            }
        }
        self.twin[3 * f1 + 2] = (3 * f2 + 2) as u32;
        self.twin[3 * f2 + 2] = (3 * f1 + 2) as u32;
        self.length[3 * f1 + 2] = l_cd;
        self.length[3 * f2 + 2] = l_cd;
        true
    }

    /// Flips until every interior edge is Delaunay; returns the number of flips.
    pub fn flip_to_delaunay(&mut self) -> usize {
        let mut stack: Vec<usize> =
            (0..self.twin.len()).filter(|&h| self.twin[h] != NONE && (h as u32) < self.twin[h]).collect();
        let mut flips = 0;
        let limit = 100 * self.twin.len() + 1000;
        while let Some(h) = stack.pop() {
            if self.twin[h] == NONE || self.is_delaunay(h) {
                continue;
            }
            let (f1, f2) = (h / 3, self.twin[h] as usize / 3);
            if !self.flip(h) {
                continue;
            }
            flips += 1;
            if flips > limit {
                break; // cannot happen in exact arithmetic (Bobenko–Springborn); guards against rounding cycles
            }
            stack.extend([3 * f1, 3 * f1 + 1, 3 * f2, 3 * f2 + 1]);
        }
        flips
    }

    /// The cotangent pair on this triangulation.
    pub fn pair(&self, n: usize, mass: Mass) -> Result<SparsePair, OperatorError> {
        cotan_pair(n, &self.faces, |f| self.face_lengths(f), mass)
    }
}

/// The intrinsic Delaunay Laplacian of a manifold mesh and the number of flips made.
pub fn intrinsic_delaunay_pair(m: &TriangleMesh, mass: Mass) -> Result<(SparsePair, usize), OperatorError> {
    let mut t = IntrinsicTriangulation::from_mesh(m)
        .map_err(|message| OperatorError::NonManifold { operator: "intrinsic-delaunay", message })?;
    let flips = t.flip_to_delaunay();
    Ok((t.pair(m.vertices.len(), mass)?, flips))
}

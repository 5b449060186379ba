//! Mass matrices: the kinds a pair can be built with, and each element's mass on its vertices (the consistent
//! FEM mass ∫ φ_a φ_b of linear elements, or the lumped row sums; Voronoi areas on triangles), used by every
//! assembly (segments, triangles, tetrahedra).

use serde::{Deserialize, Serialize};

/// Mass matrices. `Identity` and `Degree` are what the graph Laplacians use (reported, not chosen).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mass {
    Consistent,
    Lumped,
    Voronoi,
    Identity,
    Degree,
}

impl Mass {
    pub fn name(self) -> &'static str {
        match self {
            Mass::Consistent => "consistent",
            Mass::Lumped => "lumped",
            Mass::Voronoi => "voronoi",
            Mass::Identity => "identity",
            Mass::Degree => "degree",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        [Mass::Consistent, Mass::Lumped, Mass::Voronoi, Mass::Identity, Mass::Degree]
            .into_iter()
            .find(|m| m.name() == s)
    }
}

/// A segment of length h: (diagonal entry at each end, entry between them).
pub(crate) fn segment(mass: Mass, h: f64) -> (f64, f64) {
    if mass == Mass::Consistent {
        (h / 3.0, h / 6.0)
    } else {
        (h / 2.0, 0.0)
    }
}

/// A triangle's off-diagonal entry between two of its corners: area/12 for the consistent mass, else 0.
pub(crate) fn triangle_off(mass: Mass, area: f64) -> f64 {
    if mass == Mass::Consistent {
        area / 12.0
    } else {
        0.0
    }
}

/// A triangle's diagonal entry at each corner: area/6 consistent, area/3 lumped, or the Voronoi areas of its
/// corners (a quarter and a half of the area at an obtuse triangle's corners, Meyer et al. 2003); `l` the edge
/// lengths (l[k] opposite corner k), `cot` the corner cotangents.
pub(crate) fn triangle_corners(mass: Mass, l: [f64; 3], cot: [f64; 3], area: f64) -> [f64; 3] {
    match mass {
        Mass::Consistent => [area / 6.0; 3],
        Mass::Voronoi => {
            let obtuse = (0..3).find(|&k| cot[k] < 0.0);
            match obtuse {
                Some(o) => [0, 1, 2].map(|k| if k == o { area / 2.0 } else { area / 4.0 }),
                None => [0, 1, 2].map(|k| {
                    let (a, b) = ((k + 1) % 3, (k + 2) % 3);
                    (l[a] * l[a] * cot[a] + l[b] * l[b] * cot[b]) / 8.0
                }),
            }
        }
        Mass::Lumped | Mass::Identity | Mass::Degree => [area / 3.0; 3],
    }
}

/// A tetrahedron of volume `vol`: (diagonal entry at each vertex, entry between two of them).
pub(crate) fn tetrahedron(mass: Mass, vol: f64) -> (f64, f64) {
    if mass == Mass::Consistent {
        (vol / 10.0, vol / 20.0)
    } else {
        (vol / 4.0, 0.0)
    }
}

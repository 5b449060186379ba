//! A pair of shapes whose correspondence is known, shared by the correspondence tests of the CLI, the service and
//! the viewer: a lumpy sphere (no symmetry) and a copy of it rotated, moved and with its vertices shuffled.

use kac_core::geometry::{generate, TriangleMesh};

pub struct ShuffledPair {
    pub a: TriangleMesh,
    /// The copy: its vertex y is `a`'s vertex `perm[y]`, rotated a quarter turn about z and moved.
    pub b: TriangleMesh,
    pub perm: Vec<u32>,
    /// `a`'s vertex x is the copy's vertex `inverse[x]`.
    pub inverse: Vec<u32>,
}

/// The lumpy icosphere of level 3 (642 vertices) and its shuffled, rotated and moved copy (a shuffled copy alone
/// would be the same shape: the id is the canonical geometry's hash).
pub fn lumpy_sphere_and_shuffled_copy() -> ShuffledPair {
    let mut a = generate::icosphere(3);
    for p in &mut a.vertices {
        let [x, y, z] = *p;
        let r = 1.0 + 0.3 * x + 0.2 * y * y - 0.25 * z * z * z + 0.15 * x * y;
        *p = [x * r, 1.3 * y * r, 0.8 * z * r];
    }
    let n = a.vertices.len();
    let perm: Vec<u32> = (0..n as u32).map(|y| (y * 389 + 17) % n as u32).collect();
    let mut inverse = vec![0u32; n];
    for (y, &x) in perm.iter().enumerate() {
        inverse[x as usize] = y as u32;
    }
    let mut b = a.clone();
    b.vertices = perm.iter().map(|&x| a.vertices[x as usize]).map(|[x, y, z]| [-y + 2.0, x, z - 1.0]).collect();
    b.faces = a.faces.iter().map(|f| f.map(|v| inverse[v as usize])).collect();
    ShuffledPair { a, b, perm, inverse }
}

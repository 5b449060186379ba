//! The shape id: SHA-256 of a canonical byte layout of the validated geometry, independent of the input format,
//! the platform, the order of vertices and elements, and the rotation of each face.
//!
//! Canonical layout, version 1 (all integers little-endian):
//! ```text
//! "kac-shape/1\n"                      12 bytes
//! kind                                  u8: 1 triangle_mesh, 2 tet_mesh, 3 point_cloud, 4 graph, 5 polyline
//! n                                     u64: vertex count
//! n × (x, y, z)                         f32 each (coordinates rounded to binary32, −0 written as +0),
//!                                       vertices sorted by (x, y, z) of these f32 values
//! m, arity                              u64, u64: element count and vertices per element
//! m × arity × u32                       elements in sorted vertex numbering:
//!                                         faces rotated to start at their smallest index (orientation kept),
//!                                         tets, segments and edges with indices ascending; then sorted
//! graphs: m × f64                       edge weights, in the order of the sorted edges
//! ```
//! Coordinates enter the id as binary32 so that a mesh that went through a 32-bit format (STL, glTF, binary PLY
//! of floats) keeps the id of its 64-bit original: two uploads that agree to single precision are one shape.
//! Graphs without positions hash their vertices in input order (graph isomorphism is not attempted).

use super::{Point, Shape};
use serde::{Serialize, Serializer};
use sha2::{Digest, Sha256};
use std::cmp::Ordering;
use std::fmt;

/// A shape id: 32 bytes of SHA-256, shown as 64 lowercase hex digits.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ShapeId(pub [u8; 32]);

impl ShapeId {
    pub fn hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }
    /// The id its 64 lowercase hex digits name (the form [`ShapeId::hex`] writes; nothing else parses).
    pub fn parse(s: &str) -> Option<ShapeId> {
        if s.len() != 64 || !s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')) {
            return None;
        }
        let mut out = [0u8; 32];
        for (i, o) in out.iter_mut().enumerate() {
            *o = u8::from_str_radix(&s[2 * i..2 * i + 2], 16).ok()?;
        }
        Some(ShapeId(out))
    }
}

impl fmt::Debug for ShapeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ShapeId({})", self.hex())
    }
}

impl fmt::Display for ShapeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.hex())
    }
}

impl Serialize for ShapeId {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.hex())
    }
}

fn q(c: f64) -> f32 {
    let f = c as f32;
    if f == 0.0 {
        0.0
    } else {
        f
    }
}

/// The vertex order of the canonical layout: new index of each vertex.
fn canonical_order(points: &[[f64; 3]]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    let key = |i: u32| points[i as usize].map(q);
    order.sort_by(|&a, &b| {
        let (ka, kb) = (key(a), key(b));
        ka[0]
            .total_cmp(&kb[0])
            .then(ka[1].total_cmp(&kb[1]))
            .then(ka[2].total_cmp(&kb[2]))
            .then_with(|| {
                let (pa, pb) = (points[a as usize], points[b as usize]);
                pa[0].total_cmp(&pb[0]).then(pa[1].total_cmp(&pb[1])).then(pa[2].total_cmp(&pb[2]))
            })
            .then(a.cmp(&b))
    });
    let mut rank = vec![0u32; points.len()];
    for (r, &i) in order.iter().enumerate() {
        rank[i as usize] = r as u32;
    }
    rank
}

/// The id of a point cloud in Rⁿ: its dimension and its rows (quantized to f32, as positions are) in
/// lexicographic order, so that neither the order of the points nor a coincidence of their first three
/// coordinates changes it.
fn ambient_id(a: &super::Ambient) -> ShapeId {
    let mut rows: Vec<Vec<f32>> = (0..a.len()).map(|i| a.row(i).iter().map(|&c| q(c)).collect()).collect();
    rows.sort_unstable_by(|x, y| {
        x.iter().zip(y).map(|(a, b)| a.total_cmp(b)).find(|o| o.is_ne()).unwrap_or(Ordering::Equal)
    });
    let mut h = Sha256::new();
    h.update(b"kac-shape/1\nambient\n");
    h.update((a.dim as u64).to_le_bytes());
    h.update((rows.len() as u64).to_le_bytes());
    let mut buf = Vec::with_capacity(4 * a.coords.len());
    for r in &rows {
        for c in r {
            buf.extend_from_slice(&c.to_le_bytes());
        }
    }
    h.update(&buf);
    ShapeId(h.finalize().into())
}

/// The id of a validated shape with what its operators read beyond its elements: the polygons it was read from
/// (the polygon operator uses them), a cloud's normals (they orient its denoising) and curved edges' middle nodes
/// (quadratic elements use them). Without any it is [`shape_id`]; with them, that id and the extras in a canonical
/// form (each polygon as its corners' quantized positions from the smallest one, polygons sorted; each normal with
/// its point's position, sorted; each edge node with its edge's two corner positions, sorted), so neither the
/// numbering nor the order changes it.
pub fn shape_id_with(
    shape: &Shape,
    polygons: Option<&super::Polygons>,
    edge_nodes: Option<&super::EdgeNodes>,
) -> ShapeId {
    let base = shape_id(shape);
    let normals = match shape {
        Shape::PointCloud(c) => c.normals.as_ref().map(|ns| (&c.points, ns)),
        _ => None,
    };
    if polygons.is_none() && normals.is_none() && edge_nodes.is_none() {
        return base;
    }
    let mut h = Sha256::new();
    h.update(b"kac-shape/1\nextras\n");
    h.update(base.0);
    let key = |p: Point| p.map(q);
    let cmp =
        |a: &[f32; 3], b: &[f32; 3]| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])).then(a[2].total_cmp(&b[2]));
    if let (Some(polys), Some(points)) = (polygons, shape.positions()) {
        let mut all: Vec<Vec<[f32; 3]>> = polys
            .iter()
            .map(|poly| {
                let mut corners: Vec<[f32; 3]> = poly.iter().map(|&v| key(points[v as usize])).collect();
                let first = (0..corners.len()).min_by(|&a, &b| cmp(&corners[a], &corners[b])).unwrap_or(0);
                corners.rotate_left(first);
                corners
            })
            .collect();
        all.sort_by(|a, b| {
            a.iter().zip(b).map(|(x, y)| cmp(x, y)).find(|o| o.is_ne()).unwrap_or(a.len().cmp(&b.len()))
        });
        h.update(b"polygons");
        h.update((all.len() as u64).to_le_bytes());
        for poly in &all {
            h.update((poly.len() as u64).to_le_bytes());
            for c in poly {
                for x in c {
                    h.update(x.to_le_bytes());
                }
            }
        }
    }
    if let Some((points, ns)) = normals {
        let mut pairs: Vec<([f32; 3], [f32; 3])> = points.iter().zip(ns).map(|(&p, &n)| (key(p), key(n))).collect();
        pairs.sort_by(|a, b| cmp(&a.0, &b.0).then(cmp(&a.1, &b.1)));
        h.update(b"normals");
        for (p, n) in &pairs {
            for x in p.iter().chain(n) {
                h.update(x.to_le_bytes());
            }
        }
    }
    if let (Some(nodes), Some(points)) = (edge_nodes, shape.positions()) {
        let mut all: Vec<[[f32; 3]; 3]> = nodes
            .iter()
            .map(|&([a, b], p)| {
                let (x, y) = (key(points[a as usize]), key(points[b as usize]));
                if cmp(&x, &y).is_le() {
                    [x, y, key(p)]
                } else {
                    [y, x, key(p)]
                }
            })
            .collect();
        all.sort_by(|a, b| cmp(&a[0], &b[0]).then(cmp(&a[1], &b[1])).then(cmp(&a[2], &b[2])));
        h.update(b"edge-nodes");
        h.update((all.len() as u64).to_le_bytes());
        for x in all.iter().flatten().flatten() {
            h.update(x.to_le_bytes());
        }
    }
    ShapeId(h.finalize().into())
}

/// Computes the id of a validated shape.
pub fn shape_id(shape: &Shape) -> ShapeId {
    if let Shape::PointCloud(super::PointCloud { ambient: Some(a), .. }) = shape {
        return ambient_id(a);
    }
    let mut h = Sha256::new();
    h.update(b"kac-shape/1\n");
    let kind: u8 = match shape {
        Shape::TriangleMesh(_) => 1,
        Shape::TetMesh(_) => 2,
        Shape::PointCloud(_) => 3,
        Shape::Graph(_) => 4,
        Shape::Polyline(_) => 5,
    };
    h.update([kind]);
    let n = shape.vertex_count();
    h.update((n as u64).to_le_bytes());
    let rank: Vec<u32> = match shape.positions() {
        Some(p) => {
            let rank = canonical_order(p);
            let mut sorted = vec![[0f32; 3]; p.len()];
            for (i, &r) in rank.iter().enumerate() {
                sorted[r as usize] = p[i].map(q);
            }
            let mut buf = Vec::with_capacity(12 * p.len());
            for s in &sorted {
                for c in s {
                    buf.extend_from_slice(&c.to_le_bytes());
                }
            }
            h.update(&buf);
            rank
        }
        None => (0..n as u32).collect(),
    };
    let r = |v: u32| rank[v as usize];
    let mut write_elements = |mut elems: Vec<Vec<u32>>, arity: usize| {
        elems.sort_unstable();
        h.update((elems.len() as u64).to_le_bytes());
        h.update((arity as u64).to_le_bytes());
        let mut buf = Vec::with_capacity(4 * arity * elems.len());
        for e in &elems {
            for v in e {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        h.update(&buf);
    };
    match shape {
        Shape::TriangleMesh(m) => {
            let faces = m
                .faces
                .iter()
                .map(|f| {
                    let g = f.map(r);
                    let k = (0..3).min_by_key(|&k| g[k]).unwrap_or(0);
                    vec![g[k], g[(k + 1) % 3], g[(k + 2) % 3]]
                })
                .collect();
            write_elements(faces, 3);
        }
        Shape::TetMesh(m) => {
            let tets = m.tets.iter().map(|t| sorted(t.iter().map(|&v| r(v)).collect())).collect();
            write_elements(tets, 4);
        }
        Shape::Polyline(p) => {
            let segs = p.segments.iter().map(|s| sorted(s.iter().map(|&v| r(v)).collect())).collect();
            write_elements(segs, 2);
        }
        Shape::PointCloud(_) => write_elements(Vec::new(), 0),
        Shape::Graph(g) => {
            let mut edges: Vec<(Vec<u32>, f64)> =
                g.edges.iter().zip(&g.weights).map(|(e, &w)| (sorted(e.iter().map(|&v| r(v)).collect()), w)).collect();
            edges.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.partial_cmp(&b.1).unwrap_or(Ordering::Equal)));
            let weights: Vec<f64> = edges.iter().map(|e| e.1).collect();
            write_elements(edges.into_iter().map(|e| e.0).collect(), 2);
            let mut buf = Vec::with_capacity(8 * weights.len());
            for w in weights {
                buf.extend_from_slice(&w.to_le_bytes());
            }
            h.update(&buf);
        }
    }
    ShapeId(h.finalize().into())
}

fn sorted(mut v: Vec<u32>) -> Vec<u32> {
    v.sort_unstable();
    v
}

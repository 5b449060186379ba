//! Combinatorial facts of shapes: edges and their incident faces, boundary loops, non-manifold edges and
//! vertices, orientation consistency, connected components, Euler characteristic and genus.

use super::vec3;
use super::{Point, TriangleMesh};
use serde::Serialize;

/// Disjoint sets with path halving and union by size.
#[derive(Debug, Clone)]
pub struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    pub fn new(n: usize) -> Self {
        UnionFind { parent: (0..n as u32).collect(), size: vec![1; n] }
    }
    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let p = self.parent[x as usize];
            self.parent[x as usize] = self.parent[p as usize];
            x = self.parent[x as usize];
        }
        x
    }
    pub fn union(&mut self, a: u32, b: u32) -> bool {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return false;
        }
        if self.size[a as usize] < self.size[b as usize] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b as usize] = a;
        self.size[a as usize] += self.size[b as usize];
        true
    }
    /// Labels 0..k of the sets, in order of first appearance, and k.
    pub fn labels(&mut self) -> (Vec<u32>, usize) {
        let n = self.parent.len();
        let mut label = vec![u32::MAX; n];
        let mut out = vec![0u32; n];
        let mut k = 0u32;
        for i in 0..n as u32 {
            let r = self.find(i) as usize;
            if label[r] == u32::MAX {
                label[r] = k;
                k += 1;
            }
            out[i as usize] = label[r];
        }
        (out, k as usize)
    }
}

/// Undirected edges of a triangle mesh with their incident half-edges.
///
/// Half-edge `3f + k` runs from `faces[f][k]` to `faces[f][(k + 1) % 3]` and is opposite corner `(k + 2) % 3`.
#[derive(Debug, Clone)]
pub struct EdgeTopology {
    /// Edge endpoints, smaller index first, sorted.
    pub edges: Vec<[u32; 2]>,
    /// Edge of each half-edge.
    pub halfedge_edge: Vec<u32>,
    /// Half-edges of edge `e`: `edge_halfedges[edge_offsets[e]..edge_offsets[e + 1]]`.
    pub edge_offsets: Vec<u32>,
    pub edge_halfedges: Vec<u32>,
}

impl EdgeTopology {
    pub fn new(faces: &[[u32; 3]]) -> Self {
        let nh = 3 * faces.len();
        let key = |h: usize| {
            let f = faces[h / 3];
            let (a, b) = (f[h % 3], f[(h % 3 + 1) % 3]);
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            ((lo as u64) << 32) | hi as u64
        };
        let mut order: Vec<(u64, u32)> = (0..nh).map(|h| (key(h), h as u32)).collect();
        order.sort_unstable();
        let mut edges = Vec::with_capacity(nh / 2 + 1);
        let mut halfedge_edge = vec![0u32; nh];
        let mut edge_offsets = Vec::with_capacity(nh / 2 + 2);
        let mut edge_halfedges = Vec::with_capacity(nh);
        let mut prev = u64::MAX;
        for &(k, h) in &order {
            if k != prev {
                edge_offsets.push(edge_halfedges.len() as u32);
                edges.push([(k >> 32) as u32, k as u32]);
                prev = k;
            }
            halfedge_edge[h as usize] = (edges.len() - 1) as u32;
            edge_halfedges.push(h);
        }
        edge_offsets.push(edge_halfedges.len() as u32);
        EdgeTopology { edges, halfedge_edge, edge_offsets, edge_halfedges }
    }
    pub fn halfedges(&self, e: usize) -> &[u32] {
        &self.edge_halfedges[self.edge_offsets[e] as usize..self.edge_offsets[e + 1] as usize]
    }
    /// Number of faces on edge `e` (1: boundary, 2: interior manifold, more: non-manifold).
    pub fn valence(&self, e: usize) -> usize {
        (self.edge_offsets[e + 1] - self.edge_offsets[e]) as usize
    }
}

/// Bounding box.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BoundingBox {
    #[cfg_attr(feature = "openapi", schema(value_type = [f64; 3]))]
    pub min: Point,
    #[cfg_attr(feature = "openapi", schema(value_type = [f64; 3]))]
    pub max: Point,
}

impl BoundingBox {
    pub fn of(points: &[Point]) -> Option<Self> {
        let first = *points.first()?;
        let mut b = BoundingBox { min: first, max: first };
        for p in points {
            for (k, &c) in p.iter().enumerate() {
                b.min[k] = b.min[k].min(c);
                b.max[k] = b.max[k].max(c);
            }
        }
        Some(b)
    }
    pub fn diagonal(&self) -> f64 {
        vec3::norm(vec3::sub(self.max, self.min))
    }
}

/// Orientation of a surface's faces.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Orientation {
    /// Every interior manifold edge is traversed once in each direction.
    Consistent,
    /// Some adjacent faces disagree (or the surface is not orientable).
    Inconsistent,
}

/// Facts of a triangle surface.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SurfaceFacts {
    pub vertices: usize,
    pub faces: usize,
    pub edges: usize,
    pub components: usize,
    pub boundary_edges: usize,
    pub boundary_loops: usize,
    pub non_manifold_edges: usize,
    pub non_manifold_vertices: usize,
    pub misoriented_edges: usize,
    pub orientation: Orientation,
    pub closed: bool,
    pub manifold: bool,
    pub euler_characteristic: i64,
    /// Total genus Σ gᵢ over components, from χ = Σ (2 − 2gᵢ − bᵢ); only for orientable manifolds.
    pub genus: Option<i64>,
    pub area: f64,
    /// Enclosed volume, for closed, consistently oriented manifolds.
    pub enclosed_volume: Option<f64>,
}

/// Computes [`SurfaceFacts`]; `topo` is the mesh's edge topology.
pub fn surface_facts(mesh: &TriangleMesh, topo: &EdgeTopology) -> SurfaceFacts {
    let nv = mesh.vertices.len();
    let faces = &mesh.faces;
    let mut boundary_edges = 0;
    let mut non_manifold_edges = 0;
    let mut misoriented = 0;
    let mut boundary_uf = UnionFind::new(nv);
    let mut is_boundary_vertex = vec![false; nv];
    // Corners 3f + k; corners around one vertex joined across shared edges form its fans.
    let mut corner_uf = UnionFind::new(3 * faces.len());
    let corner_at = |h: u32, v: u32| -> u32 {
        let f = (h / 3) as usize;
        let k = faces[f].iter().position(|&x| x == v).unwrap_or(0);
        3 * f as u32 + k as u32
    };
    for e in 0..topo.edges.len() {
        let hs = topo.halfedges(e);
        let [a, b] = topo.edges[e];
        match hs.len() {
            1 => {
                boundary_edges += 1;
                boundary_uf.union(a, b);
                is_boundary_vertex[a as usize] = true;
                is_boundary_vertex[b as usize] = true;
            }
            2 => {
                let dir = |h: u32| faces[(h / 3) as usize][(h % 3) as usize];
                if dir(hs[0]) == dir(hs[1]) {
                    misoriented += 1;
                }
            }
            _ => non_manifold_edges += 1,
        }
        for w in hs.windows(2) {
            corner_uf.union(corner_at(w[0], a), corner_at(w[1], a));
            corner_uf.union(corner_at(w[0], b), corner_at(w[1], b));
        }
    }
    let mut boundary_roots: Vec<u32> =
        (0..nv as u32).filter(|&v| is_boundary_vertex[v as usize]).map(|v| boundary_uf.find(v)).collect();
    boundary_roots.sort_unstable();
    boundary_roots.dedup();
    // Fans per vertex.
    let mut fan_root = vec![u32::MAX; nv];
    let mut nm_vertex = vec![false; nv];
    for (f, face) in faces.iter().enumerate() {
        for (k, &v) in face.iter().enumerate() {
            let r = corner_uf.find(3 * f as u32 + k as u32);
            let slot = &mut fan_root[v as usize];
            if *slot == u32::MAX {
                *slot = r;
            } else if *slot != r {
                nm_vertex[v as usize] = true;
            }
        }
    }
    let non_manifold_vertices = nm_vertex.iter().filter(|&&x| x).count();
    let mut uf = UnionFind::new(nv);
    for f in faces {
        uf.union(f[0], f[1]);
        uf.union(f[1], f[2]);
    }
    let components = (0..nv as u32).filter(|&v| uf.find(v) == v).count();
    let area: f64 = faces.iter().map(|f| 0.5 * vec3::norm(tri_area2(&mesh.vertices, f))).sum();
    let chi = nv as i64 - topo.edges.len() as i64 + faces.len() as i64;
    let manifold = non_manifold_edges == 0 && non_manifold_vertices == 0;
    let orientation = if misoriented == 0 { Orientation::Consistent } else { Orientation::Inconsistent };
    let loops = boundary_roots.len();
    let genus = if manifold && orientation == Orientation::Consistent {
        let twice = 2 * components as i64 - chi - loops as i64;
        (twice >= 0 && twice % 2 == 0).then_some(twice / 2)
    } else {
        None
    };
    let closed = boundary_edges == 0;
    let enclosed_volume = (closed && manifold && orientation == Orientation::Consistent).then(|| {
        let v: f64 = faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| mesh.vertices[i as usize]);
                vec3::dot(a, vec3::cross(b, c))
            })
            .sum();
        (v / 6.0).abs()
    });
    SurfaceFacts {
        vertices: nv,
        faces: faces.len(),
        edges: topo.edges.len(),
        components,
        boundary_edges,
        boundary_loops: loops,
        non_manifold_edges,
        non_manifold_vertices,
        misoriented_edges: misoriented,
        orientation,
        closed,
        manifold,
        euler_characteristic: chi,
        genus,
        area,
        enclosed_volume,
    }
}

/// The edges of a triangle mesh, sorted (smaller vertex first; quadratic elements number their edge unknowns so).
pub fn triangle_edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut e: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

/// The edges of a tetrahedral mesh, sorted (smaller vertex first; quadratic elements number their edge unknowns so).
pub fn tet_edges(tets: &[[u32; 4]]) -> Vec<[u32; 2]> {
    let mut e: Vec<[u32; 2]> = tets
        .iter()
        .flat_map(|t| [[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]].map(|[a, b]| [t[a].min(t[b]), t[a].max(t[b])]))
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

#[inline]
pub fn tri_area2(v: &[Point], f: &[u32; 3]) -> Point {
    vec3::area2(v[f[0] as usize], v[f[1] as usize], v[f[2] as usize])
}

/// Boundary vertices of a triangle mesh (endpoints of edges with one incident face).
pub fn boundary_vertices(mesh: &TriangleMesh) -> Vec<bool> {
    let topo = EdgeTopology::new(&mesh.faces);
    let mut b = vec![false; mesh.vertices.len()];
    for (e, [x, y]) in topo.edges.iter().enumerate() {
        if topo.valence(e) == 1 {
            b[*x as usize] = true;
            b[*y as usize] = true;
        }
    }
    b
}

/// The (d−1)-dimensional measure of a shape's boundary, as Weyl's second term needs it: the length of a
/// surface's boundary edges, the area of a solid's boundary faces, the number of a curve's end points (0-d);
/// `None` for point clouds and graphs, which have no boundary to measure.
pub fn boundary_measure(shape: &super::Shape) -> Option<f64> {
    use super::Shape;
    match shape {
        Shape::TriangleMesh(m) => {
            let topo = EdgeTopology::new(&m.faces);
            Some(
                topo.edges
                    .iter()
                    .enumerate()
                    .filter(|&(e, _)| topo.valence(e) == 1)
                    .map(|(_, &[a, b])| vec3::norm(vec3::sub(m.vertices[a as usize], m.vertices[b as usize])))
                    .sum(),
            )
        }
        Shape::TetMesh(m) => {
            Some(tet_boundary(&m.tets).0.iter().map(|f| 0.5 * vec3::norm(tri_area2(&m.vertices, f))).sum())
        }
        Shape::Polyline(p) => {
            let mut degree = vec![0usize; p.vertices.len()];
            for s in &p.segments {
                degree[s[0] as usize] += 1;
                degree[s[1] as usize] += 1;
            }
            Some(degree.iter().filter(|&&d| d == 1).count() as f64)
        }
        Shape::PointCloud(_) | Shape::Graph(_) => None,
    }
}

/// Outward boundary triangles of a tet mesh with positively oriented tets, and the count of faces shared by
/// more than two tets.
pub fn tet_boundary(tets: &[[u32; 4]]) -> (Vec<[u32; 3]>, usize) {
    let mut faces: Vec<([u32; 3], [u32; 3])> = Vec::with_capacity(4 * tets.len());
    for t in tets {
        let [a, b, c, d] = *t;
        for f in [[a, c, b], [a, b, d], [a, d, c], [b, c, d]] {
            let mut key = f;
            key.sort_unstable();
            faces.push((key, f));
        }
    }
    faces.sort_unstable_by_key(|x| x.0);
    let mut out = Vec::new();
    let mut non_manifold = 0;
    let mut i = 0;
    while i < faces.len() {
        let mut j = i + 1;
        while j < faces.len() && faces[j].0 == faces[i].0 {
            j += 1;
        }
        match j - i {
            1 => out.push(faces[i].1),
            2 => {}
            _ => non_manifold += 1,
        }
        i = j;
    }
    (out, non_manifold)
}

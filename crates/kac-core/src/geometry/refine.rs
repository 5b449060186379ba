//! Uniform refinement: every triangle into four (edge midpoints), every tetrahedron into eight (edge midpoints,
//! the inner octahedron cut along its shortest diagonal, which keeps the shapes of the children bounded; Bey
//! 1995 and Zhang 1995 show the eight children stay within a few similarity classes). New vertices follow the
//! old ones, one per edge in the order of the sorted edge list, so the input's vertices keep their indices. The
//! refined mesh covers exactly the same domain: straight edges stay straight.

use super::{vec3, Point, TetMesh, TriangleMesh};

fn midpoints(vertices: &[Point], edges: &[[u32; 2]]) -> Vec<Point> {
    let mut out = vertices.to_vec();
    out.extend(edges.iter().map(|e| vec3::scale(vec3::add(vertices[e[0] as usize], vertices[e[1] as usize]), 0.5)));
    out
}

/// The triangle mesh with each face split into four.
pub fn refine_triangles(m: &TriangleMesh) -> TriangleMesh {
    let edges = super::topology::triangle_edges(&m.faces);
    let nv = m.vertices.len() as u32;
    let mid = |a: u32, b: u32| nv + edges.binary_search(&[a.min(b), a.max(b)]).unwrap_or(0) as u32;
    let faces = m
        .faces
        .iter()
        .flat_map(|&[a, b, c]| {
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
        })
        .collect();
    TriangleMesh { vertices: midpoints(&m.vertices, &edges), faces }
}

/// The tet mesh with each tetrahedron split into eight, orientation kept.
pub fn refine_tets(m: &TetMesh) -> TetMesh {
    let edges = super::topology::tet_edges(&m.tets);
    let vertices = midpoints(&m.vertices, &edges);
    let nv = m.vertices.len() as u32;
    let mid = |a: u32, b: u32| nv + edges.binary_search(&[a.min(b), a.max(b)]).unwrap_or(0) as u32;
    let volume = |t: &[u32; 4]| {
        let p = t.map(|i| vertices[i as usize]);
        vec3::dot(vec3::sub(p[1], p[0]), vec3::cross(vec3::sub(p[2], p[0]), vec3::sub(p[3], p[0])))
    };
    let mut tets = Vec::with_capacity(8 * m.tets.len());
    for &[a, b, c, d] in &m.tets {
        let (ab, ac, ad, bc, bd, cd) = (mid(a, b), mid(a, c), mid(a, d), mid(b, c), mid(b, d), mid(c, d));
        let corners = [[a, ab, ac, ad], [ab, b, bc, bd], [ac, bc, c, cd], [ad, bd, cd, d]];
        // The octahedron ab, ac, ad, bc, bd, cd: three diagonals (ab–cd, ac–bd, ad–bc); the shortest is cut.
        let len = |x: u32, y: u32| vec3::norm(vec3::sub(vertices[x as usize], vertices[y as usize]));
        let diagonals = [(ab, cd), (ac, bd), (ad, bc)];
        let (p, q) = *diagonals.iter().min_by(|u, v| len(u.0, u.1).total_cmp(&len(v.0, v.1))).unwrap_or(&diagonals[0]);
        // The four other octahedron vertices, in a cycle around the diagonal p–q.
        let ring: Vec<u32> = [ab, ac, ad, bc, bd, cd].into_iter().filter(|&x| x != p && x != q).collect();
        // Order the ring so consecutive members share a face of the octahedron (are not opposite).
        let opposite = |x: u32| {
            diagonals.iter().find_map(|&(u, v)| {
                if u == x {
                    Some(v)
                } else if v == x {
                    Some(u)
                } else {
                    None
                }
            })
        };
        let mut cycle = vec![ring[0]];
        let next = ring.iter().copied().find(|&x| x != ring[0] && opposite(ring[0]) != Some(x)).unwrap_or(ring[1]);
        cycle.push(next);
        cycle.push(opposite(ring[0]).unwrap_or(ring[2]));
        cycle.push(opposite(next).unwrap_or(ring[3]));
        let inner = (0..4).map(|i| [p, q, cycle[i], cycle[(i + 1) % 4]]);
        for mut t in corners.into_iter().chain(inner) {
            if volume(&t) < 0.0 {
                t.swap(2, 3);
            }
            tets.push(t);
        }
    }
    TetMesh { vertices, tets }
}

/// Whether every vertex of a triangle mesh lies in one plane (to 1e-9 of its bounding box's diagonal).
pub fn is_planar(m: &TriangleMesh) -> bool {
    let bbox = super::topology::BoundingBox::of(&m.vertices);
    let diag = bbox.map_or(0.0, |b| b.diagonal());
    let normal = m
        .faces
        .iter()
        .map(|f| super::topology::tri_area2(&m.vertices, f))
        .max_by(|a, b| vec3::norm(*a).total_cmp(&vec3::norm(*b)));
    let Some(n) = normal.filter(|n| vec3::norm(*n) > 0.0) else { return false };
    let n = vec3::scale(n, 1.0 / vec3::norm(n));
    let o = m.vertices[m.faces[0][0] as usize];
    m.vertices.iter().all(|&p| vec3::dot(vec3::sub(p, o), n).abs() <= 1e-9 * diag)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::generate;

    #[test]
    fn refinement_keeps_the_domain_and_quadruples_or_octuples_the_elements() {
        let sq = generate::unit_square(3);
        let r = refine_triangles(&sq);
        assert_eq!((r.faces.len(), r.vertices.len()), (4 * sq.faces.len(), 49));
        let area = |m: &TriangleMesh| {
            m.faces.iter().map(|f| 0.5 * vec3::norm(crate::geometry::topology::tri_area2(&m.vertices, f))).sum::<f64>()
        };
        assert!((area(&r) - 1.0).abs() < 1e-14);
        let cube = generate::unit_cube_tets(2);
        let r = refine_tets(&cube);
        assert_eq!((r.tets.len(), r.vertices.len()), (8 * cube.tets.len(), 125));
        let mut total = 0.0;
        for t in &r.tets {
            let p = t.map(|i| r.vertices[i as usize]);
            let v = vec3::dot(vec3::sub(p[1], p[0]), vec3::cross(vec3::sub(p[2], p[0]), vec3::sub(p[3], p[0]))) / 6.0;
            assert!(v > 0.0, "every child positively oriented and not flat");
            total += v;
        }
        assert!((total - 1.0).abs() < 1e-14, "{total}");
    }
}

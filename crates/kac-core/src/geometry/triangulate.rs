//! Triangulation of polygon faces on read. Quads are split along the diagonal that keeps both triangles
//! facing the polygon's (Newell) normal, the shorter one when both do; larger polygons are ear-clipped in
//! their best-fit plane, which handles non-convex faces; a fan is the fallback for self-intersecting input.

use super::vec3::{cross, dot, norm, sub};
use super::Point;

/// Newell's normal of a polygon (not normalized): robust for non-planar and non-convex polygons.
fn newell(v: &[Point], poly: &[u32]) -> Point {
    let mut n = [0.0; 3];
    for i in 0..poly.len() {
        let a = v[poly[i] as usize];
        let b = v[poly[(i + 1) % poly.len()] as usize];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

fn facing(v: &[Point], t: [u32; 3], n: Point) -> f64 {
    let [a, b, c] = t.map(|i| v[i as usize]);
    dot(cross(sub(b, a), sub(c, a)), n)
}

/// Appends the triangles of `poly` (orientation kept) to `out`.
pub fn triangulate(v: &[Point], poly: &[u32], out: &mut Vec<[u32; 3]>) {
    match poly.len() {
        0..=2 => {}
        3 => out.push([poly[0], poly[1], poly[2]]),
        4 => {
            let n = newell(v, poly);
            let d = |i: usize, j: usize| norm(sub(v[poly[i] as usize], v[poly[j] as usize]));
            let a = [[poly[0], poly[1], poly[2]], [poly[0], poly[2], poly[3]]];
            let b = [[poly[1], poly[2], poly[3]], [poly[1], poly[3], poly[0]]];
            let ok = |ts: &[[u32; 3]; 2]| ts.iter().all(|&t| facing(v, t, n) > 0.0);
            let choose_a = match (ok(&a), ok(&b)) {
                (true, false) => true,
                (false, true) => false,
                _ => d(0, 2) <= d(1, 3),
            };
            out.extend_from_slice(if choose_a { &a } else { &b });
        }
        _ => {
            if !ear_clip(v, poly, out) {
                for i in 1..poly.len() - 1 {
                    out.push([poly[0], poly[i], poly[i + 1]]);
                }
            }
        }
    }
}

/// Ear clipping in the plane orthogonal to the Newell normal. Returns false (adding nothing) if no ear is found.
fn ear_clip(v: &[Point], poly: &[u32], out: &mut Vec<[u32; 3]>) -> bool {
    let n = newell(v, poly);
    let len = norm(n);
    if len == 0.0 {
        return false;
    }
    let n = [n[0] / len, n[1] / len, n[2] / len];
    // Orthonormal basis (u, w) of the plane.
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let u = cross(n, helper);
    let ul = norm(u);
    let u = [u[0] / ul, u[1] / ul, u[2] / ul];
    let w = cross(n, u);
    let p2: Vec<[f64; 2]> = poly.iter().map(|&i| [dot(v[i as usize], u), dot(v[i as usize], w)]).collect();
    let mut idx: Vec<usize> = (0..poly.len()).collect();
    let start = out.len();
    let cross2 = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    while idx.len() > 3 {
        let m = idx.len();
        let mut clipped = false;
        for k in 0..m {
            let (ia, ib, ic) = (idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]);
            let (a, b, c) = (p2[ia], p2[ib], p2[ic]);
            if cross2(a, b, c) <= 0.0 {
                continue; // reflex or flat corner
            }
            let inside = idx.iter().any(|&j| {
                if j == ia || j == ib || j == ic {
                    return false;
                }
                let p = p2[j];
                cross2(a, b, p) >= 0.0 && cross2(b, c, p) >= 0.0 && cross2(c, a, p) >= 0.0
            });
            if inside {
                continue;
            }
            out.push([poly[ia], poly[ib], poly[ic]]);
            idx.remove(k);
            clipped = true;
            break;
        }
        if !clipped {
            out.truncate(start);
            return false;
        }
    }
    out.push([poly[idx[0]], poly[idx[1]], poly[idx[2]]]);
    true
}

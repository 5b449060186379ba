//! Polylines: welded, degenerate and duplicate segments dropped.

use super::report::{CurveFacts, Facts};
use super::weld::{compose, drop_unreferenced, weld_recorded};
use super::{Outcome, Repairs, ValidateOptions};
use crate::error::{Result, ShapeError};
use crate::geometry::topology::UnionFind;
use crate::geometry::{vec3, Polyline, RawShape, Shape};
use rustc_hash::FxHashMap as HashMap;

pub(super) fn curve(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs) -> Result<Outcome> {
    let (verts, weld_map) = weld_recorded(raw, o, r);
    let mut segs = Vec::with_capacity(raw.segments.len());
    let (mut zero, mut dups) = (Vec::new(), Vec::new());
    let mut seen: HashMap<[u32; 2], ()> = HashMap::default();
    for (i, s) in raw.segments.iter().enumerate() {
        let s = s.map(|v| weld_map[v as usize]);
        if s[0] == s[1] {
            zero.push(i);
            continue;
        }
        let k = if s[0] < s[1] { s } else { [s[1], s[0]] };
        if seen.insert(k, ()).is_some() {
            dups.push(i);
            continue;
        }
        segs.push(s);
    }
    r.add(
        "zero_length_segments",
        &zero,
        zero.len(),
        format!("{} segment(s) joining a vertex to itself dropped", zero.len()),
    );
    r.add(
        "duplicate_segments",
        &dups,
        dups.len(),
        format!("{} segment(s) repeating an earlier one dropped", dups.len()),
    );
    if segs.is_empty() {
        return Err(ShapeError::Empty { what: format!("no usable segment is left of {}", raw.segments.len()) });
    }
    let (vertices, cmap, segments) = drop_unreferenced(&verts, &weld_map, &segs, "segment", r);
    let n = vertices.len();
    let mut degree = vec![0usize; n];
    let mut uf = UnionFind::new(n);
    for s in &segments {
        degree[s[0] as usize] += 1;
        degree[s[1] as usize] += 1;
        uf.union(s[0], s[1]);
    }
    let (labels, components) = uf.labels();
    let mut all_two = vec![true; components];
    for v in 0..n {
        if degree[v] != 2 {
            all_two[labels[v] as usize] = false;
        }
    }
    let length = segments.iter().map(|s| vec3::norm(vec3::sub(vertices[s[0] as usize], vertices[s[1] as usize]))).sum();
    let facts = CurveFacts {
        vertices: n,
        segments: segments.len(),
        components,
        closed_components: all_two.iter().filter(|&&x| x).count(),
        endpoints: degree.iter().filter(|&&d| d == 1).count(),
        branch_vertices: degree.iter().filter(|&&d| d > 2).count(),
        length,
    };
    Ok((Shape::Polyline(Polyline { vertices, segments }), compose(&weld_map, &cmap), Facts::Curve(facts)))
}

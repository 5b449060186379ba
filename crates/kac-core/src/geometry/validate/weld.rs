//! Welding duplicate vertices (exactly, or within a tolerance) and the vertex maps of dropping the unreferenced
//! ones, composed so that per-vertex results return in the input's numbering.

use super::{Repairs, ValidateOptions, Weld};
use crate::geometry::topology::UnionFind;
use crate::geometry::{vec3, Point, RawShape};
use rustc_hash::FxHashMap as HashMap;

/// Welds exactly equal positions (−0 equals +0). Returns the unique positions in order of first appearance,
/// the map from each input position to its unique index, and the number merged.
pub fn weld_exact(points: &[Point]) -> (Vec<Point>, Vec<u32>, usize) {
    let key = |p: &Point| p.map(|c| if c == 0.0 { 0u64 } else { c.to_bits() });
    let mut seen: HashMap<[u64; 3], u32> = HashMap::with_capacity_and_hasher(points.len() / 2, Default::default());
    let mut unique = Vec::with_capacity(points.len() / 2);
    let map = points
        .iter()
        .map(|p| {
            *seen.entry(key(p)).or_insert_with(|| {
                unique.push(*p);
                (unique.len() - 1) as u32
            })
        })
        .collect();
    let merged = points.len() - unique.len();
    (unique, map, merged)
}

/// Welds positions closer than `tol` (single linkage through a grid of cell `tol`): every cluster becomes
/// the position of its first member.
pub fn weld_tolerance(points: &[Point], tol: f64) -> (Vec<Point>, Vec<u32>, usize) {
    if !(tol > 0.0 && tol.is_finite()) {
        return weld_exact(points);
    }
    let cell = |p: &Point| p.map(|c| (c / tol).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::default();
    for (i, p) in points.iter().enumerate() {
        grid.entry(cell(p)).or_default().push(i as u32);
    }
    let mut uf = UnionFind::new(points.len());
    for (i, p) in points.iter().enumerate() {
        let c = cell(p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &j in list {
                            if (j as usize) < i && vec3::norm(vec3::sub(*p, points[j as usize])) <= tol {
                                uf.union(i as u32, j);
                            }
                        }
                    }
                }
            }
        }
    }
    let mut root_index: HashMap<u32, u32> = HashMap::default();
    let mut unique = Vec::new();
    let map = (0..points.len() as u32)
        .map(|i| {
            let r = uf.find(i);
            *root_index.entry(r).or_insert_with(|| {
                unique.push(points[i as usize]);
                (unique.len() - 1) as u32
            })
        })
        .collect();
    let merged = points.len() - unique.len();
    (unique, map, merged)
}

pub(super) fn weld(points: &[Point], w: Weld) -> (Vec<Point>, Vec<u32>, usize) {
    match w {
        Weld::None => (points.to_vec(), (0..points.len() as u32).collect(), 0),
        Weld::Exact => weld_exact(points),
        Weld::Tolerance(t) => weld_tolerance(points, t),
    }
}

/// Drops vertices no element references; returns the compacted positions and the old→new map (u32::MAX: dropped).
pub(super) fn compact(vertices: &[Point], used: &[bool]) -> (Vec<Point>, Vec<u32>, Vec<usize>) {
    let mut map = vec![u32::MAX; vertices.len()];
    let mut out = Vec::with_capacity(vertices.len());
    let mut dropped = Vec::new();
    for (i, p) in vertices.iter().enumerate() {
        if used[i] {
            map[i] = out.len() as u32;
            out.push(*p);
        } else {
            dropped.push(i);
        }
    }
    (out, map, dropped)
}

/// Welds the raw vertices as the options say and records the repair.
pub(super) fn weld_recorded(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs) -> (Vec<Point>, Vec<u32>) {
    let (verts, weld_map, merged) = weld(&raw.vertices, o.weld);
    r.add("welded_vertices", &[], merged, format!("{merged} vertices at equal positions merged"));
    (verts, weld_map)
}

/// Drops vertices no element uses, renumbers the elements, records the repair (with input indices through
/// `weld_map`), and returns the kept positions, the welded→kept map and the renumbered elements.
pub(super) fn drop_unreferenced<const A: usize>(
    verts: &[Point],
    weld_map: &[u32],
    elems: &[[u32; A]],
    element_name: &str,
    r: &mut Repairs,
) -> (Vec<Point>, Vec<u32>, Vec<[u32; A]>) {
    let mut used = vec![false; verts.len()];
    elems.iter().flatten().for_each(|&v| used[v as usize] = true);
    let (vertices, cmap, dropped) = compact(verts, &used);
    let dropped_input: Vec<usize> =
        weld_map.iter().enumerate().filter(|(_, &w)| cmap[w as usize] == u32::MAX).map(|(i, _)| i).collect();
    r.add(
        "unreferenced_vertices",
        &dropped_input,
        dropped.len(),
        format!("{} vertex(es) used by no {element_name} dropped", dropped.len()),
    );
    let renumbered = elems.iter().map(|e| e.map(|v| cmap[v as usize])).collect();
    (vertices, cmap, renumbered)
}

pub(super) fn compose(first: &[u32], second: &[u32]) -> Vec<u32> {
    first.iter().map(|&m| if m == u32::MAX { u32::MAX } else { second[m as usize] }).collect()
}

/// Exact duplicates among points in Rⁿ merged (all coordinates equal; ±0 alike): the unique points' first three
/// coordinates, the input → unique map, the merged count, and the unique rows.
pub(super) fn weld_rows(
    a: &crate::geometry::Ambient,
    first3: &[Point],
) -> (Vec<Point>, Vec<u32>, usize, Option<crate::geometry::Ambient>) {
    let mut seen: HashMap<Vec<u64>, u32> = HashMap::with_capacity_and_hasher(a.len(), Default::default());
    let (mut points, mut coords) = (Vec::with_capacity(a.len()), Vec::with_capacity(a.coords.len()));
    let map: Vec<u32> = (0..a.len())
        .map(|i| {
            let row = a.row(i);
            let key: Vec<u64> = row.iter().map(|&c| if c == 0.0 { 0 } else { c.to_bits() }).collect();
            *seen.entry(key).or_insert_with(|| {
                points.push(first3[i]);
                coords.extend_from_slice(row);
                (points.len() - 1) as u32
            })
        })
        .collect();
    let merged = a.len() - points.len();
    (points, map, merged, Some(crate::geometry::Ambient { dim: a.dim, coords }))
}

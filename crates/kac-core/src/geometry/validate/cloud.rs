//! Point clouds: welded, in three dimensions or in the rows' own ambient dimension.

use super::report::{CloudFacts, Facts, MAX_EXAMPLES};
use super::weld::{weld, weld_rows};
use super::{Outcome, Repairs, ValidateOptions};
use crate::error::{Result, ShapeError};
use crate::geometry::{PointCloud, RawShape, Shape};

pub(super) fn cloud(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs) -> Result<Outcome> {
    if raw.vertices.is_empty() {
        return Err(ShapeError::Empty { what: "no vertices or points".into() });
    }
    // Points in Rⁿ merge only where every coordinate agrees (the first three may coincide for distinct points).
    let (points, map, merged, ambient) = match &raw.ambient {
        Some(a) => weld_rows(a, &raw.vertices),
        None => {
            let (points, map, merged) = weld(&raw.vertices, o.weld);
            (points, map, merged, None)
        }
    };
    let mut first = vec![usize::MAX; points.len()];
    let mut dup_examples = Vec::new();
    for (i, &m) in map.iter().enumerate() {
        if first[m as usize] == usize::MAX {
            first[m as usize] = i;
        } else if dup_examples.len() < MAX_EXAMPLES {
            dup_examples.push(i);
        }
    }
    r.add("duplicate_points", &dup_examples, merged, format!("{merged} point(s) at the position of an earlier point merged (k-nearest-neighbour weights need distinct points)"));
    let normals = raw.normals.as_ref().map(|ns| {
        let mut out = vec![[0.0; 3]; points.len()];
        let mut set = vec![false; points.len()];
        for (i, &m) in map.iter().enumerate() {
            if !set[m as usize] {
                out[m as usize] = ns[i];
                set[m as usize] = true;
            }
        }
        out
    });
    let ambient_dimension = ambient.as_ref().map_or(3, |a: &crate::geometry::Ambient| a.dim);
    let facts = CloudFacts { points: points.len(), has_normals: normals.is_some(), ambient_dimension };
    Ok((Shape::PointCloud(PointCloud { points, normals, ambient }), map, Facts::Cloud(facts)))
}

//! Medit `.mesh` (INRIA), ASCII: `MeshVersionFormatted`, `Dimension`, `Vertices`, `Triangles`, `Quadrilaterals`,
//! `Tetrahedra`, `Edges` and the usual auxiliary sections; indices are 1-based and every element ends with a
//! reference number. With tetrahedra it is a tet mesh (the boundary triangles it may list are not needed);
//! otherwise triangles (and quads) make a surface, edges a polyline.

use super::text::{self, Tokens};
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};

const FMT: &str = "medit";

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let mut t = Tokens::new(bytes, true);
    let mut dim = 3usize;
    let mut raw = RawShape::default();
    let mut triangles = Polygons::default();
    let mut seen_vertices = false;
    let mut skipped: Vec<String> = Vec::new();
    while let Some((ln, key)) = t.next_token() {
        let k = String::from_utf8_lossy(key).to_string();
        match k.as_str() {
            "MeshVersionFormatted" => {
                t.usize(FMT, "version")?;
            }
            "Dimension" => {
                dim = t.usize(FMT, "dimension")?;
                if !(2..=3).contains(&dim) {
                    return Err(ShapeError::Unsupported {
                        format: FMT,
                        location: Location::line(ln),
                        message: format!("dimension {dim}"),
                    });
                }
                raw.planar_input = dim == 2;
            }
            "Vertices" => {
                let n = t.usize(FMT, "vertex count")?;
                options.check_vertices(n as u64)?;
                raw.vertices.reserve(text::capacity(n, bytes.len(), 6));
                for i in 0..n {
                    let mut p = [0.0; 3];
                    for c in p.iter_mut().take(dim) {
                        *c = t.f64(FMT, "coordinate")?;
                    }
                    t.i64(FMT, "vertex reference")?;
                    raw.vertices.push(text::check_point(p, i, || Location::line(t.line()))?);
                }
                seen_vertices = true;
            }
            "Triangles" | "Quadrilaterals" | "Tetrahedra" | "Edges" => {
                if !seen_vertices {
                    return Err(text::syntax(FMT, ln, format!("'{k}' before 'Vertices'")));
                }
                let n = t.usize(FMT, "element count")?;
                options.check_elements(n as u64)?;
                let (arity, element) = match k.as_str() {
                    "Triangles" => (3, Element::Face),
                    "Quadrilaterals" => (4, Element::Face),
                    "Tetrahedra" => (4, Element::Tetrahedron),
                    _ => (2, Element::Segment),
                };
                let nv = raw.vertices.len();
                for e in 0..n {
                    let mut idx = [0u32; 4];
                    for slot in idx.iter_mut().take(arity) {
                        let v = t.i64(FMT, "vertex index")?;
                        *slot = text::check_index(v - 1, nv, element, e, || Location::line(t.line()))?;
                    }
                    t.i64(FMT, "element reference")?;
                    match k.as_str() {
                        "Tetrahedra" => raw.tets.push(idx),
                        "Edges" => raw.segments.push([idx[0], idx[1]]),
                        _ => triangles.push(&idx[..arity]),
                    }
                }
            }
            "Corners" | "RequiredVertices" | "Ridges" | "RequiredEdges" | "RequiredTriangles"
            | "RequiredTetrahedra" => {
                let n = t.usize(FMT, "count")?;
                for _ in 0..n {
                    t.i64(FMT, "index")?;
                }
                skipped.push(k);
            }
            "Normals" | "Tangents" => {
                let n = t.usize(FMT, "count")?;
                for _ in 0..n * dim {
                    t.f64(FMT, "component")?;
                }
                skipped.push(k);
            }
            "NormalAtVertices" | "TangentAtEdges" => {
                let n = t.usize(FMT, "count")?;
                for _ in 0..2 * n {
                    t.i64(FMT, "index")?;
                }
                skipped.push(k);
            }
            "End" => break,
            _ => {
                return Err(ShapeError::Unsupported {
                    format: FMT,
                    location: Location::line(ln),
                    message: format!("unknown section '{}'", text::show(key)),
                })
            }
        }
    }
    if !raw.tets.is_empty() && !triangles.is_empty() {
        raw.notes.push(format!("medit: {} boundary triangle(s) listed beside the tetrahedra not used; the boundary is computed from the tetrahedra", triangles.len()));
    } else {
        raw.polygons = triangles;
    }
    for s in skipped {
        raw.notes.push(format!("medit: section '{s}' ignored"));
    }
    Ok(raw)
}

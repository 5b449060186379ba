//! kac's JSON shape format. One object:
//!
//! ```json
//! { "vertices": [[x, y, z], ...],          // or [x, y] (planar); may be omitted for a graph with vertex_count
//!   "faces":    [[i, j, k, ...], ...],      // a surface (polygons are triangulated)
//!   "tets":     [[i, j, k, l], ...],        // a solid
//!   "edges":    [[i, j], ...],              // a graph, with optional "weights": [w, ...] (default 1)
//!   "segments": [[i, j], ...],              // a polyline (or "polylines": [[i, j, k, ...], ...])
//!   "vertex_count": n,                      // graphs without positions
//!   "normals":  [[nx, ny, nz], ...] }       // point clouds
//! ```
//! Indices are 0-based. Vertices with nothing else make a point cloud.

use super::text;
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};
use serde::Deserialize;

const FMT: &str = "json";

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonShape {
    #[serde(default)]
    vertices: Option<Vec<Vec<f64>>>,
    #[serde(default)]
    faces: Option<Vec<Vec<i64>>>,
    #[serde(default)]
    tets: Option<Vec<Vec<i64>>>,
    #[serde(default)]
    edges: Option<Vec<Vec<i64>>>,
    #[serde(default)]
    weights: Option<Vec<f64>>,
    #[serde(default)]
    segments: Option<Vec<Vec<i64>>>,
    #[serde(default)]
    polylines: Option<Vec<Vec<i64>>>,
    #[serde(default)]
    vertex_count: Option<usize>,
    #[serde(default)]
    normals: Option<Vec<Vec<f64>>>,
    /// Free-form name, echoed nowhere; allowed so files can label themselves.
    #[serde(default)]
    #[allow(dead_code)]
    name: Option<String>,
}

fn ptr(s: String) -> Location {
    Location::pointer(s)
}

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let js: JsonShape = serde_json::from_slice(bytes).map_err(|e| ShapeError::Syntax {
        format: FMT,
        location: if e.line() > 0 { Location::line(e.line()) } else { Location::Unknown },
        message: e.to_string(),
    })?;
    let mut raw = RawShape::default();
    if let Some(vs) = js.vertices {
        options.check_vertices(vs.len() as u64)?;
        raw.vertices.reserve(vs.len());
        for (i, v) in vs.iter().enumerate() {
            let p = match v.as_slice() {
                [x, y] => {
                    raw.planar_input = true;
                    [*x, *y, 0.0]
                }
                [x, y, z] => [*x, *y, *z],
                _ => {
                    return Err(ShapeError::InvalidElement {
                        element: Element::Vertex,
                        index: i,
                        rule: format!("a vertex has 2 or 3 coordinates, this one has {}", v.len()),
                        location: ptr(format!("/vertices/{i}")),
                    })
                }
            };
            raw.vertices.push(text::check_point(p, i, || ptr(format!("/vertices/{i}")))?);
        }
    }
    let nv = match (js.vertex_count, raw.vertices.len()) {
        (Some(n), 0) => {
            options.check_vertices(n as u64)?;
            n
        }
        (Some(n), m) if n != m => {
            return Err(ShapeError::InvalidElement {
                element: Element::Vertex,
                index: m,
                rule: format!("vertex_count is {n} but {m} vertices are listed"),
                location: ptr("/vertex_count".into()),
            });
        }
        (_, m) => m,
    };
    let index = |key: &str, e: usize, k: usize, v: i64, element: Element| {
        text::check_index(v, nv, element, e, || ptr(format!("/{key}/{e}/{k}")))
    };
    if let Some(faces) = js.faces {
        options.check_elements(faces.len() as u64)?;
        let mut polys = Polygons::with_capacity(faces.len(), 3 * faces.len());
        for (e, f) in faces.iter().enumerate() {
            if f.len() < 3 {
                return Err(ShapeError::InvalidElement {
                    element: Element::Face,
                    index: e,
                    rule: format!("a face needs at least 3 corners, this one has {}", f.len()),
                    location: ptr(format!("/faces/{e}")),
                });
            }
            for (k, &v) in f.iter().enumerate() {
                polys.indices.push(index("faces", e, k, v, Element::Face)?);
            }
            polys.close();
        }
        raw.polygons = polys;
    }
    let fixed = |key: &str, list: &[Vec<i64>], arity: usize, element: Element| -> Result<Vec<[u32; 4]>> {
        options.check_elements(list.len() as u64)?;
        let mut out = Vec::with_capacity(list.len());
        for (e, item) in list.iter().enumerate() {
            if item.len() != arity {
                return Err(ShapeError::InvalidElement {
                    element,
                    index: e,
                    rule: format!("expected {arity} vertex indices, found {}", item.len()),
                    location: ptr(format!("/{key}/{e}")),
                });
            }
            let mut a = [0u32; 4];
            for (k, &v) in item.iter().enumerate() {
                a[k] = index(key, e, k, v, element)?;
            }
            out.push(a);
        }
        Ok(out)
    };
    if let Some(t) = js.tets {
        raw.tets = fixed("tets", &t, 4, Element::Tetrahedron)?;
    }
    if let Some(edges) = js.edges {
        raw.segments = fixed("edges", &edges, 2, Element::Edge)?.into_iter().map(|a| [a[0], a[1]]).collect();
        raw.is_graph = true;
        if let Some(w) = js.weights {
            if w.len() != raw.segments.len() {
                return Err(ShapeError::InvalidElement {
                    element: Element::Edge,
                    index: w.len().min(raw.segments.len()),
                    rule: format!("{} weights for {} edges", w.len(), raw.segments.len()),
                    location: ptr("/weights".into()),
                });
            }
            raw.weights = Some(w);
        }
    } else if js.weights.is_some() {
        return Err(ShapeError::Syntax {
            format: FMT,
            location: ptr("/weights".into()),
            message: "weights need edges".into(),
        });
    }
    if let Some(s) = js.segments {
        raw.segments.extend(fixed("segments", &s, 2, Element::Segment)?.into_iter().map(|a| [a[0], a[1]]));
    }
    if let Some(pl) = js.polylines {
        for (e, chain) in pl.iter().enumerate() {
            if chain.len() < 2 {
                return Err(ShapeError::InvalidElement {
                    element: Element::Segment,
                    index: e,
                    rule: "a polyline needs at least 2 vertices".into(),
                    location: ptr(format!("/polylines/{e}")),
                });
            }
            let mut ids = Vec::with_capacity(chain.len());
            for (k, &v) in chain.iter().enumerate() {
                ids.push(index("polylines", e, k, v, Element::Segment)?);
            }
            raw.segments.extend(ids.windows(2).map(|w| [w[0], w[1]]));
        }
    }
    if let Some(ns) = js.normals {
        if ns.len() != raw.vertices.len() || ns.iter().any(|n| n.len() != 3) {
            return Err(ShapeError::Syntax {
                format: FMT,
                location: ptr("/normals".into()),
                message: "normals need one [nx, ny, nz] per vertex".into(),
            });
        }
        raw.normals = Some(ns.iter().map(|n| [n[0], n[1], n[2]]).collect());
    }
    if raw.is_graph && raw.vertices.is_empty() {
        raw.graph_vertex_count = Some(nv);
    }
    if raw.is_graph {
        raw.weights.get_or_insert_with(|| vec![1.0; raw.segments.len()]);
    }
    Ok(raw)
}

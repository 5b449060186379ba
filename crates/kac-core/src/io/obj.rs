//! Wavefront OBJ: `v` (2, 3 or 4+ numbers; colours after xyz are ignored), `f` with `v`, `v/vt`, `v//vn`,
//! `v/vt/vn` corners and negative (relative) indices, polygons of any size, `l` lines as polylines.
//! A vertex is a *position* index: corners that share a `v` but differ in `vt`/`vn` stay one vertex, so UV seams
//! do not cut the surface. Forward references (a face naming a `v` defined later) are accepted as most tools do.

use super::text::{self, Lines};
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};

const FMT: &str = "obj";

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let mut raw = RawShape::default();
    raw.vertices.reserve(text::capacity(bytes.len() / 60, bytes.len(), 8));
    let mut polygons = Polygons::with_capacity(bytes.len() / 40, bytes.len() / 12);
    let mut segments: Vec<[u32; 2]> = Vec::new();
    let mut ignored: std::collections::BTreeMap<String, usize> = Default::default();
    let (mut texcoords, mut normals) = (0usize, 0usize);
    let mut planar = false;
    // Largest positive index seen and where, to report forward references that never resolve.
    let mut max_ref: Option<(i64, Element, usize, usize)> = None;
    let mut corner: Vec<u32> = Vec::with_capacity(16);

    for (ln, line) in Lines::new(bytes) {
        let line = line.trim_ascii();
        if line.is_empty() || line[0] == b'#' {
            continue;
        }
        let mut toks = text::tokens(line);
        let key = toks.next().unwrap_or_default();
        match key {
            b"v" => {
                let x = text::expect_f64(FMT, ln, toks.next(), "x")?;
                let y = text::expect_f64(FMT, ln, toks.next(), "y")?;
                let z = match toks.next() {
                    Some(t) => text::expect_f64(FMT, ln, Some(t), "z")?,
                    None => {
                        planar = true;
                        0.0
                    }
                };
                let index = raw.vertices.len();
                let p = text::check_point([x, y, z], index, || Location::line(ln))?;
                raw.vertices.push(p);
                if raw.vertices.len() > options.max_vertices {
                    options.check_vertices(raw.vertices.len() as u64)?;
                }
            }
            b"vt" => texcoords += 1,
            b"vn" => normals += 1,
            b"f" | b"fo" | b"l" => {
                let is_face = key != b"l";
                let element = if is_face { Element::Face } else { Element::Segment };
                let element_index = if is_face { polygons.len() } else { segments.len() };
                corner.clear();
                for tok in toks {
                    let vtok = tok.split(|&b| b == b'/').next().unwrap_or_default();
                    let v = text::parse_i64(vtok).ok_or_else(|| {
                        text::syntax(FMT, ln, format!("expected a vertex index, found '{}'", text::show(tok)))
                    })?;
                    let resolved = if v < 0 {
                        raw.vertices.len() as i64 + v
                    } else if v == 0 {
                        return Err(ShapeError::IndexOutOfRange {
                            element,
                            index: element_index,
                            value: 0,
                            vertex_count: raw.vertices.len(),
                            location: Location::line(ln),
                        });
                    } else {
                        v - 1
                    };
                    if resolved < 0 || resolved > u32::MAX as i64 {
                        return Err(ShapeError::IndexOutOfRange {
                            element,
                            index: element_index,
                            value: v,
                            vertex_count: raw.vertices.len(),
                            location: Location::line(ln),
                        });
                    }
                    if resolved >= raw.vertices.len() as i64 && max_ref.is_none_or(|m| resolved > m.0) {
                        max_ref = Some((resolved, element, element_index, ln));
                    }
                    corner.push(resolved as u32);
                }
                if is_face {
                    if corner.len() < 3 {
                        return Err(ShapeError::InvalidElement {
                            element,
                            index: element_index,
                            rule: format!("a face needs at least 3 corners, this one has {}", corner.len()),
                            location: Location::line(ln),
                        });
                    }
                    polygons.push(&corner);
                } else {
                    if corner.len() < 2 {
                        return Err(ShapeError::InvalidElement {
                            element,
                            index: element_index,
                            rule: "a line needs at least 2 vertices".into(),
                            location: Location::line(ln),
                        });
                    }
                    segments.extend(corner.windows(2).map(|w| [w[0], w[1]]));
                }
                if polygons.len() + segments.len() > options.max_elements {
                    options.check_elements((polygons.len() + segments.len()) as u64)?;
                }
            }
            b"vp" | b"o" | b"g" | b"s" | b"usemtl" | b"mtllib" | b"usemap" | b"maplib" | b"lod" | b"shadow_obj"
            | b"trace_obj" | b"p" | b"cstype" | b"deg" | b"curv" | b"curv2" | b"surf" | b"parm" | b"trim" | b"hole"
            | b"scrv" | b"sp" | b"end" | b"con" | b"mg" | b"bmat" | b"step" | b"ctech" | b"stech" | b"bevel"
            | b"c_interp" | b"d_interp" => {
                if !matches!(key, b"o" | b"g" | b"s" | b"usemtl" | b"mtllib") {
                    *ignored.entry(text::show(key)).or_default() += 1;
                }
            }
            other => {
                return Err(text::syntax(FMT, ln, format!("unknown statement '{}'", text::show(other))));
            }
        }
    }
    if let Some((value, element, index, ln)) = max_ref {
        if value >= raw.vertices.len() as i64 {
            return Err(ShapeError::IndexOutOfRange {
                element,
                index,
                value: value + 1,
                vertex_count: raw.vertices.len(),
                location: Location::line(ln),
            });
        }
    }
    if polygons.is_empty() && segments.is_empty() && !raw.vertices.is_empty() {
        let mut w = format!("obj: no faces or lines: read as a point cloud of {} vertices", raw.vertices.len());
        if !bytes.trim_ascii_end().is_empty() && !bytes.ends_with(b"\n") {
            w.push_str("; the file does not end with a line break (was it cut short?)");
        }
        if texcoords + normals > 0 {
            w.push_str(&format!(
                "; it has {texcoords} texture coordinates and {normals} normals, which belong to faces (a mesh cut short?)"
            ));
        }
        raw.warnings.push(w);
    }
    if texcoords + normals > 0 {
        raw.notes.push(format!(
            "obj: {texcoords} texture coordinates and {normals} normals ignored; faces use position indices only"
        ));
    }
    for (k, n) in ignored {
        raw.notes.push(format!("obj: {n} '{k}' statement(s) ignored"));
    }
    raw.planar_input = planar;
    raw.polygons = polygons;
    raw.segments = segments;
    Ok(raw)
}

//! Legacy VTK, ASCII: `DATASET UNSTRUCTURED_GRID` (CELLS + CELL_TYPES, in the classic layout and the 5.x
//! OFFSETS/CONNECTIVITY layout) and `DATASET POLYDATA` (POLYGONS, TRIANGLE_STRIPS, LINES).
//! lapy stores tetrahedral meshes as POLYDATA whose POLYGONS all have four vertices (its `cubeTetra.vtk`); such
//! polygons are read as tetrahedra when they are solid (not flat quads), and the report says so.
//! Point and cell data sections after the geometry are ignored.

use super::text::{self, show, Tokens};
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{vec3, Polygons, RawShape};

const FMT: &str = "vtk";

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let mut lines = text::Lines::new(bytes);
    let (_, h) = lines.next().ok_or_else(|| ShapeError::Empty { what: "the VTK file is empty".into() })?;
    if !h.trim_ascii().starts_with(b"# vtk DataFile") {
        return Err(text::syntax(FMT, 1, "the first line must be '# vtk DataFile Version x.x'"));
    }
    lines.next(); // title
    let (ln, enc) = lines.next().ok_or_else(|| ShapeError::Truncated {
        format: FMT,
        location: Location::line(2),
        message: "missing ASCII/BINARY line".into(),
    })?;
    if !enc.trim_ascii().eq_ignore_ascii_case(b"ASCII") {
        return Err(ShapeError::Unsupported {
            format: FMT,
            location: Location::line(ln),
            message: format!("'{}' encoding; only ASCII legacy VTK is taken", show(enc.trim_ascii())),
        });
    }
    let header_lines = lines.line();
    let mut t = Tokens::new(lines.rest(), false);
    let line_of = |t: &Tokens<'_>| t.line() + header_lines;
    let mut dataset = Vec::new();
    let mut raw = RawShape::default();
    let mut cells: Vec<Vec<u32>> = Vec::new();
    let mut cell_types: Vec<i64> = Vec::new();
    let mut polydata_polys = Polygons::default();
    let mut polydata_lines: Vec<[u32; 2]> = Vec::new();
    let mut strips = 0usize;
    while let Some((_, key)) = t.next_token() {
        let k = key.to_ascii_uppercase();
        match k.as_slice() {
            b"DATASET" => {
                dataset = t.next_token().map(|x| x.1.to_ascii_uppercase()).unwrap_or_default();
                if dataset != b"UNSTRUCTURED_GRID" && dataset != b"POLYDATA" {
                    return Err(ShapeError::Unsupported {
                        format: FMT,
                        location: Location::line(line_of(&t)),
                        message: format!("DATASET {}; UNSTRUCTURED_GRID and POLYDATA are taken", show(&dataset)),
                    });
                }
            }
            b"POINTS" => {
                let n = t.usize(FMT, "point count")?;
                options.check_vertices(n as u64)?;
                t.next_token(); // data type
                raw.vertices.reserve(text::capacity(n, bytes.len(), 6));
                for i in 0..n {
                    let p = [t.f64(FMT, "x")?, t.f64(FMT, "y")?, t.f64(FMT, "z")?];
                    let l = line_of(&t);
                    raw.vertices.push(text::check_point(p, i, || Location::line(l))?);
                }
            }
            b"CELLS" | b"POLYGONS" | b"LINES" | b"TRIANGLE_STRIPS" | b"VERTICES" => {
                let n = t.usize(FMT, "cell count")?;
                let size = t.usize(FMT, "cell list size")?;
                options.check_elements(n as u64)?;
                let list = read_cell_list(&mut t, n, size, raw.vertices.len(), header_lines)?;
                match k.as_slice() {
                    b"CELLS" => cells = list,
                    b"POLYGONS" => list.iter().try_for_each(|c| push_polygon(&mut polydata_polys, c, header_lines))?,
                    b"LINES" => list.iter().for_each(|c| polydata_lines.extend(c.windows(2).map(|w| [w[0], w[1]]))),
                    b"TRIANGLE_STRIPS" => {
                        for c in &list {
                            for i in 2..c.len() {
                                let tri =
                                    if i % 2 == 0 { [c[i - 2], c[i - 1], c[i]] } else { [c[i - 1], c[i - 2], c[i]] };
                                polydata_polys.push(&tri);
                                strips += 1;
                            }
                        }
                    }
                    _ => {}
                }
            }
            b"CELL_TYPES" => {
                let n = t.usize(FMT, "cell type count")?;
                cell_types.reserve(text::capacity(n, bytes.len(), 2));
                for _ in 0..n {
                    cell_types.push(t.i64(FMT, "cell type")?);
                }
            }
            b"POINT_DATA" | b"CELL_DATA" | b"FIELD" | b"METADATA" => break,
            _ => return Err(text::syntax(FMT, line_of(&t), format!("unexpected keyword '{}'", show(key)))),
        }
    }
    if dataset.is_empty() {
        return Err(text::syntax(FMT, header_lines + 1, "missing DATASET line"));
    }
    if dataset == b"UNSTRUCTURED_GRID" {
        if cells.len() != cell_types.len() {
            return Err(text::syntax(
                FMT,
                line_of(&t),
                format!("{} cells but {} cell types", cells.len(), cell_types.len()),
            ));
        }
        let mut polys = Polygons::default();
        let mut other = 0usize;
        for (i, (c, &ty)) in cells.iter().zip(&cell_types).enumerate() {
            let want = match ty {
                10 => 4,
                5 => 3,
                9 => 4,
                3 => 2,
                _ => 0,
            };
            if want != 0 && c.len() != want {
                return Err(ShapeError::InvalidElement {
                    element: Element::Tetrahedron,
                    index: i,
                    rule: format!("cell type {ty} needs {want} points, the cell has {}", c.len()),
                    location: Location::Unknown,
                });
            }
            match ty {
                10 => raw.tets.push([c[0], c[1], c[2], c[3]]),
                5 | 9 => polys.push(c),
                3 => raw.segments.push([c[0], c[1]]),
                4 => raw.segments.extend(c.windows(2).map(|w| [w[0], w[1]])),
                7 if c.len() >= 3 => polys.push(c),
                _ => other += 1,
            }
        }
        if other > 0 {
            raw.notes.push(format!("vtk: {other} cell(s) of other types ignored"));
        }
        if raw.tets.is_empty() {
            raw.polygons = polys;
        }
    } else {
        let all_quads = !polydata_polys.is_empty() && strips == 0 && polydata_polys.iter().all(|p| p.len() == 4);
        if all_quads && solid_quads(&raw.vertices, &polydata_polys) {
            raw.tets = polydata_polys.iter().map(|p| [p[0], p[1], p[2], p[3]]).collect();
            raw.notes.push(format!(
                "vtk: {} POLYDATA 4-vertex polygons are solid and were read as tetrahedra (lapy's convention)",
                raw.tets.len()
            ));
        } else {
            raw.polygons = polydata_polys;
            raw.segments = polydata_lines;
        }
    }
    Ok(raw)
}

fn push_polygon(polys: &mut Polygons, c: &[u32], header_lines: usize) -> Result<()> {
    if c.len() < 3 {
        return Err(ShapeError::InvalidElement {
            element: Element::Face,
            index: polys.len(),
            rule: format!("a polygon needs 3 points, this one has {}", c.len()),
            location: Location::line(header_lines),
        });
    }
    polys.push(c);
    Ok(())
}

/// Reads `n` cells, classic (`k i1 .. ik` per cell) or 5.x (`OFFSETS` and `CONNECTIVITY` arrays) layout.
fn read_cell_list(t: &mut Tokens<'_>, n: usize, size: usize, nv: usize, header_lines: usize) -> Result<Vec<Vec<u32>>> {
    let mut cells = Vec::with_capacity(n.min(size));
    let mut used = 0usize;
    // Peek: the 5.x layout has the word OFFSETS here.
    let first = t.next_token();
    let Some((l0, tok0)) = first else {
        return if n == 0 {
            Ok(cells)
        } else {
            Err(ShapeError::Truncated {
                format: FMT,
                location: Location::line(t.line() + header_lines),
                message: "missing cells".into(),
            })
        };
    };
    if tok0.eq_ignore_ascii_case(b"OFFSETS") {
        t.next_token(); // type
        let mut offsets = Vec::with_capacity(n.min(1 << 24));
        for _ in 0..n {
            offsets.push(t.usize(FMT, "offset")?);
        }
        match t.next_token() {
            Some((_, k)) if k.eq_ignore_ascii_case(b"CONNECTIVITY") => {}
            _ => return Err(text::syntax(FMT, t.line() + header_lines, "expected CONNECTIVITY after OFFSETS")),
        }
        t.next_token();
        let mut conn = Vec::with_capacity(size.min(1 << 26));
        for i in 0..size {
            let v = t.i64(FMT, "point index")?;
            conn.push(text::check_index(v, nv, Element::Face, i, || Location::line(t.line() + header_lines))?);
        }
        for w in offsets.windows(2) {
            let (a, b) = (w[0], w[1]);
            if a > b || b > conn.len() {
                return Err(text::syntax(
                    FMT,
                    t.line() + header_lines,
                    "OFFSETS are not increasing within CONNECTIVITY",
                ));
            }
            cells.push(conn[a..b].to_vec());
        }
        return Ok(cells);
    }
    let mut pending = Some((l0, tok0));
    for i in 0..n {
        let (l, tok) = match pending.take() {
            Some(x) => x,
            None => t.next_token().ok_or_else(|| ShapeError::Truncated {
                format: FMT,
                location: Location::line(t.line() + header_lines),
                message: format!("expected {n} cells, found {i}"),
            })?,
        };
        let k = text::expect_usize(FMT, l + header_lines, Some(tok), "cell size")?;
        used += k + 1;
        if used > size {
            return Err(text::syntax(
                FMT,
                l + header_lines,
                format!("the cells use more than the declared list size {size}"),
            ));
        }
        let mut c = Vec::with_capacity(k);
        for _ in 0..k {
            let v = t.i64(FMT, "point index")?;
            c.push(text::check_index(v, nv, Element::Face, i, || Location::line(t.line() + header_lines))?);
        }
        cells.push(c);
    }
    Ok(cells)
}

/// Whether 4-vertex polygons are tetrahedra: most of them enclose volume (|6V| well above ℓ³·10⁻³, ℓ the
/// longest edge), where a quad of a surface is flat.
fn solid_quads(v: &[[f64; 3]], polys: &Polygons) -> bool {
    let mut solid = 0usize;
    for p in polys.iter() {
        let [a, b, c, d] = [v[p[0] as usize], v[p[1] as usize], v[p[2] as usize], v[p[3] as usize]];
        let vol = vec3::volume6(a, b, c, d).abs();
        let l = [vec3::sub(a, b), vec3::sub(a, c), vec3::sub(a, d), vec3::sub(b, c), vec3::sub(b, d), vec3::sub(c, d)]
            .iter()
            .map(|e| vec3::norm(*e))
            .fold(0.0, f64::max);
        if vol > 1e-3 * l * l * l {
            solid += 1;
        }
    }
    2 * solid > polys.len()
}

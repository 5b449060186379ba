//! Point clouds as text: one point per line, `x y z` or `x y z nx ny nz` (2 columns: planar), separated by
//! white space (`.xyz`) or commas/semicolons (`.csv`, which may start with one header line). Every line must
//! have the column count of the first.

use super::text::{self, Lines};
use super::ReadOptions;
use crate::error::{Location, Result, ShapeError};
use crate::geometry::RawShape;

pub fn read(bytes: &[u8], options: &ReadOptions, csv: bool) -> Result<RawShape> {
    let fmt: &'static str = if csv { "csv" } else { "xyz" };
    let mut raw = RawShape::default();
    let mut normals: Vec<[f64; 3]> = Vec::new();
    let mut columns: Option<usize> = None;
    let mut header_skipped = false;
    let mut vals: Vec<f64> = Vec::with_capacity(8);
    for (ln, line) in Lines::new(bytes) {
        let line = line.trim_ascii();
        if line.is_empty() || line[0] == b'#' || line.starts_with(b"//") {
            continue;
        }
        vals.clear();
        let mut bad = None;
        let fields: Box<dyn Iterator<Item = &[u8]>> = if csv || line.contains(&b',') || line.contains(&b';') {
            Box::new(line.split(|&b| b == b',' || b == b';').map(|f| f.trim_ascii()))
        } else {
            Box::new(text::tokens(line))
        };
        for f in fields {
            match text::parse_f64(f) {
                Some(v) => vals.push(v),
                None => {
                    bad = Some(text::show(f));
                    break;
                }
            }
        }
        if let Some(b) = bad {
            if columns.is_none() && !header_skipped && raw.vertices.is_empty() {
                header_skipped = true;
                raw.notes.push(format!("{fmt}: header line {ln} skipped"));
                continue;
            }
            return Err(text::syntax(fmt, ln, format!("expected a number, found '{b}'")));
        }
        let c = *columns.get_or_insert(vals.len());
        if !matches!(c, 2 | 3 | 6) {
            return Err(text::syntax(fmt, ln, format!("{c} columns; a point line has 2, 3 or 6 (x y z nx ny nz)")));
        }
        if vals.len() != c {
            return Err(text::syntax(fmt, ln, format!("{} columns where the first point line has {c}", vals.len())));
        }
        let p = [vals[0], vals[1], if c >= 3 { vals[2] } else { 0.0 }];
        let i = raw.vertices.len();
        raw.vertices.push(text::check_point(p, i, || Location::line(ln))?);
        if c == 6 {
            normals.push([vals[3], vals[4], vals[5]]);
        }
        if raw.vertices.len() > options.max_vertices {
            options.check_vertices(raw.vertices.len() as u64)?;
        }
    }
    if raw.vertices.is_empty() {
        return Err(ShapeError::Empty { what: format!("the {fmt} input has no points") });
    }
    raw.planar_input = columns == Some(2);
    if columns == Some(6) {
        raw.normals = Some(normals);
    }
    Ok(raw)
}

//! Point clouds as text: one point per line, `x y z` or `x y z nx ny nz` (2 columns: planar; 4, 5 or 7 and more:
//! points in Rⁿ, for manifold learning; 6 columns are a position and a normal unless a header line names the
//! fourth column other than `nx`/`normal_x`, then points in R⁶), separated by white space (`.xyz`) or
//! commas/semicolons (`.csv`, which may start with one header line). Every line must have the column count of
//! the first.

use super::text::{self, Lines};
use super::ReadOptions;
use crate::error::{Location, Result, ShapeError};
use crate::geometry::{Ambient, RawShape};

pub fn read(bytes: &[u8], options: &ReadOptions, csv: bool) -> Result<RawShape> {
    let fmt: &'static str = if csv { "csv" } else { "xyz" };
    let mut raw = RawShape::default();
    let mut normals: Vec<[f64; 3]> = Vec::new();
    let mut columns: Option<usize> = None;
    let mut header_skipped = false;
    // The header's fourth name, where a header names the columns.
    let mut fourth_name: Option<String> = None;
    let mut coords: Vec<f64> = Vec::new();
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
                let names: Vec<String> = line
                    .split(|&b| b == b',' || b == b';' || b == b' ' || b == b'\t')
                    .filter(|f| !f.is_empty())
                    .map(|f| String::from_utf8_lossy(f.trim_ascii()).trim_matches('"').to_ascii_lowercase())
                    .collect();
                fourth_name = names.get(3).cloned();
                raw.notes.push(format!("{fmt}: header line {ln} skipped"));
                continue;
            }
            return Err(text::syntax(fmt, ln, format!("expected a number, found '{b}'")));
        }
        let c = *columns.get_or_insert(vals.len());
        let normals_given = c == 6 && fourth_name.as_deref().is_none_or(|n| matches!(n, "nx" | "normal_x" | "normalx"));
        if c < 2 {
            return Err(text::syntax(
                fmt,
                ln,
                format!("{c} column; a point line has 2 or 3 coordinates, x y z nx ny nz, or n ≥ 4 coordinates"),
            ));
        }
        if vals.len() != c {
            return Err(text::syntax(fmt, ln, format!("{} columns where the first point line has {c}", vals.len())));
        }
        let p = [vals[0], vals[1], if c >= 3 { vals[2] } else { 0.0 }];
        let i = raw.vertices.len();
        raw.vertices.push(text::check_point(p, i, || Location::line(ln))?);
        if normals_given {
            normals.push([vals[3], vals[4], vals[5]]);
        } else if c >= 4 {
            if let Some(j) = vals.iter().position(|v| !v.is_finite()) {
                return Err(text::syntax(fmt, ln, format!("coordinate {} is not finite ({})", j + 1, vals[j])));
            }
            coords.extend_from_slice(&vals);
        }
        if raw.vertices.len() > options.max_vertices {
            options.check_vertices(raw.vertices.len() as u64)?;
        }
    }
    if raw.vertices.is_empty() {
        return Err(ShapeError::Empty { what: format!("the {fmt} input has no points") });
    }
    raw.planar_input = columns == Some(2);
    match columns {
        Some(6) if !normals.is_empty() => raw.normals = Some(normals),
        Some(c) if c >= 4 => {
            raw.notes.push(format!("{fmt}: {c} coordinates per point: a point cloud in R^{c}"));
            raw.ambient = Some(Ambient { dim: c, coords });
        }
        _ => {}
    }
    Ok(raw)
}

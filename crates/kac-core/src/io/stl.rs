//! STL, ASCII and binary. Binary is decided by the size rule (84 + 50·n bytes for the n triangles the header
//! declares, or one byte more), even when the 80-byte header starts with `solid`, as many exporters write.
//! STL stores every triangle with its own three corners; they are welded here by exact position (a tolerance
//! weld is a validation option), so the surface is connected as it was meant to be.

use super::text::{self, Lines};
use super::ReadOptions;
use crate::error::{Location, Result, ShapeError};
use crate::geometry::{validate::weld_exact, Polygons, RawShape};

const FMT: &str = "stl";

/// The binary size rule: the header's triangle count matches the length, tolerating one trailing byte.
pub fn is_binary_by_size(bytes: &[u8]) -> bool {
    if bytes.len() < 84 {
        return false;
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    let expected = 84 + 50 * n;
    let len = bytes.len() as u64;
    len == expected || len == expected + 1
}

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let looks_ascii = bytes.trim_ascii_start().starts_with(b"solid") && !is_binary_by_size(bytes);
    let (soup, mut notes) = if looks_ascii { read_ascii(bytes, options)? } else { read_binary(bytes, options)? };
    let (vertices, map, welded) = weld_exact(&soup);
    let mut polygons = Polygons::with_capacity(soup.len() / 3, soup.len());
    for t in map.chunks_exact(3) {
        polygons.push(t);
    }
    notes.push(format!("stl: {} corners welded into {} vertices by exact position", soup.len(), vertices.len()));
    Ok(RawShape { vertices, polygons, reader_welded: welded, notes, ..Default::default() })
}

fn read_binary(bytes: &[u8], options: &ReadOptions) -> Result<(Vec<[f64; 3]>, Vec<String>)> {
    if bytes.len() < 84 {
        return Err(ShapeError::Truncated {
            format: FMT,
            location: Location::byte(bytes.len()),
            message: "a binary STL needs an 84-byte header".into(),
        });
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    options.check_elements(n as u64)?;
    let mut notes = Vec::new();
    let body = &bytes[84..];
    let have = body.len() / 50;
    if have < n {
        return Err(ShapeError::Truncated {
            format: FMT,
            location: Location::byte(84 + have * 50),
            message: format!("the header declares {n} triangles but the data holds {have}"),
        });
    }
    let extra = body.len() - 50 * n;
    if extra > 0 {
        notes.push(format!("stl: {extra} trailing byte(s) after {n} triangles ignored"));
    }
    let mut soup = Vec::with_capacity(3 * n);
    for (t, rec) in body.chunks_exact(50).take(n).enumerate() {
        for k in 0..3 {
            let o = 12 + 12 * k;
            let f = |i: usize| {
                f32::from_le_bytes([rec[o + 4 * i], rec[o + 4 * i + 1], rec[o + 4 * i + 2], rec[o + 4 * i + 3]]) as f64
            };
            let p = [f(0), f(1), f(2)];
            soup.push(text::check_point(p, 3 * t + k, || Location::byte(84 + 50 * t + o))?);
        }
    }
    Ok((soup, notes))
}

fn read_ascii(bytes: &[u8], options: &ReadOptions) -> Result<(Vec<[f64; 3]>, Vec<String>)> {
    let mut soup: Vec<[f64; 3]> = Vec::new();
    let mut in_loop = 0usize;
    let mut loop_line = 0;
    let mut solids = 0;
    for (ln, line) in Lines::new(bytes) {
        let mut t = text::tokens(line);
        let Some(key) = t.next() else { continue };
        match key.to_ascii_lowercase().as_slice() {
            b"solid" => solids += 1,
            b"vertex" => {
                if in_loop == 0 {
                    return Err(text::syntax(FMT, ln, "'vertex' outside 'outer loop'"));
                }
                let x = text::expect_f64(FMT, ln, t.next(), "x")?;
                let y = text::expect_f64(FMT, ln, t.next(), "y")?;
                let z = text::expect_f64(FMT, ln, t.next(), "z")?;
                soup.push(text::check_point([x, y, z], soup.len(), || Location::line(ln))?);
                in_loop += 1;
                if in_loop > 4 {
                    return Err(text::syntax(FMT, ln, "a facet has more than three vertices"));
                }
            }
            b"outer" => {
                in_loop = 1;
                loop_line = ln;
            }
            b"endloop" => {
                if in_loop != 4 {
                    return Err(text::syntax(
                        FMT,
                        loop_line,
                        format!("a facet loop has {} vertices, STL needs 3", in_loop.saturating_sub(1)),
                    ));
                }
                in_loop = 0;
                if soup.len() / 3 > options.max_elements {
                    options.check_elements((soup.len() / 3) as u64)?;
                }
            }
            b"facet" | b"endfacet" | b"endsolid" => {}
            _ => return Err(text::syntax(FMT, ln, format!("unknown keyword '{}'", text::show(key)))),
        }
    }
    if in_loop != 0 {
        return Err(ShapeError::Truncated {
            format: FMT,
            location: Location::line(loop_line),
            message: "the last facet loop is not closed".into(),
        });
    }
    let notes = if solids > 1 { vec![format!("stl: {solids} solids merged")] } else { Vec::new() };
    Ok((soup, notes))
}

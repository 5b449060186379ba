//! Object File Format: `OFF` and its variants `COFF`, `NOFF`, `CNOFF`, `STOFF`, `4OFF`, `nOFF` (dimension line).
//! One vertex or face per line (the form every common writer uses); extra numbers after the coordinates
//! (normals, colours, texture coordinates) and after a face's indices (colour) are ignored.
//! Homogeneous `4OFF` coordinates are divided by w. Binary OFF is not taken.

use super::text::{self, Lines};
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};

const FMT: &str = "off";

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let mut lines = Lines::new(bytes);
    let next_content = |lines: &mut Lines<'_>| -> Option<(usize, Vec<u8>)> {
        for (ln, line) in lines.by_ref() {
            let l = text::strip_comment(line);
            if !l.is_empty() {
                return Some((ln, l.to_vec()));
            }
        }
        None
    };
    let (ln, header) =
        next_content(&mut lines).ok_or_else(|| ShapeError::Empty { what: "the OFF file has no header".into() })?;
    let mut toks: Vec<&[u8]> = text::tokens(&header).collect();
    let keyword = toks.first().copied().unwrap_or_default();
    let kw = String::from_utf8_lossy(keyword).to_string();
    if !kw.ends_with("OFF") {
        return Err(text::syntax(FMT, ln, format!("expected an OFF header keyword, found '{}'", text::show(keyword))));
    }
    let prefix = &kw[..kw.len() - 3];
    let homogeneous = prefix.contains('4');
    let mut dim = 3usize;
    toks.remove(0);
    if toks.first().is_some_and(|t| t.eq_ignore_ascii_case(b"BINARY")) {
        return Err(ShapeError::Unsupported {
            format: FMT,
            location: Location::line(ln),
            message: "binary OFF is not supported; write it as ASCII OFF".into(),
        });
    }
    let mut counts_line = (ln, toks.iter().map(|t| t.to_vec()).collect::<Vec<_>>());
    if prefix.contains('n') {
        // nOFF: the dimension comes first (on the header line or the next one).
        if counts_line.1.is_empty() {
            let (l, c) =
                next_content(&mut lines).ok_or_else(|| text::syntax(FMT, ln, "missing dimension after nOFF"))?;
            counts_line = (l, text::tokens(&c).map(|t| t.to_vec()).collect());
        }
        let d = text::expect_usize(FMT, counts_line.0, counts_line.1.first().map(|v| v.as_slice()), "dimension")?;
        if !(2..=3).contains(&d) {
            return Err(ShapeError::Unsupported {
                format: FMT,
                location: Location::line(counts_line.0),
                message: format!("dimension {d}; only 2 and 3 are taken"),
            });
        }
        dim = d;
        counts_line.1.remove(0);
    }
    if counts_line.1.is_empty() {
        let (l, c) = next_content(&mut lines).ok_or_else(|| text::syntax(FMT, ln, "missing vertex/face counts"))?;
        counts_line = (l, text::tokens(&c).map(|t| t.to_vec()).collect());
    }
    let cl = counts_line.0;
    let nv = text::expect_usize(FMT, cl, counts_line.1.first().map(|v| v.as_slice()), "vertex count")?;
    let nf = text::expect_usize(FMT, cl, counts_line.1.get(1).map(|v| v.as_slice()), "face count")?;
    options.check_vertices(nv as u64)?;
    options.check_elements(nf as u64)?;

    let mut raw = RawShape { planar_input: dim == 2, ..Default::default() };
    raw.vertices.reserve(text::capacity(nv, bytes.len(), 6));
    let coords = dim + usize::from(homogeneous);
    while raw.vertices.len() < nv {
        let Some((ln, line)) = lines.next() else {
            return Err(ShapeError::Truncated {
                format: FMT,
                location: Location::line(lines.line()),
                message: format!("expected {nv} vertices, found {}", raw.vertices.len()),
            });
        };
        let line = text::strip_comment(line);
        if line.is_empty() {
            continue;
        }
        let mut t = text::tokens(line);
        let mut c = [0.0f64; 4];
        for (k, slot) in c.iter_mut().take(coords).enumerate() {
            *slot = text::expect_f64(FMT, ln, t.next(), ["x", "y", "z", "w"][k.min(3)])?;
        }
        let mut p = [c[0], c[1], if dim == 3 { c[2] } else { 0.0 }];
        if homogeneous {
            let w = c[coords - 1];
            p = [p[0] / w, p[1] / w, p[2] / w];
        }
        let index = raw.vertices.len();
        raw.vertices.push(text::check_point(p, index, || Location::line(ln))?);
    }
    let mut polygons = Polygons::with_capacity(text::capacity(nf, bytes.len(), 6), 0);
    let mut colored = 0usize;
    while polygons.len() < nf {
        let Some((ln, line)) = lines.next() else {
            return Err(ShapeError::Truncated {
                format: FMT,
                location: Location::line(lines.line()),
                message: format!("expected {nf} faces, found {}", polygons.len()),
            });
        };
        let line = text::strip_comment(line);
        if line.is_empty() {
            continue;
        }
        let face = polygons.len();
        let mut t = text::tokens(line);
        let k = text::expect_usize(FMT, ln, t.next(), "face size")?;
        if k < 3 {
            return Err(ShapeError::InvalidElement {
                element: Element::Face,
                index: face,
                rule: format!("a face needs at least 3 corners, this one has {k}"),
                location: Location::line(ln),
            });
        }
        for _ in 0..k {
            let tok = t
                .next()
                .ok_or_else(|| text::syntax(FMT, ln, format!("face {face} declares {k} corners but lists fewer")))?;
            let v = text::parse_i64(tok).ok_or_else(|| {
                text::syntax(FMT, ln, format!("expected a vertex index, found '{}'", text::show(tok)))
            })?;
            polygons.indices.push(text::check_index(v, nv, Element::Face, face, || Location::line(ln))?);
        }
        polygons.close();
        if t.next().is_some() {
            colored += 1;
        }
    }
    if colored > 0 {
        raw.notes.push(format!("off: extra values (colours) after the indices of {colored} face(s) ignored"));
    }
    if !prefix.is_empty() {
        raw.notes.push(format!("off: {kw} header; per-vertex extras beyond the coordinates ignored"));
    }
    raw.polygons = polygons;
    Ok(raw)
}

//! Gmsh `.msh`: version 2 (ASCII and binary) and version 4.1 (ASCII). Node tags may be arbitrary; elements are
//! read by type: tetrahedra (4, and the corners of 10-node tets), triangles (2, 9), quads (3) and lines (1, 8).
//! With tetrahedra the file is a tet mesh; otherwise triangles make a surface and lines a polyline.

use super::text::{self, show};
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};
use std::collections::HashMap;

const FMT: &str = "gmsh";

/// Number of nodes of a Gmsh element type, where known.
fn nodes_of(ty: i64) -> Option<usize> {
    Some(match ty {
        1 => 2,
        2 => 3,
        3 => 4,
        4 => 4,
        5 => 8,
        6 => 6,
        7 => 5,
        8 => 3,
        9 => 6,
        10 => 9,
        11 => 10,
        12 => 27,
        13 => 18,
        14 => 14,
        15 => 1,
        16 => 8,
        17 => 20,
        18 => 15,
        19 => 13,
        20 => 9,
        21 => 10,
        22 => 12,
        23 => 15,
        24 => 15,
        25 => 21,
        26 => 4,
        27 => 5,
        28 => 6,
        29 => 20,
        30 => 35,
        31 => 56,
        _ => return None,
    })
}

struct Scanner<'a> {
    b: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Scanner<'a> {
    fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.b.len() {
            return None;
        }
        let rest = &self.b[self.pos..];
        let end = rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        self.line += 1;
        Some((self.line, rest[..end].trim_ascii()))
    }
    fn token(&mut self) -> Option<(usize, &'a [u8])> {
        while self.pos < self.b.len() && self.b[self.pos].is_ascii_whitespace() {
            if self.b[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        if self.pos >= self.b.len() {
            return None;
        }
        let s = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some((self.line, &self.b[s..self.pos]))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        let t = self.token();
        text::expect_f64(FMT, t.map_or(self.line, |t| t.0), t.map(|t| t.1), what)
    }
    fn i64(&mut self, what: &str) -> Result<i64> {
        match self.token() {
            Some((l, t)) => text::parse_i64(t)
                .ok_or_else(|| text::syntax(FMT, l, format!("expected an integer for {what}, found '{}'", show(t)))),
            None => Err(text::syntax(FMT, self.line, format!("missing {what}"))),
        }
    }
    fn count(&mut self, what: &str) -> Result<usize> {
        let t = self.token();
        text::expect_usize(FMT, t.map_or(self.line, |t| t.0), t.map(|t| t.1), what)
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.b.len()).ok_or_else(|| ShapeError::Truncated {
            format: FMT,
            location: Location::byte(self.pos),
            message: format!("the binary data ends inside {what}"),
        })?;
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    /// Skips to the line after `$End<name>`.
    fn skip_section(&mut self, name: &[u8]) -> Result<()> {
        let mut end = b"$End".to_vec();
        end.extend_from_slice(name);
        let start = self.line;
        while let Some((_, l)) = self.next_line() {
            if l == end.as_slice() {
                return Ok(());
            }
        }
        Err(ShapeError::Truncated {
            format: FMT,
            location: Location::line(start),
            message: format!("section ${} is not closed", String::from_utf8_lossy(name)),
        })
    }
    fn expect_end(&mut self, name: &str) -> Result<()> {
        // Binary sections end with a newline before `$End...`; ASCII ones too.
        match self.token() {
            Some((_, t)) if t == format!("$End{name}").as_bytes() => Ok(()),
            Some((l, t)) => Err(text::syntax(FMT, l, format!("expected $End{name}, found '{}'", show(t)))),
            None => Err(ShapeError::Truncated {
                format: FMT,
                location: Location::line(self.line),
                message: format!("missing $End{name}"),
            }),
        }
    }
}

struct Builder {
    raw: RawShape,
    tags: HashMap<u64, u32>,
    polygons: Polygons,
    higher_order: usize,
    other: usize,
}

impl Builder {
    fn node(&mut self, tag: i64, p: [f64; 3], loc: impl FnOnce() -> Location) -> Result<()> {
        let i = self.raw.vertices.len();
        self.raw.vertices.push(text::check_point(p, i, loc)?);
        if tag < 0 || self.tags.insert(tag as u64, i as u32).is_some() {
            return Err(ShapeError::InvalidElement {
                element: Element::Vertex,
                index: i,
                rule: format!("node tag {tag} is negative or repeated"),
                location: Location::Unknown,
            });
        }
        Ok(())
    }
    fn element(&mut self, ty: i64, index: usize, nodes: &[i64], loc: impl Fn() -> Location) -> Result<()> {
        let (arity, element) = match ty {
            4 | 11 => (4, Element::Tetrahedron),
            2 | 9 => (3, Element::Face),
            3 | 16 | 10 => (4, Element::Face),
            1 | 8 => (2, Element::Segment),
            _ => {
                self.other += 1;
                return Ok(());
            }
        };
        if nodes.len() > arity {
            self.higher_order += 1;
        }
        let mut idx = [0u32; 4];
        for (k, &tag) in nodes.iter().take(arity).enumerate() {
            idx[k] = *self.tags.get(&(tag as u64)).filter(|_| tag >= 0).ok_or_else(|| ShapeError::IndexOutOfRange {
                element,
                index,
                value: tag,
                vertex_count: self.raw.vertices.len(),
                location: loc(),
            })?;
        }
        match element {
            Element::Tetrahedron => self.raw.tets.push(idx),
            Element::Face => self.polygons.push(&idx[..arity]),
            _ => self.raw.segments.push([idx[0], idx[1]]),
        }
        Ok(())
    }
}

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let mut s = Scanner { b: bytes, pos: 0, line: 0 };
    let mut version = 0.0f64;
    let mut binary = false;
    let mut big = false;
    let mut bld = Builder {
        raw: RawShape::default(),
        tags: HashMap::new(),
        polygons: Polygons::default(),
        higher_order: 0,
        other: 0,
    };
    let mut seen_format = false;
    while let Some((ln, line)) = s.next_line() {
        if line.is_empty() {
            continue;
        }
        match line {
            b"$MeshFormat" => {
                let (l, head) = s.next_line().ok_or_else(|| text::syntax(FMT, ln, "missing version line"))?;
                let mut t = text::tokens(head);
                version = text::expect_f64(FMT, l, t.next(), "version")?;
                let ft = text::expect_usize(FMT, l, t.next(), "file type")?;
                let ds = text::expect_usize(FMT, l, t.next(), "data size")?;
                binary = ft == 1;
                if !(2.0..3.0).contains(&version) && !(4.1..4.2).contains(&version) {
                    return Err(ShapeError::Unsupported {
                        format: FMT,
                        location: Location::line(l),
                        message: format!("MSH version {version}; versions 2.x and 4.1 are taken"),
                    });
                }
                if binary && version >= 4.0 {
                    return Err(ShapeError::Unsupported {
                        format: FMT,
                        location: Location::line(l),
                        message: "binary MSH 4 is not supported; save as MSH 4.1 ASCII or MSH 2 binary".into(),
                    });
                }
                if binary {
                    if ds != 8 {
                        return Err(ShapeError::Unsupported {
                            format: FMT,
                            location: Location::line(l),
                            message: format!("data size {ds}; binary MSH needs 8-byte doubles"),
                        });
                    }
                    let one = s.take(4, "the endianness marker")?;
                    big = i32::from_le_bytes([one[0], one[1], one[2], one[3]]) != 1;
                    if big && i32::from_be_bytes([one[0], one[1], one[2], one[3]]) != 1 {
                        return Err(text::syntax(FMT, l + 1, "invalid endianness marker"));
                    }
                }
                s.expect_end("MeshFormat")?;
                seen_format = true;
            }
            b"$Nodes" => {
                if !seen_format {
                    return Err(text::syntax(FMT, ln, "$Nodes before $MeshFormat"));
                }
                if version >= 4.0 {
                    nodes_v4(&mut s, &mut bld, options)?;
                } else {
                    nodes_v2(&mut s, &mut bld, options, binary, big)?;
                }
                s.expect_end("Nodes")?;
            }
            b"$Elements" => {
                if version >= 4.0 {
                    elements_v4(&mut s, &mut bld, options)?;
                } else {
                    elements_v2(&mut s, &mut bld, options, binary, big)?;
                }
                s.expect_end("Elements")?;
            }
            l if l.starts_with(b"$") && !l.starts_with(b"$End") => s.skip_section(&l[1..])?,
            other => return Err(text::syntax(FMT, ln, format!("unexpected line '{}'", show(other)))),
        }
    }
    let Builder { mut raw, mut polygons, higher_order, other, .. } = bld;
    if !raw.tets.is_empty() {
        if !polygons.is_empty() {
            raw.notes.push(format!("gmsh: {} surface element(s) beside the tetrahedra not used", polygons.len()));
        }
        polygons = Polygons::default();
    }
    if higher_order > 0 {
        raw.notes.push(format!("gmsh: {higher_order} higher-order element(s) reduced to their corner vertices"));
    }
    if other > 0 {
        raw.notes.push(format!("gmsh: {other} element(s) of other types (points, hexahedra, prisms, ...) ignored"));
    }
    raw.polygons = polygons;
    Ok(raw)
}

fn nodes_v2(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions, binary: bool, big: bool) -> Result<()> {
    let n = s.count("node count")?;
    options.check_vertices(n as u64)?;
    b.raw.vertices.reserve(text::capacity(n, s.b.len(), 8));
    if binary {
        // The count line ends with a newline, then n records of (int tag, 3 doubles).
        s.take(1, "node data")?;
        for i in 0..n {
            let at = s.pos;
            let r = s.take(28, "a node record")?;
            let tag = rd_i32(&r[0..4], big) as i64;
            let p = [rd_f64(&r[4..12], big), rd_f64(&r[12..20], big), rd_f64(&r[20..28], big)];
            b.node(tag, p, || Location::byte(at)).map_err(|e| relocate(e, i, Location::byte(at)))?;
        }
    } else {
        for i in 0..n {
            let tag = s.i64("node tag")?;
            let p = [s.f64("x")?, s.f64("y")?, s.f64("z")?];
            let line = s.line;
            b.node(tag, p, || Location::line(line)).map_err(|e| relocate(e, i, Location::line(line)))?;
        }
    }
    Ok(())
}

fn elements_v2(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions, binary: bool, big: bool) -> Result<()> {
    let n = s.count("element count")?;
    options.check_elements(n as u64)?;
    let mut nodes: Vec<i64> = Vec::new();
    if binary {
        s.take(1, "element data")?;
        let mut done = 0;
        while done < n {
            let at = s.pos;
            let h = s.take(12, "an element block header")?;
            let (ty, count, ntags) = (rd_i32(&h[0..4], big) as i64, rd_i32(&h[4..8], big), rd_i32(&h[8..12], big));
            let nn = nodes_of(ty).ok_or_else(|| ShapeError::Unsupported {
                format: FMT,
                location: Location::byte(at),
                message: format!("element type {ty}"),
            })?;
            if count <= 0 || ntags < 0 || done + count as usize > n {
                return Err(ShapeError::Syntax {
                    format: FMT,
                    location: Location::byte(at),
                    message: format!("invalid element block header ({count} elements, {ntags} tags)"),
                });
            }
            let rec = 4 * (1 + ntags as usize + nn);
            for _ in 0..count {
                let at = s.pos;
                let r = s.take(rec, "an element record")?;
                nodes.clear();
                let off = 4 * (1 + ntags as usize);
                nodes.extend((0..nn).map(|k| rd_i32(&r[off + 4 * k..], big) as i64));
                b.element(ty, done, &nodes, || Location::byte(at))?;
                done += 1;
            }
        }
    } else {
        for i in 0..n {
            let _id = s.i64("element id")?;
            let line = s.line;
            let ty = s.i64("element type")?;
            let ntags = s.count("tag count")?;
            for _ in 0..ntags {
                s.i64("tag")?;
            }
            let nn = nodes_of(ty).ok_or_else(|| ShapeError::Unsupported {
                format: FMT,
                location: Location::line(line),
                message: format!("element type {ty}"),
            })?;
            nodes.clear();
            for _ in 0..nn {
                nodes.push(s.i64("node tag")?);
            }
            b.element(ty, i, &nodes, || Location::line(line))?;
        }
    }
    Ok(())
}

fn nodes_v4(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
    let blocks = s.count("entity block count")?;
    let n = s.count("node count")?;
    options.check_vertices(n as u64)?;
    s.count("min node tag")?;
    s.count("max node tag")?;
    b.raw.vertices.reserve(text::capacity(n, s.b.len(), 8));
    let mut tags = Vec::new();
    for _ in 0..blocks {
        let dim = s.count("entity dimension")?;
        s.i64("entity tag")?;
        let parametric = s.count("parametric flag")? != 0;
        let m = s.count("nodes in block")?;
        if b.raw.vertices.len() + m > n {
            return Err(text::syntax(FMT, s.line, "more nodes in blocks than declared"));
        }
        tags.clear();
        for _ in 0..m {
            tags.push(s.i64("node tag")?);
        }
        let extra = if parametric { dim.min(3) } else { 0 };
        for (k, &tag) in tags.iter().enumerate() {
            let p = [s.f64("x")?, s.f64("y")?, s.f64("z")?];
            for _ in 0..extra {
                s.f64("parametric coordinate")?;
            }
            let line = s.line;
            let i = b.raw.vertices.len();
            b.node(tag, p, || Location::line(line)).map_err(|e| relocate(e, i.max(k), Location::line(line)))?;
        }
    }
    Ok(())
}

fn elements_v4(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
    let blocks = s.count("entity block count")?;
    let n = s.count("element count")?;
    options.check_elements(n as u64)?;
    s.count("min element tag")?;
    s.count("max element tag")?;
    let mut nodes = Vec::new();
    let mut index = 0;
    for _ in 0..blocks {
        s.count("entity dimension")?;
        s.i64("entity tag")?;
        let line = s.line;
        let ty = s.i64("element type")?;
        let m = s.count("elements in block")?;
        let nn = nodes_of(ty).ok_or_else(|| ShapeError::Unsupported {
            format: FMT,
            location: Location::line(line),
            message: format!("element type {ty}"),
        })?;
        if index + m > n {
            return Err(text::syntax(FMT, line, "more elements in blocks than declared"));
        }
        for _ in 0..m {
            s.i64("element tag")?;
            let line = s.line;
            nodes.clear();
            for _ in 0..nn {
                nodes.push(s.i64("node tag")?);
            }
            b.element(ty, index, &nodes, || Location::line(line))?;
            index += 1;
        }
    }
    Ok(())
}

fn relocate(e: ShapeError, index: usize, location: Location) -> ShapeError {
    match e {
        ShapeError::InvalidElement { element, rule, .. } => {
            ShapeError::InvalidElement { element, index, rule, location }
        }
        other => other,
    }
}

fn rd_i32(b: &[u8], big: bool) -> i32 {
    let a = [b[0], b[1], b[2], b[3]];
    if big {
        i32::from_be_bytes(a)
    } else {
        i32::from_le_bytes(a)
    }
}

fn rd_f64(b: &[u8], big: bool) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[..8]);
    if big {
        f64::from_be_bytes(a)
    } else {
        f64::from_le_bytes(a)
    }
}

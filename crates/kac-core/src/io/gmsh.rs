//! Gmsh `.msh`, versions 2.x and 4.1, ASCII and binary (either byte order; 4.1 binary with a 4- or 8-byte
//! `size_t`). Node tags may be arbitrary; elements are read by type: tetrahedra (4, and the corners of 10-node
//! tets), triangles (2, 9), quads (3, 10, 16) and lines (1, 8). With tetrahedra the file is a tet mesh; otherwise
//! triangles make a surface and lines a polyline.
//!
//! Only `$MeshFormat`, `$Nodes` and `$Elements` are read. Every other section is skipped, wherever it stands,
//! and named in a note:
//! - `$NodeData`, `$ElementData`, `$ElementNodeData`: by the sizes their header declares (integer tag 2 is the
//!   component count, 3 the entity count); binary values are never searched for a closing tag.
//! - `$Entities`, `$PartitionedEntities`, `$Periodic`, `$GhostElements`, `$Parametrizations` of a 4.1 binary
//!   file: by the counts inside them.
//! - Sections of text (`$PhysicalNames`, `$InterpolationScheme`, `$Comments`, 2.x `$Periodic`, every section of
//!   an ASCII file) and unknown sections: line by line up to `$End<Name>`. In a binary file that is a search for
//!   the closing tag, which the note of an unknown section says.
//!
//! A closing tag may follow binary data with a newline (Gmsh) or without (MshIO). Every declared count is checked
//! against the bytes left before it is used, so a lying header is a typed error, never an allocation or a panic.

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
    /// The 1-based line of `pos`.
    line: usize,
    /// Set by `$MeshFormat`: binary file, its byte order, and the width of its `size_t` (4.1).
    binary: bool,
    big: bool,
    word: usize,
}

impl<'a> Scanner<'a> {
    fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.b.len() {
            return None;
        }
        let rest = &self.b[self.pos..];
        let line = self.line;
        let end = match rest.iter().position(|&c| c == b'\n') {
            Some(end) => {
                self.line += 1;
                end
            }
            None => rest.len(),
        };
        self.pos += (end + 1).min(rest.len());
        Some((line, rest[..end].trim_ascii()))
    }
    fn skip_space(&mut self) {
        while self.pos < self.b.len() && self.b[self.pos].is_ascii_whitespace() {
            if self.b[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }
    fn token(&mut self) -> Option<(usize, &'a [u8])> {
        self.skip_space();
        if self.pos >= self.b.len() {
            return None;
        }
        let s = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some((self.line, &self.b[s..self.pos]))
    }
    /// Where the next read starts: a byte offset in a binary file, a line in an ASCII one.
    fn here(&self) -> Location {
        if self.binary {
            Location::byte(self.pos)
        } else {
            Location::line(self.line)
        }
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
    /// `n` records of `size` bytes; the declared count is checked against the bytes left before anything is read.
    fn records(&mut self, n: u64, size: usize, what: &str) -> Result<&'a [u8]> {
        let left = self.b.len() - self.pos;
        match usize::try_from(n).ok().and_then(|n| n.checked_mul(size)) {
            Some(total) if total <= left => self.take(total, what),
            _ => Err(ShapeError::Truncated {
                format: FMT,
                location: Location::byte(self.pos),
                message: format!("{what}: {n} × {size} bytes declared, {left} left"),
            }),
        }
    }
    /// A binary `int`.
    fn int(&mut self, what: &str) -> Result<i32> {
        let big = self.big;
        self.take(4, what).map(|r| rd_i32(r, big))
    }
    /// A binary `size_t` of the file's width.
    fn size(&mut self, what: &str) -> Result<u64> {
        let (word, big) = (self.word, self.big);
        self.take(word, what).map(|r| rd_size(r, word, big))
    }
    /// Skips to the line after `$End<name>`; `header` is where the section starts.
    fn skip_lines(&mut self, name: &[u8], header: &Location) -> Result<()> {
        let mut end = b"$End".to_vec();
        end.extend_from_slice(name);
        while let Some((_, l)) = self.next_line() {
            if l == end.as_slice() {
                return Ok(());
            }
        }
        Err(ShapeError::Truncated {
            format: FMT,
            location: header.clone(),
            message: format!("section ${} is not closed", show(name)),
        })
    }
    fn expect_end(&mut self, name: &str) -> Result<()> {
        // Gmsh writes a newline between binary data and `$End...`; other writers (MshIO) none.
        self.skip_space();
        let at = self.here();
        match self.token() {
            Some((_, t)) if t.strip_prefix(b"$End") == Some(name.as_bytes()) => Ok(()),
            Some((_, t)) => Err(ShapeError::Syntax {
                format: FMT,
                location: at,
                message: format!("expected $End{name} after the declared content of ${name}, found '{}'", show(t)),
            }),
            None => Err(ShapeError::Truncated { format: FMT, location: at, message: format!("missing $End{name}") }),
        }
    }
    /// The next line of a section's ASCII header, with where it starts.
    fn header_line(&mut self, section: &str, what: &str) -> Result<(Location, &'a [u8])> {
        let at = self.here();
        match self.next_line() {
            Some((_, l)) if !l.starts_with(b"$End") => Ok((at, l)),
            Some((_, l)) => Err(ShapeError::Syntax {
                format: FMT,
                location: at,
                message: format!("{section} ends before its {what}: found '{}'", show(l)),
            }),
            None => Err(ShapeError::Truncated {
                format: FMT,
                location: at,
                message: format!("the input ends in the header of {section}, before its {what}"),
            }),
        }
    }
    /// A header line holding a non-negative integer (the first token, as Gmsh reads it).
    fn header_count(&mut self, section: &str, what: &str) -> Result<u64> {
        let (at, l) = self.header_line(section, what)?;
        let t = text::tokens(l).next().unwrap_or(b"");
        text::parse_i64(t).and_then(|v| u64::try_from(v).ok()).ok_or_else(|| ShapeError::Syntax {
            format: FMT,
            location: at,
            message: format!("expected a non-negative integer for the {what} of {section}, found '{}'", show(t)),
        })
    }
}

/// How a section other than the mesh was passed over.
enum Passed {
    /// A post-processing view, with its number of values.
    Data(u64),
    /// By its declared counts, or line by line through text.
    Section,
    /// An unknown section of a binary file, by searching for its closing tag.
    Searched,
}

#[derive(Default)]
struct Tally {
    sections: usize,
    values: Option<u64>,
    searched: bool,
}

/// The sections skipped, by name in order of first appearance; past `NOTED_KINDS` names only counted.
#[derive(Default)]
struct Skipped {
    kinds: Vec<(String, Tally)>,
    others: usize,
}

const NOTED_KINDS: usize = 16;

impl Skipped {
    fn add(&mut self, name: &[u8], passed: Passed) {
        let name = show(name);
        let i = match self.kinds.iter().position(|(n, _)| *n == name) {
            Some(i) => i,
            None if self.kinds.len() < NOTED_KINDS => {
                self.kinds.push((name, Tally::default()));
                self.kinds.len() - 1
            }
            None => {
                self.others += 1;
                return;
            }
        };
        let t = &mut self.kinds[i].1;
        t.sections += 1;
        match passed {
            Passed::Data(v) => t.values = Some(t.values.unwrap_or(0).saturating_add(v)),
            Passed::Searched => t.searched = true,
            Passed::Section => {}
        }
    }
    fn notes(self) -> Vec<String> {
        let mut notes: Vec<String> = self
            .kinds
            .into_iter()
            .map(|(name, t)| match t.values {
                Some(v) => {
                    format!("gmsh: skipped ${name} ({}, {})", plural(t.sections as u64, "view"), plural(v, "value"))
                }
                None if t.searched => format!(
                    "gmsh: skipped ${name} ({}; unknown in a binary file, its end was found by searching for $End{name})",
                    plural(t.sections as u64, "section")
                ),
                None => format!("gmsh: skipped ${name} ({})", plural(t.sections as u64, "section")),
            })
            .collect();
        if self.others > 0 {
            notes.push(format!("gmsh: skipped {} of other kinds", plural(self.others as u64, "more section")));
        }
        notes
    }
}

fn plural(n: u64, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
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
    let mut s = Scanner { b: bytes, pos: 0, line: 1, binary: false, big: false, word: 8 };
    let mut version = 0.0f64;
    let mut bld = Builder {
        raw: RawShape::default(),
        tags: HashMap::new(),
        polygons: Polygons::default(),
        higher_order: 0,
        other: 0,
    };
    let mut seen_format = false;
    let mut skipped = Skipped::default();
    loop {
        let at = s.pos;
        let Some((ln, line)) = s.next_line() else { break };
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
                if !(2.0..3.0).contains(&version) && !(4.1..4.2).contains(&version) {
                    return Err(ShapeError::Unsupported {
                        format: FMT,
                        location: Location::line(l),
                        message: format!("MSH version {version}; versions 2.x and 4.1 are taken"),
                    });
                }
                if ft == 1 {
                    // 2.x: the size of a double; 4.1: the size of a size_t (doubles are 8 bytes).
                    let taken = if version >= 4.0 { ds == 4 || ds == 8 } else { ds == 8 };
                    if !taken {
                        return Err(ShapeError::Unsupported {
                            format: FMT,
                            location: Location::line(l),
                            message: format!("data size {ds}; binary MSH 2 needs 8, MSH 4.1 4 or 8"),
                        });
                    }
                    let one = s.take(4, "the endianness marker")?;
                    let one = [one[0], one[1], one[2], one[3]];
                    s.big = i32::from_le_bytes(one) != 1;
                    if s.big && i32::from_be_bytes(one) != 1 {
                        return Err(text::syntax(FMT, l + 1, "invalid endianness marker"));
                    }
                    s.word = ds;
                }
                s.binary = ft == 1;
                s.expect_end("MeshFormat")?;
                seen_format = true;
            }
            b"$Nodes" => {
                if !seen_format {
                    return Err(text::syntax(FMT, ln, "$Nodes before $MeshFormat"));
                }
                match (version >= 4.0, s.binary) {
                    (true, false) => nodes_v4(&mut s, &mut bld, options)?,
                    (true, true) => nodes_v4_binary(&mut s, &mut bld, options)?,
                    (false, binary) => nodes_v2(&mut s, &mut bld, options, binary)?,
                }
                s.expect_end("Nodes")?;
            }
            b"$Elements" => {
                match (version >= 4.0, s.binary) {
                    (true, false) => elements_v4(&mut s, &mut bld, options)?,
                    (true, true) => elements_v4_binary(&mut s, &mut bld, options)?,
                    (false, binary) => elements_v2(&mut s, &mut bld, options, binary)?,
                }
                s.expect_end("Elements")?;
            }
            l if l.starts_with(b"$") && !l.starts_with(b"$End") => {
                let header = if s.binary { Location::byte(at) } else { Location::line(ln) };
                let passed = skip_section(&mut s, &l[1..], &header, version >= 4.0)?;
                skipped.add(&l[1..], passed);
            }
            other => return Err(text::syntax(FMT, ln, format!("unexpected line '{}'", show(other)))),
        }
    }
    let Builder { mut raw, mut polygons, higher_order, other, .. } = bld;
    raw.notes.extend(skipped.notes());
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

/// Passes over the section whose header line `$<name>` was just read, to the line after its closing tag.
fn skip_section(s: &mut Scanner<'_>, name: &[u8], header: &Location, v4: bool) -> Result<Passed> {
    let binary4 = s.binary && v4;
    match name {
        b"NodeData" => skip_data(s, "NodeData", header, false).map(Passed::Data),
        b"ElementData" => skip_data(s, "ElementData", header, false).map(Passed::Data),
        b"ElementNodeData" => skip_data(s, "ElementNodeData", header, true).map(Passed::Data),
        b"Entities" if binary4 => skip_entities(s, "Entities").map(|_| Passed::Section),
        b"PartitionedEntities" if binary4 => skip_entities(s, "PartitionedEntities").map(|_| Passed::Section),
        b"Periodic" if binary4 => skip_periodic(s).map(|_| Passed::Section),
        b"GhostElements" if binary4 => skip_ghost_elements(s).map(|_| Passed::Section),
        b"Parametrizations" if binary4 => skip_parametrizations(s).map(|_| Passed::Section),
        // Text in every encoding (the 4.1 sections above too, in an ASCII file).
        b"PhysicalNames" | b"InterpolationScheme" | b"Comments" | b"Periodic" => {
            s.skip_lines(name, header).map(|_| Passed::Section)
        }
        _ if s.binary => s.skip_lines(name, header).map(|_| Passed::Searched),
        _ => s.skip_lines(name, header).map(|_| Passed::Section),
    }
}

/// `$NodeData`, `$ElementData`, `$ElementNodeData`: a header of string, real and integer tags, each group a count
/// line and one line per tag; integer tag 2 is the component count, 3 the entity count (none with fewer tags, as
/// Gmsh reads it). Each entity is a tag, for `$ElementNodeData` a node count, then components × nodes values:
/// ASCII tokens, or in binary an `int`, an `int` and `double`s. Returns the number of values.
fn skip_data(s: &mut Scanner<'_>, name: &str, header: &Location, per_node: bool) -> Result<u64> {
    let section = format!("${name}");
    for group in ["string tag", "real tag"] {
        let n = s.header_count(&section, &format!("{group} count"))?;
        for _ in 0..n {
            s.header_line(&section, group)?;
        }
    }
    let n = s.header_count(&section, "integer tag count")?;
    let mut int_tags = [0u64; 3];
    for k in 0..n {
        if (1..3).contains(&k) {
            int_tags[k as usize] = s.header_count(&section, if k == 1 { "component count" } else { "entity count" })?;
        } else {
            s.header_line(&section, "integer tag")?;
        }
    }
    let (components, entities) = (int_tags[1], int_tags[2]);
    let mut values = 0u64;
    if s.binary {
        let what = format!("the values of {section}");
        if per_node {
            for i in 0..entities {
                let at = s.pos;
                let head = s.take(8, &what)?;
                let nodes = rd_i32(&head[4..], s.big);
                let n = u64::try_from(nodes).map_err(|_| ShapeError::Syntax {
                    format: FMT,
                    location: Location::byte(at),
                    message: format!("entity {i} of {section} has {nodes} nodes"),
                })?;
                let n = n.saturating_mul(components);
                s.records(n, 8, &what)?;
                values = values.saturating_add(n);
            }
        } else {
            let record = usize::try_from(components).ok().and_then(|c| c.checked_mul(8)?.checked_add(4));
            s.records(entities, record.unwrap_or(usize::MAX), &what)?;
            values = entities.saturating_mul(components);
        }
        s.expect_end(name)?;
    } else {
        let (tag, nodes) = (format!("an entity tag of {section}"), format!("a node count of {section}"));
        for _ in 0..entities {
            s.i64(&tag)?;
            let n = if per_node { s.count(&nodes)? as u64 } else { 1 };
            let n = n.saturating_mul(components);
            for _ in 0..n {
                match s.token() {
                    Some((_, t)) if !t.starts_with(b"$") => {}
                    Some((l, t)) => {
                        return Err(text::syntax(
                            FMT,
                            l,
                            format!("{section} ends before its declared values: found '{}'", show(t)),
                        ))
                    }
                    None => {
                        return Err(ShapeError::Truncated {
                            format: FMT,
                            location: Location::line(s.line),
                            message: format!("the input ends inside the values of {section}"),
                        })
                    }
                }
            }
            values = values.saturating_add(n);
        }
        // Gmsh, too, passes over whatever follows the declared values up to the closing tag.
        s.skip_lines(name.as_bytes(), header)?;
    }
    Ok(values)
}

/// `$Entities` / `$PartitionedEntities` of a 4.1 binary file. Partitioned: `size_t` partition count, `size_t`
/// ghost count and two `int`s per ghost first. Then four `size_t` counts (points, curves, surfaces, volumes);
/// each entity is an `int` tag (partitioned: tag, parent dimension, parent tag, `size_t` count of `int`
/// partitions), 3 (point) or 6 (bounding box) `double`s, `size_t` count of `int` physical tags and, but for
/// points, `size_t` count of `int` bounding entities.
fn skip_entities(s: &mut Scanner<'_>, name: &str) -> Result<()> {
    let what = format!("${name}");
    let partitioned = name == "PartitionedEntities";
    if partitioned {
        s.size(&what)?;
        let ghosts = s.size(&what)?;
        s.records(ghosts, 8, &what)?;
    }
    let mut counts = [0u64; 4];
    for c in &mut counts {
        *c = s.size(&what)?;
    }
    for (dim, &n) in counts.iter().enumerate() {
        for _ in 0..n {
            if partitioned {
                s.records(3, 4, &what)?;
                let partitions = s.size(&what)?;
                s.records(partitions, 4, &what)?;
            } else {
                s.int(&what)?;
            }
            s.records(if dim == 0 { 3 } else { 6 }, 8, &what)?;
            let physicals = s.size(&what)?;
            s.records(physicals, 4, &what)?;
            if dim > 0 {
                let bounding = s.size(&what)?;
                s.records(bounding, 4, &what)?;
            }
        }
    }
    s.expect_end(name)
}

/// `$Periodic` of a 4.1 binary file: `size_t` link count; each link is three `int`s (dimension, tag, source
/// tag), `size_t` count of affine `double`s, `size_t` count of node pairs of two `size_t`s.
fn skip_periodic(s: &mut Scanner<'_>) -> Result<()> {
    let what = "$Periodic";
    let links = s.size(what)?;
    for _ in 0..links {
        s.records(3, 4, what)?;
        let affine = s.size(what)?;
        s.records(affine, 8, what)?;
        let pairs = s.size(what)?;
        s.records(pairs, 2 * s.word, what)?;
    }
    s.expect_end("Periodic")
}

/// `$GhostElements` of a 4.1 binary file: `size_t` count; each is a `size_t` element tag, an `int` partition and
/// a `size_t` count of `int` ghost partitions.
fn skip_ghost_elements(s: &mut Scanner<'_>) -> Result<()> {
    let what = "$GhostElements";
    let n = s.size(what)?;
    for _ in 0..n {
        s.size(what)?;
        s.int(what)?;
        let partitions = s.size(what)?;
        s.records(partitions, 4, what)?;
    }
    s.expect_end("GhostElements")
}

/// `$Parametrizations` of a 4.1 binary file: `size_t` curve and surface counts; a curve is an `int` tag and a
/// `size_t` count of nodes of 4 `double`s, a surface an `int` tag, `size_t` counts of nodes (11 `double`s) and
/// triangles (3 `int`s).
fn skip_parametrizations(s: &mut Scanner<'_>) -> Result<()> {
    let what = "$Parametrizations";
    let curves = s.size(what)?;
    let surfaces = s.size(what)?;
    for _ in 0..curves {
        s.int(what)?;
        let nodes = s.size(what)?;
        s.records(nodes, 4 * 8, what)?;
    }
    for _ in 0..surfaces {
        s.int(what)?;
        let nodes = s.size(what)?;
        let triangles = s.size(what)?;
        s.records(nodes, 11 * 8, what)?;
        s.records(triangles, 3 * 4, what)?;
    }
    s.expect_end("Parametrizations")
}

fn nodes_v2(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions, binary: bool) -> Result<()> {
    let n = s.count("node count")?;
    options.check_vertices(n as u64)?;
    b.raw.vertices.reserve(text::capacity(n, s.b.len(), 8));
    if binary {
        let big = s.big;
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

fn elements_v2(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions, binary: bool) -> Result<()> {
    let n = s.count("element count")?;
    options.check_elements(n as u64)?;
    let mut nodes: Vec<i64> = Vec::new();
    if binary {
        let big = s.big;
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

/// 4.1 binary `$Nodes`: four `size_t` (blocks, nodes, min and max tag); each block is three `int`s (dimension,
/// entity tag, parametric), a `size_t` node count, the `size_t` tags, then per node x, y, z and, when
/// parametric, one `double` per dimension.
fn nodes_v4_binary(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
    let (word, big) = (s.word, s.big);
    let what = "the $Nodes header";
    let blocks = s.size(what)?;
    let n = s.size(what)?;
    options.check_vertices(n)?;
    s.size(what)?;
    s.size(what)?;
    b.raw.vertices.reserve(text::capacity(usize::try_from(n).unwrap_or(usize::MAX), s.b.len() - s.pos, 24 + word));
    for _ in 0..blocks {
        let at = s.pos;
        let head = s.records(3, 4, "a $Nodes block header")?;
        let (dim, parametric) = (rd_i32(&head[0..4], big), rd_i32(&head[8..12], big) != 0);
        let m = s.size("a $Nodes block header")?;
        if (b.raw.vertices.len() as u64).saturating_add(m) > n {
            return Err(ShapeError::Syntax {
                format: FMT,
                location: Location::byte(at),
                message: format!("more nodes in blocks than the {n} declared"),
            });
        }
        let extra = if parametric { dim.clamp(0, 3) as usize } else { 0 };
        let tags = s.records(m, word, "the node tags of a $Nodes block")?;
        let coords_at = s.pos;
        let stride = 8 * (3 + extra);
        let coords = s.records(m, stride, "the node coordinates of a $Nodes block")?;
        for (k, (t, c)) in tags.chunks_exact(word).zip(coords.chunks_exact(stride)).enumerate() {
            let tag = i64::try_from(rd_size(t, word, big)).unwrap_or(i64::MAX);
            let p = [rd_f64(&c[0..8], big), rd_f64(&c[8..16], big), rd_f64(&c[16..24], big)];
            let i = b.raw.vertices.len();
            let at = coords_at + k * stride;
            b.node(tag, p, || Location::byte(at)).map_err(|e| relocate(e, i, Location::byte(at)))?;
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

/// 4.1 binary `$Elements`: four `size_t` (blocks, elements, min and max tag); each block is three `int`s
/// (dimension, entity tag, element type), a `size_t` element count, then per element its tag and node tags,
/// all `size_t`.
fn elements_v4_binary(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
    let (word, big) = (s.word, s.big);
    let what = "the $Elements header";
    let blocks = s.size(what)?;
    let n = s.size(what)?;
    options.check_elements(n)?;
    s.size(what)?;
    s.size(what)?;
    let mut nodes = Vec::new();
    let mut index = 0usize;
    for _ in 0..blocks {
        let at = s.pos;
        let head = s.records(3, 4, "an $Elements block header")?;
        let ty = rd_i32(&head[8..12], big) as i64;
        let m = s.size("an $Elements block header")?;
        let nn = nodes_of(ty).ok_or_else(|| ShapeError::Unsupported {
            format: FMT,
            location: Location::byte(at),
            message: format!("element type {ty}"),
        })?;
        if (index as u64).saturating_add(m) > n {
            return Err(ShapeError::Syntax {
                format: FMT,
                location: Location::byte(at),
                message: format!("more elements in blocks than the {n} declared"),
            });
        }
        let stride = word * (1 + nn);
        let records_at = s.pos;
        let records = s.records(m, stride, "the element records of an $Elements block")?;
        for (k, r) in records.chunks_exact(stride).enumerate() {
            nodes.clear();
            nodes
                .extend(r[word..].chunks_exact(word).map(|t| i64::try_from(rd_size(t, word, big)).unwrap_or(i64::MAX)));
            b.element(ty, index, &nodes, || Location::byte(records_at + k * stride))?;
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

/// A `size_t` of 4 or 8 bytes.
fn rd_size(b: &[u8], word: usize, big: bool) -> u64 {
    if word == 4 {
        rd_i32(b, big) as u32 as u64
    } else {
        let mut a = [0u8; 8];
        a.copy_from_slice(&b[..8]);
        if big {
            u64::from_be_bytes(a)
        } else {
            u64::from_le_bytes(a)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh to write: nodes with their tags, elements with their Gmsh type and node tags.
    struct Mesh {
        nodes: Vec<(u64, [f64; 3])>,
        elements: Vec<(i32, Vec<u64>)>,
    }

    /// The unit cube as six tetrahedra around the diagonal from corner 0 to corner 6 (node tags 101..=108), with
    /// one boundary triangle that is not used beside them.
    fn cube() -> Mesh {
        let corners =
            [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [0., 0., 1.], [1., 0., 1.], [1., 1., 1.]];
        let mut nodes: Vec<(u64, [f64; 3])> = corners.iter().enumerate().map(|(i, &p)| (101 + i as u64, p)).collect();
        nodes.push((108, [0., 1., 1.]));
        let tets = [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]];
        let mut elements = vec![(2, vec![101, 102, 103])];
        elements.extend(tets.iter().map(|t| (4, t.iter().map(|&k| 101 + k as u64).collect())));
        Mesh { nodes, elements }
    }

    /// A unit square of two triangles and a boundary line, tags out of order.
    fn square() -> Mesh {
        Mesh {
            nodes: vec![(7, [0., 0., 0.]), (3, [1., 0., 0.]), (9, [1., 1., 0.]), (4, [0.25, 1., 0.])],
            elements: vec![(2, vec![7, 3, 9]), (2, vec![7, 9, 4]), (1, vec![7, 3])],
        }
    }

    fn dim_of(ty: i32) -> i32 {
        match ty {
            4 => 3,
            2 => 2,
            1 => 1,
            _ => 0,
        }
    }

    /// What the reader should make of a mesh.
    fn expected(mesh: &Mesh) -> RawShape {
        let index: HashMap<u64, u32> = mesh.nodes.iter().enumerate().map(|(i, n)| (n.0, i as u32)).collect();
        let mut raw = RawShape { vertices: mesh.nodes.iter().map(|n| n.1).collect(), ..RawShape::default() };
        let at = |tags: &[u64]| tags.iter().map(|t| index[t]).collect::<Vec<u32>>();
        let has_tets = mesh.elements.iter().any(|e| e.0 == 4);
        for (ty, tags) in &mesh.elements {
            let v = at(tags);
            match ty {
                4 => raw.tets.push([v[0], v[1], v[2], v[3]]),
                2 if !has_tets => raw.polygons.push(&v),
                1 => raw.segments.push([v[0], v[1]]),
                _ => {}
            }
        }
        raw
    }

    /// A section other than the mesh, written as Gmsh and solvers write it.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Kind {
        PhysicalNames,
        Entities,
        PartitionedEntities,
        Periodic,
        GhostElements,
        Parametrizations,
        InterpolationScheme,
        NodeData,
        ElementData,
        ElementNodeData,
        Comments,
        Unknown,
    }

    const KINDS: [Kind; 12] = [
        Kind::PhysicalNames,
        Kind::Entities,
        Kind::PartitionedEntities,
        Kind::Periodic,
        Kind::GhostElements,
        Kind::Parametrizations,
        Kind::InterpolationScheme,
        Kind::NodeData,
        Kind::ElementData,
        Kind::ElementNodeData,
        Kind::Comments,
        Kind::Unknown,
    ];

    impl Kind {
        fn name(self) -> &'static str {
            match self {
                Kind::PhysicalNames => "PhysicalNames",
                Kind::Entities => "Entities",
                Kind::PartitionedEntities => "PartitionedEntities",
                Kind::Periodic => "Periodic",
                Kind::GhostElements => "GhostElements",
                Kind::Parametrizations => "Parametrizations",
                Kind::InterpolationScheme => "InterpolationScheme",
                Kind::NodeData => "NodeData",
                Kind::ElementData => "ElementData",
                Kind::ElementNodeData => "ElementNodeData",
                Kind::Comments => "Comments",
                Kind::Unknown => "SolverAttributes",
            }
        }
        /// Sections of MSH 4 only.
        fn v4_only(self) -> bool {
            matches!(self, Kind::Entities | Kind::PartitionedEntities | Kind::GhostElements | Kind::Parametrizations)
        }
    }

    /// Where a section goes: before `$Nodes`, between `$Nodes` and `$Elements`, after `$Elements`.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Place {
        BeforeNodes,
        BeforeElements,
        AfterElements,
    }

    const PLACES: [Place; 3] = [Place::BeforeNodes, Place::BeforeElements, Place::AfterElements];

    /// A file layout: version 2.2 or 4.1, ASCII or binary, byte order and (4.1 binary) `size_t` width.
    #[derive(Clone, Copy, Debug)]
    struct Msh {
        v4: bool,
        binary: bool,
        big: bool,
        word: usize,
    }

    const LAYOUTS: [Msh; 7] = [
        Msh { v4: false, binary: false, big: false, word: 8 },
        Msh { v4: false, binary: true, big: false, word: 8 },
        Msh { v4: false, binary: true, big: true, word: 8 },
        Msh { v4: true, binary: false, big: false, word: 8 },
        Msh { v4: true, binary: true, big: false, word: 8 },
        Msh { v4: true, binary: true, big: true, word: 8 },
        Msh { v4: true, binary: true, big: false, word: 4 },
    ];

    /// `text` padded with spaces to `n` bytes: raw bytes where a binary file holds doubles, so that the
    /// closing tag of the section appears inside its data.
    fn spelled(text: &[u8], n: usize) -> Vec<u8> {
        let mut v = text.to_vec();
        v.resize(n, b' ');
        v
    }

    impl Msh {
        fn int(&self, o: &mut Vec<u8>, x: i32) {
            o.extend_from_slice(&if self.big { x.to_be_bytes() } else { x.to_le_bytes() });
        }
        fn f64(&self, o: &mut Vec<u8>, x: f64) {
            o.extend_from_slice(&if self.big { x.to_be_bytes() } else { x.to_le_bytes() });
        }
        fn size(&self, o: &mut Vec<u8>, x: u64) {
            match (self.word, self.big) {
                (4, true) => o.extend_from_slice(&(x as u32).to_be_bytes()),
                (4, false) => o.extend_from_slice(&(x as u32).to_le_bytes()),
                (_, true) => o.extend_from_slice(&x.to_be_bytes()),
                (_, false) => o.extend_from_slice(&x.to_le_bytes()),
            }
        }
        fn ints(&self, o: &mut Vec<u8>, xs: &[i32]) {
            xs.iter().for_each(|&x| self.int(o, x));
        }
        /// A 4.1 section of binary content: `ascii` in an ASCII file, `binary` written otherwise.
        fn counted(&self, o: &mut Vec<u8>, name: &str, ascii: &str, binary: impl FnOnce(&mut Vec<u8>)) {
            o.extend_from_slice(format!("${name}\n").as_bytes());
            if self.binary {
                binary(o);
                o.push(b'\n');
            } else {
                o.extend_from_slice(ascii.as_bytes());
            }
            o.extend_from_slice(format!("$End{name}\n").as_bytes());
        }

        fn write(&self, mesh: &Mesh, sections: &[(Place, Kind)]) -> Vec<u8> {
            let mut o =
                format!("$MeshFormat\n{} {} {}\n", if self.v4 { "4.1" } else { "2.2" }, self.binary as u8, self.word)
                    .into_bytes();
            if self.binary {
                self.int(&mut o, 1);
                o.push(b'\n');
            }
            o.extend_from_slice(b"$EndMeshFormat\n");
            let put = |o: &mut Vec<u8>, place: Place| {
                for &(_, kind) in sections.iter().filter(|s| s.0 == place) {
                    self.section(o, kind, mesh);
                }
            };
            put(&mut o, Place::BeforeNodes);
            if self.v4 {
                self.nodes_v4(&mut o, mesh);
            } else {
                self.nodes_v2(&mut o, mesh);
            }
            put(&mut o, Place::BeforeElements);
            if self.v4 {
                self.elements_v4(&mut o, mesh);
            } else {
                self.elements_v2(&mut o, mesh);
            }
            put(&mut o, Place::AfterElements);
            o
        }

        fn nodes_v2(&self, o: &mut Vec<u8>, mesh: &Mesh) {
            o.extend_from_slice(format!("$Nodes\n{}\n", mesh.nodes.len()).as_bytes());
            for &(tag, p) in &mesh.nodes {
                if self.binary {
                    self.int(o, tag as i32);
                    p.iter().for_each(|&c| self.f64(o, c));
                } else {
                    o.extend_from_slice(format!("{tag} {} {} {}\n", p[0], p[1], p[2]).as_bytes());
                }
            }
            o.extend_from_slice(if self.binary { b"\n$EndNodes\n" } else { b"$EndNodes\n" });
        }

        fn elements_v2(&self, o: &mut Vec<u8>, mesh: &Mesh) {
            o.extend_from_slice(format!("$Elements\n{}\n", mesh.elements.len()).as_bytes());
            // Binary: one block per run of one type, each element with two tags (physical, elementary).
            let mut i = 0;
            while i < mesh.elements.len() {
                let ty = mesh.elements[i].0;
                let run = mesh.elements[i..].iter().take_while(|e| e.0 == ty).count();
                if self.binary {
                    self.ints(o, &[ty, run as i32, 2]);
                }
                for (k, (_, tags)) in mesh.elements[i..i + run].iter().enumerate() {
                    let id = (i + k + 1) as i32;
                    if self.binary {
                        self.ints(o, &[id, 1, dim_of(ty)]);
                        tags.iter().for_each(|&t| self.int(o, t as i32));
                    } else {
                        let nodes: Vec<String> = tags.iter().map(u64::to_string).collect();
                        o.extend_from_slice(format!("{id} {ty} 2 1 {} {}\n", dim_of(ty), nodes.join(" ")).as_bytes());
                    }
                }
                i += run;
            }
            o.extend_from_slice(if self.binary { b"\n$EndElements\n" } else { b"$EndElements\n" });
        }

        /// Three blocks: the first node on a point, the next two on a surface with parametric (u, v), the
        /// rest in a volume.
        fn nodes_v4(&self, o: &mut Vec<u8>, mesh: &Mesh) {
            let n = mesh.nodes.len();
            let (min, max) = (mesh.nodes.iter().map(|x| x.0).min(), mesh.nodes.iter().map(|x| x.0).max());
            let (min, max) = (min.unwrap_or(0), max.unwrap_or(0));
            let blocks = [(0, 0..1, false), (2, 1..3, true), (3, 3..n, false)];
            o.extend_from_slice(b"$Nodes\n");
            if self.binary {
                [3, n as u64, min, max].iter().for_each(|&x| self.size(o, x));
            } else {
                o.extend_from_slice(format!("3 {n} {min} {max}\n").as_bytes());
            }
            for (dim, range, parametric) in blocks {
                let nodes = &mesh.nodes[range];
                if self.binary {
                    self.ints(o, &[dim, 1, parametric as i32]);
                    self.size(o, nodes.len() as u64);
                    nodes.iter().for_each(|x| self.size(o, x.0));
                    for (_, p) in nodes {
                        p.iter().for_each(|&c| self.f64(o, c));
                        if parametric {
                            self.f64(o, 0.5);
                            self.f64(o, 0.25);
                        }
                    }
                } else {
                    o.extend_from_slice(format!("{dim} 1 {} {}\n", parametric as u8, nodes.len()).as_bytes());
                    nodes.iter().for_each(|x| o.extend_from_slice(format!("{}\n", x.0).as_bytes()));
                    for (_, p) in nodes {
                        let uv = if parametric { " 0.5 0.25" } else { "" };
                        o.extend_from_slice(format!("{} {} {}{uv}\n", p[0], p[1], p[2]).as_bytes());
                    }
                }
            }
            o.extend_from_slice(if self.binary { b"\n$EndNodes\n" } else { b"$EndNodes\n" });
        }

        /// One block per run of one type; element tags from 1.
        fn elements_v4(&self, o: &mut Vec<u8>, mesh: &Mesh) {
            let mut runs = Vec::new();
            let mut i = 0;
            while i < mesh.elements.len() {
                let run = mesh.elements[i..].iter().take_while(|e| e.0 == mesh.elements[i].0).count();
                runs.push(i..i + run);
                i += run;
            }
            let m = mesh.elements.len() as u64;
            o.extend_from_slice(b"$Elements\n");
            if self.binary {
                [runs.len() as u64, m, 1, m].iter().for_each(|&x| self.size(o, x));
            } else {
                o.extend_from_slice(format!("{} {m} 1 {m}\n", runs.len()).as_bytes());
            }
            for run in runs {
                let ty = mesh.elements[run.start].0;
                if self.binary {
                    self.ints(o, &[dim_of(ty), 1, ty]);
                    self.size(o, run.len() as u64);
                } else {
                    o.extend_from_slice(format!("{} 1 {ty} {}\n", dim_of(ty), run.len()).as_bytes());
                }
                for k in run {
                    let tags = &mesh.elements[k].1;
                    if self.binary {
                        self.size(o, k as u64 + 1);
                        tags.iter().for_each(|&t| self.size(o, t));
                    } else {
                        let nodes: Vec<String> = tags.iter().map(u64::to_string).collect();
                        o.extend_from_slice(format!("{} {}\n", k + 1, nodes.join(" ")).as_bytes());
                    }
                }
            }
            o.extend_from_slice(if self.binary { b"\n$EndElements\n" } else { b"$EndElements\n" });
        }

        fn section(&self, o: &mut Vec<u8>, kind: Kind, mesh: &Mesh) {
            match kind {
                Kind::PhysicalNames => {
                    o.extend_from_slice(b"$PhysicalNames\n2\n2 1 \"boundary\"\n3 2 \"solid body\"\n$EndPhysicalNames\n")
                }
                Kind::Comments => o.extend_from_slice(
                    b"$Comments\nwritten by the kac tests; a line that looks like a section:\n$Nodes\n$EndComments\n",
                ),
                Kind::Unknown => {
                    o.extend_from_slice(b"$SolverAttributes\nsolver = \"kac test\"\n$Elements\n$EndSolverAttributes\n")
                }
                Kind::InterpolationScheme => {
                    o.extend_from_slice(b"$InterpolationScheme\n\"INTERPOLATION_SCHEME\"\n1\n5\n2\n4 4\n");
                    for r in 0..4 {
                        let row: Vec<&str> = (0..4).map(|c| if r == c { "1" } else { "0" }).collect();
                        o.extend_from_slice(format!("{}\n", row.join(" ")).as_bytes());
                    }
                    o.extend_from_slice(b"4 3\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndInterpolationScheme\n");
                }
                Kind::Periodic if !self.v4 => {
                    o.extend_from_slice(b"$Periodic\n1\n0 1 2\n1\n101 102\n$EndPeriodic\n");
                }
                Kind::Periodic => self.counted(
                    o,
                    "Periodic",
                    "1\n2 1 2\n16 1 0 0 1 0 1 0 0 0 0 1 0 0 0 0 1\n2\n101 105\n102 106\n",
                    |o| {
                        self.size(o, 1);
                        self.ints(o, &[2, 1, 2]);
                        self.size(o, 16);
                        o.extend_from_slice(&spelled(b"\n$EndPeriodic\n", 16 * 8));
                        self.size(o, 2);
                        [101, 105, 102, 106].iter().for_each(|&t| self.size(o, t));
                    },
                ),
                Kind::Entities => self.counted(
                    o,
                    "Entities",
                    "1 1 1 1\n1 0 0 0 0\n1 0 0 0 1 1 1 1 7 2 1 -1\n1 0 0 0 1 1 1 1 1 1 1\n1 0 0 0 1 1 1 1 2 1 1\n",
                    |o| {
                        [1, 1, 1, 1].iter().for_each(|&n| self.size(o, n));
                        self.int(o, 1);
                        [0., 0., 0.].iter().for_each(|&c| self.f64(o, c));
                        self.size(o, 0);
                        for dim in 1..4 {
                            self.int(o, 1);
                            o.extend_from_slice(&spelled(b"\n$EndEntities\n", 6 * 8));
                            self.size(o, 1);
                            self.int(o, 7);
                            self.size(o, 2);
                            self.ints(o, &[1, -dim]);
                        }
                    },
                ),
                Kind::PartitionedEntities => self.counted(
                    o,
                    "PartitionedEntities",
                    "2\n1\n5 2\n1 0 0 1\n3 0 1 1 1 0.5 0.5 0.5 0\n4 3 1 2 1 2 0 0 0 1 1 1 1 2 1 -3\n",
                    |o| {
                        self.size(o, 2);
                        self.size(o, 1);
                        self.ints(o, &[5, 2]);
                        [1, 0, 0, 1].iter().for_each(|&n| self.size(o, n));
                        self.ints(o, &[3, 0, 1]);
                        self.size(o, 1);
                        self.int(o, 1);
                        [0.5, 0.5, 0.5].iter().for_each(|&c| self.f64(o, c));
                        self.size(o, 0);
                        self.ints(o, &[4, 3, 1]);
                        self.size(o, 2);
                        self.ints(o, &[1, 2]);
                        o.extend_from_slice(&spelled(b"\n$EndPartitionedEntities\n", 6 * 8));
                        self.size(o, 1);
                        self.int(o, 2);
                        self.size(o, 1);
                        self.int(o, -3);
                    },
                ),
                Kind::GhostElements => self.counted(o, "GhostElements", "2\n1 1 1 2\n2 2 2 1 3\n", |o| {
                    self.size(o, 2);
                    self.size(o, 1);
                    self.int(o, 1);
                    self.size(o, 1);
                    self.int(o, 2);
                    self.size(o, 2);
                    self.int(o, 2);
                    self.size(o, 2);
                    self.ints(o, &[1, 3]);
                }),
                Kind::Parametrizations => {
                    let node = "0 0 0 0.5 0.5 1 0 0 0 1 0\n";
                    let ascii = format!("1 1\n1 2\n0 0 0 0\n1 0 0 1\n2 3 1\n{node}{node}{node}0 1 2\n");
                    self.counted(o, "Parametrizations", &ascii, |o| {
                        self.size(o, 1);
                        self.size(o, 1);
                        self.int(o, 1);
                        self.size(o, 2);
                        o.extend_from_slice(&spelled(b"\n$EndParametrizations\n", 2 * 4 * 8));
                        self.int(o, 2);
                        self.size(o, 3);
                        self.size(o, 1);
                        (0..33).for_each(|k| self.f64(o, k as f64));
                        self.ints(o, &[0, 1, 2]);
                    });
                }
                Kind::NodeData | Kind::ElementData | Kind::ElementNodeData => self.data(o, kind, mesh),
            }
        }

        /// A view as Gmsh writes it: `$NodeData` a 3-vector per node, `$ElementData` a 3-vector per element,
        /// `$ElementNodeData` a scalar per node of each element. In binary, the first entity's values spell the
        /// closing tag.
        fn data(&self, o: &mut Vec<u8>, kind: Kind, mesh: &Mesh) {
            let name = kind.name();
            let (components, tags): (usize, Vec<(u64, usize)>) = match kind {
                Kind::NodeData => (3, mesh.nodes.iter().map(|n| (n.0, 1)).collect()),
                Kind::ElementData => (3, (1..=mesh.elements.len() as u64).map(|t| (t, 1)).collect()),
                _ => (1, mesh.elements.iter().enumerate().map(|(i, e)| (i as u64 + 1, e.1.len())).collect()),
            };
            o.extend_from_slice(
                format!("${name}\n2\n\"velocity \\\"u\\\"\"\n\"INTERPOLATION_SCHEME\"\n1\n0.25\n4\n3\n{components}\n{}\n0\n", tags.len())
                    .as_bytes(),
            );
            let per_node = kind == Kind::ElementNodeData;
            for (k, &(tag, nodes)) in tags.iter().enumerate() {
                let n = components * nodes;
                if self.binary {
                    self.int(o, tag as i32);
                    if per_node {
                        self.int(o, nodes as i32);
                    }
                    let end = format!("\n$End{name}\n");
                    if k == 0 && end.len() <= 8 * n {
                        o.extend_from_slice(&spelled(end.as_bytes(), 8 * n));
                    } else {
                        (0..n).for_each(|j| self.f64(o, (k * 10 + j) as f64 * 0.5));
                    }
                } else {
                    let values: Vec<String> = (0..n).map(|j| ((k * 10 + j) as f64 * 0.5).to_string()).collect();
                    let mult = if per_node { format!(" {nodes}") } else { String::new() };
                    o.extend_from_slice(format!("{tag}{mult} {}\n", values.join(" ")).as_bytes());
                }
            }
            o.extend_from_slice(format!("{}$End{name}\n", if self.binary { "\n" } else { "" }).as_bytes());
        }
    }

    fn read_ok(bytes: &[u8], what: &str) -> RawShape {
        read(bytes, &ReadOptions::default()).unwrap_or_else(|e| panic!("{what}: {e}"))
    }

    fn same_mesh(raw: &RawShape, mesh: &Mesh, what: &str) {
        let want = expected(mesh);
        assert_eq!(raw.vertices, want.vertices, "{what}: vertices");
        assert_eq!(raw.tets, want.tets, "{what}: tetrahedra");
        assert_eq!(raw.polygons, want.polygons, "{what}: faces");
        assert_eq!(raw.segments, want.segments, "{what}: segments");
    }

    fn kinds_of(layout: Msh) -> impl Iterator<Item = Kind> {
        KINDS.into_iter().filter(move |k| layout.v4 || !k.v4_only())
    }

    #[test]
    fn each_section_kind_is_skipped_before_nodes_before_and_after_elements_in_every_layout() {
        for layout in LAYOUTS {
            for (mesh_name, mesh) in [("cube", cube()), ("square", square())] {
                let plain = layout.write(&mesh, &[]);
                let raw = read_ok(&plain, &format!("{layout:?} {mesh_name}"));
                same_mesh(&raw, &mesh, &format!("{layout:?} {mesh_name}"));
                assert!(!raw.notes.iter().any(|n| n.contains("skipped")), "{:?}", raw.notes);
                for kind in kinds_of(layout) {
                    for place in PLACES {
                        let what = format!("{layout:?} {mesh_name} {kind:?} {place:?}");
                        let bytes = layout.write(&mesh, &[(place, kind)]);
                        let raw = read_ok(&bytes, &what);
                        same_mesh(&raw, &mesh, &what);
                        let prefix = format!("gmsh: skipped ${} (1 ", kind.name());
                        let note = raw.notes.iter().find(|n| n.starts_with(&prefix));
                        let note = note.unwrap_or_else(|| panic!("{what}: no note in {:?}", raw.notes));
                        let searched = layout.binary && kind == Kind::Unknown;
                        assert_eq!(note.contains("searching for $EndSolverAttributes"), searched, "{what}: {note}");
                    }
                }
            }
        }
    }

    #[test]
    fn all_section_kinds_at_once_are_noted_once_per_kind_with_their_values() {
        let mesh = cube();
        for layout in LAYOUTS {
            let mut sections = Vec::new();
            for kind in kinds_of(layout) {
                sections.extend(PLACES.iter().map(|&p| (p, kind)));
            }
            let raw = read_ok(&layout.write(&mesh, &sections), &format!("{layout:?}"));
            same_mesh(&raw, &mesh, &format!("{layout:?}"));
            // 8 nodes × 3, 7 elements × 3, 1 triangle × 3 + 6 tets × 4 nodes; three views of each.
            for (name, values) in [("NodeData", 3 * 24), ("ElementData", 3 * 21), ("ElementNodeData", 3 * 27)] {
                let note = format!("gmsh: skipped ${name} (3 views, {values} values)");
                assert!(raw.notes.contains(&note), "{layout:?}: {note} not in {:?}", raw.notes);
            }
            for kind in
                kinds_of(layout).filter(|k| !matches!(k, Kind::NodeData | Kind::ElementData | Kind::ElementNodeData))
            {
                let prefix = format!("gmsh: skipped ${} (3 sections", kind.name());
                assert_eq!(
                    raw.notes.iter().filter(|n| n.starts_with(&prefix)).count(),
                    1,
                    "{layout:?} {kind:?}: {:?}",
                    raw.notes
                );
            }
            assert!(raw.notes.contains(&"gmsh: 1 surface element(s) beside the tetrahedra not used".to_string()));
        }
    }

    #[test]
    fn binary_data_that_spells_its_closing_tag_is_skipped_by_its_declared_size() {
        let mesh = cube();
        for layout in LAYOUTS.into_iter().filter(|l| l.binary) {
            // The sections with doubles in binary (2.x `$Periodic` is text; `$GhostElements` holds no doubles).
            let with_doubles = |k: &Kind| match k {
                Kind::Periodic => layout.v4,
                k => !matches!(
                    k,
                    Kind::PhysicalNames
                        | Kind::Comments
                        | Kind::Unknown
                        | Kind::InterpolationScheme
                        | Kind::GhostElements
                ),
            };
            for kind in kinds_of(layout).filter(with_doubles) {
                let bytes = layout.write(&mesh, &[(Place::AfterElements, kind), (Place::BeforeNodes, kind)]);
                let tag = format!("\n$End{}\n", kind.name());
                let tags = bytes.windows(tag.len()).filter(|w| *w == tag.as_bytes()).count();
                assert!(tags >= 4, "{layout:?} {kind:?}: the closing tag is inside the data of each section");
                let raw = read_ok(&bytes, &format!("{layout:?} {kind:?}"));
                same_mesh(&raw, &mesh, &format!("{layout:?} {kind:?}"));
            }
        }
    }

    /// The bug: "section $ElementData is not closed" for a Gmsh 2.2 binary tet mesh with an `$ElementData` view.
    /// Writers such as MshIO put the closing tags right after the binary data, with no newline, so no line of
    /// the file is `$EndElementData`; Gmsh puts a newline first. Both are read.
    #[test]
    fn v22_binary_tet_mesh_with_element_data_is_read_not_refused_as_unclosed() {
        let mesh = cube();
        let layout = Msh { v4: false, binary: true, big: false, word: 8 };
        let gmsh = layout.write(&mesh, &[(Place::AfterElements, Kind::ElementData)]);
        let mut tight = gmsh.clone();
        for tag in [&b"\n$EndNodes"[..], b"\n$EndElements", b"\n$EndElementData"] {
            let at = tight.windows(tag.len()).rposition(|w| w == tag).unwrap_or_else(|| panic!("no closing tag"));
            tight.remove(at);
        }
        let end = tight.len() - b"$EndElementData\n".len();
        assert!(tight[end..] == b"$EndElementData\n"[..] && tight[end - 1] != b'\n');
        // And with the view's values free of the tag's bytes: then no line at all is `$EndElementData`.
        let mut plain = tight.clone();
        let spelled = b"\n$EndElementData\n";
        let at = plain.windows(spelled.len()).position(|w| w == spelled).unwrap_or_else(|| panic!("no spelled tag"));
        plain[at..at + spelled.len()].fill(0);
        assert!(!plain.split(|&c| c == b'\n').any(|l| l.trim_ascii() == b"$EndElementData"));
        for bytes in [gmsh, tight, plain] {
            let v = crate::load_bytes(&bytes, crate::Format::Gmsh, &ReadOptions::default(), &Default::default())
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(v.report.kind, crate::ShapeKind::TetMesh);
            assert_eq!(v.shape.vertex_count(), 8);
            let note = "gmsh: skipped $ElementData (1 view, 21 values)".to_string();
            assert!(v.report.notes.contains(&note), "{:?}", v.report.notes);
            same_mesh(&read_ok(&bytes, "v2.2 binary"), &mesh, "v2.2 binary");
        }
    }

    #[test]
    fn declared_sizes_beyond_the_input_are_typed_errors_naming_the_section() {
        let v2 = Msh { v4: false, binary: true, big: false, word: 8 };
        let mut bytes = v2.write(&cube(), &[]);
        bytes.extend_from_slice(b"$ElementData\n1\n\"p\"\n1\n0\n3\n0\n1\n1000000\n");
        let at = bytes.len();
        bytes.extend_from_slice(&[0u8; 40]);
        bytes.extend_from_slice(b"\n$EndElementData\n");
        match read(&bytes, &ReadOptions::default()) {
            Err(ShapeError::Truncated { location, message, .. }) => {
                assert_eq!(location, Location::byte(at));
                assert!(message.contains("$ElementData"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // A 4.1 binary $Entities that declares more points than there are bytes.
        let v4 = Msh { v4: true, binary: true, big: false, word: 8 };
        let mut bytes = v4.write(&cube(), &[]);
        bytes.extend_from_slice(b"$Entities\n");
        [u64::MAX, 0, 0, 0].iter().for_each(|&n| v4.size(&mut bytes, n));
        bytes.extend_from_slice(b"\n$EndEntities\n");
        assert!(matches!(read(&bytes, &ReadOptions::default()), Err(ShapeError::Truncated { .. })));
        // 4.1 binary node and element counts past the input.
        let mut bytes = b"$MeshFormat\n4.1 1 8\n".to_vec();
        v4.int(&mut bytes, 1);
        bytes.extend_from_slice(b"\n$EndMeshFormat\n$Nodes\n");
        [1, 3, 1, 3].iter().for_each(|&n| v4.size(&mut bytes, n));
        v4.ints(&mut bytes, &[3, 1, 0]);
        v4.size(&mut bytes, 3);
        bytes.extend_from_slice(&[0u8; 30]);
        match read(&bytes, &ReadOptions::default()) {
            Err(ShapeError::Truncated { message, .. }) => assert!(message.contains("$Nodes"), "{message}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn data_that_disagrees_with_its_declared_size_is_an_error_at_its_place() {
        // Binary: one entity more than declared leaves bytes where $EndNodeData should be.
        let v2 = Msh { v4: false, binary: true, big: false, word: 8 };
        let mut bytes = v2.write(&square(), &[]);
        bytes.extend_from_slice(b"$NodeData\n0\n0\n3\n0\n1\n1\n");
        for tag in [7, 3] {
            v2.int(&mut bytes, tag);
            v2.f64(&mut bytes, 1.5);
        }
        let at = bytes.len() - 12;
        bytes.extend_from_slice(b"\n$EndNodeData\n");
        match read(&bytes, &ReadOptions::default()) {
            Err(ShapeError::Syntax { location, message, .. }) => {
                assert_eq!(location, Location::byte(at));
                assert!(message.contains("expected $EndNodeData"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // ASCII: fewer values than declared.
        let text =
            b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$NodeData\n1\n\"t\"\n0\n3\n0\n1\n3\n1 0.5\n2 0.5\n$EndNodeData\n";
        match read(text, &ReadOptions::default()) {
            Err(ShapeError::Syntax { location, message, .. }) => {
                assert_eq!(location, Location::line(14));
                assert!(message.contains("$NodeData"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // An unknown section of a binary file with no closing tag.
        let mut bytes = v2.write(&square(), &[]);
        let at = bytes.len();
        bytes.extend_from_slice(b"$Foo\n\x01\x02\n");
        match read(&bytes, &ReadOptions::default()) {
            Err(ShapeError::Truncated { location, message, .. }) => {
                assert_eq!(location, Location::byte(at));
                assert_eq!(message, "section $Foo is not closed");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn every_prefix_of_a_binary_file_with_every_section_reads_or_fails_without_panic() {
        for layout in [LAYOUTS[1], LAYOUTS[5], LAYOUTS[6]] {
            let mut sections = Vec::new();
            for kind in kinds_of(layout) {
                sections.extend([(Place::BeforeNodes, kind), (Place::AfterElements, kind)]);
            }
            let bytes = layout.write(&cube(), &sections);
            for n in 0..bytes.len() {
                let _ = read(&bytes[..n], &ReadOptions::default());
            }
            // A flipped byte anywhere fails or reads, but never panics.
            for n in (0..bytes.len()).step_by(3) {
                let mut b = bytes.clone();
                b[n] ^= 0xA5;
                let _ = read(&b, &ReadOptions::default());
            }
        }
    }

    #[test]
    fn many_kinds_of_unknown_sections_are_noted_up_to_a_bound() {
        let mut text = b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n".to_vec();
        for k in 0..20 {
            text.extend_from_slice(format!("$Extra{k}\nx\n$EndExtra{k}\n").as_bytes());
        }
        text.extend_from_slice(
            b"$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n$Elements\n1\n1 2 0 1 2 3\n$EndElements\n",
        );
        let raw = read_ok(&text, "20 unknown sections");
        assert_eq!(raw.polygons.len(), 1);
        assert_eq!(raw.notes.len(), NOTED_KINDS + 1);
        assert_eq!(raw.notes[0], "gmsh: skipped $Extra0 (1 section)");
        assert_eq!(raw.notes[NOTED_KINDS], "gmsh: skipped 4 more sections of other kinds");
    }
}

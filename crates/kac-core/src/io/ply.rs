//! Stanford PLY: `ascii`, `binary_little_endian` and `binary_big_endian`, any element and property order, any
//! scalar and list types. Read: `vertex` (x, y, z and optionally nx, ny, nz), `face` (`vertex_indices` or
//! `vertex_index`), `tetra`/`tetrahedron`/`cell` lists of four, and `edge` (vertex1, vertex2); every other element
//! is skipped (and noted). A PLY with vertices only is a point cloud.

use super::text::{self, Lines};
use super::ReadOptions;
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};

const FMT: &str = "ply";

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &[u8]) -> Option<Scalar> {
        Some(match name {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
    /// Decodes one value; `b` has at least `size()` bytes.
    #[inline(always)]
    fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

#[derive(Debug, Clone)]
enum Property {
    Scalar { name: Vec<u8>, ty: Scalar },
    List { name: Vec<u8>, count: Scalar, item: Scalar },
}

impl Property {
    fn name(&self) -> &[u8] {
        match self {
            Property::Scalar { name, .. } | Property::List { name, .. } => name,
        }
    }
}

#[derive(Debug, Clone)]
struct ElementDecl {
    name: Vec<u8>,
    count: usize,
    properties: Vec<Property>,
    line: usize,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

/// What each element is for.
#[derive(Clone, Copy, PartialEq)]
enum Role {
    Vertex,
    Face,
    Tet,
    Edge,
    Skip,
}

fn role(e: &ElementDecl) -> Role {
    match e.name.as_slice() {
        b"vertex" => Role::Vertex,
        b"face" => Role::Face,
        b"tetra" | b"tetrahedron" | b"tetrahedra" | b"cell" | b"tet" => Role::Tet,
        b"edge" => Role::Edge,
        _ => Role::Skip,
    }
}

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let mut lines = Lines::new(bytes);
    let Some((_, magic)) = lines.next() else { return Err(ShapeError::Empty { what: "the PLY file is empty".into() }) };
    if magic.trim_ascii() != b"ply" {
        return Err(text::syntax(FMT, 1, "the first line must be 'ply'"));
    }
    let mut encoding = None;
    let mut elements: Vec<ElementDecl> = Vec::new();
    loop {
        let Some((ln, line)) = lines.next() else {
            return Err(ShapeError::Truncated {
                format: FMT,
                location: Location::line(lines.line()),
                message: "the header has no 'end_header'".into(),
            });
        };
        let mut t = text::tokens(line);
        match t.next() {
            None => continue,
            Some(b"comment") | Some(b"obj_info") => continue,
            Some(b"end_header") => break,
            Some(b"format") => {
                encoding = Some(match t.next() {
                    Some(b"ascii") => Encoding::Ascii,
                    Some(b"binary_little_endian") => Encoding::Little,
                    Some(b"binary_big_endian") => Encoding::Big,
                    other => {
                        return Err(text::syntax(
                            FMT,
                            ln,
                            format!("unknown format '{}'", text::show(other.unwrap_or_default())),
                        ))
                    }
                });
            }
            Some(b"element") => {
                let name = t.next().ok_or_else(|| text::syntax(FMT, ln, "element without a name"))?.to_vec();
                let count = text::expect_usize(FMT, ln, t.next(), "element count")?;
                elements.push(ElementDecl { name, count, properties: Vec::new(), line: ln });
            }
            Some(b"property") => {
                let e = elements.last_mut().ok_or_else(|| text::syntax(FMT, ln, "property before any element"))?;
                let ty = t.next().ok_or_else(|| text::syntax(FMT, ln, "property without a type"))?;
                let prop = if ty == b"list" {
                    let count = t
                        .next()
                        .and_then(Scalar::parse)
                        .ok_or_else(|| text::syntax(FMT, ln, "list property needs a valid count type"))?;
                    let item = t
                        .next()
                        .and_then(Scalar::parse)
                        .ok_or_else(|| text::syntax(FMT, ln, "list property needs a valid item type"))?;
                    if !count.is_integer() {
                        return Err(text::syntax(FMT, ln, "a list count type must be an integer type"));
                    }
                    let name = t.next().ok_or_else(|| text::syntax(FMT, ln, "property without a name"))?.to_vec();
                    Property::List { name, count, item }
                } else {
                    let ty = Scalar::parse(ty)
                        .ok_or_else(|| text::syntax(FMT, ln, format!("unknown property type '{}'", text::show(ty))))?;
                    let name = t.next().ok_or_else(|| text::syntax(FMT, ln, "property without a name"))?.to_vec();
                    Property::Scalar { name, ty }
                };
                e.properties.push(prop);
            }
            Some(other) => {
                return Err(text::syntax(FMT, ln, format!("unknown header keyword '{}'", text::show(other))))
            }
        }
    }
    let encoding = encoding.ok_or_else(|| text::syntax(FMT, lines.line(), "the header has no 'format' line"))?;
    let vertex_decl = elements
        .iter()
        .find(|e| role(e) == Role::Vertex)
        .ok_or_else(|| ShapeError::Empty { what: "the PLY file has no 'vertex' element".into() })?;
    let nv = vertex_decl.count;
    options.check_vertices(nv as u64)?;
    let elements_total: u64 = elements
        .iter()
        .filter(|e| matches!(role(e), Role::Face | Role::Tet | Role::Edge))
        .map(|e| e.count as u64)
        .sum();
    options.check_elements(elements_total)?;

    let mut out = Output { raw: RawShape::default(), polygons: Polygons::default(), nv, skipped: Vec::new() };
    let body_start = lines.offset();
    match encoding {
        Encoding::Ascii => read_ascii(&mut lines, &elements, &mut out, bytes.len())?,
        Encoding::Little | Encoding::Big => {
            read_binary(&bytes[body_start..], body_start, encoding == Encoding::Big, &elements, &mut out)?
        }
    }
    let Output { mut raw, polygons, skipped, .. } = out;
    raw.polygons = polygons;
    for s in skipped {
        raw.notes.push(format!("ply: element '{s}' skipped"));
    }
    Ok(raw)
}

struct Output {
    raw: RawShape,
    polygons: Polygons,
    nv: usize,
    skipped: Vec<String>,
}

/// Indices of x, y, z (and nx, ny, nz) among a vertex element's properties.
fn vertex_slots(e: &ElementDecl) -> Result<([usize; 3], Option<[usize; 3]>)> {
    let find = |n: &[u8]| e.properties.iter().position(|p| p.name() == n && matches!(p, Property::Scalar { .. }));
    let x = find(b"x").ok_or_else(|| text::syntax(FMT, e.line, "the vertex element has no scalar 'x' property"))?;
    let y = find(b"y").ok_or_else(|| text::syntax(FMT, e.line, "the vertex element has no scalar 'y' property"))?;
    let z = find(b"z");
    let normals = match (find(b"nx"), find(b"ny"), find(b"nz")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    // A missing z means planar input; usize::MAX marks it.
    Ok(([x, y, z.unwrap_or(usize::MAX)], normals))
}

/// Index of the list property holding an element's vertex indices.
fn index_list(e: &ElementDecl) -> Result<usize> {
    let names: &[&[u8]] = &[b"vertex_indices", b"vertex_index", b"indices"];
    for n in names {
        if let Some(i) = e.properties.iter().position(|p| p.name() == *n && matches!(p, Property::List { .. })) {
            return Ok(i);
        }
    }
    e.properties.iter().position(|p| matches!(p, Property::List { .. })).ok_or_else(|| {
        text::syntax(
            FMT,
            e.line,
            format!("element '{}' has no list of vertex indices", String::from_utf8_lossy(&e.name)),
        )
    })
}

fn edge_slots(e: &ElementDecl) -> Result<[usize; 2]> {
    let find = |n: &[u8]| e.properties.iter().position(|p| p.name() == n && matches!(p, Property::Scalar { .. }));
    match (find(b"vertex1"), find(b"vertex2")) {
        (Some(a), Some(b)) => Ok([a, b]),
        _ => Err(text::syntax(FMT, e.line, "an edge element needs scalar 'vertex1' and 'vertex2' properties")),
    }
}

fn push_vertex(out: &mut Output, p: [f64; 3], location: impl FnOnce() -> Location) -> Result<()> {
    let i = out.raw.vertices.len();
    out.raw.vertices.push(text::check_point(p, i, location)?);
    Ok(())
}

/// A list value as a vertex index; a non-integral or out-of-range value becomes one that fails the range check.
fn as_index(v: f64) -> i64 {
    if v.fract() == 0.0 && v.abs() < 9.0e15 {
        v as i64
    } else {
        i64::MIN
    }
}

fn push_indices(
    out: &mut Output,
    r: Role,
    idx: &[f64],
    element_index: usize,
    location: impl Fn() -> Location,
) -> Result<()> {
    let (element, want) = match r {
        Role::Face => (Element::Face, 0),
        Role::Tet => (Element::Tetrahedron, 4),
        _ => (Element::Edge, 2),
    };
    if r == Role::Face && idx.len() < 3 {
        return Err(ShapeError::InvalidElement {
            element,
            index: element_index,
            rule: format!("a face needs at least 3 corners, this one has {}", idx.len()),
            location: location(),
        });
    }
    if want != 0 && idx.len() != want {
        return Err(ShapeError::InvalidElement {
            element,
            index: element_index,
            rule: format!("expected {want} vertex indices, found {}", idx.len()),
            location: location(),
        });
    }
    let mut buf = [0u32; 4];
    for (k, &v) in idx.iter().enumerate() {
        let vi = as_index(v);
        let checked = text::check_index(vi, out.nv, element, element_index, &location)?;
        match r {
            Role::Face => out.polygons.indices.push(checked),
            _ => buf[k] = checked,
        }
    }
    match r {
        Role::Face => out.polygons.close(),
        Role::Tet => out.raw.tets.push([buf[0], buf[1], buf[2], buf[3]]),
        _ => out.raw.segments.push([buf[0], buf[1]]),
    }
    Ok(())
}

fn read_ascii(lines: &mut Lines<'_>, elements: &[ElementDecl], out: &mut Output, len: usize) -> Result<()> {
    let mut values: Vec<f64> = Vec::new();
    let mut list: Vec<f64> = Vec::new();
    for e in elements {
        let r = role(e);
        let (vslots, nslots) = if r == Role::Vertex { vertex_slots(e)? } else { ([0; 3], None) };
        let list_slot = if matches!(r, Role::Face | Role::Tet) { index_list(e)? } else { usize::MAX };
        let eslots = if r == Role::Edge { edge_slots(e)? } else { [0; 2] };
        if r == Role::Vertex {
            out.raw.vertices.reserve(text::capacity(e.count, len, 6));
            out.raw.planar_input = vslots[2] == usize::MAX;
            if nslots.is_some() {
                out.raw.normals = Some(Vec::with_capacity(text::capacity(e.count, len, 6)));
            }
        }
        if r == Role::Skip {
            out.skipped.push(String::from_utf8_lossy(&e.name).into_owned());
        }
        let mut done = 0;
        while done < e.count {
            let Some((ln, line)) = lines.next() else {
                return Err(ShapeError::Truncated {
                    format: FMT,
                    location: Location::line(lines.line()),
                    message: format!(
                        "element '{}' declares {} records, found {}",
                        String::from_utf8_lossy(&e.name),
                        e.count,
                        done
                    ),
                });
            };
            let mut toks = text::tokens(line).peekable();
            if toks.peek().is_none() {
                continue;
            }
            values.clear();
            list.clear();
            for (pi, p) in e.properties.iter().enumerate() {
                match p {
                    Property::Scalar { name, .. } => {
                        values.push(text::expect_f64(FMT, ln, toks.next(), &String::from_utf8_lossy(name))?);
                    }
                    Property::List { name, .. } => {
                        let n = text::expect_usize(
                            FMT,
                            ln,
                            toks.next(),
                            &format!("count of list '{}'", String::from_utf8_lossy(name)),
                        )?;
                        values.push(f64::NAN);
                        for _ in 0..n {
                            let v = text::expect_f64(FMT, ln, toks.next(), "list item")?;
                            if pi == list_slot {
                                list.push(v);
                            }
                        }
                    }
                }
            }
            match r {
                Role::Vertex => {
                    let z = if vslots[2] == usize::MAX { 0.0 } else { values[vslots[2]] };
                    push_vertex(out, [values[vslots[0]], values[vslots[1]], z], || Location::line(ln))?;
                    if let (Some(ns), Some(normals)) = (nslots, out.raw.normals.as_mut()) {
                        normals.push([values[ns[0]], values[ns[1]], values[ns[2]]]);
                    }
                }
                Role::Face | Role::Tet => push_indices(out, r, &list, done, || Location::line(ln))?,
                Role::Edge => {
                    push_indices(out, r, &[values[eslots[0]], values[eslots[1]]], done, || Location::line(ln))?
                }
                Role::Skip => {}
            }
            done += 1;
        }
    }
    Ok(())
}

/// A cursor over the binary body that reports byte offsets relative to the whole file.
struct Cursor<'a> {
    b: &'a [u8],
    pos: usize,
    base: usize,
    big: bool,
}

impl Cursor<'_> {
    #[inline(always)]
    fn scalar(&mut self, ty: Scalar, what: &str) -> Result<f64> {
        let n = ty.size();
        match self.b.get(self.pos..self.pos + n) {
            Some(s) => {
                self.pos += n;
                Ok(ty.decode(s, self.big))
            }
            None => Err(ShapeError::Truncated {
                format: FMT,
                location: Location::byte(self.base + self.pos),
                message: format!("the data ends inside {what}"),
            }),
        }
    }
    fn at(&self) -> usize {
        self.base + self.pos
    }
}

fn read_binary(body: &[u8], base: usize, big: bool, elements: &[ElementDecl], out: &mut Output) -> Result<()> {
    let mut c = Cursor { b: body, pos: 0, base, big };
    let mut values: Vec<f64> = Vec::new();
    let mut list: Vec<f64> = Vec::new();
    for e in elements {
        let r = role(e);
        let ename = String::from_utf8_lossy(&e.name).into_owned();
        let what = format!("element '{ename}'");
        if r == Role::Skip {
            out.skipped.push(ename.clone());
        }
        // Fast path: a vertex element of fixed-size scalars is a fixed-size record.
        if r == Role::Vertex {
            let (vslots, nslots) = vertex_slots(e)?;
            out.raw.planar_input = vslots[2] == usize::MAX;
            let mut offsets = Vec::with_capacity(e.properties.len());
            let mut record = 0usize;
            let mut all_scalar = true;
            for p in &e.properties {
                match p {
                    Property::Scalar { ty, .. } => {
                        offsets.push((record, *ty));
                        record += ty.size();
                    }
                    Property::List { .. } => all_scalar = false,
                }
            }
            if all_scalar {
                let need = record.checked_mul(e.count).filter(|&n| n <= body.len() - c.pos).ok_or_else(|| {
                    ShapeError::Truncated {
                        format: FMT,
                        location: Location::byte(c.at()),
                        message: format!("{} vertices of {record} bytes need more data than the file has", e.count),
                    }
                })?;
                let data = &body[c.pos..c.pos + need];
                out.raw.vertices.reserve(e.count);
                let mut normals = nslots.map(|_| Vec::with_capacity(e.count));
                let get = |rec: &[u8], slot: usize| -> f64 {
                    if slot == usize::MAX {
                        0.0
                    } else {
                        let (o, ty) = offsets[slot];
                        ty.decode(&rec[o..], big)
                    }
                };
                for (i, rec) in data.chunks_exact(record.max(1)).enumerate() {
                    let p = [get(rec, vslots[0]), get(rec, vslots[1]), get(rec, vslots[2])];
                    push_vertex(out, p, || Location::byte(base + c.pos + i * record))?;
                    if let (Some(ns), Some(n)) = (nslots, normals.as_mut()) {
                        n.push([get(rec, ns[0]), get(rec, ns[1]), get(rec, ns[2])]);
                    }
                }
                out.raw.normals = normals;
                c.pos += need;
                continue;
            }
            // General path for vertex elements with lists.
            for _ in 0..e.count {
                let start = c.at();
                values.clear();
                for p in &e.properties {
                    match p {
                        Property::Scalar { ty, .. } => values.push(c.scalar(*ty, &what)?),
                        Property::List { count, item, .. } => {
                            let n = c.scalar(*count, &what)?;
                            skip_list(&mut c, n, *item, &what)?;
                            values.push(f64::NAN);
                        }
                    }
                }
                let z = if vslots[2] == usize::MAX { 0.0 } else { values[vslots[2]] };
                push_vertex(out, [values[vslots[0]], values[vslots[1]], z], || Location::byte(start))?;
            }
            continue;
        }
        let list_slot = if matches!(r, Role::Face | Role::Tet) { index_list(e)? } else { usize::MAX };
        let eslots = if r == Role::Edge { edge_slots(e)? } else { [0; 2] };
        if r == Role::Face {
            // At least one count byte per face must be there: no allocation beyond the input's size.
            out.polygons = Polygons::with_capacity(
                text::capacity(e.count, body.len(), 1),
                text::capacity(3 * e.count, body.len(), 1),
            );
        }
        // Fast path for the common face layout: one list property and nothing else.
        if r == Role::Face && e.properties.len() == 1 {
            if let Property::List { count, item, .. } = e.properties[0] {
                for f in 0..e.count {
                    let start = c.at();
                    let n = c.scalar(count, &what)?;
                    if !(3.0..=1.0e6).contains(&n) {
                        return Err(ShapeError::InvalidElement {
                            element: Element::Face,
                            index: f,
                            rule: format!("a face needs between 3 and 10⁶ corners, this one declares {n}"),
                            location: Location::byte(start),
                        });
                    }
                    let n = n as usize;
                    let size = item.size();
                    let data = c.b.get(c.pos..c.pos + n * size).ok_or_else(|| ShapeError::Truncated {
                        format: FMT,
                        location: Location::byte(c.at()),
                        message: format!("the data ends inside face {f}"),
                    })?;
                    for k in 0..n {
                        let v = item.decode(&data[k * size..], big);
                        let vi = as_index(v);
                        out.polygons
                            .indices
                            .push(text::check_index(vi, out.nv, Element::Face, f, || Location::byte(start))?);
                    }
                    out.polygons.close();
                    c.pos += n * size;
                }
                continue;
            }
        }
        for idx in 0..e.count {
            let start = c.at();
            values.clear();
            list.clear();
            for (pi, p) in e.properties.iter().enumerate() {
                match p {
                    Property::Scalar { ty, .. } => values.push(c.scalar(*ty, &what)?),
                    Property::List { count, item, .. } => {
                        let n = c.scalar(*count, &what)?;
                        values.push(f64::NAN);
                        if pi == list_slot {
                            if !(0.0..=1.0e6).contains(&n) {
                                return Err(ShapeError::InvalidElement {
                                    element: Element::Face,
                                    index: idx,
                                    rule: format!("list length {n} is out of range"),
                                    location: Location::byte(start),
                                });
                            }
                            for _ in 0..n as usize {
                                list.push(c.scalar(*item, &what)?);
                            }
                        } else {
                            skip_list(&mut c, n, *item, &what)?;
                        }
                    }
                }
            }
            match r {
                Role::Face | Role::Tet => push_indices(out, r, &list, idx, || Location::byte(start))?,
                Role::Edge => {
                    push_indices(out, r, &[values[eslots[0]], values[eslots[1]]], idx, || Location::byte(start))?
                }
                _ => {}
            }
        }
    }
    if c.pos < body.len() {
        let extra = body.len() - c.pos;
        out.raw.notes.push(format!("ply: {extra} byte(s) after the last element ignored"));
    }
    Ok(())
}

fn skip_list(c: &mut Cursor<'_>, n: f64, item: Scalar, what: &str) -> Result<()> {
    if !(0.0..=1.0e9).contains(&n) {
        return Err(ShapeError::Syntax {
            format: FMT,
            location: Location::byte(c.at()),
            message: format!("a list in {what} has an invalid length {n}"),
        });
    }
    let bytes = n as usize * item.size();
    if c.pos + bytes > c.b.len() {
        return Err(ShapeError::Truncated {
            format: FMT,
            location: Location::byte(c.at()),
            message: format!("the data ends inside a list of {what}"),
        });
    }
    c.pos += bytes;
    Ok(())
}

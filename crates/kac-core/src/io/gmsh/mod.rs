//! Gmsh `.msh`, versions 2.x and 4.1, ASCII and binary (either byte order; 4.1 binary with a 4- or 8-byte
//! `size_t`). Node tags may be arbitrary; elements are read by type: tetrahedra (4, and the corners of 10-node
//! tets), triangles (2, 9), quads (3, 10, 16) and lines (1, 8). With tetrahedra the file is a tet mesh; otherwise
//! triangles make a surface and lines a polyline. Of second-order elements the corners are the vertices and the
//! middle node of each edge is kept as [`RawShape::edge_nodes`](crate::geometry::RawShape) (curved quadratic
//! elements); the nodes stay in the vertex list, so the file's numbering is the input's (validation drops them as
//! unreferenced).
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

mod scanner;
mod sections;
mod skip;
#[cfg(test)]
mod tests;

use scanner::*;
use sections::*;
use skip::*;

pub(super) struct Builder {
    pub(super) raw: RawShape,
    pub(super) tags: HashMap<u64, u32>,
    pub(super) polygons: Polygons,
    pub(super) higher_order: usize,
    pub(super) other: usize,
}

impl Builder {
    pub(super) fn node(&mut self, tag: i64, p: [f64; 3], loc: impl FnOnce() -> Location) -> Result<()> {
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
    pub(super) fn element(&mut self, ty: i64, index: usize, nodes: &[i64], loc: impl Fn() -> Location) -> Result<()> {
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
        // A node tag's vertex, or the element's error naming it.
        let vertex = |tags: &HashMap<u64, u32>, count: usize, tag: i64| {
            tags.get(&(tag as u64)).copied().filter(|_| tag >= 0).ok_or_else(|| ShapeError::IndexOutOfRange {
                element,
                index,
                value: tag,
                vertex_count: count,
                location: loc(),
            })
        };
        let mut idx = [0u32; 4];
        for (k, &tag) in nodes.iter().take(arity).enumerate() {
            idx[k] = vertex(&self.tags, self.raw.vertices.len(), tag)?;
        }
        // Second-order elements: the middle node of each edge (Gmsh's node ordering: the corners, then one node
        // per edge in this order).
        let edges: &[[usize; 2]] = match ty {
            8 => &[[0, 1]],
            9 => &[[0, 1], [1, 2], [2, 0]],
            10 | 16 => &[[0, 1], [1, 2], [2, 3], [3, 0]],
            11 => &[[0, 1], [1, 2], [2, 0], [3, 0], [3, 2], [3, 1]],
            _ => &[],
        };
        for (k, &[a, b]) in edges.iter().enumerate() {
            if let Some(&tag) = nodes.get(arity + k) {
                let node = vertex(&self.tags, self.raw.vertices.len(), tag)?;
                self.raw.edge_nodes.push(([idx[a], idx[b]], self.raw.vertices[node as usize]));
            }
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
        raw.notes.push(format!(
            "gmsh: {higher_order} higher-order element(s): their corners are the mesh's vertices; the middle nodes of \
             second-order elements' edges ({}) place the edges of quadratic elements (order 2), other nodes are unused",
            raw.edge_nodes.len()
        ));
    }
    if other > 0 {
        raw.notes.push(format!("gmsh: {other} element(s) of other types (points, hexahedra, prisms, ...) ignored"));
    }
    raw.polygons = polygons;
    Ok(raw)
}

pub(super) fn relocate(e: ShapeError, index: usize, location: Location) -> ShapeError {
    match e {
        ShapeError::InvalidElement { element, rule, .. } => {
            ShapeError::InvalidElement { element, index, rule, location }
        }
        other => other,
    }
}

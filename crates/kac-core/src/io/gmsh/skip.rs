//! Sections other than the mesh, passed over by their declared sizes or line by line, and the notes that
//! name them.

use super::*;

/// How a section other than the mesh was passed over.
pub(super) enum Passed {
    /// A post-processing view, with its number of values.
    Data(u64),
    /// By its declared counts, or line by line through text.
    Section,
    /// An unknown section of a binary file, by searching for its closing tag.
    Searched,
}

#[derive(Default)]
pub(super) struct Tally {
    pub(super) sections: usize,
    pub(super) values: Option<u64>,
    pub(super) searched: bool,
}

/// The sections skipped, by name in order of first appearance; past `NOTED_KINDS` names only counted.
#[derive(Default)]
pub(super) struct Skipped {
    pub(super) kinds: Vec<(String, Tally)>,
    pub(super) others: usize,
}

pub(super) const NOTED_KINDS: usize = 16;

impl Skipped {
    pub(super) fn add(&mut self, name: &[u8], passed: Passed) {
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
    pub(super) fn notes(self) -> Vec<String> {
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

pub(super) fn plural(n: u64, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
}

/// Passes over the section whose header line `$<name>` was just read, to the line after its closing tag.
pub(super) fn skip_section(s: &mut Scanner<'_>, name: &[u8], header: &Location, v4: bool) -> Result<Passed> {
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
pub(super) fn skip_data(s: &mut Scanner<'_>, name: &str, header: &Location, per_node: bool) -> Result<u64> {
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
pub(super) fn skip_entities(s: &mut Scanner<'_>, name: &str) -> Result<()> {
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
pub(super) fn skip_periodic(s: &mut Scanner<'_>) -> Result<()> {
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
pub(super) fn skip_ghost_elements(s: &mut Scanner<'_>) -> Result<()> {
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
pub(super) fn skip_parametrizations(s: &mut Scanner<'_>) -> Result<()> {
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

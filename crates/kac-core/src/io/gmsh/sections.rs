//! `$Nodes` and `$Elements` of versions 2.x and 4.1, ASCII and binary.

use super::*;

pub(super) fn nodes_v2(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions, binary: bool) -> Result<()> {
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

pub(super) fn elements_v2(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions, binary: bool) -> Result<()> {
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

pub(super) fn nodes_v4(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
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
pub(super) fn nodes_v4_binary(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
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

pub(super) fn elements_v4(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
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
pub(super) fn elements_v4_binary(s: &mut Scanner<'_>, b: &mut Builder, options: &ReadOptions) -> Result<()> {
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

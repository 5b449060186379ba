//! Matrix Market in: a symmetric or general coordinate matrix is read as the weighted adjacency of a graph
//! (off-diagonal entries are edges, the diagonal is ignored). Operators are written by [`super::matrix`].

use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::RawShape;

/// Reads a Matrix Market `coordinate` matrix (real, integer or pattern; general or symmetric) as a graph.
/// Parsed here rather than by sprs: its reader panics on indices outside the declared size, and an upload
/// must get a located error instead.
pub fn read_graph(bytes: &[u8], options: &super::ReadOptions) -> Result<RawShape> {
    use super::text::{self, Lines};
    const FMT: &str = "mtx";
    let mut lines = Lines::new(bytes);
    let (_, banner) =
        lines.next().ok_or_else(|| ShapeError::Empty { what: "the Matrix Market file is empty".into() })?;
    let banner = String::from_utf8_lossy(banner).to_ascii_lowercase();
    let words: Vec<&str> = banner.split_whitespace().collect();
    if words.first() != Some(&"%%matrixmarket") || words.get(1) != Some(&"matrix") {
        return Err(text::syntax(FMT, 1, "the first line must be '%%MatrixMarket matrix ...'"));
    }
    if words.get(2) != Some(&"coordinate") {
        return Err(ShapeError::Unsupported {
            format: FMT,
            location: Location::line(1),
            message: "only the coordinate (sparse) layout is taken".into(),
        });
    }
    let field = words.get(3).copied().unwrap_or("real");
    if !matches!(field, "real" | "integer" | "pattern") {
        return Err(ShapeError::Unsupported {
            format: FMT,
            location: Location::line(1),
            message: format!("field '{field}'; real, integer or pattern weights are taken"),
        });
    }
    let pattern = field == "pattern";
    // W = (A + Aᵀ)/2 for a general matrix (each edge listed twice keeps its weight), A for a symmetric one.
    let half = if words.get(4).copied().unwrap_or("general") == "general" { 0.5 } else { 1.0 };
    let mut size: Option<(usize, usize)> = None;
    let mut raw = RawShape { is_graph: true, ..Default::default() };
    let mut weights = Vec::new();
    let mut entries = 0usize;
    for (ln, line) in lines {
        let line = line.trim_ascii();
        if line.is_empty() || line[0] == b'%' {
            continue;
        }
        let mut t = text::tokens(line);
        match size {
            None => {
                let r = text::expect_usize(FMT, ln, t.next(), "row count")?;
                let c = text::expect_usize(FMT, ln, t.next(), "column count")?;
                let nnz = text::expect_usize(FMT, ln, t.next(), "entry count")?;
                if r != c {
                    return Err(ShapeError::Unsupported {
                        format: FMT,
                        location: Location::line(ln),
                        message: format!("a {r}×{c} matrix is not an adjacency matrix"),
                    });
                }
                options.check_vertices(r as u64)?;
                options.check_elements(nnz as u64)?;
                size = Some((r, nnz));
            }
            Some((n, nnz)) => {
                entries += 1;
                if entries > nnz {
                    return Err(text::syntax(FMT, ln, format!("more entries than the {nnz} declared")));
                }
                let i = text::expect_usize(FMT, ln, t.next(), "row index")?;
                let j = text::expect_usize(FMT, ln, t.next(), "column index")?;
                let w = if pattern { 1.0 } else { text::expect_f64(FMT, ln, t.next(), "value")? };
                let e = entries - 1;
                let i = text::check_index(i as i64 - 1, n, Element::Edge, e, || Location::line(ln))?;
                let j = text::check_index(j as i64 - 1, n, Element::Edge, e, || Location::line(ln))?;
                if i == j {
                    continue;
                }
                if !w.is_finite() || w < 0.0 {
                    return Err(ShapeError::InvalidElement {
                        element: Element::Edge,
                        index: e,
                        rule: format!("adjacency weights must be finite and non-negative, found {w}"),
                        location: Location::line(ln),
                    });
                }
                raw.segments.push([i.min(j), i.max(j)]);
                weights.push(half * w);
            }
        }
    }
    let (n, nnz) = size.ok_or_else(|| ShapeError::Truncated {
        format: FMT,
        location: Location::Unknown,
        message: "missing the size line".into(),
    })?;
    if entries < nnz {
        return Err(ShapeError::Truncated {
            format: FMT,
            location: Location::Unknown,
            message: format!("{entries} of {nnz} declared entries"),
        });
    }
    raw.graph_vertex_count = Some(n);
    raw.weights = Some(weights);
    raw.notes
        .push("mtx: off-diagonal entries read as weighted edges; a general matrix is symmetrized as (A + Aᵀ)/2".into());
    Ok(raw)
}

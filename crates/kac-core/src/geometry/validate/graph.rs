//! Graphs: weights checked, self-loops and zero-weight edges dropped, repeated edges merged (weights summed).

use super::report::{Facts, GraphFacts};
use super::{Outcome, Repairs};
use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::topology::UnionFind;
use crate::geometry::{Graph, RawShape, Shape};
use rustc_hash::FxHashMap as HashMap;

pub(super) fn graph(raw: &RawShape, r: &mut Repairs) -> Result<Outcome> {
    let n = raw.graph_vertex_count.unwrap_or(raw.vertices.len());
    if n == 0 {
        return Err(ShapeError::Empty { what: "the graph has no vertices".into() });
    }
    let weights = raw.weights.clone().unwrap_or_else(|| vec![1.0; raw.segments.len()]);
    let mut merged: HashMap<[u32; 2], usize> = HashMap::default();
    let mut edges: Vec<[u32; 2]> = Vec::new();
    let mut w: Vec<f64> = Vec::new();
    let (mut loops, mut dups, mut zero) = (Vec::new(), Vec::new(), Vec::new());
    for (i, (s, &wi)) in raw.segments.iter().zip(&weights).enumerate() {
        if !wi.is_finite() || wi < 0.0 {
            return Err(ShapeError::InvalidElement {
                element: Element::Edge,
                index: i,
                rule: format!("edge weights must be finite and non-negative, this one is {wi}"),
                location: Location::pointer(format!("/weights/{i}")),
            });
        }
        if s[0] == s[1] {
            loops.push(i);
            continue;
        }
        if wi == 0.0 {
            zero.push(i);
            continue;
        }
        let k = if s[0] < s[1] { *s } else { [s[1], s[0]] };
        match merged.get(&k) {
            Some(&j) => {
                w[j] += wi;
                dups.push(i);
            }
            None => {
                merged.insert(k, edges.len());
                edges.push(k);
                w.push(wi);
            }
        }
    }
    r.add(
        "self_loops",
        &loops,
        loops.len(),
        format!("{} self-loop(s) dropped (they do not change a Laplacian)", loops.len()),
    );
    r.add("zero_weight_edges", &zero, zero.len(), format!("{} edge(s) of weight 0 dropped", zero.len()));
    r.add(
        "duplicate_edges",
        &dups,
        dups.len(),
        format!("{} repeated edge(s) merged into one, weights summed", dups.len()),
    );
    let mut degree = vec![0usize; n];
    let mut uf = UnionFind::new(n);
    for e in &edges {
        degree[e[0] as usize] += 1;
        degree[e[1] as usize] += 1;
        uf.union(e[0], e[1]);
    }
    let (_, components) = uf.labels();
    let facts = GraphFacts {
        vertices: n,
        edges: edges.len(),
        components,
        isolated_vertices: degree.iter().filter(|&&d| d == 0).count(),
        total_weight: w.iter().sum(),
        min_degree: degree.iter().copied().min().unwrap_or(0),
        max_degree: degree.iter().copied().max().unwrap_or(0),
    };
    let positions = (!raw.vertices.is_empty()).then(|| raw.vertices.clone());
    let g = Graph { vertex_count: n, positions, edges, weights: w };
    Ok((Shape::Graph(g), (0..n as u32).collect(), Facts::Graph(facts)))
}

//! One search: what it asks, the candidates it keeps, and what it answers.

use super::*;

/// The rows whose distance may be among the `count` smallest: each row offered with a lower and an upper bound
/// on its exact distance; kept while its lower bound is at most the `count`-th smallest upper bound seen.
pub(crate) struct Collector {
    pub(crate) count: usize,
    pub(crate) uppers: std::collections::BinaryHeap<u64>,
    pub(crate) kept: Vec<(f64, u32)>,
    /// When `kept` is next pruned (twice its size after the last pruning, so that many rows within rounding of the
    /// bound never make pruning quadratic).
    pub(crate) prune_at: usize,
    pub(crate) offered: usize,
}

impl Collector {
    pub(crate) fn new(count: usize) -> Self {
        Collector { count, uppers: Default::default(), kept: vec![], prune_at: 4 * count + 64, offered: 0 }
    }
    /// The `count`-th smallest upper bound so far (∞ before `count` rows).
    pub(crate) fn bound(&self) -> f64 {
        if self.uppers.len() < self.count {
            f64::INFINITY
        } else {
            self.uppers.peek().map_or(f64::INFINITY, |b| f64::from_bits(*b))
        }
    }
    pub(crate) fn offer(&mut self, approx: f64, err: f64, row: u32) {
        self.offered += 1;
        // Distances are never negative, so their bit patterns order as they do.
        let (lower, upper) = ((approx - err).max(0.0), approx + err + 1e-12 * approx);
        if lower > self.bound() {
            return;
        }
        if self.uppers.len() < self.count {
            self.uppers.push(upper.to_bits());
        } else if upper < self.bound() {
            self.uppers.pop();
            self.uppers.push(upper.to_bits());
        }
        self.kept.push((lower, row));
        if self.kept.len() > self.prune_at {
            let b = self.bound();
            self.kept.retain(|(l, _)| *l <= b);
            self.prune_at = (2 * self.kept.len()).max(4 * self.count + 64);
        }
    }
    pub(crate) fn rows(mut self) -> Vec<u32> {
        let b = self.bound();
        self.kept.retain(|(l, _)| *l <= b);
        self.kept.into_iter().map(|(_, r)| r).collect()
    }
}

/// How a search went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Every fingerprint of the family (or carrying the tags) was compared.
    Scan,
    /// The index's nearest cells were probed.
    Index,
}

/// One search.
pub struct Query<'a> {
    pub family: &'a str,
    pub values: &'a [f64],
    pub metric: Metric,
    pub count: usize,
    /// A shape left out of the answer (the query shape).
    pub exclude: Option<ShapeId>,
    /// Only shapes carrying every one of these tags.
    pub tags: &'a [Tag],
    /// Compare every fingerprint (no index).
    pub exact: bool,
    /// The most cells the index probes before it answers without a proof.
    pub max_cells: usize,
}

/// A search's answer.
#[derive(Debug)]
pub struct Found {
    /// Nearest first, ties by id: (shape id, exact distance).
    pub neighbours: Vec<(String, f64)>,
    /// Fingerprints the family holds.
    pub searched: usize,
    /// Fingerprints whose distance was computed.
    pub probed: usize,
    /// Whether the neighbours are proven to be the exact ones: a scan, or a probe whose unprobed cells all lie
    /// farther than the last neighbour.
    pub exact: bool,
    pub method: Method,
}

/// Why a search could not answer.
#[derive(Debug)]
pub enum SearchError {
    /// The query's length is not the family's.
    Length(String),
    /// The store could not give the candidates' exact values.
    Store(std::io::Error),
}

/// The exact values of some fingerprints of a family, by shape id (those still stored).
pub type Fetch<'a> = &'a dyn Fn(&str, &[String]) -> std::io::Result<HashMap<String, Vec<f64>>>;

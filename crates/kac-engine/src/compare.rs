//! Comparisons of stored shapes by shape-DNA, run as jobs (`POST /v1/compare`): the request, and the
//! computation a worker runs, shape by shape through the eigenpair cache, inside the queue's limits, the job
//! timeout and cancel. A shape whose fingerprint cannot be computed is reported with its problem, and the others
//! are compared without it.

use super::store::StoredShape;
use crate::analysis::{
    self, compare, AnalysisError, CompareFailure, Descriptor, Fingerprint, FingerprintOptions, Hooks, OperatorSpec,
    Output, SolverSpec, Summary,
};
use kac_core::descriptors::shape_dna::{Metric, ShapeDnaOptions};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The most shapes one comparison takes.
pub const MAX_SHAPES: usize = 500;

/// Distances between stored shapes by their fingerprints (fused, or one family), each family's distances, and
/// each shape's nearest neighbours.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct CompareRequest {
    /// Shapes to compare (default: every stored shape, at most 500, in id order).
    pub shape_ids: Option<Vec<String>>,
    /// `fused` (default: every family, each distance divided by its spread over the shapes compared, weighted) or
    /// one family: `shape-dna`, `heat-distribution`, `gps-d2`. Every family's distances are reported unless it is
    /// `shape-dna` (which needs no eigenvectors).
    #[serde(default)]
    pub descriptor: Descriptor,
    /// The fingerprint's options (k, normalization, reweighting, include_zero) at the top level, with retrieval's
    /// defaults, as `/v1/search` takes them.
    #[serde(flatten)]
    pub options: FingerprintOptions,
    /// Distances within a family (default euclidean; a fused comparison is euclidean only).
    #[serde(default)]
    pub metric: Metric,
    /// Nearest neighbours listed per shape (default 5).
    #[serde(default = "default_neighbours")]
    pub neighbours: usize,
    #[serde(default)]
    pub operator: OperatorSpec,
}

fn default_neighbours() -> usize {
    5
}

kac_core::object_only_serde!(CompareRequest);

impl CompareRequest {
    /// The shape-DNA the options ask for.
    pub fn options(&self) -> ShapeDnaOptions {
        self.options.dna()
    }
    /// Options that only mean something together, checked before the job is queued.
    pub fn check(&self) -> Result<(), AnalysisError> {
        if self.descriptor == Descriptor::Fused && self.metric != Metric::Euclidean {
            return Err(AnalysisError::invalid_parameter(format!(
                "metric {}: a fused comparison sums Euclidean distances (give one family as `descriptor` for another \
                 metric)",
                self.metric.name()
            )));
        }
        Ok(())
    }
}

/// The comparison: each shape's shape-DNA (typed, through the cache), the distances between those that have one,
/// and each one's nearest neighbours; a shape that failed is listed under `failures` with its problem.
///
/// A failure's `status` in the result is the number the host gives its code (`status_of`: the HTTP layer's
/// mapping, so that the engine decides no status).
pub fn run(
    shapes: &[Arc<StoredShape>],
    req: &CompareRequest,
    collection: Option<&crate::search::Index>,
    hooks: Hooks<'_>,
    status_of: fn(crate::Code) -> u16,
) -> Result<Output, AnalysisError> {
    req.check()?;
    let options = req.options();
    let solver = SolverSpec::default();
    let every_family = req.descriptor != Descriptor::ShapeDna;
    let (mut found, mut failures) = (vec![], vec![]);
    // With every family: each shape's values per family, in the order of `Descriptor::FAMILIES`.
    let mut values: Vec<Vec<analysis::FamilyValues>> = vec![];
    for (i, s) in shapes.iter().enumerate() {
        hooks.control.check()?;
        if let Some(p) = hooks.control.progress {
            p(kac_core::spectrum::Progress { phase: "shape-dna", converged: i, wanted: shapes.len() });
        }
        // Each shape's own solve reports no progress (the comparison reports shapes done), but stops on the flag.
        let own = Hooks { control: kac_core::spectrum::Control { progress: None, ..hooks.control }, ..hooks };
        let got = if every_family {
            analysis::fingerprint_families(&s.validated, &req.options, &req.operator, &solver, own, &Default::default())
                .map(|f| {
                    values.push(f.families);
                    compare::Fingerprinted { id: s.id.clone(), dna: f.shape_dna, operator: Some(f.operator) }
                })
        } else {
            compare::fingerprint(&s.id, &s.validated, &options, &req.operator, &solver, own)
        };
        match got {
            Ok(f) => found.push(f),
            Err(e) if e.is_stop() => return Err(e),
            Err(e) => {
                let p = crate::failure::Failure::of_analysis(&e);
                failures.push(CompareFailure {
                    shape_id: s.id.clone(),
                    code: p.code.as_str().into(),
                    status: status_of(p.code),
                    detail: p.detail,
                });
            }
        }
    }
    let mut summary = compare::comparison(&found, failures, &options, &req.operator, req.metric, req.neighbours)?;
    let fingerprints = if every_family {
        by_families(&mut summary, &values, req, collection)?;
        found
            .iter()
            .zip(&values)
            .flat_map(|(f, fams)| {
                fams.iter().map(|x| Fingerprint {
                    family: x.family.clone(),
                    shape_id: f.id.clone(),
                    values: x.values.clone(),
                })
            })
            .collect()
    } else {
        let family = analysis::fingerprint_family(&options, &req.operator);
        found
            .into_iter()
            .map(|f| Fingerprint { family: family.clone(), shape_id: f.id, values: f.dna.values })
            .collect()
    };
    let summary =
        serde_json::to_value(Summary::Compare(summary)).map_err(|e| AnalysisError::invalid_parameter(e.to_string()))?;
    Ok(Output { fingerprints, summary, arrays: vec![] })
}

/// The fewest fingerprints a spread is taken over: with two, each family's distance divided by its spread is √2
/// whatever the shapes, and the fused distance says nothing.
pub const MIN_SPREAD_ROWS: usize = 3;

/// Each family's distances, and `distances` and `nearest` by the request's descriptor (the fused distance
/// Σ wᵢ dᵢ / sᵢ with each family's spread sᵢ over the collection: the search index's fingerprints of the family
/// when it holds at least [`MIN_SPREAD_ROWS`], else the shapes compared; a fused comparison with fewer is refused).
fn by_families(
    summary: &mut analysis::CompareSummary,
    values: &[Vec<analysis::FamilyValues>],
    req: &CompareRequest,
    collection: Option<&crate::search::Index>,
) -> Result<(), AnalysisError> {
    let n = values.len();
    let mut fused = vec![vec![0.0; n]; n];
    summary.families.clear();
    for (i, d) in Descriptor::FAMILIES.into_iter().enumerate() {
        let rows: Vec<Vec<f64>> = values.iter().map(|f| f[i].values.clone()).collect();
        let distances = kac_core::descriptors::shape_dna::distance_matrix(&rows, req.metric)?;
        let family = values
            .first()
            .map_or_else(|| analysis::descriptor_family(d, &req.options, &req.operator), |f| f[i].family.clone());
        let spread = match collection.and_then(|c| c.spread_of(&family)) {
            Some((s, rows)) if rows >= MIN_SPREAD_ROWS => s,
            _ if n >= MIN_SPREAD_ROWS => compare::spread(&rows),
            // One shape (or none) has no distance to scale.
            _ if req.descriptor == Descriptor::Fused && n >= 2 => {
                return Err(AnalysisError::invalid_parameter(format!(
                    "descriptor fused: each family's distance is divided by its spread over at least \
                     {MIN_SPREAD_ROWS} fingerprints, and the collection holds fewer of family {family} than that \
                     (two shapes alone are always √2 apart in every family so scaled): compare by one family \
                     (`descriptor`), or more shapes"
                )))
            }
            _ => compare::spread(&rows),
        };
        let scale = if spread > 0.0 && spread.is_finite() { d.weight() / spread } else { d.weight() };
        for (row, got) in fused.iter_mut().zip(&distances) {
            row.iter_mut().zip(got).for_each(|(f, x)| *f += scale * x);
        }
        if req.descriptor == d {
            summary.distances = distances.clone();
        }
        summary.families.push(analysis::CompareFamily {
            descriptor: d.name(),
            family,
            weight: d.weight(),
            spread,
            distances,
        });
    }
    if req.descriptor == Descriptor::Fused {
        summary.distances = fused;
    }
    summary.descriptor = req.descriptor.name();
    summary.nearest = compare::nearest_of(&summary.shape_ids, &summary.distances, req.neighbours);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flattened shape-DNA options refuse a field no part declares even without the request check (which
    /// refuses it first over HTTP, with its suggestion).
    #[test]
    fn unknown_fields_are_refused_by_the_type_too() {
        let ok: CompareRequest = serde_json::from_value(serde_json::json!({ "k": 7, "neighbours": 2 })).unwrap();
        assert_eq!((ok.options.k, ok.neighbours), (7, 2));
        assert!(serde_json::from_value::<CompareRequest>(serde_json::json!({ "normalisation": "area" })).is_err());
    }
}

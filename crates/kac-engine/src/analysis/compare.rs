//! Comparisons by shape-DNA, one code path for the CLI (`kac compare A B`) and the service (`POST /v1/compare`):
//! each input's fingerprint (a shape through its eigenpairs, or eigenvalues read from a `.ev` file), then the
//! distances between those that have one and each one's nearest neighbours.

use super::*;
use kac_core::descriptors::shape_dna::{Metric, ShapeDna};

/// One input's fingerprint, with the operator it was heard through (none for eigenvalues given as a file).
pub struct Fingerprinted {
    pub id: String,
    pub dna: ShapeDna,
    pub operator: Option<OperatorUsed>,
}

/// The fingerprint of a shape: its shape-DNA through the eigenpairs (the cache's when `hooks` has one).
pub fn fingerprint(
    id: &str,
    v: &Validated,
    options: &ShapeDnaOptions,
    operator: &OperatorSpec,
    solver: &SolverSpec,
    hooks: Hooks<'_>,
) -> Result<Fingerprinted, AnalysisError> {
    let (e, dna, _) = shape_dna_of(v, options, operator, solver, hooks, &Default::default())?;
    Ok(Fingerprinted { id: id.to_string(), dna, operator: Some(OperatorUsed::of(&e.operator)) })
}

/// The fingerprint of eigenvalues computed elsewhere (a lapy/ShapeDNA `.ev` file), with the measures it gives.
pub fn fingerprint_eigenvalues(
    id: &str,
    eigenvalues: &[f64],
    measures: &Measures,
    options: &ShapeDnaOptions,
) -> Result<Fingerprinted, AnalysisError> {
    let tol = 1e-9 * eigenvalues.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let dna = shape_dna::shape_dna(eigenvalues, tol, measures, options)?;
    Ok(Fingerprinted { id: id.to_string(), dna, operator: None })
}

/// Each input's `neighbours` nearest by a distance matrix (ties by order).
pub fn nearest_of(ids: &[String], distances: &[Vec<f64>], neighbours: usize) -> Vec<CompareNearest> {
    (0..ids.len())
        .map(|i| CompareNearest {
            shape_id: ids[i].clone(),
            nearest: shape_dna::nearest(distances, i, neighbours)
                .into_iter()
                .map(|(j, d)| CompareNeighbour { shape_id: ids[j].clone(), distance: d })
                .collect(),
        })
        .collect()
}

/// The spread of fingerprints: their root-mean-square Euclidean distance over all ordered pairs (a pair with itself
/// included), √(2 Σⱼ Var(xⱼ)); the search index computes the same over a family ([`crate::search`]).
pub fn spread(rows: &[Vec<f64>]) -> f64 {
    let n = rows.len() as f64;
    let k = rows.first().map_or(0, Vec::len);
    let var: f64 = (0..k)
        .map(|j| {
            let mean = rows.iter().map(|r| r[j]).sum::<f64>() / n;
            rows.iter().map(|r| (r[j] - mean).powi(2)).sum::<f64>() / n
        })
        .sum();
    (2.0 * var).sqrt()
}

/// The comparison of the fingerprinted inputs, in their order: distances, each one's `neighbours` nearest
/// (ties by order), and the inputs that could not be fingerprinted with their problems.
pub fn comparison(
    found: &[Fingerprinted],
    failures: Vec<CompareFailure>,
    options: &ShapeDnaOptions,
    operator: &OperatorSpec,
    metric: Metric,
    neighbours: usize,
) -> Result<CompareSummary, AnalysisError> {
    let ids: Vec<String> = found.iter().map(|f| f.id.clone()).collect();
    let fingerprints: Vec<Vec<f64>> = found.iter().map(|f| f.dna.values.clone()).collect();
    let distances = shape_dna::distance_matrix(&fingerprints, metric)?;
    let nearest = nearest_of(&ids, &distances, neighbours);
    let summary = CompareSummary {
        descriptor: "shape-dna",
        options: options.clone(),
        metric: metric.name(),
        operator: operator.clone(),
        shape_ids: ids,
        fingerprints,
        distances,
        nearest,
        families: vec![],
        failures,
        algorithm_version: ALGORITHM_VERSION,
        warnings: vec![],
    };
    // Every number checked before the comparison is returned (by the CLI and the service alike).
    match super::first_non_finite(&summary) {
        Some((place, value)) => Err(AnalysisError::NonFinite { place, value }),
        None => Ok(summary),
    }
}

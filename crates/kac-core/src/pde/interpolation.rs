//! Harmonic interpolation of values fixed on some vertices, and semi-supervised labels.

use super::*;

/// Checks that every connected component of the operator holds a fixed vertex (else the free block is singular).
pub(crate) fn check_anchored(pair: &SparsePair, mask: &[bool], what: &str) -> Result<(), PdeError> {
    let (labels, count) = components(pair);
    let mut anchored = vec![false; count];
    for (i, &m) in mask.iter().enumerate() {
        if m {
            anchored[labels[i] as usize] = true;
        }
    }
    if let Some(c) = anchored.iter().position(|a| !a) {
        let v = labels.iter().position(|&l| l as usize == c).unwrap_or(0);
        return Err(PdeError::NotApplicable {
            message: format!("component {c} (containing vertex {v}) has no {what}; every component needs one"),
        });
    }
    Ok(())
}

pub(crate) fn mask_of(n: usize, known: &[(usize, f64)]) -> Result<(Vec<bool>, Vec<f64>), PdeError> {
    let mut mask = vec![false; n];
    let mut g = vec![0.0; n];
    for &(i, v) in known {
        if i >= n {
            return Err(PdeError::param("vertices", format!("vertex {i} does not exist ({n} vertices)")));
        }
        if !v.is_finite() {
            return Err(PdeError::param("values", format!("vertex {i} has value {v}")));
        }
        mask[i] = true;
        g[i] = v;
    }
    Ok((mask, g))
}

/// Harmonic interpolation: Δu = 0 away from the vertices with known values, u equal to them there. Reproduces
/// linear functions on flat meshes with the cotangent Laplacian (linear precision).
pub fn harmonic(pair: &SparsePair, known: &[(usize, f64)]) -> Result<Vec<f64>, PdeError> {
    let n = pair.n();
    let (mask, g) = mask_of(n, known)?;
    check_anchored(pair, &mask, "vertex with a known value")?;
    let gm = Mat::from_fn(n, 1, |i, _| g[i]);
    let x = solve_spd(&pair.pattern, &pair.stiffness, Mat::<f64>::zeros(n, 1).as_ref(), Some((&mask, gm.as_ref())))?;
    Ok(x.col(0).iter().copied().collect())
}

/// Semi-supervised labels (Zhu, Ghahramani & Lafferty 2003): one harmonic function per class, 1 on the class's
/// labelled vertices and 0 on the others'; each vertex takes the class of largest value.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Labels {
    pub classes: Vec<u32>,
    #[serde(skip)]
    pub label: Vec<u32>,
    /// n × C harmonic class scores (each row sums to 1 on a connected shape).
    #[serde(skip)]
    pub scores: Mat<f64>,
    pub counts: Vec<usize>,
}

pub fn labels(pair: &SparsePair, labelled: &[(usize, u32)]) -> Result<Labels, PdeError> {
    let n = pair.n();
    let mut classes: Vec<u32> = labelled.iter().map(|l| l.1).collect();
    classes.sort_unstable();
    classes.dedup();
    if classes.is_empty() {
        return Err(PdeError::param("labels", "no labelled vertices"));
    }
    let (mask, _) = mask_of(n, &labelled.iter().map(|&(i, _)| (i, 0.0)).collect::<Vec<_>>())?;
    check_anchored(pair, &mask, "labelled vertex")?;
    let mut g = Mat::<f64>::zeros(n, classes.len());
    for &(i, c) in labelled {
        let j = classes.binary_search(&c).unwrap_or(0);
        for q in 0..classes.len() {
            g[(i, q)] = if q == j { 1.0 } else { 0.0 };
        }
    }
    let scores = solve_spd(
        &pair.pattern,
        &pair.stiffness,
        Mat::<f64>::zeros(n, classes.len()).as_ref(),
        Some((&mask, g.as_ref())),
    )?;
    let label: Vec<u32> = (0..n)
        .map(|i| {
            let best = (0..classes.len()).max_by(|&a, &b| scores[(i, a)].total_cmp(&scores[(i, b)])).unwrap_or(0);
            classes[best]
        })
        .collect();
    let counts = classes.iter().map(|c| label.iter().filter(|l| *l == c).count()).collect();
    Ok(Labels { classes, label, scores, counts })
}

//! The Poisson problem Δf = g in its weak form L f = M g, Neumann (made compatible) or Dirichlet.

use super::*;

/// The solution of a Poisson problem Δf = g.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Poisson {
    #[serde(skip)]
    pub values: Vec<f64>,
    /// The condition solved with: `neumann`, `dirichlet` (f = 0 on the boundary the operator eliminated), or
    /// `dirichlet-values` (f fixed at the given vertices).
    pub boundary: &'static str,
    /// Neumann: per component, the M-mean of g removed to make the problem solvable (∫ g = 0 is required);
    /// f is returned with M-mean zero on each component.
    pub removed_mean: Vec<f64>,
}

/// Poisson's equation Δf = g with Δ = −∇·∇ positive semidefinite: L f = M g (Galerkin FEM, §9.5). With
/// `dirichlet`, f takes the given values on those vertices; without, the problem is Neumann (compatible only
/// when g integrates to zero on each component: the mean is removed and reported).
pub fn poisson(pair: &SparsePair, g: &[f64], dirichlet: Option<&[(usize, f64)]>) -> Result<Poisson, PdeError> {
    match dirichlet {
        Some(known) => poisson_with(pair, g, PoissonBoundary::Values(known)),
        None => poisson_with(pair, g, PoissonBoundary::Neumann),
    }
}

/// The boundary condition of a Poisson problem.
#[derive(Debug, Clone, Copy)]
pub enum PoissonBoundary<'a> {
    /// ∂f/∂n = 0: solvable when g integrates to zero on each component (the mean is removed and reported).
    Neumann,
    /// f = 0 on the boundary that the operator already eliminated (built with a Dirichlet condition): L is
    /// positive definite and L f = M g is solved as it is, g untouched.
    Eliminated,
    /// f fixed at these (operator row, value) pairs.
    Values(&'a [(usize, f64)]),
}

/// Poisson's equation Δf = g (L f = M g) under the given condition (see [`poisson`]).
pub fn poisson_with(pair: &SparsePair, g: &[f64], condition: PoissonBoundary<'_>) -> Result<Poisson, PdeError> {
    let n = pair.n();
    if let PoissonBoundary::Eliminated = condition {
        check_len("g", g.len(), n)?;
        let gm = Mat::from_fn(n, 1, |i, _| g[i]);
        let rhs = mass_times(pair, gm.as_ref());
        let x = solve_spd(&pair.pattern, &pair.stiffness, rhs.as_ref(), None)?;
        return Ok(Poisson { values: x.col(0).iter().copied().collect(), boundary: "dirichlet", removed_mean: vec![] });
    }
    let dirichlet = match condition {
        PoissonBoundary::Values(v) => Some(v),
        _ => None,
    };
    check_len("g", g.len(), n)?;
    let (labels, count) = components(pair);
    let mut g = g.to_vec();
    let mut removed = Vec::new();
    let (mask, fixed, boundary) = match dirichlet {
        Some(known) => {
            let (mask, vals) = mask_of(n, known)?;
            check_anchored(pair, &mask, "Dirichlet vertex")?;
            (mask, vals, "dirichlet-values")
        }
        None => {
            removed = component_means(pair, &labels, count, &g);
            g.iter_mut().enumerate().for_each(|(i, v)| *v -= removed[labels[i] as usize]);
            // Pin the first vertex of each component; shifted to mean zero below.
            let mut mask = vec![false; n];
            let mut seen = vec![false; count];
            for i in 0..n {
                if !seen[labels[i] as usize] {
                    seen[labels[i] as usize] = true;
                    mask[i] = true;
                }
            }
            (mask, vec![0.0; n], "neumann")
        }
    };
    let gm = Mat::from_fn(n, 1, |i, _| g[i]);
    let rhs = mass_times(pair, gm.as_ref());
    let fm = Mat::from_fn(n, 1, |i, _| fixed[i]);
    let x = solve_spd(&pair.pattern, &pair.stiffness, rhs.as_ref(), Some((&mask, fm.as_ref())))?;
    let mut f: Vec<f64> = x.col(0).iter().copied().collect();
    if dirichlet.is_none() {
        let means = component_means(pair, &labels, count, &f);
        f.iter_mut().enumerate().for_each(|(i, v)| *v -= means[labels[i] as usize]);
    }
    Ok(Poisson { values: f, boundary, removed_mean: removed })
}

/// The M-weighted mean of `u` on each component: Σ (M1)_i u_i / Σ (M1)_i, M1 the row sums of M (the integral of
/// each hat function).
pub(crate) fn component_means(pair: &SparsePair, labels: &[u32], count: usize, u: &[f64]) -> Vec<f64> {
    let n = pair.n();
    let mut rows = vec![0.0; n];
    matvec(&pair.pattern, &pair.mass, &vec![1.0; n], &mut rows);
    let (mut s, mut w) = (vec![0.0; count], vec![0.0; count]);
    for i in 0..n {
        s[labels[i] as usize] += rows[i] * u[i];
        w[labels[i] as usize] += rows[i];
    }
    (0..count).map(|c| s[c] / w[c]).collect()
}

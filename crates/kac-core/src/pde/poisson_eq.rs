//! The Poisson problem Δf = g in its weak form L f = M g, Neumann (made compatible) or Dirichlet.

use super::*;

/// The solution of a Poisson problem Δf = g.
#[derive(Debug, Clone, Serialize)]
pub struct Poisson {
    #[serde(skip)]
    pub values: Vec<f64>,
    pub boundary: &'static str,
    /// Neumann: per component, the M-mean of g removed to make the problem solvable (∫ g = 0 is required);
    /// f is returned with M-mean zero on each component.
    pub removed_mean: Vec<f64>,
}

/// Poisson's equation Δf = g with Δ = −∇·∇ positive semidefinite: L f = M g (Galerkin FEM, §9.5). With
/// `dirichlet`, f takes the given values on those vertices; without, the problem is Neumann (compatible only
/// when g integrates to zero on each component: the mean is removed and reported).
pub fn poisson(pair: &SparsePair, g: &[f64], dirichlet: Option<&[(usize, f64)]>) -> Result<Poisson, DescriptorError> {
    let n = pair.n();
    check_len("g", g.len(), n)?;
    let (labels, count) = components(pair);
    let mut g = g.to_vec();
    let mut removed = Vec::new();
    let (mask, fixed, boundary) = match dirichlet {
        Some(known) => {
            let (mask, vals) = mask_of(n, known)?;
            check_anchored(pair, &mask, "Dirichlet vertex")?;
            (mask, vals, "dirichlet")
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

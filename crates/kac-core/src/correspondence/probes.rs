//! The probe functions both sides are compared by: wave-kernel signatures at shared energies and landmark WKS,
//! each of unit M-norm.

use super::{mass_times, SpectralShape};
use crate::descriptors::signatures::{self, WksOptions};
use crate::descriptors::DescriptorError;
use crate::operators::sparse::SparsePair;
use faer::Mat;

/// Unit M-norm columns (a column of zero norm is left as it is).
fn normalize_columns(pair: &SparsePair, f: &mut Mat<f64>) {
    let mf = mass_times(pair, f.as_ref());
    for j in 0..f.ncols() {
        let norm = (0..f.nrows()).map(|i| f[(i, j)] * mf[(i, j)]).sum::<f64>().max(0.0).sqrt();
        if norm > 0.0 {
            for i in 0..f.nrows() {
                f[(i, j)] /= norm;
            }
        }
    }
}

/// The probes of one side: WKS at shared log-energies (the union of both spectra's ranges, so that a function on one
/// shape has its counterpart on the other), every `step`-th kept, then landmark WKS (the heat of each landmark's
/// kernel weighted per energy), each column of unit M-norm.
pub(super) fn probes(
    side: &SpectralShape<'_>,
    energies: &[f64],
    step: usize,
    landmarks: &[u32],
) -> Result<Mat<f64>, DescriptorError> {
    let w = signatures::wks(
        &side.basis,
        &WksOptions { count: energies.len(), variance: 6.0, energies: Some(energies.to_vec()) },
    )?;
    let kept: Vec<usize> = (0..energies.len()).step_by(step.max(1)).collect();
    let n = side.n();
    let extra = landmarks.len() * kept.len();
    let mut f = Mat::zeros(n, kept.len() + extra);
    for (c, &j) in kept.iter().enumerate() {
        for i in 0..n {
            f[(i, c)] = w.values[(i, j)];
        }
    }
    // Landmark descriptors: Σ_i φ_i(x) φ_i(l) g_e(λ_i) for each kept energy e (the wave kernel from the landmark).
    let b = &side.basis;
    let i1 = (0..b.k()).find(|&i| !b.is_zero(i)).unwrap_or(b.k());
    let logs: Vec<f64> = b.values.iter().map(|l| if *l > b.zero_tol { l.ln() } else { f64::NAN }).collect();
    let sigma = w.sigma;
    for (li, &l) in landmarks.iter().enumerate() {
        for (c, &j) in kept.iter().enumerate() {
            let e = energies[j];
            let col = kept.len() + li * kept.len() + c;
            let weights: Vec<f64> = (0..b.k())
                .map(|i| {
                    if i < i1 {
                        0.0
                    } else {
                        (-(e - logs[i]).powi(2) / (2.0 * sigma * sigma)).exp() * b.vectors[(l as usize, i)]
                    }
                })
                .collect();
            for x in 0..n {
                f[(x, col)] = (i1..b.k()).map(|i| weights[i] * b.vectors[(x, i)]).sum();
            }
        }
    }
    normalize_columns(side.pair, &mut f);
    Ok(f)
}

//! Per-vertex spectral signatures: HKS, scale-invariant HKS, WKS and GPS. Every one returns the grid it was
//! sampled on and the parameters it used.

use super::{check_times, lin_space, log_space, squared_basis_times, Basis, DescriptorError};
use faer::Mat;
use serde::{Deserialize, Serialize};
use std::f64::consts::LN_10;

/// Heat kernel signature (Sun, Ovsjanikov & Guibas 2009): HKS(x, t) = k_t(x, x) = Σ_i e^{−λ_i t} φ_i(x)².
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default)]
pub struct HksOptions {
    /// Explicit times; when absent, `count` times log-spaced in [4 ln 10 / λ_max, 4 ln 10 / λ₁] (λ₁ the first
    /// non-zero eigenvalue, λ_max the largest computed): the range in which the computed eigenpairs decide
    /// the signature, as proposed by Sun et al.
    #[cfg_attr(feature = "cli", arg(long, value_delimiter = ','))]
    pub times: Option<Vec<f64>>,
    /// Times on the default grid (default 100).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = HksOptions::default().count))]
    pub count: usize,
    /// Divide HKS(·, t) by the heat trace Z(t) = Σ_i e^{−λ_i t} (Sun et al.'s scaling, which weighs all
    /// times alike).
    #[cfg_attr(feature = "cli", arg(long))]
    pub scale: bool,
}

impl Default for HksOptions {
    fn default() -> Self {
        HksOptions { times: None, count: 100, scale: false }
    }
}

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Hks {
    pub times: Vec<f64>,
    /// n × T.
    #[serde(skip)]
    pub values: Mat<f64>,
    pub scaled: bool,
    /// How the times were chosen: "explicit" or "default".
    pub time_grid: &'static str,
    /// Eigenpairs summed (zero modes included: they carry the constant 1/area term).
    pub eigenpairs: usize,
    pub zero_modes: usize,
    pub lambda_first_nonzero: f64,
    pub lambda_max: f64,
}

fn first_nonzero(basis: &Basis<'_>, what: &str) -> Result<usize, DescriptorError> {
    basis.first_nonzero().ok_or_else(|| DescriptorError::TooFewEigenpairs {
        message: format!("{what} needs a non-zero eigenvalue; all {} computed are zero modes", basis.k()),
    })
}

/// The default HKS time grid of a basis.
pub fn default_hks_times(basis: &Basis<'_>, count: usize) -> Result<Vec<f64>, DescriptorError> {
    let i1 = first_nonzero(basis, "the default HKS time grid")?;
    let (l1, lmax) = (basis.values[i1], basis.max_value());
    Ok(log_space(4.0 * LN_10 / lmax, 4.0 * LN_10 / l1, count))
}

pub fn hks(basis: &Basis<'_>, opts: &HksOptions) -> Result<Hks, DescriptorError> {
    if opts.times.is_none() && opts.count == 0 {
        return Err(DescriptorError::param("count", "at least one time is needed"));
    }
    let (times, grid) = match &opts.times {
        Some(t) => (t.clone(), "explicit"),
        None => (default_hks_times(basis, opts.count)?, "default"),
    };
    check_times("times", &times)?;
    let w = Mat::from_fn(basis.k(), times.len(), |i, j| (-basis.values[i] * times[j]).exp());
    let mut values = squared_basis_times(basis, w.as_ref());
    if opts.scale {
        let z = super::heat::heat_trace(basis.values, &times);
        for (j, z) in z.iter().enumerate() {
            values.col_mut(j).iter_mut().for_each(|v| *v /= z);
        }
    }
    let i1 = basis.first_nonzero();
    Ok(Hks {
        times,
        values,
        scaled: opts.scale,
        time_grid: grid,
        eigenpairs: basis.k(),
        zero_modes: basis.zero_modes(),
        lambda_first_nonzero: i1.map_or(f64::NAN, |i| basis.values[i]),
        lambda_max: basis.max_value(),
    })
}

/// Scale-invariant HKS (Bronstein & Kokkinos 2010). The HKS is sampled at log-times t = α^τ, τ = τ₀ + j·Δτ;
/// scaling the shape by β multiplies the HKS by β⁻² and shifts τ by 2 log_α β. The log removes the factor into
/// an additive constant, the derivative in τ (a forward difference) removes the constant, and the modulus of
/// the discrete Fourier transform over τ removes the shift. The first `frequencies` moduli are the descriptor.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default)]
pub struct SiHksOptions {
    /// Base α of the log-time grid (default 2).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SiHksOptions::default().alpha))]
    pub alpha: f64,
    /// First τ; default log_α(1 / λ_max), so that the grid starts where the computed spectrum stops resolving
    /// the kernel and follows the shape's scale.
    #[cfg_attr(feature = "cli", arg(long, allow_hyphen_values = true))]
    pub tau_start: Option<f64>,
    /// Grid step Δτ (default 1/16).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SiHksOptions::default().tau_step))]
    pub tau_step: f64,
    /// Number of τ samples (default 385: 24 octaves at Δτ = 1/16).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SiHksOptions::default().samples))]
    pub samples: usize,
    /// Fourier moduli kept, from frequency 0 up (default 6).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SiHksOptions::default().frequencies))]
    pub frequencies: usize,
}

impl Default for SiHksOptions {
    fn default() -> Self {
        SiHksOptions { alpha: 2.0, tau_start: None, tau_step: 1.0 / 16.0, samples: 385, frequencies: 6 }
    }
}

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SiHks {
    pub alpha: f64,
    pub tau_start: f64,
    pub tau_step: f64,
    pub samples: usize,
    /// Kept frequencies, in cycles per `samples − 1` steps of τ.
    pub frequencies: Vec<usize>,
    /// n × Ω.
    #[serde(skip)]
    pub values: Mat<f64>,
    pub eigenpairs: usize,
}

pub fn si_hks(basis: &Basis<'_>, opts: &SiHksOptions) -> Result<SiHks, DescriptorError> {
    if !(opts.alpha > 1.0 && opts.alpha.is_finite()) {
        return Err(DescriptorError::param("alpha", format!("{} is not a number above 1", opts.alpha)));
    }
    if !(opts.tau_step > 0.0 && opts.tau_step.is_finite()) {
        return Err(DescriptorError::param("tau_step", format!("{} is not positive", opts.tau_step)));
    }
    if opts.samples < 3 {
        return Err(DescriptorError::param("samples", "at least 3 samples are needed"));
    }
    let len = opts.samples - 1; // the differenced sequence
    if opts.frequencies == 0 || opts.frequencies > len / 2 + 1 {
        return Err(DescriptorError::param("frequencies", format!("must be in 1..={}", len / 2 + 1)));
    }
    let lmax = basis.max_value();
    if !(lmax > 0.0) {
        return Err(DescriptorError::TooFewEigenpairs { message: "SI-HKS needs a non-zero eigenvalue".into() });
    }
    let tau0 = opts.tau_start.unwrap_or_else(|| (1.0 / lmax).ln() / opts.alpha.ln());
    let times: Vec<f64> = (0..opts.samples).map(|j| opts.alpha.powf(tau0 + j as f64 * opts.tau_step)).collect();
    check_times("times", &times)?;
    let h = hks(basis, &HksOptions { times: Some(times), count: 0, scale: false })?.values;
    let n = basis.n();
    let omega = opts.frequencies;
    // DFT by direct sums: only Ω ≪ len frequencies are wanted.
    let (cos, sin): (Vec<f64>, Vec<f64>) = (0..omega * len)
        .map(|q| {
            let (f, j) = (q / len, q % len);
            let a = -2.0 * std::f64::consts::PI * (f * j) as f64 / len as f64;
            (a.cos(), a.sin())
        })
        .unzip();
    let mut values = Mat::<f64>::zeros(n, omega);
    let mut d = vec![0.0; len];
    for x in 0..n {
        for j in 0..len {
            // HKS is positive wherever the basis has any support; guard the log all the same.
            let (a, b) = (h[(x, j)].max(f64::MIN_POSITIVE), h[(x, j + 1)].max(f64::MIN_POSITIVE));
            d[j] = b.ln() - a.ln();
        }
        for f in 0..omega {
            let (mut re, mut im) = (0.0, 0.0);
            for j in 0..len {
                re += d[j] * cos[f * len + j];
                im += d[j] * sin[f * len + j];
            }
            values[(x, f)] = re.hypot(im);
        }
    }
    Ok(SiHks {
        alpha: opts.alpha,
        tau_start: tau0,
        tau_step: opts.tau_step,
        samples: opts.samples,
        frequencies: (0..omega).collect(),
        values,
        eigenpairs: basis.k(),
    })
}

/// Wave kernel signature (Aubry, Schlickewei & Cremers 2011): the probability of finding a quantum particle of
/// log-energy e at x, WKS(x, e) = Σ_i φ_i(x)² exp(−(e − log λ_i)² / 2σ²) / C_e with
/// C_e = Σ_i exp(−(e − log λ_i)² / 2σ²). Zero modes are left out (log 0).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default)]
pub struct WksOptions {
    /// Number of log-energies, evenly spaced in [log λ₁, log λ_max] (default 100).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = WksOptions::default().count))]
    pub count: usize,
    /// σ as a multiple of the energy spacing (default 6, as in the authors' code).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = WksOptions::default().variance))]
    pub variance: f64,
    /// Explicit log-energies instead of the default grid (σ is then `variance` times their mean spacing, or
    /// `variance` itself for a single energy).
    #[cfg_attr(feature = "cli", arg(long, value_delimiter = ',', allow_hyphen_values = true))]
    pub energies: Option<Vec<f64>>,
}

impl Default for WksOptions {
    fn default() -> Self {
        WksOptions { count: 100, variance: 6.0, energies: None }
    }
}

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Wks {
    pub energies: Vec<f64>,
    pub sigma: f64,
    pub variance: f64,
    /// n × N.
    #[serde(skip)]
    pub values: Mat<f64>,
    /// Eigenpairs summed (zero modes excluded).
    pub eigenpairs: usize,
}

pub fn wks(basis: &Basis<'_>, opts: &WksOptions) -> Result<Wks, DescriptorError> {
    if !(opts.variance > 0.0 && opts.variance.is_finite()) {
        return Err(DescriptorError::param("variance", format!("{} is not positive", opts.variance)));
    }
    let i1 = first_nonzero(basis, "the WKS")?;
    let logs: Vec<f64> = basis.values[i1..].iter().map(|l| l.ln()).collect();
    let energies = match &opts.energies {
        Some(e) if e.is_empty() || e.iter().any(|v| !v.is_finite()) => {
            return Err(DescriptorError::param("energies", "give finite log-energies"))
        }
        Some(e) => e.clone(),
        None if opts.count == 0 => return Err(DescriptorError::param("count", "at least one energy is needed")),
        None => lin_space(logs[0], *logs.last().unwrap_or(&logs[0]), opts.count),
    };
    let spacing = if energies.len() > 1 {
        (energies[energies.len() - 1] - energies[0]).abs() / (energies.len() - 1) as f64
    } else {
        1.0
    };
    let sigma = opts.variance * if spacing > 0.0 { spacing } else { 1.0 };
    let k = basis.k();
    let mut w = Mat::<f64>::zeros(k, energies.len());
    for (j, e) in energies.iter().enumerate() {
        let mut c = 0.0;
        for (q, l) in logs.iter().enumerate() {
            let g = (-(e - l).powi(2) / (2.0 * sigma * sigma)).exp();
            w[(i1 + q, j)] = g;
            c += g;
        }
        if c > 0.0 {
            for q in 0..logs.len() {
                w[(i1 + q, j)] /= c;
            }
        }
    }
    Ok(Wks {
        energies,
        sigma,
        variance: opts.variance,
        values: squared_basis_times(basis, w.as_ref()),
        eigenpairs: logs.len(),
    })
}

/// Global point signature (Rustamov 2007): GPS(x) = (φ₁(x)/√λ₁, φ₂(x)/√λ₂, …) over the non-zero modes.
///
/// Each eigenvector is defined up to sign (and, inside a multiplicity cluster, up to rotation), so GPS
/// coordinates are too. kac's eigenvectors follow one deterministic convention, the entry of largest
/// magnitude positive, so the same input always gives the same GPS; two different meshes of one shape need not
/// agree in sign, and no convention can make clusters agree.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Gps {
    /// Eigenvalues used (the non-zero ones, ascending).
    pub eigenvalues: Vec<f64>,
    /// n × d.
    #[serde(skip)]
    pub values: Mat<f64>,
    pub sign_convention: &'static str,
}

pub const SIGN_CONVENTION: &str = "each eigenvector's entry of largest magnitude is positive";

pub fn gps(basis: &Basis<'_>, dimensions: Option<usize>) -> Result<Gps, DescriptorError> {
    let i1 = first_nonzero(basis, "the GPS")?;
    let available = basis.k() - i1;
    let d = dimensions.unwrap_or(available);
    if d == 0 || d > available {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!("{d} GPS dimensions asked, {available} non-zero eigenpairs computed"),
        });
    }
    let phi = basis.vectors;
    let values = Mat::from_fn(basis.n(), d, |x, j| phi[(x, i1 + j)] / basis.values[i1 + j].sqrt());
    Ok(Gps { eigenvalues: basis.values[i1..i1 + d].to_vec(), values, sign_convention: SIGN_CONVENTION })
}

crate::object_only_serde!(HksOptions);

crate::object_only_serde!(SiHksOptions);

crate::object_only_serde!(WksOptions);

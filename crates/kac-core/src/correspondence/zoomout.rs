//! The correspondence itself: the fit, then ZoomOut's refinement (Melzi et al. 2019), and the vertex maps of a
//! functional map both ways.

use super::fit::{fit, spd_solve};
use super::nearest::nearest_rows;
use super::options::{CorrespondenceOptions, MAX_COUPLED_FIT_K};
use super::orientation::{oriented, Orienter};
use super::probes::probes;
use super::{leading, mass_times, truncated, Correspondence, CorrespondenceError, SpectralShape};
use crate::descriptors::{Basis, DescriptorError};
use crate::spectrum::Control;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

/// The vertex maps of C (k_T × k_S) both ways, with their costs.
fn vertex_maps(s: &SpectralShape<'_>, t: &SpectralShape<'_>, c: &Mat<f64>) -> (Vec<u32>, Vec<f64>, Vec<u32>, Vec<f64>) {
    let (ts, ts_cost) = pull_back(s, t, c);
    let (st, st_cost) = push_forward(s, t, c);
    (ts, ts_cost, st, st_cost)
}

/// The functional map (k_T × k_S) of a vertex map π: T → S: Φ_T[:, :k_T]ᵀ M_T Φ_S[π, :k_S].
pub fn map_of_vertices(s: &SpectralShape<'_>, t: &SpectralShape<'_>, pi: &[u32], kt: usize, ks: usize) -> Mat<f64> {
    let pulled = Mat::from_fn(t.n(), ks, |y, j| s.basis.vectors[(pi[y] as usize, j)]);
    t.coefficients(kt, pulled.as_ref())
}

/// The correspondence between `s` and `t`: the fitted map in `fit_k` functions, refined by ZoomOut up to
/// `refine_k`, and the vertex maps of the last one. `stop` is asked between steps.
pub fn correspond(
    s: &SpectralShape<'_>,
    t: &SpectralShape<'_>,
    o: &CorrespondenceOptions,
    control: &Control<'_>,
) -> Result<Correspondence, CorrespondenceError> {
    o.check()?;
    let available = s.basis.k().min(t.basis.k());
    if o.fit_k > available {
        Err(DescriptorError::param(
            "fit_k",
            format!("{} is out of range: 2 ≤ fit_k ≤ the eigenpairs computed ({available})", o.fit_k),
        ))?;
    }
    let orientation = oriented(s, t, o);
    let oriented = orientation.is_some();
    if (o.commutativity_weight > 0.0 || orientation.is_some()) && o.fit_k > MAX_COUPLED_FIT_K {
        Err(DescriptorError::param(
            "fit_k",
            format!(
                "{}: with descriptor commutativity or orientation the fit is one dense system of fit_k² unknowns; \
                 at most {MAX_COUPLED_FIT_K} (or both weights 0, whose rows are solved apart)",
                o.fit_k
            ),
        ))?;
    }
    for &(a, b) in &o.landmarks {
        if a as usize >= s.n() || b as usize >= t.n() {
            Err(DescriptorError::param("landmarks", format!("({a}, {b}) names a vertex that is not there")))?;
        }
    }
    // Basis sizes: the target's grows from fit_k to refine_k; the source's is the same, or for a partial target the
    // source's eigenvalues up to the target's largest (their count follows the areas' ratio: Weyl's law).
    let mut last = o.refine_k.clamp(o.fit_k, if o.partial { t.basis.k() } else { available });
    if o.partial {
        // The target's basis no further than the source's computed eigenvalues reach (the slanted diagonal must
        // fit in the source's basis).
        let top = s.basis.values[s.basis.k() - 1];
        let reach = t.basis.values.iter().take_while(|&&l| l <= top).count();
        last = last.min(reach.max(o.fit_k));
    }
    let source_size = |kt: usize| -> usize {
        if !o.partial {
            return kt;
        }
        let top = t.basis.values[kt - 1];
        let within = s.basis.values.iter().filter(|&&l| l <= top * (1.0 + 1e-9)).count();
        within.clamp(2, s.basis.k())
    };
    let last_s = source_size(last);
    // Shared log-energies over both spectra's non-zero range in the eigenpairs used.
    let range = |b: &Basis<'_>, k: usize| {
        let nz: Vec<f64> = b.values[..k].iter().copied().filter(|&l| l > b.zero_tol).collect();
        (nz.first().copied().unwrap_or(1.0).ln(), nz.last().copied().unwrap_or(1.0).ln())
    };
    let ((a0, a1), (b0, b1)) = (range(&s.basis, last_s), range(&t.basis, last));
    let (e0, e1) = (a0.min(b0), a1.max(b1));
    let count = o.descriptors.max(2);
    let energies: Vec<f64> = (0..count).map(|i| e0 + (e1 - e0) * i as f64 / (count - 1) as f64).collect();
    let (bs, bt) = (truncated(&s.basis, last_s), truncated(&t.basis, last));
    let (ss, tt) = (
        SpectralShape { basis: bs, pair: s.pair, surface: s.surface },
        SpectralShape { basis: bt, pair: t.pair, surface: t.surface },
    );
    let ls: Vec<u32> = o.landmarks.iter().map(|p| p.0).collect();
    let lt: Vec<u32> = o.landmarks.iter().map(|p| p.1).collect();
    let fs = probes(&ss, &energies, o.descriptor_step, &ls)?;
    let ft = probes(&tt, &energies, o.descriptor_step, &lt)?;
    let (kt, ks) = (o.fit_k, source_size(o.fit_k));
    let a = ss.coefficients(ks, fs.as_ref());
    let b = tt.coefficients(kt, ft.as_ref());
    // The multiplication operators of the probes, in the fit's functions.
    let mut ops = vec![];
    if o.commutativity_weight != 0.0 {
        // Φᵀ (M diag f + diag f M) Φ / 2: symmetric, as the multiplication operator is (with a lumped mass the two
        // halves are equal; with a consistent one Φᵀ M diag f Φ alone is not symmetric).
        // Φᵀ M diag f Φ = (M Φ)ᵀ (f ⊙ Φ): the mass applied once per side, the probes in parallel.
        let op = |side: &SpectralShape<'_>, m_phi: &Mat<f64>, col: MatRef<'_, f64>, k: usize| {
            let phi = leading(side, k);
            let scaled = Mat::from_fn(side.n(), k, |x, j| col[(x, 0)] * phi[(x, j)]);
            let mut a = Mat::zeros(k, k);
            matmul(a.as_mut(), Accum::Replace, m_phi.transpose(), scaled.as_ref(), 1.0, Par::Seq);
            Mat::from_fn(k, k, |i, j| 0.5 * (a[(i, j)] + a[(j, i)]))
        };
        let (m_phi_s, m_phi_t) = (mass_times(ss.pair, leading(&ss, ks)), mass_times(tt.pair, leading(&tt, kt)));
        ops = (0..fs.ncols())
            .into_par_iter()
            .map(|f| {
                let x = op(&ss, &m_phi_s, fs.as_ref().subcols(f, 1), ks);
                (x, op(&tt, &m_phi_t, ft.as_ref().subcols(f, 1), kt), o.commutativity_weight)
            })
            .collect();
    }
    // The orientation operators of the probes (both sides triangle meshes).
    if let Some(((ms, sign_s), (mt, sign_t))) = orientation {
        // Each pair scaled to the mean size of the multiplication operators (or to unit size without them): a
        // gradient is larger than its function by about the inverse wavelength, which would otherwise let this
        // term outweigh the others by orders of magnitude.
        let size = |x: &Mat<f64>, y: &Mat<f64>| 0.5 * (x.norm_l2() + y.norm_l2());
        let reference =
            if ops.is_empty() { 1.0 } else { ops.iter().map(|(x, y, _)| size(x, y)).sum::<f64>() / ops.len() as f64 };
        let (os, ot) = (Orienter::new(ms, sign_s, &ss, ks), Orienter::new(mt, sign_t, &tt, kt));
        let pairs: Vec<_> = (0..fs.ncols())
            .into_par_iter()
            .map(|f| {
                let (x, y) = (os.op(fs.as_ref().subcols(f, 1)), ot.op(ft.as_ref().subcols(f, 1)));
                let scale = if size(&x, &y) > 0.0 { reference / size(&x, &y) } else { 0.0 };
                (x * scale, y * scale, o.orientation_weight)
            })
            .collect();
        ops.extend(pairs);
    }
    control.check()?;
    let mut c = fit(&a, &b, &ss.basis.values[..ks], &tt.basis.values[..kt], &ops, o)?;
    let mut sizes = vec![kt];
    // ZoomOut: the vertex map of C, then the map of that vertex map in `refine_step` more functions; on samples of
    // the vertices (the map of the sampled pairs by least squares), or on every vertex (by M-weighted projection).
    let (sub_s, sub_t) = (sample(ss.n(), o.refine_samples, 1), sample(tt.n(), o.refine_samples, 2));
    // On samples: both bases' sampled rows gathered once, and the Gram matrix of the target's, whose leading blocks
    // are every step's normal matrices.
    let sampled = match (&sub_s, &sub_t) {
        (Some(sub_s), Some(sub_t)) => {
            let s_all = Mat::from_fn(sub_s.len(), last_s, |i, j| ss.basis.vectors[(sub_s[i], j)]);
            let t_all = Mat::from_fn(sub_t.len(), last, |i, j| tt.basis.vectors[(sub_t[i], j)]);
            let gram = |x: &Mat<f64>| {
                let mut g = Mat::zeros(x.ncols(), x.ncols());
                matmul(g.as_mut(), Accum::Replace, x.transpose(), x.as_ref(), 1.0, Par::Seq);
                g
            };
            let (gram_s, gram_t) = (if o.bijective { gram(&s_all) } else { Mat::zeros(0, 0) }, gram(&t_all));
            Some((s_all, t_all, gram_s, gram_t))
        }
        _ => None,
    };
    let few = || DescriptorError::param("refine_samples", "too few samples for the basis: give more");
    let mut size = kt;
    while size < last {
        control.check()?;
        let next = (size + o.refine_step).min(last);
        let (ks_next, kt_next) = (source_size(next), next);
        c = match &sampled {
            Some((s_all, t_all, gram_s, gram_t)) => {
                let (ks_now, kt_now) = (c.ncols(), c.nrows());
                // The map of matched sampled rows by least squares: Xᵀ X C = Xᵀ Y[matches], Xᵀ X a leading block of
                // the Gram matrix.
                let fit_rows = |x: &Mat<f64>, gram: &Mat<f64>, y: &Mat<f64>, matches: &[u32], kx: usize, ky: usize| {
                    let b = Mat::from_fn(matches.len(), ky, |i, j| y[(matches[i] as usize, j)]);
                    let mut xtb = Mat::zeros(kx, ky);
                    matmul(xtb.as_mut(), Accum::Replace, x.subcols(0, kx).transpose(), b.as_ref(), 1.0, Par::Seq);
                    spd_solve(&gram.submatrix(0, 0, kx, kx).to_owned(), &xtb).ok_or_else(few)
                };
                // Target samples to source samples: source rows Φ_S Cᵀ searched from target rows Φ_T.
                let mut s_emb = Mat::zeros(s_all.nrows(), kt_now);
                matmul(s_emb.as_mut(), Accum::Replace, s_all.subcols(0, ks_now), c.transpose(), 1.0, Par::Seq);
                let (pi, _) = nearest_rows(s_emb.as_ref(), t_all.subcols(0, kt_now));
                let forward = fit_rows(t_all, gram_t, s_all, &pi, kt_next, ks_next)?;
                if o.bijective {
                    // Source samples to target samples: target rows Φ_T C searched from source rows Φ_S; the
                    // reverse map (ks × kt) by least squares, and the mean of C and its transpose.
                    let mut t_emb = Mat::zeros(t_all.nrows(), ks_now);
                    matmul(t_emb.as_mut(), Accum::Replace, t_all.subcols(0, kt_now), c.as_ref(), 1.0, Par::Seq);
                    let (sigma, _) = nearest_rows(t_emb.as_ref(), s_all.subcols(0, ks_now));
                    let backward = fit_rows(s_all, gram_s, t_all, &sigma, ks_next, kt_next)?;
                    Mat::from_fn(kt_next, ks_next, |i, j| 0.5 * (forward[(i, j)] + backward[(j, i)]))
                } else {
                    forward
                }
            }
            _ => {
                let (pi, _) = pull_back(&ss, &tt, &c);
                let forward = map_of_vertices(&ss, &tt, &pi, kt_next, ks_next);
                if o.bijective {
                    // The reverse map of the source-to-target matches σ, Φ_Sᵀ M_S Φ_T[σ] (ks × kt).
                    let (sigma, _) = push_forward(&ss, &tt, &c);
                    let backward = map_of_vertices(&tt, &ss, &sigma, ks_next, kt_next);
                    Mat::from_fn(kt_next, ks_next, |i, j| 0.5 * (forward[(i, j)] + backward[(j, i)]))
                } else {
                    forward
                }
            }
        };
        size = next;
        sizes.push(size);
    }
    let (ts, ts_cost, st, st_cost) = vertex_maps(&ss, &tt, &c);
    // Rows of C are orthonormal for a map onto an isometric (or partial) target.
    let mut cct = Mat::zeros(c.nrows(), c.nrows());
    matmul(cct.as_mut(), Accum::Replace, c.as_ref(), c.transpose(), 1.0, Par::Seq);
    let k = c.nrows();
    let defect = Mat::from_fn(k, k, |i, j| cct[(i, j)] - if i == j { 1.0 } else { 0.0 }).norm_l2() / (k as f64).sqrt();
    Ok(Correspondence {
        c,
        target_to_source: ts,
        source_to_target: st,
        target_cost: ts_cost,
        source_cost: st_cost,
        sizes,
        orthogonality_defect: defect,
        oriented,
    })
}

/// A fixed pseudo-random sample of `count` of `n` vertices, sorted (None: every vertex, when count is 0 or ≥ n).
pub(super) fn sample(n: usize, count: usize, seed: u64) -> Option<Vec<usize>> {
    if count == 0 || count >= n {
        return None;
    }
    let mut all: Vec<usize> = (0..n).collect();
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    for i in 0..count {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let j = i + (x >> 33) as usize % (n - i);
        all.swap(i, j);
    }
    let mut picked = all[..count].to_vec();
    picked.sort_unstable();
    Some(picked)
}

/// The vertex map T → S of C (k_T × k_S) and each match's cost.
fn pull_back(s: &SpectralShape<'_>, t: &SpectralShape<'_>, c: &Mat<f64>) -> (Vec<u32>, Vec<f64>) {
    let (kt, ks) = (c.nrows(), c.ncols());
    let mut s_emb = Mat::zeros(s.n(), kt);
    matmul(s_emb.as_mut(), Accum::Replace, leading(s, ks), c.transpose(), 1.0, Par::Seq);
    nearest_rows(s_emb.as_ref(), leading(t, kt))
}

/// The vertex map S → T of C (k_T × k_S) and each match's cost: target rows Φ_T C (n_T × k_S) searched from source
/// rows Φ_S.
fn push_forward(s: &SpectralShape<'_>, t: &SpectralShape<'_>, c: &Mat<f64>) -> (Vec<u32>, Vec<f64>) {
    let (kt, ks) = (c.nrows(), c.ncols());
    let mut t_emb = Mat::zeros(t.n(), ks);
    matmul(t_emb.as_mut(), Accum::Replace, leading(t, kt), c.as_ref(), 1.0, Par::Seq);
    nearest_rows(t_emb.as_ref(), leading(s, ks))
}

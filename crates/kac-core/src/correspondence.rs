//! Which point of one shape is which point of another: functional maps (Ovsjanikov, Ben-Chen, Solomon, Butscher
//! & Guibas 2012, "Functional maps: a flexible representation of maps between shapes", ACM TOG 31(4)) refined
//! spectrally by ZoomOut (Melzi, Ren, Rodolà, Sharma, Wonka & Ovsjanikov 2019, "ZoomOut: spectral upsampling for
//! efficient shape correspondence", ACM TOG 38(6)).
//!
//! Conventions. The source S and the target T each have k M-orthonormal eigenfunctions (columns of Φ_S, Φ_T). A
//! functional map C (k_T × k_S) takes the coefficients a = Φ_Sᵀ M_S f of a function f on S to the coefficients C a
//! of its transfer to T. A vertex map π: T → S (each target vertex's match on the source) pulls functions back,
//! f ∘ π, and has the functional map C = Φ_Tᵀ M_T Φ_S[π, :].
//!
//! The map is fitted as the small dense problem it is (Nogneng & Ovsjanikov 2017, "Informative descriptor
//! preservation via commutativity for shape matching", Computer Graphics Forum 36(2), for the third term):
//!
//! E(C) = w_d ‖C A − B‖² + w_l Σ_ij (λ_i^T − λ_j^S)² C_ij² / ‖(λ^T − λ^S)²‖ + w_c Σ_f ‖C D_S^f − D_T^f C‖²
//!
//! with A, B the descriptors' coefficients (one column per descriptor function, each of unit M-norm), and
//! D^f = Φᵀ M diag(f) Φ the operator of multiplication by descriptor f. Without the third term the rows of C
//! decouple (k small systems); with it, E is one k_T·k_S system, solved densely.
//!
//! Vertex maps come from C by nearest neighbours in the spectral embedding: π(y) = argmin_x ‖Φ_S[x] Cᵀ − Φ_T[y]‖
//! (T → S), and σ(x) = argmin_y ‖Φ_T[y] C − Φ_S[x]‖ (S → T; Cᵀ inverts C for near-isometries, where C is nearly
//! orthogonal). The search goes through every row, by tiles of matrix products in single precision: a row within
//! single-precision rounding of the nearest may be chosen in its place (see [`nearest_rows`]).

use crate::descriptors::signatures::{self, WksOptions};
use crate::descriptors::{Basis, DescriptorError};
use crate::geometry::vec3::{add, cross, dot, sub};
use crate::geometry::TriangleMesh;
use crate::operators::sparse::{matvec, SparsePair};
use crate::spectrum::{Control, EigenError};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// One side of a correspondence: its eigenpairs (M-orthonormal), its operator (for M) and, for a triangle mesh, the
/// surface (its faces orient the orientation term; vertices in the operator's numbering).
pub struct SpectralShape<'a> {
    pub basis: Basis<'a>,
    pub pair: &'a SparsePair,
    pub surface: Option<&'a TriangleMesh>,
}

impl SpectralShape<'_> {
    fn n(&self) -> usize {
        self.basis.n()
    }
    /// Φ[:, :k]ᵀ M F: the coefficients of the columns of F in the first k eigenfunctions.
    fn coefficients(&self, k: usize, f: MatRef<'_, f64>) -> Mat<f64> {
        let mf = mass_times(self.pair, f);
        let mut out = Mat::zeros(k, f.ncols());
        matmul(out.as_mut(), Accum::Replace, self.basis.vectors.subcols(0, k).transpose(), mf.as_ref(), 1.0, Par::Seq);
        out
    }
}

/// M F, column by column.
fn mass_times(pair: &SparsePair, f: MatRef<'_, f64>) -> Mat<f64> {
    let n = f.nrows();
    let mut out = Mat::zeros(n, f.ncols());
    let (mut x, mut y) = (vec![0.0; n], vec![0.0; n]);
    for j in 0..f.ncols() {
        for i in 0..n {
            x[i] = f[(i, j)];
        }
        matvec(&pair.pattern, &pair.mass, &x, &mut y);
        for i in 0..n {
            out[(i, j)] = y[i];
        }
    }
    out
}

/// How the map is fitted and refined.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct CorrespondenceOptions {
    /// Eigenfunctions the first map is fitted in (default 30).
    #[cfg_attr(feature = "cli", arg(long = "fit-k", default_value_t = CorrespondenceOptions::default().fit_k))]
    pub fit_k: usize,
    /// WKS log-energies computed per shape (default 100), of which every `descriptor_step`-th is a probe.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().descriptors))]
    pub descriptors: usize,
    /// Keep every this-many-th descriptor (default 5: 20 probes).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().descriptor_step))]
    pub descriptor_step: usize,
    /// Weight of descriptor preservation (default 1).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().descriptor_weight))]
    pub descriptor_weight: f64,
    /// Weight of Laplacian commutativity (default 0.01).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().laplacian_weight))]
    pub laplacian_weight: f64,
    /// Weight of descriptor-operator commutativity (default 0.1; 0 leaves the rows of C decoupled).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().commutativity_weight))]
    pub commutativity_weight: f64,
    /// Weight of orientation preservation (default 0.1; 0 turns it off): the probes' orientation operators
    /// g ↦ ⟨n × ∇f, ∇g⟩ must commute with the map (Ren, Poulenard, Wonka & Ovsjanikov 2018, "Continuous and
    /// orientation-preserving correspondences via functional maps", ACM TOG 37(6)), which a map onto the mirror image
    /// (a left-right flip of a symmetric shape) does not. Triangle meshes enclosing a volume on both sides only
    /// (closed, or with small holes, as scans' at feet and paws; their normals turned outward first): an open sheet
    /// or a partial scan may be wound either way.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().orientation_weight))]
    pub orientation_weight: f64,
    /// ZoomOut's last basis size (default 100; at most the eigenpairs computed; the fit's size: no refinement).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().refine_k))]
    pub refine_k: usize,
    /// ZoomOut's step in basis size (default 5).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().refine_step))]
    pub refine_step: usize,
    /// Vertices per shape ZoomOut's steps match (a fixed pseudo-random sample; default 3,000; 0: every vertex), as
    /// Melzi et al. do; the final maps are over every vertex.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = CorrespondenceOptions::default().refine_samples))]
    pub refine_samples: usize,
    /// The target is a part of the source (a cut, a partial scan): the map is rectangular, the source's basis
    /// holding its eigenvalues up to the target's largest (Rodolà et al. 2017, "Partial functional correspondence",
    /// Computer Graphics Forum 36(1): the map's slanted diagonal). Default false.
    #[cfg_attr(feature = "cli", arg(long))]
    pub partial: bool,
    /// Bijective ZoomOut (default false): each step matches both ways and averages the two functional maps, C of
    /// the target-to-source matches and the transpose of the reverse one (the inverse of an orthogonal C), so that
    /// one map serves both directions: a simple form of the bijectivity term of Ren, Melzi, Wonka & Ovsjanikov 2021
    /// ("Discrete optimization for shape matching", CGF 40(5)), the two maps averaged rather than solved jointly.
    /// About twice ZoomOut's matching work; not with `partial`.
    #[cfg_attr(feature = "cli", arg(long))]
    pub bijective: bool,
    /// Known pairs (source vertex, target vertex): each adds its WKS-weighted landmark descriptors.
    #[cfg_attr(feature = "cli", arg(skip))]
    #[cfg_attr(feature = "openapi", schema(value_type = Vec<Vec<u32>>))]
    pub landmarks: Vec<(u32, u32)>,
}

impl Default for CorrespondenceOptions {
    fn default() -> Self {
        CorrespondenceOptions {
            fit_k: 30,
            descriptors: 100,
            descriptor_step: 5,
            descriptor_weight: 1.0,
            laplacian_weight: 1e-2,
            commutativity_weight: 1e-1,
            orientation_weight: 1e-1,
            refine_k: 100,
            refine_step: 5,
            refine_samples: 3000,
            partial: false,
            bijective: false,
            landmarks: vec![],
        }
    }
}

crate::object_only_serde!(CorrespondenceOptions);

/// The most WKS energies per shape, and landmarks.
pub const MAX_DESCRIPTORS: usize = 1000;
pub const MAX_LANDMARKS: usize = 100;
/// The largest fit with descriptor commutativity: its dense system has (fit_k · k_S)² entries (a partial source
/// about twice fit_k): 100 gives 2 × 10⁸ values, 1.6 GB at most.
pub const MAX_COUPLED_FIT_K: usize = 100;
/// The largest weight of a term of E(C). Only the weights' ratios change the minimiser (E scaled by s has the same
/// C), so a bound costs nothing: 10⁶ against the default descriptor weight 1 is a term a million times stronger. It
/// keeps the fit's systems finite: their entries are a weight times sums of squared coefficients of unit M-norm
/// probes (each at most 1, at most `MAX_DESCRIPTORS` · (1 + `MAX_LANDMARKS`) of them), far below f64's 1.8e308 at
/// 10⁶, where a weight of 1e308 overflowed them (a fit refused as singular).
pub const MAX_WEIGHT: f64 = 1e6;

impl CorrespondenceOptions {
    /// The checks that need no shape: every count and step in range, every weight finite within
    /// [0, [`MAX_WEIGHT`]], and landmarks that map each vertex once on each side. Each refusal names its option;
    /// [`correspond`] makes them again, with those that need the spectra.
    pub fn check(&self) -> Result<(), DescriptorError> {
        if self.fit_k < 2 {
            return Err(DescriptorError::param("fit_k", format!("{}: give at least 2", self.fit_k)));
        }
        if self.descriptors == 0 || self.descriptors > MAX_DESCRIPTORS {
            return Err(DescriptorError::param(
                "descriptors",
                format!("{}: give 1 to {MAX_DESCRIPTORS} descriptors", self.descriptors),
            ));
        }
        for (name, step) in [("descriptor_step", self.descriptor_step), ("refine_step", self.refine_step)] {
            if step == 0 {
                return Err(DescriptorError::param(name, "0: give a step of at least 1"));
            }
        }
        for (name, w) in [
            ("descriptor_weight", self.descriptor_weight),
            ("laplacian_weight", self.laplacian_weight),
            ("commutativity_weight", self.commutativity_weight),
            ("orientation_weight", self.orientation_weight),
        ] {
            if !(0.0..=MAX_WEIGHT).contains(&w) {
                let shown = if w.is_finite() && w.abs() >= 1e16 { format!("{w:e}") } else { format!("{w}") };
                return Err(DescriptorError::param(
                    name,
                    format!(
                        "{shown} is out of range: give a finite weight in [0, {MAX_WEIGHT:e}] (only the weights' \
                         ratios matter)"
                    ),
                ));
            }
        }
        if self.bijective && self.partial {
            return Err(DescriptorError::param(
                "bijective",
                "a part has no map back onto the whole: give bijective or partial, not both",
            ));
        }
        if self.landmarks.len() > MAX_LANDMARKS {
            return Err(DescriptorError::param(
                "landmarks",
                format!("{} pairs: at most {MAX_LANDMARKS}", self.landmarks.len()),
            ));
        }
        conflicting_landmarks(&self.landmarks)
    }
}

/// Landmarks that pair one vertex with two different vertices of the other shape (either side) are refused, naming
/// both pairs; a pair given twice is the same pair.
fn conflicting_landmarks(landmarks: &[(u32, u32)]) -> Result<(), DescriptorError> {
    let mut source = std::collections::HashMap::new();
    let mut target = std::collections::HashMap::new();
    for (i, &(a, b)) in landmarks.iter().enumerate() {
        for (side, seen, vertex, other) in [("source", &mut source, a, b), ("target", &mut target, b, a)] {
            if let Some(&(j, before)) = seen.get(&vertex) {
                if before != other {
                    return Err(DescriptorError::param(
                        "landmarks",
                        format!(
                            "pairs {j} {:?} and {i} {:?} map {side} vertex {vertex} to two vertices: each vertex is \
                             one landmark",
                            landmarks[j],
                            (a, b)
                        ),
                    ));
                }
            }
            seen.entry(vertex).or_insert((i, other));
        }
    }
    Ok(())
}

/// A correspondence: the functional map and the vertex maps both ways, with the cost of each match.
#[derive(Debug, Clone)]
pub struct Correspondence {
    /// C (k_T × k_S) in the last basis size.
    pub c: Mat<f64>,
    /// For each target vertex, its match on the source.
    pub target_to_source: Vec<u32>,
    /// For each source vertex, its match on the target.
    pub source_to_target: Vec<u32>,
    /// ‖Φ_S[π(y)] Cᵀ − Φ_T[y]‖ per target vertex: how far its match is in the spectral embedding.
    pub target_cost: Vec<f64>,
    /// ‖Φ_T[σ(x)] C − Φ_S[x]‖ per source vertex.
    pub source_cost: Vec<f64>,
    /// The basis sizes of the refinement, first (the fit) to last.
    pub sizes: Vec<usize>,
    /// ‖CCᵀ − I‖_F / √k_T of the final map (0 for an exact isometry's, or a part's).
    pub orthogonality_defect: f64,
    /// Whether the orientation term was in the fit (a weight, and triangle meshes enclosing a volume on both sides).
    pub oriented: bool,
}

/// Why a correspondence cannot be computed: a parameter or descriptor, or a stop (cancel, timeout).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CorrespondenceError {
    #[error(transparent)]
    Descriptor(#[from] DescriptorError),
    #[error(transparent)]
    Stopped(#[from] EigenError),
}

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
fn probes(
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

/// The orientation operators of one side in its first k eigenfunctions: for a probe f, O_f g = ⟨n × ∇f, ∇g⟩ (a
/// rotated gradient of f acting as a derivative), projected as Φᵀ M O_f Φ with the lumped mass:
/// Σ_T (A_T / 3) (Σ_{v ∈ T} φ_i(v)) ⟨n_T × ∇f_T, ∇φ_j,T⟩. The operator is antisymmetric (n × ∇f is divergence-free),
/// and a map onto a mirror image turns its sign, so commuting with it keeps orientation (Ren et al. 2018). The
/// normals are turned outward ([`outward_sign`]) so that two inputs wound oppositely agree.
struct Orienter<'a> {
    mesh: &'a TriangleMesh,
    /// Per face (row): (A_T / 3) Σ_{v ∈ T} φ_i(v), i < k.
    lumped: Mat<f64>,
    /// Per face: the gradients ∇λ_a of its three hat functions.
    grads: Vec<[[f64; 3]; 3]>,
    /// Per face: the outward unit normal (zero for a degenerate face).
    normals: Vec<[f64; 3]>,
    phi: MatRef<'a, f64>,
    k: usize,
}

/// The largest ratio of [`outward_sign`]'s bound to the signed volume for which a surface counts as enclosing a volume.
/// Measured: 10⁻¹⁵ for closed meshes, 0.010 to 0.014 for TOSCA's cat and dog (small holes at the paws), infinite
/// for a flat sheet, about 1.5 for a hemisphere.
const ENCLOSURE_RATIO: f64 = 0.1;

/// The sign that turns the surface's normals outward (±1), when it encloses a volume: the signed volume
/// V(p) = Σ_T (a − p)·((b − p) × (c − p)) / 6 about a point p does not depend on p for a closed surface, and for an
/// open one changes as −p·N/3, N the surface's vector area (the area its holes would need to close them). The
/// surface counts as enclosing when that change across its bounding box, |N|·diagonal/3, is within
/// [`ENCLOSURE_RATIO`] of |V| about the centroid: closed meshes, and scans with small holes. An open sheet or a
/// partial scan, which may be wound either way, has no outward side (None), and the orientation term is left out:
/// it would otherwise favour the mirror map.
fn outward_sign(mesh: &TriangleMesh) -> Option<f64> {
    let p = &mesh.vertices;
    if p.is_empty() {
        return None;
    }
    // About the centroid: about the origin, coordinates far from it would drown the volume in rounding.
    let centre = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).sum::<f64>() / p.len() as f64);
    let at = |v: u32| sub(p[v as usize], centre);
    let (mut volume6, mut area2) = (0.0, [0.0; 3]);
    for f in &mesh.faces {
        let (a, b, c) = (at(f[0]), at(f[1]), at(f[2]));
        volume6 += dot(a, cross(b, c));
        let n = cross(sub(b, a), sub(c, a));
        area2 = add(area2, n);
    }
    let lo = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).fold(f64::INFINITY, f64::min));
    let hi = [0, 1, 2].map(|c| p.iter().map(|q| q[c]).fold(f64::NEG_INFINITY, f64::max));
    let diagonal = dot(sub(hi, lo), sub(hi, lo)).sqrt();
    // |N| D / 3 against |V|, both times 6 (N = area2 / 2).
    let drift6 = dot(area2, area2).sqrt() * diagonal;
    (volume6 != 0.0 && drift6 <= ENCLOSURE_RATIO * volume6.abs()).then_some(volume6.signum())
}

/// The two surfaces the orientation term is built on, each with its outward sign, when it applies: a weight, and
/// triangle meshes enclosing a volume on both sides.
#[allow(clippy::type_complexity)]
fn oriented<'a>(
    s: &SpectralShape<'a>,
    t: &SpectralShape<'a>,
    o: &CorrespondenceOptions,
) -> Option<((&'a TriangleMesh, f64), (&'a TriangleMesh, f64))> {
    match (s.surface, t.surface) {
        (Some(a), Some(b)) if o.orientation_weight != 0.0 => Some(((a, outward_sign(a)?), (b, outward_sign(b)?))),
        _ => None,
    }
}

impl<'a> Orienter<'a> {
    fn new(mesh: &'a TriangleMesh, sign: f64, side: &SpectralShape<'a>, k: usize) -> Self {
        let p = &mesh.vertices;
        let phi = side.basis.vectors.subcols(0, k);
        let (mut lumped, mut grads, mut normals) = (Mat::<f64>::zeros(mesh.faces.len(), k), vec![], vec![]);
        for (t, f) in mesh.faces.iter().enumerate() {
            let [a, b, c] = [p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]];
            let n2 = cross(sub(b, a), sub(c, a));
            let twice = dot(n2, n2).sqrt();
            if twice == 0.0 {
                grads.push([[0.0; 3]; 3]);
                normals.push([0.0; 3]);
                continue;
            }
            let n = [n2[0] / twice, n2[1] / twice, n2[2] / twice];
            // ∇λ_a = n × e_a / (2A), e_a the edge opposite a, run counter-clockwise about n.
            let opposite = [sub(c, b), sub(a, c), sub(b, a)];
            let g = opposite.map(|e| cross(n, e).map(|x| x / twice));
            grads.push(g);
            normals.push(n.map(|x| sign * x));
            let w = twice / 6.0;
            for i in 0..k {
                lumped[(t, i)] = w * (0..3).map(|q| phi[(f[q] as usize, i)]).sum::<f64>();
            }
        }
        Orienter { mesh, lumped, grads, normals, phi, k }
    }

    /// Φᵀ M O_f Φ (k × k) for the probe f (one column). With w_T,q = ⟨n_T × ∇f_T, ∇λ_q⟩ the derivative of the hat
    /// function of the face's corner q, the operator is Σ_T Σ_q lumped_Tᵀ w_T,q φ(v_T,q) = Hᵀ Φ, where row v of
    /// H gathers w_T,q lumped_T over the faces at v (one product of n × k, not of faces × k).
    fn op(&self, f: MatRef<'_, f64>) -> Mat<f64> {
        let k = self.k;
        let n = self.phi.nrows();
        // Row-major n × k, gathered face by face.
        let mut h = vec![0.0f64; n * k];
        for (t, face) in self.mesh.faces.iter().enumerate() {
            let grad = &self.grads[t];
            let mut gf = [0.0; 3];
            for q in 0..3 {
                let v = f[(face[q] as usize, 0)];
                for c in 0..3 {
                    gf[c] += v * grad[q][c];
                }
            }
            let rotated = cross(self.normals[t], gf);
            let lumped = self.lumped.row(t);
            for q in 0..3 {
                let w = dot(rotated, grad[q]);
                let row = &mut h[face[q] as usize * k..(face[q] as usize + 1) * k];
                for (i, x) in row.iter_mut().enumerate() {
                    *x += w * lumped[i];
                }
            }
        }
        let h = MatRef::from_row_major_slice(&h, n, k);
        let mut out = Mat::<f64>::zeros(k, k);
        matmul(out.as_mut(), Accum::Replace, h.transpose(), self.phi, 1.0, Par::Seq);
        out
    }
}

/// Solves the SPD system A X = B (A k × k) by Cholesky; None when A is not positive definite.
fn spd_solve(a: &Mat<f64>, b: &Mat<f64>) -> Option<Mat<f64>> {
    let llt = a.llt(Side::Lower).ok()?;
    let mut x = b.clone();
    solve_lower_triangular_in_place(llt.L(), x.as_mut(), Par::Seq);
    solve_upper_triangular_in_place(llt.L().transpose(), x.as_mut(), Par::Seq);
    Some(x)
}

/// The functional map C (k × k) fitted to the probes' coefficients A (source), B (target), the eigenvalues, and
/// pairs of operators (source, target) that C must commute with, each with its weight: the probes' multiplication
/// operators (descriptor commutativity) and orientation operators.
fn fit(
    a: &Mat<f64>,
    b: &Mat<f64>,
    lambda_s: &[f64],
    lambda_t: &[f64],
    ops: &[(Mat<f64>, Mat<f64>, f64)],
    o: &CorrespondenceOptions,
) -> Result<Mat<f64>, DescriptorError> {
    let (kt, ks) = (lambda_t.len(), lambda_s.len());
    // (λ_i^T − λ_j^S)², scaled to unit Frobenius norm (the weight then does not depend on the shapes' scale).
    let mut d = Mat::from_fn(kt, ks, |i, j| (lambda_t[i] - lambda_s[j]).powi(2));
    let norm = d.norm_l2();
    if norm > 0.0 {
        d = Mat::from_fn(kt, ks, |i, j| d[(i, j)] / norm);
    }
    let aat = {
        let mut m = Mat::zeros(ks, ks);
        matmul(m.as_mut(), Accum::Replace, a.as_ref(), a.transpose(), 1.0, Par::Seq);
        m
    };
    let bat = {
        let mut m = Mat::zeros(kt, ks);
        matmul(m.as_mut(), Accum::Replace, b.as_ref(), a.transpose(), 1.0, Par::Seq);
        m
    };
    let singular = || DescriptorError::param("correspondence", "the fit's system is singular: give more descriptors");
    if ops.is_empty() {
        // Row by row: (w_d A Aᵀ + w_l diag(D_i)) c_iᵀ = w_d A b_iᵀ.
        let mut c = Mat::zeros(kt, ks);
        for i in 0..kt {
            let sys = Mat::from_fn(ks, ks, |p, q| {
                o.descriptor_weight * aat[(p, q)] + if p == q { o.laplacian_weight * d[(i, p)] } else { 0.0 }
            });
            let rhs = Mat::from_fn(ks, 1, |p, _| o.descriptor_weight * bat[(i, p)]);
            let x = spd_solve(&sys, &rhs).ok_or_else(singular)?;
            for p in 0..ks {
                c[(i, p)] = x[(p, 0)];
            }
        }
        return Ok(c);
    }
    // vec(C) column-major: index i + kt·j. The normal equations of E.
    let m = kt * ks;
    let idx = |i: usize, j: usize| i + kt * j;
    let mut sys = Mat::<f64>::zeros(m, m);
    let mut rhs = Mat::<f64>::zeros(m, 1);
    for j in 0..ks {
        for i in 0..kt {
            // w_d: (A Aᵀ ⊗ I); right-hand side w_d vec(B Aᵀ).
            for q in 0..ks {
                sys[(idx(i, j), idx(i, q))] += o.descriptor_weight * aat[(q, j)];
            }
            rhs[(idx(i, j), 0)] = o.descriptor_weight * bat[(i, j)];
            sys[(idx(i, j), idx(i, j))] += o.laplacian_weight * d[(i, j)];
        }
    }
    // w Σ ‖C X − Y C‖²: K = Xᵀ ⊗ I − I ⊗ Y, KᵀK = (X Xᵀ ⊗ I) − (X ⊗ Y) − (Xᵀ ⊗ Yᵀ) + (I ⊗ YᵀY), summed over the
    // pairs. Σ w X Xᵀ and Σ w YᵀY are formed once. The cross terms: T = Σ w (X ⊗ Y), entry ((i, j), (p, q)) =
    // Σ w X_jq Y_ip = G[(j, q), (i, p)] for G = Σ w vec(X) vec(Y)ᵀ, one product of the stacked vec(X) and vec(Y)
    // (formed for one q at a time, ks × kt² values); the other is Tᵀ, added by symmetrizing the system (every
    // other term is symmetric).
    if !ops.is_empty() {
        let mut xxt = Mat::<f64>::zeros(ks, ks);
        let mut yty = Mat::<f64>::zeros(kt, kt);
        for (x, y, w) in ops {
            matmul(xxt.as_mut(), Accum::Add, x.as_ref(), x.transpose(), *w, Par::Seq);
            matmul(yty.as_mut(), Accum::Add, y.transpose(), y.as_ref(), *w, Par::Seq);
        }
        for j in 0..ks {
            for q in 0..ks {
                for i in 0..kt {
                    sys[(idx(i, j), idx(i, q))] += xxt[(q, j)];
                }
            }
            for p in 0..kt {
                for i in 0..kt {
                    sys[(idx(i, j), idx(p, j))] += yty[(i, p)];
                }
            }
        }
        let nf = ops.len();
        // Row (f, i + kt p) of the stacked vec(Y)ᵀ: Y_f[i, p].
        let yv = Mat::from_fn(nf, kt * kt, |f, r| ops[f].1[(r % kt, r / kt)]);
        let mut g = Mat::<f64>::zeros(ks, kt * kt);
        for q in 0..ks {
            // Rows j of G[(j, q), ·] = Σ_f w_f X_f[j, q] vec(Y_f)ᵀ.
            let xq = Mat::from_fn(ks, nf, |j, f| ops[f].2 * ops[f].0[(j, q)]);
            matmul(g.as_mut(), Accum::Replace, xq.as_ref(), yv.as_ref(), 1.0, Par::Seq);
            for p in 0..kt {
                for j in 0..ks {
                    let column = idx(p, q);
                    for i in 0..kt {
                        // −2T here, then (S − 2T + (S − 2T)ᵀ) / 2 = S − T − Tᵀ below.
                        sys[(idx(i, j), column)] -= 2.0 * g[(j, i + kt * p)];
                    }
                }
            }
        }
        for r in 0..m {
            for c in r + 1..m {
                let mean = 0.5 * (sys[(r, c)] + sys[(c, r)]);
                sys[(r, c)] = mean;
                sys[(c, r)] = mean;
            }
        }
    }
    // A direction no term sees (a symmetric shape without the orientation term: the map and its mirror fit
    // alike) leaves the system singular: a small ridge then picks the least-norm blend of them.
    let v = match spd_solve(&sys, &rhs) {
        Some(v) => v,
        None => {
            let ridge = 1e-10 * (0..m).map(|p| sys[(p, p)]).sum::<f64>() / m as f64;
            for p in 0..m {
                sys[(p, p)] += ridge.max(f64::MIN_POSITIVE);
            }
            spd_solve(&sys, &rhs).ok_or_else(singular)?
        }
    };
    Ok(Mat::from_fn(kt, ks, |i, j| v[(idx(i, j), 0)]))
}

/// For each row of `query` (q × d), the row of `data` (n × d) nearest to it, and the distance, by tiles of matrix
/// products (|a − b|² = |a|² + |b|² − 2 a·b), the query's blocks in parallel.
///
/// The search runs in single precision (twice the products per instruction of double, half the memory), so a row
/// within single-precision rounding of the nearest (about 10⁻⁶ of the rows' squared norms) may be chosen in its
/// place; the distance returned is the chosen row's, in double precision. A tile of products (64 query rows × 1,024
/// data rows, 256 KiB) stays in cache while it is scanned: a product block as wide as the data (tens of MB at 30,000
/// vertices) went to memory and back, which cost more than the products. (Trees do not prune in the 30 to 200
/// dimensions of a spectral embedding: a clustered search with triangle-inequality bounds measured twice as slow.)
pub fn nearest_rows(data: MatRef<'_, f64>, query: MatRef<'_, f64>) -> (Vec<u32>, Vec<f64>) {
    const QUERY_ROWS: usize = 64;
    const DATA_ROWS: usize = 1024;
    let (n, q, d) = (data.nrows(), query.nrows(), data.ncols());
    if n == 0 {
        return (vec![0; q], vec![f64::INFINITY; q]);
    }
    let single = |m: MatRef<'_, f64>| Mat::<f32>::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)] as f32);
    let (data32, query32) = (single(data), single(query));
    let dn: Vec<f32> = (0..n).map(|i| (0..d).map(|j| data32[(i, j)].powi(2)).sum()).collect();
    let blocks: Vec<usize> = (0..q).step_by(QUERY_ROWS).collect();
    let isa = crate::simd::Isa::detect();
    let best: Vec<Vec<u32>> = blocks
        .par_iter()
        .map_init(
            // One tile per thread, reused (a fresh one per block spent as much time in page faults as in products).
            || vec![0.0f32; QUERY_ROWS * DATA_ROWS],
            |tile, &r0| {
                let rows = QUERY_ROWS.min(q - r0);
                let qb = query32.as_ref().subrows(r0, rows);
                // Per query row: the least |b|² − 2 a·b so far and its data row; within a tile, the row's place in
                // the tile as f32 (−1: none closer there), so that the scan is of one width and vectorizes.
                let mut bd = vec![f32::INFINITY; rows];
                let mut bi = vec![0u32; rows];
                let mut local = vec![-1.0f32; rows];
                for d0 in (0..n).step_by(DATA_ROWS) {
                    let cols = DATA_ROWS.min(n - d0);
                    // G = Q_b D_tileᵀ, column-major (rows × cols): column i holds every query row's product with
                    // data row d0 + i.
                    let g = &mut tile[..rows * cols];
                    let dt = data32.as_ref().subrows(d0, cols).transpose();
                    let gm = MatMut::from_column_major_slice_mut(g, rows, cols);
                    matmul(gm, Accum::Replace, qb, dt, 1.0f32, Par::Seq);
                    local.fill(-1.0);
                    scan_tile(isa, g, &dn[d0..d0 + cols], &mut bd, &mut local);
                    for (x, &l) in bi.iter_mut().zip(&local) {
                        if l >= 0.0 {
                            *x = (d0 + l as usize) as u32;
                        }
                    }
                }
                bi
            },
        )
        .collect();
    let idx: Vec<u32> = best.into_iter().flatten().collect();
    let dist = idx
        .iter()
        .enumerate()
        .map(|(r, &i)| (0..d).map(|j| (query[(r, j)] - data[(i as usize, j)]).powi(2)).sum::<f64>().sqrt())
        .collect();
    (idx, dist)
}

/// The scan of one tile of products (column-major, `bd.len()` rows): for each row r, over the columns i, the least
/// dn[i] − 2 g[r, i] below bd[r], and i where it is (as f32) in `local`. Compiled for AVX-512 and AVX2, `isa`
/// chosen at run time (the portable build leaves it scalar, with a branch per row).
fn scan_tile(isa: crate::simd::Isa, g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
    #[inline(always)]
    fn body(g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
        let rows = bd.len();
        let local = &mut local[..rows];
        for (i, col) in g.chunks_exact(rows).enumerate() {
            let (di, place) = (dn[i], i as f32);
            for r in 0..rows {
                let d2 = di - 2.0 * col[r];
                let closer = d2 < bd[r];
                local[r] = if closer { place } else { local[r] };
                bd[r] = if closer { d2 } else { bd[r] };
            }
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f")]
        fn wide(g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
            body(g, dn, bd, local)
        }
        #[target_feature(enable = "avx2,fma")]
        fn narrow(g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
            body(g, dn, bd, local)
        }
        match isa {
            // SAFETY: the CPU has AVX-512F (`isa` is one it supports).
            crate::simd::Isa::Avx512 => return unsafe { wide(g, dn, bd, local) },
            // SAFETY: the CPU has AVX2 and FMA (`isa` is one it supports).
            crate::simd::Isa::Avx2 => return unsafe { narrow(g, dn, bd, local) },
            crate::simd::Isa::Scalar => {}
        }
    }
    body(g, dn, bd, local)
}

/// A function on the source carried to the target by the functional map: its coefficients in the source's first
/// k_S eigenfunctions (Φ_Sᵀ M_S f), mapped by C, summed over the target's first k_T (so the band-limited part of f
/// travels; what lies above the basis is lost).
pub fn transfer_function(s: &SpectralShape<'_>, t: &SpectralShape<'_>, c: &Mat<f64>, f: &[f64]) -> Vec<f64> {
    let (kt, ks) = (c.nrows(), c.ncols());
    let col = Mat::from_fn(f.len(), 1, |i, _| f[i]);
    let a = s.coefficients(ks, col.as_ref());
    let mut b = Mat::zeros(kt, 1);
    matmul(b.as_mut(), Accum::Replace, c.as_ref(), a.as_ref(), 1.0, Par::Seq);
    let mut g = Mat::zeros(t.n(), 1);
    matmul(g.as_mut(), Accum::Replace, leading(t, kt), b.as_ref(), 1.0, Par::Seq);
    (0..t.n()).map(|i| g[(i, 0)]).collect()
}

/// The first k pairs of a basis.
fn truncated<'a>(b: &Basis<'a>, k: usize) -> Basis<'a> {
    Basis::new(&b.values[..k], b.vectors.subcols(0, k), b.zero_tol)
}

/// Φ[:, :k].
fn leading<'a>(side: &SpectralShape<'a>, k: usize) -> MatRef<'a, f64> {
    side.basis.vectors.subcols(0, k)
}

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
fn sample(n: usize, count: usize, seed: u64) -> Option<Vec<usize>> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::generate;
    use crate::geometry::TriangleMesh;
    use crate::operators::{self, OperatorOptions};
    use crate::spectrum::{self, EigenOptions, Spectrum};
    use crate::Shape;

    /// A permutation of 0..n from a fixed seed (a linear congruential shuffle: reproducible, no dependency).
    fn permutation(n: usize, seed: u64) -> Vec<u32> {
        let mut p: Vec<u32> = (0..n as u32).collect();
        let mut s = seed;
        for i in (1..n).rev() {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let j = (s >> 33) as usize % (i + 1);
            p.swap(i, j);
        }
        p
    }

    /// The copy of `m` whose vertex y is `m`'s vertex perm[y], moved by `motion`.
    fn shuffled(m: &TriangleMesh, perm: &[u32], motion: impl Fn([f64; 3]) -> [f64; 3]) -> TriangleMesh {
        let mut inverse = vec![0u32; perm.len()];
        for (y, &x) in perm.iter().enumerate() {
            inverse[x as usize] = y as u32;
        }
        let mut out = m.clone();
        out.vertices = perm.iter().map(|&x| motion(m.vertices[x as usize])).collect();
        out.faces = m.faces.iter().map(|f| f.map(|v| inverse[v as usize])).collect();
        out
    }

    /// A lumpy sphere with no symmetry.
    fn lumpy(level: u32) -> TriangleMesh {
        let mut m = generate::icosphere(level);
        for p in &mut m.vertices {
            let [x, y, z] = *p;
            let r = 1.0 + 0.3 * x + 0.2 * y * y - 0.25 * z * z * z + 0.15 * x * y + 0.1 * (3.0 * z).sin();
            *p = [x * r, 1.3 * y * r, 0.8 * z * r];
        }
        m
    }

    fn spectrum_of(m: &TriangleMesh, k: usize) -> (operators::Operator, Spectrum) {
        let op = operators::build(&Shape::TriangleMesh(m.clone()), &OperatorOptions::default()).unwrap();
        let s = spectrum::eigs(&op.pair, &EigenOptions { k, ..Default::default() }, None, Control::default()).unwrap();
        (op, s)
    }

    fn run(a: &TriangleMesh, b: &TriangleMesh, k: usize, o: &CorrespondenceOptions) -> Correspondence {
        let (oa, sa) = spectrum_of(a, k);
        let (ob, sb) = spectrum_of(b, k);
        let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(a) };
        let t = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(b) };
        correspond(&s, &t, o, &Control::default()).unwrap()
    }

    fn area(m: &TriangleMesh) -> f64 {
        m.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| m.vertices[v as usize]);
                let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
                let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
                0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
            })
            .sum()
    }

    /// The mean geodesic distance (heat method on the source) between each sampled target vertex's match and its
    /// true match, over √area.
    fn geodesic_error(src: &TriangleMesh, found: &[u32], truth: &[u32], samples: usize) -> f64 {
        let step = (truth.len() / samples).max(1);
        let mut total = 0.0;
        let mut count = 0;
        for y in (0..truth.len()).step_by(step) {
            let (a, b) = (truth[y] as usize, found[y] as usize);
            if a != b {
                let g = crate::pde::geodesic::heat_method(src, &[a], &Default::default()).unwrap();
                total += g.distance[b];
            }
            count += 1;
        }
        total / count as f64 / area(src).sqrt()
    }

    /// A rigidly moved copy with its vertices shuffled: the answer is the permutation, both ways.
    #[test]
    fn a_shuffled_rigid_copy_is_matched_by_its_permutation() {
        let a = lumpy(3);
        let perm = permutation(a.vertices.len(), 7);
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let b = shuffled(&a, &perm, |[x, y, z]| [c * x - s * y + 3.0, s * x + c * y - 1.0, z + 0.5]);
        let o = CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() };
        let r = run(&a, &b, 60, &o);
        let exact = r.target_to_source.iter().zip(&perm).filter(|(f, t)| f == t).count();
        let fraction = exact as f64 / perm.len() as f64;
        let err = geodesic_error(&a, &r.target_to_source, &perm, 60);
        eprintln!("rigid copy: {fraction} exact, mean geodesic error {err:.5}");
        assert!(fraction > 0.97 && err < 0.005, "{fraction} exact, mean geodesic error {err}");
        let back = r.source_to_target.iter().enumerate().filter(|(x, &y)| perm[y as usize] as usize == *x).count();
        assert!(back as f64 / perm.len() as f64 > 0.97, "{back} of {} matched back", perm.len());
        assert_eq!(r.sizes.first().copied(), Some(20));
        assert_eq!(r.sizes.last().copied(), Some(60));
        assert!(r.orthogonality_defect < 0.05, "C of an isometry is orthogonal: {}", r.orthogonality_defect);
    }

    /// A bend of an asymmetric flat domain (one of Gordon, Webb & Wolpert's drums) onto a cylinder: a near-isometry
    /// (edges across the bend become chords), with its vertices shuffled.
    #[test]
    fn a_bent_drum_is_matched_within_a_small_geodesic_error() {
        let a = generate::gww_drum(1, 12);
        let perm = permutation(a.vertices.len(), 11);
        let r0 = 0.6;
        let b = shuffled(&a, &perm, |[x, y, _]| [r0 * (x / r0).sin(), y, r0 * (1.0 - (x / r0).cos())]);
        let r = run(&a, &b, 60, &CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() });
        let err = geodesic_error(&a, &r.target_to_source, &perm, 60);
        eprintln!("bent drum: mean geodesic error {err:.4} (√area units)");
        assert!(err < 0.02, "mean geodesic error {err}");
    }

    /// A partial copy: the source with a cap cut off (its vertices beyond a plane, about a tenth of the area), the
    /// remaining vertices shuffled, three pairs known. Each target vertex's true match is the vertex it was copied
    /// from.
    #[test]
    fn a_partial_copy_is_matched_within_a_stated_geodesic_error() {
        let a = lumpy(3);
        let cut = 0.75 * a.vertices.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
        let kept: Vec<u32> = (0..a.vertices.len() as u32).filter(|&v| a.vertices[v as usize][0] < cut).collect();
        let mut new_of = vec![u32::MAX; a.vertices.len()];
        for (i, &v) in kept.iter().enumerate() {
            new_of[v as usize] = i as u32;
        }
        let mut part = a.clone();
        part.vertices = kept.iter().map(|&v| a.vertices[v as usize]).collect();
        part.faces = a
            .faces
            .iter()
            .filter(|f| f.iter().all(|&v| new_of[v as usize] != u32::MAX))
            .map(|f| f.map(|v| new_of[v as usize]))
            .collect();
        let perm = permutation(part.vertices.len(), 13);
        let b = shuffled(&part, &perm, |p| p);
        let truth: Vec<u32> = perm.iter().map(|&i| kept[i as usize]).collect();
        // Three known pairs: WKS alone does not survive the cut (the cut's boundary changes every eigenfunction
        // near it; measured 0.39 without landmarks), three landmarks pin the map.
        let mut inverse = vec![0u32; perm.len()];
        for (y, &x) in perm.iter().enumerate() {
            inverse[x as usize] = y as u32;
        }
        let landmarks: Vec<(u32, u32)> = [0usize, 97, 194].iter().map(|&x| (kept[x], inverse[x])).collect();
        let o = CorrespondenceOptions { fit_k: 20, refine_k: 60, partial: true, landmarks, ..Default::default() };
        let r = run(&a, &b, 80, &o);
        let err = geodesic_error(&a, &r.target_to_source, &truth, 60);
        // Without the landmarks the map goes astray, and C's orthogonality defect says so: 0.47 against 0.22 for
        // the exact map (the service warns above 0.35: `correspondence-not-isometric`).
        let astray = run(&a, &b, 80, &CorrespondenceOptions { landmarks: vec![], ..o.clone() });
        let err_astray = geodesic_error(&a, &astray.target_to_source, &truth, 60);
        assert!(err_astray > 0.2, "without landmarks: {err_astray}");
        assert!(
            r.orthogonality_defect < 0.3 && astray.orthogonality_defect > 0.4,
            "{} {}",
            r.orthogonality_defect,
            astray.orthogonality_defect
        );
        eprintln!("partial copy ({} of {} vertices): mean geodesic error {err:.4}", kept.len(), a.vertices.len());
        assert!(err < 0.01, "mean geodesic error {err}");
    }

    /// The refinement improves on the fit alone, and a stop ends it.
    #[test]
    fn zoomout_improves_the_fit_and_a_stop_ends_it() {
        let a = generate::gww_drum(2, 12);
        let perm = permutation(a.vertices.len(), 5);
        // A strong near-isometry: a tight bend, and a 15 % stretch growing across the drum.
        let r0 = 0.5;
        let b = shuffled(&a, &perm, |[x, y, _]| {
            let y = y * (1.0 + 0.15 * x / 3.0);
            [x, r0 * (y / r0).sin(), r0 * (1.0 - (y / r0).cos())]
        });
        eprintln!("{} vertices", a.vertices.len());
        let fitted = run(&a, &b, 80, &CorrespondenceOptions { fit_k: 10, refine_k: 10, ..Default::default() });
        let refined = run(&a, &b, 80, &CorrespondenceOptions { fit_k: 10, refine_k: 80, ..Default::default() });
        let (e0, e1) = (
            geodesic_error(&a, &fitted.target_to_source, &perm, 60),
            geodesic_error(&a, &refined.target_to_source, &perm, 60),
        );
        // ZoomOut's steps on a sample of 300 vertices per shape (the final maps over every vertex).
        let sampled = CorrespondenceOptions { fit_k: 10, refine_k: 80, refine_samples: 300, ..Default::default() };
        let e2 = geodesic_error(&a, &run(&a, &b, 80, &sampled).target_to_source, &perm, 60);
        eprintln!("fit alone {e0:.4}, refined {e1:.4}, refined on samples {e2:.4}");
        assert!(e1 < 0.5 * e0 && e1 < 0.02, "fit {e0}, refined {e1}");
        assert!(e2 < e0 && e2 < 0.02, "fit {e0}, refined on samples {e2}");
        let (oa, sa) = spectrum_of(&a, 30);
        let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
        let stop = std::sync::atomic::AtomicBool::new(true);
        let stopped = Control { stop: Some(&stop), ..Control::default() };
        let r = correspond(&s, &s, &CorrespondenceOptions { fit_k: 10, refine_k: 30, ..Default::default() }, &stopped);
        assert!(matches!(r, Err(CorrespondenceError::Stopped(_))));
    }

    /// The fit's normal equations against the energy written term by term: for small random A, B, eigenvalues and
    /// non-symmetric operators, the solution of fit() has zero gradient of E(C) = w_d‖CA − B‖² + w_l Σ D_ij C_ij²
    /// + w_c Σ_f ‖C X_f − Y_f C‖² (checked by central differences of E, entry by entry).
    #[test]
    fn the_fit_solves_its_energy() {
        let (kt, ks, q) = (3usize, 4usize, 5usize);
        let r = |i: usize| ((i * 7919 + 13) % 101) as f64 / 50.0 - 1.0;
        let a = Mat::from_fn(ks, q, |i, j| r(i * 31 + j));
        let b = Mat::from_fn(kt, q, |i, j| r(i * 17 + j + 500));
        let ls: Vec<f64> = (0..ks).map(|i| i as f64 * 1.3).collect();
        let lt: Vec<f64> = (0..kt).map(|i| i as f64 * 1.1 + 0.2).collect();
        let ops: Vec<(Mat<f64>, Mat<f64>, f64)> = (0..2)
            .map(|f| {
                (
                    Mat::from_fn(ks, ks, |i, j| r(900 + f * 50 + i * 5 + j)),
                    Mat::from_fn(kt, kt, |i, j| r(300 + f * 40 + i * 3 + j)),
                    0.7,
                )
            })
            .collect();
        let o = CorrespondenceOptions {
            descriptor_weight: 1.0,
            laplacian_weight: 0.3,
            commutativity_weight: 0.7,
            ..Default::default()
        };
        let c = fit(&a, &b, &ls, &lt, &ops, &o).unwrap();
        let mut d = Mat::from_fn(kt, ks, |i, j| (lt[i] - ls[j]).powi(2));
        let norm = d.norm_l2();
        d = Mat::from_fn(kt, ks, |i, j| d[(i, j)] / norm);
        let energy = |c: &Mat<f64>| {
            let mut e = 0.0;
            let mut ca = Mat::zeros(kt, q);
            matmul(ca.as_mut(), Accum::Replace, c.as_ref(), a.as_ref(), 1.0, Par::Seq);
            e += o.descriptor_weight
                * (0..kt)
                    .flat_map(|i| (0..q).map(move |j| (i, j)))
                    .map(|(i, j)| (ca[(i, j)] - b[(i, j)]).powi(2))
                    .sum::<f64>();
            e += o.laplacian_weight
                * (0..kt)
                    .flat_map(|i| (0..ks).map(move |j| (i, j)))
                    .map(|(i, j)| d[(i, j)] * c[(i, j)].powi(2))
                    .sum::<f64>();
            for (x, y, w) in &ops {
                let mut cx = Mat::zeros(kt, ks);
                matmul(cx.as_mut(), Accum::Replace, c.as_ref(), x.as_ref(), 1.0, Par::Seq);
                matmul(cx.as_mut(), Accum::Add, y.as_ref(), c.as_ref(), -1.0, Par::Seq);
                e += w * cx.norm_l2().powi(2);
            }
            e
        };
        let h = 1e-6;
        for i in 0..kt {
            for j in 0..ks {
                let (mut up, mut down) = (c.clone(), c.clone());
                up[(i, j)] += h;
                down[(i, j)] -= h;
                let g = (energy(&up) - energy(&down)) / (2.0 * h);
                assert!(g.abs() < 1e-6, "∂E/∂C[{i},{j}] = {g}");
            }
        }
    }

    /// A function carried by C to a rotated shuffled copy is the function at the permutation, up to what lies above
    /// the basis (the x coordinate of a smooth shape: within 2 % in 60 eigenfunctions).
    #[test]
    fn a_function_travels_by_the_map() {
        let a = lumpy(3);
        let perm = permutation(a.vertices.len(), 7);
        let b = shuffled(&a, &perm, |[x, y, z]| [-y, x, z]);
        let (oa, sa) = spectrum_of(&a, 60);
        let (ob, sb) = spectrum_of(&b, 60);
        let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
        let t = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(&b) };
        let r = correspond(
            &s,
            &t,
            &CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() },
            &Control::default(),
        )
        .unwrap();
        let f: Vec<f64> = a.vertices.iter().map(|p| p[0]).collect();
        let g = transfer_function(&s, &t, &r.c, &f);
        let want: Vec<f64> = perm.iter().map(|&x| f[x as usize]).collect();
        let err = g.iter().zip(&want).map(|(u, v)| (u - v).powi(2)).sum::<f64>().sqrt();
        let norm = want.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(err < 0.02 * norm, "relative error {}", err / norm);
    }

    /// A shape with a mirror symmetry (x → −x: an icosphere made lumpy by a function even in x) against a rotated,
    /// shuffled copy: the mirror map is an isometry too, which WKS probes, Laplacian and descriptor commutativity
    /// cannot tell from the true map. The orientation term can: with it the map is the true one (no flip); the
    /// mirror map turns orientation, so its orientation operators anticommute, and the fit's energy says so.
    #[test]
    fn the_orientation_term_keeps_a_symmetric_shape_from_flipping() {
        let a = symmetric_lumpy();
        orientation_keeps_the_map(&a, &mirror_of(&a));
    }

    /// The same with holes (two faces and their mirror images cut out, as a scan's holes at a cat's paws): the
    /// surface still encloses a volume by [`outward_sign`], so the term still applies and still holds the map.
    #[test]
    fn the_orientation_term_holds_on_a_surface_with_small_holes() {
        let mut a = symmetric_lumpy();
        let mirror = mirror_of(&a);
        let key = |f: &[u32; 3]| {
            let mut k = *f;
            k.sort_unstable();
            k
        };
        let mut cut = vec![];
        for start in [0, a.faces.len() / 2] {
            let f = a.faces[start];
            let image = key(&f.map(|v| mirror[v as usize]));
            let g = a.faces.iter().position(|h| key(h) == image).expect("the mirror image of a face is a face");
            cut.extend([start, g]);
        }
        cut.sort_unstable();
        cut.dedup();
        assert_eq!(cut.len(), 4, "two faces and their images, none its own");
        for &f in cut.iter().rev() {
            a.faces.remove(f);
        }
        assert!(outward_sign(&a).is_some(), "small holes still enclose");
        orientation_keeps_the_map(&a, &mirror);
    }

    /// Which surfaces enclose a volume, and which way they are wound.
    #[test]
    fn outward_sign_tells_enclosing_surfaces_and_their_winding() {
        let sphere = lumpy(2);
        assert_eq!(outward_sign(&sphere), Some(1.0));
        let mut inside_out = sphere.clone();
        inside_out.faces.iter_mut().for_each(|f| f.swap(1, 2));
        assert_eq!(outward_sign(&inside_out), Some(-1.0));
        let mut holed = sphere.clone();
        holed.faces.truncate(holed.faces.len() - 3);
        assert_eq!(outward_sign(&holed), Some(1.0), "a few faces missing");
        // A hemisphere and a flat drum have no outward side.
        let mut half = sphere.clone();
        half.faces.retain(|f| f.iter().all(|&v| half_z(&sphere, v)));
        assert_eq!(outward_sign(&half), None);
        assert_eq!(outward_sign(&generate::gww_drum(1, 6)), None);
    }

    fn half_z(m: &TriangleMesh, v: u32) -> bool {
        m.vertices[v as usize][2] >= 0.0
    }

    /// A lumpy sphere with a mirror symmetry, x → −x.
    fn symmetric_lumpy() -> TriangleMesh {
        let mut a = generate::icosphere(3);
        for p in &mut a.vertices {
            let [x, y, z] = *p;
            let r = 1.0 + 0.3 * y + 0.2 * x * x - 0.25 * z * z * z + 0.1 * (3.0 * z).sin();
            *p = [x * r, 1.3 * y * r, 0.8 * z * r];
        }
        a
    }

    /// The mirror image of each vertex (the icosphere's vertices are symmetric under x → −x).
    fn mirror_of(a: &TriangleMesh) -> Vec<u32> {
        let mirror: Vec<u32> = a
            .vertices
            .iter()
            .map(|&[x, y, z]| {
                let d = |q: &[f64; 3]| (q[0] + x).powi(2) + (q[1] - y).powi(2) + (q[2] - z).powi(2);
                (0..a.vertices.len()).min_by(|&i, &j| d(&a.vertices[i]).total_cmp(&d(&a.vertices[j]))).unwrap() as u32
            })
            .collect();
        let moved = (0..a.vertices.len()).filter(|&v| mirror[v] as usize != v).count();
        assert!(moved > a.vertices.len() / 2, "the mirror moves most vertices");
        for (v, &m) in mirror.iter().enumerate() {
            let (p, q) = (a.vertices[v], a.vertices[m as usize]);
            assert!((p[0] + q[0]).abs() + (p[1] - q[1]).abs() + (p[2] - q[2]).abs() < 1e-9, "an exact mirror");
        }
        mirror
    }

    /// Against a rotated shuffled copy: with the orientation term the true map, away from the mirror map.
    fn orientation_keeps_the_map(a: &TriangleMesh, mirror: &[u32]) {
        let perm = permutation(a.vertices.len(), 17);
        let b = shuffled(a, &perm, |[x, y, z]| [-y, x, z + 1.0]);
        let truth_flipped: Vec<u32> = perm.iter().map(|&x| mirror[x as usize]).collect();
        let base = CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() };
        let with = run(a, &b, 80, &base);
        let without = run(a, &b, 80, &CorrespondenceOptions { orientation_weight: 0.0, ..base.clone() });
        let err = |r: &Correspondence, truth: &[u32]| geodesic_error(a, &r.target_to_source, truth, 60);
        let (w, wf) = (err(&with, &perm), err(&with, &truth_flipped));
        let (o, of) = (err(&without, &perm), err(&without, &truth_flipped));
        eprintln!("with orientation: {w:.4} (mirror {wf:.4}); without: {o:.4} (mirror {of:.4})");
        assert!(w < 0.02 && wf > 0.1, "with the orientation term: error {w}, against the mirror {wf}");
        assert!(w <= o, "the orientation term does not make the map worse: {w} against {o}");
    }

    /// The nearest rows against every distance (f64): each query's chosen row within single-precision rounding of
    /// the nearest, its distance the chosen row's; across tiles (n past 1,024) and blocks (q not a multiple of 64).
    #[test]
    fn nearest_rows_finds_the_nearest() {
        let r = |i: usize| ((i.wrapping_mul(2654435761) >> 7) % 10_007) as f64 / 5003.5 - 1.0;
        let (n, q, d) = (2_500, 130, 37);
        let data = Mat::from_fn(n, d, |i, j| r(i * d + j));
        let query = Mat::from_fn(q, d, |i, j| r(900_001 + i * d + j) * 0.9);
        let (idx, dist) = nearest_rows(data.as_ref(), query.as_ref());
        let dist_to = |a: usize, b: usize| (0..d).map(|j| (query[(a, j)] - data[(b, j)]).powi(2)).sum::<f64>().sqrt();
        let mut exact = 0;
        for a in 0..q {
            let best = (0..n).map(|b| dist_to(a, b)).fold(f64::INFINITY, f64::min);
            let chosen = dist_to(a, idx[a] as usize);
            assert!(chosen * chosen - best * best <= 1e-5 * d as f64, "query {a}: {chosen} against {best}");
            assert!((dist[a] - chosen).abs() <= 1e-12 * chosen.max(1.0), "the chosen row's distance");
            exact += usize::from(chosen == best);
        }
        assert!(exact * 100 >= q * 95, "{exact} of {q} exactly the nearest (the rest within rounding)");
    }

    /// The scan of a tile is the same on every instruction set this CPU has.
    #[test]
    fn the_tile_scan_is_the_same_on_every_instruction_set() {
        let (rows, cols) = (37, 300);
        let g: Vec<f32> = (0..rows * cols).map(|i| ((i * 7919) % 1009) as f32 / 1009.0).collect();
        let dn: Vec<f32> = (0..cols).map(|i| ((i * 104_729) % 997) as f32 / 997.0).collect();
        let mut results = vec![];
        for isa in crate::simd::Isa::available() {
            let (mut bd, mut local) = (vec![0.5f32; rows], vec![-1.0f32; rows]);
            bd[3] = f32::INFINITY;
            scan_tile(isa, &g, &dn, &mut bd, &mut local);
            assert!(local[3] >= 0.0, "a row with no bound finds one");
            results.push((isa, bd, local));
        }
        for (isa, bd, local) in &results[1..] {
            assert_eq!((bd, local), (&results[0].1, &results[0].2), "{isa:?} against {:?}", results[0].0);
        }
    }

    /// Bijective ZoomOut on the bent drum, on samples and on every vertex: the map stays as good, and the vertex maps
    /// both ways agree at least as often (a source vertex carried to the target and back lands on itself).
    #[test]
    fn bijective_zoomout_keeps_the_two_maps_together() {
        let a = generate::gww_drum(1, 12);
        let perm = permutation(a.vertices.len(), 11);
        let r0 = 0.45;
        let b = shuffled(&a, &perm, |[x, y, _]| {
            let y = y * (1.0 + 0.15 * x / 3.0);
            [r0 * (x / r0).sin(), y, r0 * (1.0 - (x / r0).cos())]
        });
        let (oa, sa) = spectrum_of(&a, 60);
        let (ob, sb) = spectrum_of(&b, 60);
        let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
        let t = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(&b) };
        let round_trips = |r: &Correspondence| {
            let back =
                (0..a.vertices.len()).filter(|&x| r.target_to_source[r.source_to_target[x] as usize] as usize == x);
            back.count() as f64 / a.vertices.len() as f64
        };
        for samples in [300, 0] {
            let o = CorrespondenceOptions { fit_k: 20, refine_k: 60, refine_samples: samples, ..Default::default() };
            let plain = correspond(&s, &t, &o, &Control::default()).unwrap();
            let both =
                correspond(&s, &t, &CorrespondenceOptions { bijective: true, ..o }, &Control::default()).unwrap();
            let (e0, e1) = (
                geodesic_error(&a, &plain.target_to_source, &perm, 60),
                geodesic_error(&a, &both.target_to_source, &perm, 60),
            );
            let (r0, r1) = (round_trips(&plain), round_trips(&both));
            eprintln!("samples {samples}: error {e0:.4} → {e1:.4} bijective; round trips {r0:.3} → {r1:.3}");
            assert!(e1 < 0.02 && e1 <= e0 + 0.002, "bijective error {e1} against {e0}");
            assert!(r1 >= r0 - 0.01, "round trips {r1} against {r0}");
        }
    }

    /// Parameters out of range are refused, naming the parameter.
    #[test]
    fn bad_parameters_are_refused() {
        let a = lumpy(2);
        let (oa, sa) = spectrum_of(&a, 20);
        let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
        let go = Control::default();
        // A coupled fit larger than the bound is refused before any allocation (the spectrum would allow it).
        let b = lumpy(3);
        let (ob, sb) = spectrum_of(&b, MAX_COUPLED_FIT_K + 1);
        let big = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(&b) };
        let o = CorrespondenceOptions { fit_k: MAX_COUPLED_FIT_K + 1, ..Default::default() };
        assert!(matches!(correspond(&big, &big, &o, &go), Err(CorrespondenceError::Descriptor(_))));
        for o in [
            CorrespondenceOptions { fit_k: 1, ..Default::default() },
            CorrespondenceOptions { fit_k: 21, ..Default::default() },
            CorrespondenceOptions { landmarks: vec![(0, 9999)], fit_k: 10, ..Default::default() },
            CorrespondenceOptions { laplacian_weight: f64::NAN, fit_k: 10, ..Default::default() },
            CorrespondenceOptions { descriptors: MAX_DESCRIPTORS + 1, fit_k: 10, ..Default::default() },
            CorrespondenceOptions { bijective: true, partial: true, fit_k: 10, ..Default::default() },
        ] {
            assert!(matches!(correspond(&s, &s, &o, &go), Err(CorrespondenceError::Descriptor(_))), "{o:?}");
        }
    }

    /// Options that no pair of shapes could honour are refused by `check`, before any spectrum, each naming the
    /// option it is about (a step of 0 was taken as 1 or named `descriptors`; a weight of 1e308 overflowed the fit's
    /// system, refused as "singular: give more descriptors"; two pairs sharing a vertex were each taken).
    #[test]
    fn options_no_shapes_could_honour_are_refused_naming_the_option() {
        let named = |o: CorrespondenceOptions| match o.check() {
            Err(DescriptorError::InvalidParameter { name, message }) => (name, message),
            other => panic!("{o:?}: {other:?}"),
        };
        let d = CorrespondenceOptions::default;
        assert_eq!(named(CorrespondenceOptions { descriptor_step: 0, ..d() }).0, "descriptor_step");
        assert_eq!(named(CorrespondenceOptions { refine_step: 0, ..d() }).0, "refine_step");
        assert_eq!(named(CorrespondenceOptions { descriptors: 0, ..d() }).0, "descriptors");
        assert_eq!(named(CorrespondenceOptions { fit_k: 1, ..d() }).0, "fit_k");
        let (name, message) = named(CorrespondenceOptions { descriptor_weight: 1e308, ..d() });
        assert_eq!(name, "descriptor_weight");
        assert!(message.contains("[0, 1e6]"), "{message}");
        for w in [-1.0, f64::NAN, f64::INFINITY, MAX_WEIGHT * 2.0] {
            assert_eq!(named(CorrespondenceOptions { orientation_weight: w, ..d() }).0, "orientation_weight");
        }
        assert!(CorrespondenceOptions { descriptor_weight: MAX_WEIGHT, laplacian_weight: 0.0, ..d() }.check().is_ok());
        // A vertex paired twice, on either side; the same pair twice is one landmark.
        for landmarks in [vec![(0, 0), (0, 1)], vec![(0, 0), (1, 0)], vec![(3, 4), (5, 6), (5, 7)]] {
            let (name, message) = named(CorrespondenceOptions { landmarks: landmarks.clone(), ..d() });
            assert_eq!(name, "landmarks", "{landmarks:?}");
            assert!(message.contains("two vertices"), "{message}");
        }
        assert!(CorrespondenceOptions { landmarks: vec![(0, 0), (0, 0), (1, 1)], ..d() }.check().is_ok());
        let too_many = (0..=MAX_LANDMARKS as u32).map(|i| (i, i)).collect();
        assert_eq!(named(CorrespondenceOptions { landmarks: too_many, ..d() }).0, "landmarks");
    }
}

//! The options of a correspondence and the checks that need no shape.

use crate::descriptors::DescriptorError;
use serde::{Deserialize, Serialize};

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
    /// [`correspond`](super::correspond) makes them again, with those that need the spectra.
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

//! What an analysis returns: a JSON summary, per-vertex arrays, and the shape-DNA fingerprints it computed.

use super::*;

/// Every name a per-vertex array can have.
pub const ARRAY_NAMES: &[&str] = &[
    "eigenvectors",
    "hks",
    "si_hks",
    "wks",
    "gps",
    "heat_kernel",
    "heat",
    "distance",
    "embedding",
    "fiedler",
    "smoothed",
    "interpolated",
    "labels",
    "scores",
    "mean_curvature",
    "normals",
    "gaussian_curvature",
    "heat_curvature",
    "wave",
    "schrodinger_re",
    "schrodinger_im",
    "solution",
    "diffused",
    "gradient",
    "divergence",
    "stiffness",
    "mass",
    "unknown_vertices",
    "source_to_target",
    "target_to_source",
    "source_cost",
    "target_cost",
    "transferred",
];

/// A per-vertex array in the input numbering, row-major (rows × cols).
#[derive(Debug, Clone, PartialEq)]
pub struct VertexArray {
    pub name: &'static str,
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
    /// What the columns are (times, energies, frequencies, …), for JSON and file headers.
    pub columns: Option<Vec<f64>>,
}

impl VertexArray {
    /// Rows as nested JSON arrays (NaN and ±∞ as null).
    pub fn to_json(&self) -> Value {
        Value::Array(
            self.data
                .chunks(self.cols.max(1))
                .map(|r| {
                    Value::Array(
                        r.iter().map(|&v| serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)).collect(),
                    )
                })
                .collect(),
        )
    }
}

/// The result of an analysis: a JSON summary and per-vertex arrays.
#[derive(Debug, Clone)]
pub struct Output {
    pub summary: Value,
    pub arrays: Vec<VertexArray>,
    /// Shape-DNA fingerprints the analysis computed, for the service's search index.
    pub fingerprints: Vec<Fingerprint>,
}

/// One shape's shape-DNA with the family of parameters it was computed with ([`fingerprint_family`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Fingerprint {
    pub family: String,
    pub shape_id: String,
    pub values: Vec<f64>,
}

/// The family of one descriptor's fingerprints computed with `options` on `operator`: shape-DNA's is
/// [`fingerprint_family`] of the shape-DNA the options ask for (the same family a `shape-dna` job fills); the
/// other families depend on the eigenpairs (`k`, zero modes aside), the operator and the descriptor's own fixed
/// parameters (its version).
pub fn descriptor_family(descriptor: Descriptor, options: &FingerprintOptions, operator: &OperatorSpec) -> String {
    use kac_core::descriptors::global;
    use sha2::Digest;
    let params = match descriptor {
        Descriptor::ShapeDna | Descriptor::Fused => return fingerprint_family(&options.dna(), operator),
        Descriptor::HeatDistribution => json!({ "times": global::HEAT_TIMES, "quantiles": global::HEAT_QUANTILES }),
        Descriptor::GpsD2 => json!({
            "dimensions": global::GPS_DIMENSIONS, "points": global::GPS_POINTS, "quantiles": global::GPS_QUANTILES
        }),
    };
    let canonical = serde_json::to_vec(&json!({
        "descriptor": descriptor.name(), "k": options.k, "params": params, "operator": operator,
        "version": GLOBAL_DESCRIPTOR_VERSION
    }))
    .unwrap_or_default();
    sha2::Sha256::digest(&canonical).iter().take(8).map(|b| format!("{b:02x}")).collect()
}

/// Bumped whenever the heat distribution's or GPS D2's values could change for the same eigenpairs (part of their
/// families).
pub const GLOBAL_DESCRIPTOR_VERSION: u32 = 1;

/// The family of a fingerprint: every parameter that changes its values (the shape-DNA options and the
/// operator), canonical JSON hashed to 16 hex digits. Fingerprints are compared only within a family.
pub fn fingerprint_family(options: &ShapeDnaOptions, operator: &OperatorSpec) -> String {
    use sha2::Digest;
    let canonical =
        serde_json::to_vec(&json!({ "options": options, "operator": operator, "version": FINGERPRINT_VERSION }))
            .unwrap_or_default();
    sha2::Sha256::digest(&canonical).iter().take(8).map(|b| format!("{b:02x}")).collect()
}

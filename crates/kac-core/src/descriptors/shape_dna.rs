//! Shape-DNA (Reuter, Wolter & Peinecke 2006): the beginning of the spectrum as a fingerprint, with explicit
//! conventions for the zero mode, normalization and reweighting, distances between fingerprints, and lapy's
//! `.ev` text format so that existing collections can be compared.
//!
//! Normalizations multiply the eigenvalues by a power of the shape's measure so that scaling the shape by β
//! (λ ↦ λ/β²) leaves them unchanged:
//!
//! | name | value | for |
//! |---|---|---|
//! | `none` | λ | |
//! | `area` | λ · A | surfaces (A the area) |
//! | `volume` | λ · V^{2/3} | solids, or closed surfaces with enclosed volume V |
//! | `geometry` | `area` for surfaces, `volume` for solids, λ·ℓ² for curves | any |
//! | `weyl` | λ_n / λ_n^{Weyl} with λ_n^{Weyl} = (2π)² (n / (ω_d |Ω|))^{2/d} | any (→ 1 for large n) |
//! | `first-nonzero` | λ / λ₁ | any (λ₁ the first non-zero eigenvalue) |
//!
//! For `weyl`, n counts the non-zero eigenvalues from 1 (d = 2: λ_n^{Weyl} = 4πn/A; d = 3: (6π²n/V)^{2/3};
//! d = 1: (πn/ℓ)²) and zero modes stay 0. Reweighting `index` divides the i-th reported value by i (1-based over
//! the reported list, as lapy's `reweight_ev` does), which keeps high eigenvalues from dominating distances.

use super::DescriptorError;
use serde::{Deserialize, Serialize};

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Normalization {
    #[default]
    None,
    Area,
    Volume,
    Geometry,
    Weyl,
    FirstNonzero,
}

impl Normalization {
    pub const ALL: [Normalization; 6] = [
        Normalization::None,
        Normalization::Area,
        Normalization::Volume,
        Normalization::Geometry,
        Normalization::Weyl,
        Normalization::FirstNonzero,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Normalization::None => "none",
            Normalization::Area => "area",
            Normalization::Volume => "volume",
            Normalization::Geometry => "geometry",
            Normalization::Weyl => "weyl",
            Normalization::FirstNonzero => "first-nonzero",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|n| n.name() == s)
    }
    /// A name, or a sentence listing the names.
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::from_name(s)
            .ok_or_else(|| format!("unknown normalization '{s}'; one of: {}", Self::ALL.map(|n| n.name()).join(", ")))
    }
}

impl std::fmt::Display for Normalization {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Reweighting {
    #[default]
    None,
    Index,
}

impl Reweighting {
    pub fn name(self) -> &'static str {
        match self {
            Reweighting::None => "none",
            Reweighting::Index => "index",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        [Reweighting::None, Reweighting::Index].into_iter().find(|r| r.name() == s)
    }
    /// A name, or a sentence listing the names.
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::from_name(s).ok_or_else(|| format!("unknown reweighting '{s}'; one of: none, index"))
    }
}

impl std::fmt::Display for Reweighting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A `(name, value)` pair's schema: an array of two items, a string then a number, or null. (utoipa writes a tuple
/// with `items: false`, which openapi-python-client cannot read; this says the same with `items` both may be.)
#[cfg(feature = "openapi")]
fn name_and_value() -> utoipa::openapi::schema::Array {
    use utoipa::openapi::schema::{ArrayBuilder, ObjectBuilder, SchemaType, Type};
    ArrayBuilder::new()
        .schema_type(SchemaType::from_iter([Type::Array, Type::Null]))
        .items(ObjectBuilder::new().schema_type(SchemaType::from_iter([Type::String, Type::Number])))
        .min_items(Some(2))
        .max_items(Some(2))
        .description(Some("The measure the normalization used: its name and value, as a pair [\"area\", 12.56]."))
        .build()
}

/// The measures of a shape that normalizations use.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct Measures {
    /// Intrinsic dimension: 1 curves, 2 surfaces (meshes, point clouds), 3 solids.
    pub dimension: u8,
    pub length: Option<f64>,
    pub area: Option<f64>,
    pub volume: Option<f64>,
    /// Whether the domain has a boundary (a surface mesh's open edges; a solid always): `false` leaves the
    /// boundary term out of the Weyl estimates, where it has no meaning; unknown (`None`) for clouds, graphs and
    /// curves.
    #[serde(default)]
    pub has_boundary: Option<bool>,
    /// The boundary condition of the operator the eigenvalues are of, which gives the sign of Weyl's boundary
    /// term; `None` (a library caller's spectrum, exact spectra): read from the zero modes (a spectrum with zero
    /// modes is Neumann). `mixed` (Dirichlet on part of the boundary) leaves the boundary estimate out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<BoundaryCondition>,
}

/// The boundary condition of a spectrum, for Weyl's boundary term.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BoundaryCondition {
    Neumann,
    Dirichlet,
    /// Dirichlet on part of the boundary only.
    Mixed,
}

impl Measures {
    /// The d-dimensional measure: length, area or volume.
    pub fn measure(&self) -> Option<f64> {
        match self.dimension {
            1 => self.length,
            2 => self.area,
            3 => self.volume,
            _ => None,
        }
    }
}

/// λ_n^{Weyl} = (2π)² (n / (ω_d |Ω|))^{2/d}: the n-th eigenvalue Weyl's law predicts (ω_d the volume of the unit
/// ball in R^d).
pub fn weyl_eigenvalue(n: f64, dimension: u8, measure: f64) -> f64 {
    crate::spectrum::weyl_law::weyl_eigenvalue(dimension, measure, n)
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct ShapeDnaOptions {
    /// Values reported (default 50).
    #[cfg_attr(feature = "cli", arg(short = 'k', long = "k", default_value_t = ShapeDnaOptions::default().k))]
    pub k: usize,
    /// Report the zero modes (λ ≤ zero tolerance) too; default false: the fingerprint starts at the first
    /// non-zero eigenvalue.
    #[cfg_attr(feature = "cli", arg(long))]
    pub include_zero: bool,
    /// none, area, volume, geometry, weyl, first-nonzero.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ShapeDnaOptions::default().normalization, value_parser = Normalization::parse))]
    pub normalization: Normalization,
    /// none or index (divide the i-th value by i).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ShapeDnaOptions::default().reweighting, value_parser = Reweighting::parse))]
    pub reweighting: Reweighting,
}

impl Default for ShapeDnaOptions {
    fn default() -> Self {
        ShapeDnaOptions {
            k: 50,
            include_zero: false,
            normalization: Normalization::None,
            reweighting: Reweighting::None,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ShapeDna {
    /// The fingerprint: k values after normalization and reweighting.
    pub values: Vec<f64>,
    /// The same k eigenvalues before normalization.
    pub eigenvalues: Vec<f64>,
    pub k: usize,
    pub include_zero: bool,
    pub zero_modes_dropped: usize,
    pub normalization: Normalization,
    /// The factor every eigenvalue was multiplied by (`none`, `area`, `volume`, `geometry`, `first-nonzero`);
    /// absent for `weyl`, whose factor depends on n.
    pub factor: Option<f64>,
    /// The measure the normalization used: its name and value, as a pair `["area", 12.56]`.
    #[cfg_attr(feature = "openapi", schema(schema_with = name_and_value))]
    pub measure: Option<(String, f64)>,
    pub reweighting: Reweighting,
}

/// The shape-DNA of a computed spectrum (ascending eigenvalues, at least k after dropping zero modes).
pub fn shape_dna(
    eigenvalues: &[f64],
    zero_tol: f64,
    measures: &Measures,
    opts: &ShapeDnaOptions,
) -> Result<ShapeDna, DescriptorError> {
    if opts.k == 0 {
        return Err(DescriptorError::param("k", "at least one eigenvalue is needed"));
    }
    let zeros = eigenvalues.iter().take_while(|&&l| l <= zero_tol).count();
    let start = if opts.include_zero { 0 } else { zeros };
    if eigenvalues.len() < start + opts.k {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!(
                "{} values asked{}, {} eigenvalues computed ({zeros} zero modes)",
                opts.k,
                if opts.include_zero { "" } else { " after the zero modes" },
                eigenvalues.len()
            ),
        });
    }
    let ev = eigenvalues[start..start + opts.k].to_vec();
    let need = |name: &'static str, v: Option<f64>| -> Result<f64, DescriptorError> {
        v.filter(|x| *x > 0.0 && x.is_finite()).ok_or_else(|| DescriptorError::NotApplicable {
            message: format!(
                "the '{}' normalization needs the shape's {name}, which it does not have",
                opts.normalization.name()
            ),
        })
    };
    let (factor, measure): (Option<f64>, Option<(String, f64)>) = match opts.normalization {
        Normalization::None => (Some(1.0), None),
        Normalization::Area => {
            let a = need("area", measures.area)?;
            (Some(a), Some(("area".into(), a)))
        }
        Normalization::Volume => {
            let v = need("volume", measures.volume)?;
            (Some(v.powf(2.0 / 3.0)), Some(("volume".into(), v)))
        }
        Normalization::Geometry => match measures.dimension {
            1 => {
                let l = need("length", measures.length)?;
                (Some(l * l), Some(("length".into(), l)))
            }
            2 => {
                let a = need("area", measures.area)?;
                (Some(a), Some(("area".into(), a)))
            }
            _ => {
                let v = need("volume", measures.volume)?;
                (Some(v.powf(2.0 / 3.0)), Some(("volume".into(), v)))
            }
        },
        Normalization::Weyl => {
            let name = match measures.dimension {
                1 => "length",
                2 => "area",
                _ => "volume",
            };
            (None, Some((name.into(), need(name, measures.measure())?)))
        }
        Normalization::FirstNonzero => {
            let l1 = eigenvalues.get(zeros).copied().ok_or_else(|| DescriptorError::TooFewEigenpairs {
                message: "no non-zero eigenvalue was computed".into(),
            })?;
            (Some(1.0 / l1), Some(("first_nonzero_eigenvalue".into(), l1)))
        }
    };
    let mut values: Vec<f64> = match (factor, &measure) {
        (Some(f), _) => ev.iter().map(|l| l * f).collect(),
        (None, Some((_, m))) => ev
            .iter()
            .enumerate()
            .map(|(i, &l)| {
                let nonzero_index = (start + i + 1).saturating_sub(zeros);
                if nonzero_index == 0 {
                    0.0
                } else {
                    l / weyl_eigenvalue(nonzero_index as f64, measures.dimension, *m)
                }
            })
            .collect(),
        (None, None) => unreachable!("weyl always has a measure"),
    };
    if opts.reweighting == Reweighting::Index {
        values.iter_mut().enumerate().for_each(|(i, v)| *v /= (i + 1) as f64);
    }
    Ok(ShapeDna {
        values,
        eigenvalues: ev,
        k: opts.k,
        include_zero: opts.include_zero,
        zero_modes_dropped: if opts.include_zero { 0 } else { zeros },
        normalization: opts.normalization,
        factor,
        measure,
        reweighting: opts.reweighting,
    })
}

/// Distances between fingerprints of equal length.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Metric {
    /// √Σ (a_i − b_i)² (lapy's `euc`).
    #[default]
    Euclidean,
    /// Σ |a_i − b_i|.
    Manhattan,
    /// Σ |a_i − b_i| / (|a_i| + |b_i|) (terms with a zero denominator count 0): each index weighs alike.
    Canberra,
}

impl Metric {
    pub fn name(self) -> &'static str {
        match self {
            Metric::Euclidean => "euclidean",
            Metric::Manhattan => "manhattan",
            Metric::Canberra => "canberra",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        [Metric::Euclidean, Metric::Manhattan, Metric::Canberra].into_iter().find(|m| m.name() == s)
    }
    /// A name, or a sentence listing the names.
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::from_name(s).ok_or_else(|| format!("unknown metric '{s}'; one of: euclidean, manhattan, canberra"))
    }
}

impl std::fmt::Display for Metric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The symmetric matrix of distances between fingerprints of equal length (zero diagonal).
pub fn distance_matrix(fingerprints: &[Vec<f64>], metric: Metric) -> Result<Vec<Vec<f64>>, DescriptorError> {
    let n = fingerprints.len();
    let mut d = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            let x = distance(&fingerprints[i], &fingerprints[j], metric)?;
            d[i][j] = x;
            d[j][i] = x;
        }
    }
    Ok(d)
}

/// The `count` nearest others of row `i` of a distance matrix, nearest first (ties by index): (index, distance).
pub fn nearest(distances: &[Vec<f64>], i: usize, count: usize) -> Vec<(usize, f64)> {
    let row = &distances[i];
    let mut o: Vec<usize> = (0..row.len()).filter(|&j| j != i).collect();
    o.sort_by(|&a, &b| row[a].total_cmp(&row[b]).then(a.cmp(&b)));
    o.into_iter().take(count).map(|j| (j, row[j])).collect()
}

pub fn distance(a: &[f64], b: &[f64], metric: Metric) -> Result<f64, DescriptorError> {
    if a.len() != b.len() {
        return Err(DescriptorError::param("k", format!("fingerprints of {} and {} values", a.len(), b.len())));
    }
    let pairs = a.iter().zip(b);
    Ok(match metric {
        Metric::Euclidean => pairs.map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt(),
        Metric::Manhattan => pairs.map(|(x, y)| (x - y).abs()).sum(),
        Metric::Canberra => pairs
            .map(|(x, y)| {
                let d = x.abs() + y.abs();
                if d > 0.0 {
                    (x - y).abs() / d
                } else {
                    0.0
                }
            })
            .sum(),
    })
}

/// The contents of a ShapeDNA / lapy `.ev` file kac reads and writes: header fields and the eigenvalues
/// (eigenvectors, which the format can hold, are skipped on reading and not written).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct EvFile {
    /// Header fields in file order ("Creator", "Area", "DoF", …) with their text values.
    pub header: Vec<(String, String)>,
    pub eigenvalues: Vec<f64>,
}

impl EvFile {
    pub fn field(&self, key: &str) -> Option<&str> {
        self.header.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }
}

/// Writes the `.ev` text layout lapy's `write_ev` produces: ` Key: value` header lines, then `Eigenvalues:` and
/// the values in braces separated by ` ; `, each with 17 significant digits (round-trips binary64).
pub fn write_ev(file: &EvFile) -> String {
    let mut s = String::new();
    for (k, v) in &file.header {
        s.push_str(&format!(" {k}: {v}\n"));
    }
    s.push('\n');
    s.push_str("Eigenvalues:\n{ ");
    let vals: Vec<String> = file.eigenvalues.iter().map(|v| format!("{v:.16e}")).collect();
    s.push_str(&vals.join(" ; "));
    s.push_str(" }\n");
    s
}

/// Reads a ShapeDNA / lapy `.ev` file: header lines `Key: value` (the known `Time(...) : value` form too), and the
/// `Eigenvalues:` block `{ v ; v ; … }` spread over any number of lines. Errors name the line.
pub fn read_ev(text: &str) -> Result<EvFile, DescriptorError> {
    let bad = |line: usize, msg: String| DescriptorError::param("ev", format!("line {line}: {msg}"));
    let mut out = EvFile::default();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    let mut found = false;
    while i < lines.len() {
        let line = lines[i].trim();
        if line.starts_with("Eigenvalues") {
            // Collect everything from the first '{' to the matching '}'.
            let mut body = String::new();
            let mut j = i + 1;
            let mut open = false;
            let rest = line.split_once(':').map(|x| x.1).unwrap_or("");
            let mut chunks: Vec<(usize, &str)> = vec![(i + 1, rest)];
            while j < lines.len() {
                chunks.push((j + 1, lines[j]));
                j += 1;
            }
            let mut end_line = None;
            'outer: for (ln, c) in chunks {
                for ch in c.chars() {
                    match ch {
                        '{' if !open => open = true,
                        '}' if open => {
                            end_line = Some(ln);
                            break 'outer;
                        }
                        _ if open => body.push(ch),
                        _ => {}
                    }
                }
                if open {
                    body.push(' ');
                }
            }
            let Some(end) = end_line else {
                return Err(bad(i + 1, "the Eigenvalues block has no closing '}'".into()));
            };
            for tok in body.split(';').map(str::trim).filter(|t| !t.is_empty()) {
                let v: f64 = tok.parse().map_err(|_| bad(i + 1, format!("'{tok}' is not a number")))?;
                out.eigenvalues.push(v);
            }
            found = true;
            i = end;
            continue;
        }
        if line.starts_with("Eigenvectors") {
            break;
        }
        if let Some((k, v)) = line.split_once(':') {
            out.header.push((k.trim().to_string(), v.trim().to_string()));
        }
        i += 1;
    }
    if !found {
        return Err(DescriptorError::param("ev", "no 'Eigenvalues:' block"));
    }
    Ok(out)
}

impl Measures {
    /// The measures of a validated shape: its summary's length, area and volume, and the dimension of its kind.
    /// Point clouds have no measured area; `mass_total` (Σ M, the operator's estimate of it) stands in.
    pub fn of(summary: &crate::geometry::summary::Summary, mass_total: Option<f64>) -> Self {
        use crate::geometry::ShapeKind;
        let dimension = match summary.kind {
            ShapeKind::Polyline => 1,
            ShapeKind::TetMesh => 3,
            _ => 2,
        };
        let area = match summary.kind {
            ShapeKind::PointCloud => mass_total,
            _ => summary.area,
        };
        let has_boundary = match summary.kind {
            ShapeKind::TriangleMesh => summary.closed.map(|c| !c),
            ShapeKind::TetMesh => Some(true),
            _ => None,
        };
        Measures { dimension, length: summary.length, area, volume: summary.volume, has_boundary, condition: None }
    }
}

crate::object_only_serde!(ShapeDnaOptions);

//! The descriptor and PDE subcommands: each turns its flags into an [`Analysis`] (the same request the service's
//! job API takes), runs it, and prints the JSON summary. Per-vertex arrays go into the JSON under `arrays`
//! (rows in the input file's vertex numbering) unless `--out FILE.npy` asks for a NumPy file (several arrays:
//! `FILE.npy`, `FILE.<name>.npy`, …).

use super::{print_json, Failure, ShapeArgs};
use crate::analysis::OperatorSpec;
use crate::analysis::{self, compare, Analysis, EmbedScaling, HeatMethod, Hooks, Output, SolverSpec};
use clap::Args;
use kac_core::descriptors::shape_dna::{self, Metric, ShapeDnaOptions};
use kac_core::descriptors::signatures::{HksOptions, SiHksOptions, WksOptions};
use kac_core::pde::geodesic::HeatMethodOptions;
use kac_core::Validated;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Where per-vertex arrays go.
#[derive(Args, Debug, Clone)]
pub struct OutArgs {
    /// Write per-vertex arrays as float64 .npy (rows: input vertices) instead of into the JSON.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Solver threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    #[command(flatten)]
    pub solver: SolverSpec,
}

fn io_fail(path: &Path, e: impl std::fmt::Display) -> Failure {
    Failure { code: 1, message: format!("cannot write {}: {e}", path.display()) }
}

pub(super) fn emit(mut out: Output, args: &OutArgs) -> Result<(), Failure> {
    let mut files = vec![];
    let mut inline = serde_json::Map::new();
    for (i, a) in out.arrays.iter().enumerate() {
        match &args.out {
            Some(base) => {
                let path = if i == 0 { base.clone() } else { base.with_extension(format!("{}.npy", a.name)) };
                std::fs::write(&path, kac_core::io::npy::encode_f64(a.rows, a.cols, &a.data))
                    .map_err(|e| io_fail(&path, e))?;
                files.push(json!({ "name": a.name, "path": path.display().to_string(), "rows": a.rows, "cols": a.cols, "columns": a.columns }));
            }
            None => {
                let key = if inline.contains_key(a.name) { format!("{}_{i}", a.name) } else { a.name.to_string() };
                inline.insert(
                    key,
                    json!({ "rows": a.rows, "cols": a.cols, "columns": a.columns, "values": a.to_json() }),
                );
            }
        }
    }
    if let Some(obj) = out.summary.as_object_mut() {
        if !files.is_empty() {
            obj.insert("files".into(), Value::Array(files));
        }
        if !inline.is_empty() {
            obj.insert("arrays".into(), Value::Object(inline));
        }
    }
    print_json(&out.summary)
}

pub(super) fn run(v: &Validated, a: &Analysis, o: &OutArgs) -> Result<Output, Failure> {
    Ok(super::on_pool(o.threads, || analysis::run(v, a, Hooks { threads: o.threads, ..Default::default() }))?)
}

fn solver(o: &OutArgs) -> SolverSpec {
    o.solver.clone()
}

#[derive(Args)]
pub struct HksCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    /// Eigenpairs summed.
    #[arg(short = 'k', long = "k", default_value_t = analysis::k_signature())]
    pub k: usize,
    #[command(flatten)]
    pub hks: HksOptions,
    /// The scale-invariant HKS (Bronstein & Kokkinos 2010) instead, with the SI-HKS flags.
    #[arg(long)]
    pub scale_invariant: bool,
    #[command(flatten)]
    pub si: SiHksOptions,
}

pub fn hks(a: HksCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = if a.scale_invariant {
        Analysis::SiHks { k: a.k, options: a.si, operator: a.op.clone(), solver: solver(&a.out) }
    } else {
        Analysis::Hks { k: a.k, options: a.hks, operator: a.op.clone(), solver: solver(&a.out) }
    };
    emit(run(&v, &an, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct WksCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    #[arg(short = 'k', long = "k", default_value_t = analysis::k_signature())]
    pub k: usize,
    #[command(flatten)]
    pub options: WksOptions,
}

pub fn wks(a: WksCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = Analysis::Wks { k: a.k, options: a.options, operator: a.op.clone(), solver: solver(&a.out) };
    emit(run(&v, &an, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct ShapeDnaCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub dna: ShapeDnaOptions,
    #[command(flatten)]
    pub out: OutArgs,
    /// Also write the raw eigenvalues as a lapy/ShapeDNA .ev file.
    #[arg(long)]
    pub ev: Option<PathBuf>,
}

pub fn shape_dna(a: ShapeDnaCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = Analysis::ShapeDna { options: a.dna.clone(), operator: a.op.clone(), solver: solver(&a.out) };
    let out = run(&v, &an, &a.out)?;
    if let Some(path) = &a.ev {
        let dna = &out.summary["shape_dna"];
        let eigenvalues: Vec<f64> = serde_json::from_value(dna["eigenvalues"].clone()).unwrap_or_default();
        let s = v.summary();
        let mut header = vec![("Creator".to_string(), format!("kac {}", env!("CARGO_PKG_VERSION")))];
        header.push(("File".into(), a.shape.file.display().to_string()));
        header.push(("DoF".into(), out.summary["size"].to_string()));
        header.push(("NumEW".into(), eigenvalues.len().to_string()));
        if let Some(x) = s.area {
            header.push(("Area".into(), x.to_string()));
        }
        if let Some(x) = s.volume {
            header.push(("Volume".into(), x.to_string()));
        }
        if let Some(x) = s.euler_characteristic {
            header.push(("EulerChar".into(), x.to_string()));
        }
        std::fs::write(path, shape_dna::write_ev(&shape_dna::EvFile { header, eigenvalues }))
            .map_err(|e| io_fail(path, e))?;
    }
    emit(out, &a.out)
}

#[derive(Args)]
pub struct HeatCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    #[arg(short = 'k', long = "k", default_value_t = analysis::k_signature())]
    pub k: usize,
    /// Times (default: 10 on the HKS grid; required for --method implicit).
    #[arg(long, value_delimiter = ',')]
    pub times: Option<Vec<f64>>,
    /// Source vertices (input numbering) for heat kernel rows / diffusion.
    #[arg(long, value_delimiter = ',')]
    pub source: Vec<u32>,
    /// spectral (eigenpairs) or implicit (backward Euler, no eigenpairs).
    #[arg(long, value_enum, default_value_t = HeatMethod::default())]
    pub method: HeatMethod,
    /// Backward-Euler steps per time.
    #[arg(long, default_value_t = analysis::steps_default())]
    pub steps: usize,
}

pub fn heat(a: HeatCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = Analysis::Heat {
        k: a.k,
        times: a.times,
        sources: a.source,
        method: a.method,
        steps: a.steps,
        operator: a.op.clone(),
        solver: solver(&a.out),
    };
    emit(run(&v, &an, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct GeodesicCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub out: OutArgs,
    /// Source vertices (input numbering).
    #[arg(long, value_delimiter = ',', required = true)]
    pub source: Vec<u32>,
    #[command(flatten)]
    pub options: HeatMethodOptions,
}

pub fn geodesic(a: GeodesicCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = Analysis::Geodesic { sources: a.source, options: a.options };
    emit(run(&v, &an, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct TreesCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
}

pub fn trees(a: TreesCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let o = OutArgs { out: None, threads: 0, solver: SolverSpec::default() };
    emit(run(&v, &Analysis::Trees {}, &o)?, &o)
}

#[derive(Args)]
pub struct EmbedCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    #[arg(short = 'd', long, default_value_t = analysis::dimensions_default())]
    pub dimensions: usize,
    /// none (Laplacian eigenmap) or gps (φ/√λ).
    #[arg(long, value_enum, default_value_t = EmbedScaling::default())]
    pub scaling: EmbedScaling,
}

pub fn embed(a: EmbedCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = Analysis::Embed {
        dimensions: a.dimensions,
        scaling: a.scaling,
        operator: a.op.clone(),
        solver: solver(&a.out),
    };
    emit(run(&v, &an, &a.out)?, &a.out)
}

/// Reads a per-vertex function: `.npy` (1-D or one column) or text with one number per line.
pub(super) fn read_function(path: &Path) -> Result<Vec<f64>, Failure> {
    let bytes = std::fs::read(path).map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
    let bad = |m: String| Failure { code: 2, message: format!("{}: {m}", path.display()) };
    if bytes.starts_with(b"\x93NUMPY") {
        let (_, cols, data) = kac_core::io::npy::decode_f64(&bytes).map_err(bad)?;
        if cols != 1 {
            return Err(bad(format!("a function has one column, this array has {cols}")));
        }
        return Ok(data);
    }
    let text = String::from_utf8(bytes).map_err(|_| bad("neither .npy nor text".into()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            l.trim().parse::<f64>().map_err(|_| bad(format!("line {}: '{}' is not a number", i + 1, l.trim())))
        })
        .collect()
}

#[derive(Args)]
pub struct SmoothCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    /// α in (M + αL) u = M ū (units of length²).
    #[arg(long)]
    pub alpha: f64,
    /// The function ū (.npy or one value per line, input numbering); default: the vertex coordinates.
    #[arg(long)]
    pub function: Option<PathBuf>,
    /// Keep ū on the boundary.
    #[arg(long)]
    pub fixed_boundary: bool,
}

pub fn smooth(a: SmoothCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let function = a.function.as_deref().map(read_function).transpose()?;
    let an = Analysis::Smooth { alpha: a.alpha, function, fixed_boundary: a.fixed_boundary, operator: a.op.clone() };
    emit(run(&v, &an, &a.out)?, &a.out)
}

fn parse_pair<T: std::str::FromStr>(s: &str) -> Result<(u32, T), String> {
    let (i, x) = s.split_once(':').ok_or_else(|| format!("'{s}' is not VERTEX:VALUE"))?;
    let i = i.trim().parse::<u32>().map_err(|_| format!("'{i}' is not a vertex index"))?;
    let x = x.trim().parse::<T>().map_err(|_| format!("'{x}' is not a valid value"))?;
    Ok((i, x))
}

#[derive(Args)]
pub struct InterpolateCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    /// Known values, VERTEX:VALUE comma-separated (input numbering).
    #[arg(long, value_delimiter = ',', value_parser = parse_pair::<f64>, allow_hyphen_values = true)]
    pub values: Vec<(u32, f64)>,
    /// Known classes, VERTEX:CLASS comma-separated (instead of --values).
    #[arg(long, value_delimiter = ',', value_parser = parse_pair::<u32>)]
    pub labels: Vec<(u32, u32)>,
}

pub fn interpolate(a: InterpolateCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let an = Analysis::Interpolate { values: a.values, labels: a.labels, operator: a.op.clone() };
    emit(run(&v, &an, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct CompareCmd {
    /// First shape, or a .ev file of eigenvalues.
    pub a: PathBuf,
    /// Second shape, or a .ev file.
    pub b: PathBuf,
    /// The fingerprint family compared: shape-dna (default: it also reads .ev files), heat-distribution or gps-d2
    /// (shapes only). The fused distance needs a collection's spreads: the service's compare and search have it.
    #[arg(long, default_value = "shape-dna", value_parser = ["shape-dna", "heat-distribution", "gps-d2"])]
    pub descriptor: String,
    /// The fingerprint's options, with retrieval's defaults (k 50, geometry, index: invariant to scale).
    #[command(flatten)]
    pub fp: analysis::FingerprintOptions,
    #[command(flatten)]
    pub op: OperatorSpec,
    /// euclidean, manhattan or canberra.
    #[arg(long, default_value_t = Metric::default(), value_parser = Metric::parse)]
    pub metric: Metric,
    #[command(flatten)]
    pub solver: SolverSpec,
}

/// Two shapes (or `.ev` files) compared through the same code as the service's comparisons
/// ([`analysis::compare`]): each one's fingerprint, then their distance.
pub fn compare(a: CompareCmd) -> Result<(), Failure> {
    let dna_options = a.fp.dna();
    let descriptor: analysis::Descriptor =
        serde_json::from_value(json!(a.descriptor)).map_err(|e| Failure { code: 2, message: e.to_string() })?;
    let fail =
        |path: &Path, e: &dyn std::fmt::Display| Failure { code: 2, message: format!("{}: {e}", path.display()) };
    // Each side's shape-DNA, its values in the family compared, and what is shown of it.
    let side = |path: &Path| -> Result<(compare::Fingerprinted, Vec<f64>, Value), Failure> {
        let source = path.display().to_string();
        if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ev")) {
            if descriptor != analysis::Descriptor::ShapeDna {
                return Err(fail(
                    path,
                    &format!("a .ev file holds eigenvalues only: compare it by shape-dna, not {}", a.descriptor),
                ));
            }
            let text = std::fs::read_to_string(path).map_err(|e| fail(path, &e))?;
            let ev = shape_dna::read_ev(&text).map_err(|e| fail(path, &e))?;
            let field = |k: &str| ev.field(k).and_then(|x| x.parse::<f64>().ok());
            let dimension = if field("Volume").is_some() && field("Area").is_none() { 3 } else { 2 };
            let m = shape_dna::Measures {
                dimension,
                area: field("Area"),
                volume: field("Volume"),
                length: None,
                has_boundary: None,
                condition: None,
            };
            let f = compare::fingerprint_eigenvalues(&source, &ev.eigenvalues, &m, &dna_options)
                .map_err(|e| fail(path, &e))?;
            let shown = json!({ "source": source, "format": "ev", "shape_dna": f.dna });
            let values = f.dna.values.clone();
            return Ok((f, values, shown));
        }
        let shape =
            ShapeArgs { file: path.to_path_buf(), format: None, weld: kac_core::Weld::Exact, keep_degenerate: false };
        let (v, _) = shape.load()?;
        an_supported(&v, &a, descriptor)?;
        let (f, values) = if descriptor == analysis::Descriptor::ShapeDna {
            let f = compare::fingerprint(&v.id.hex(), &v, &dna_options, &a.op, &a.solver, Hooks::default())?;
            let values = f.dna.values.clone();
            (f, values)
        } else {
            let fams =
                analysis::fingerprint_families(&v, &a.fp, &a.op, &a.solver, Hooks::default(), &Default::default())?;
            let values = fams
                .families
                .iter()
                .find(|x| x.descriptor == descriptor.name())
                .map(|x| x.values.clone())
                .unwrap_or_default();
            (compare::Fingerprinted { id: v.id.hex(), dna: fams.shape_dna, operator: Some(fams.operator) }, values)
        };
        let (operator, mass) = f.operator.as_ref().map_or(("", ""), |o| (o.operator, o.mass));
        let mut shown =
            json!({ "source": source, "shape_id": f.id, "shape_dna": f.dna, "operator": operator, "mass": mass });
        if descriptor != analysis::Descriptor::ShapeDna {
            shown[descriptor.name().replace('-', "_")] = json!(values);
        }
        Ok((f, values, shown))
    };
    let (x, y) = (side(&a.a)?, side(&a.b)?);
    let distance =
        shape_dna::distance(&x.1, &y.1, a.metric).map_err(|e| Failure { code: 2, message: e.to_string() })?;
    // Every number checked before it is printed, as the comparison's are.
    let found = [x.0, y.0];
    compare::comparison(&found, vec![], &dna_options, &a.op, a.metric, 1)
        .map_err(|e| Failure { code: 2, message: e.to_string() })?;
    if !distance.is_finite() {
        return Err(Failure { code: 2, message: format!("the distance is not finite ({distance})") });
    }
    print_json(&json!({
        "descriptor": a.descriptor,
        "metric": a.metric.name(),
        "distance": distance,
        "k": a.fp.k,
        "normalization": a.fp.normalization.name(),
        "reweighting": a.fp.reweighting.name(),
        "include_zero": a.fp.include_zero,
        "a": x.2,
        "b": y.2,
    }))
}

/// The fingerprint of this shape is one the truth table admits (the same check as its job).
fn an_supported(v: &Validated, a: &CompareCmd, descriptor: analysis::Descriptor) -> Result<(), Failure> {
    let (operator, solver) = (a.op.clone(), a.solver.clone());
    let an = match descriptor {
        analysis::Descriptor::ShapeDna => Analysis::ShapeDna { options: a.fp.dna(), operator, solver },
        _ => Analysis::Fingerprint { options: a.fp.clone(), operator, solver },
    };
    an.supported(&v.shape)?;
    Ok(())
}

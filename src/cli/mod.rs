//! Command-line parsing and the subcommands. Exit codes: 0 success, 2 unreadable input or bad arguments,
//! 1 any other failure.

use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use kac_core::geometry::validate::Weld;
use kac_core::{Format, ReadOptions, ValidateOptions, Validated};
use std::path::PathBuf;

mod analyses;
mod correspond;
mod curvature;
mod derived;
mod evolution;
mod generate;
mod inspect;
mod operator;
mod pde;
mod spectrum;

#[derive(Parser)]
#[command(name = "kac", version, about = "Can you hear the shape of a drum? Spectral shape analysis.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Read, validate and summarize a shape as JSON (kind, counts, id, bbox, area/volume, topology, repairs).
    Inspect(inspect::InspectArgs),
    /// Build a Laplace operator (L, M): summary, property report, Matrix Market output.
    Operator(operator::OperatorCmd),
    /// The k smallest eigenpairs of L φ = λ M φ.
    Spectrum(spectrum::SpectrumCmd),
    /// Write a shape with a known spectrum (icosphere, square, disk, torus, cube-tets, graphs).
    Generate(generate::GenerateCmd),
    /// Heat kernel signature per vertex (or its scale-invariant form, --scale-invariant).
    Hks(analyses::HksCmd),
    /// Wave kernel signature per vertex.
    Wks(analyses::WksCmd),
    /// Shape-DNA (normalized eigenvalues) with Weyl's-law estimates; lapy .ev output.
    ShapeDna(analyses::ShapeDnaCmd),
    /// Heat trace, and heat kernel rows from source vertices (spectral or backward Euler).
    Heat(analyses::HeatCmd),
    /// Geodesic distance from source vertices by the heat method (triangle meshes).
    Geodesic(analyses::GeodesicCmd),
    /// Number of spanning trees of the shape's edge graph (Kirchhoff's theorem).
    Trees(analyses::TreesCmd),
    /// Mean curvature and outward normals from M⁻¹LX = 2Hn, with the angle-defect Gaussian curvature.
    MeanCurvature(curvature::MeanCurvatureCmd),
    /// Gaussian curvature from the heat kernel's diagonal at small times, beside the angle defect.
    HeatCurvature(curvature::HeatCurvatureCmd),
    /// The wave equation ∂²u/∂t² = −Δu by modal superposition, from a displacement and a velocity.
    Wave(evolution::WaveCmd),
    /// The Schrödinger equation ∂ψ/∂t = −iΔψ, unitary in the eigenbasis (real and imaginary parts, M-norm).
    Schrodinger(evolution::SchrodingerCmd),
    /// Poisson's equation Δf = g (Neumann with the incompatible mean removed, or Dirichlet values).
    Poisson(pde::PoissonCmd),
    /// Heat diffusion ∂u/∂t = −αΔu of a function (spectral or backward Euler).
    Diffuse(pde::DiffuseCmd),
    /// The Dirichlet energy ½ uᵀLu of a function (or of each coordinate).
    DirichletEnergy(pde::DirichletEnergyCmd),
    /// The gradient of a per-vertex function on each triangle or tetrahedron (Prop. 9.2).
    Gradient(pde::GradientCmd),
    /// The divergence of a per-element vector field per vertex (Def. 9.1), integrated and pointwise.
    Divergence(pde::DivergenceCmd),
    /// Laplacian eigenmap or GPS embedding, with the Fiedler vector and bisection.
    Embed(analyses::EmbedCmd),
    /// Smooth vertex coordinates or a function: (M + αL) u = M ū.
    Smooth(analyses::SmoothCmd),
    /// Harmonic interpolation of values on some vertices, or semi-supervised labels.
    Interpolate(analyses::InterpolateCmd),
    /// Distance between two shapes (or .ev files) by shape-DNA.
    Compare(analyses::CompareCmd),
    /// Which vertex of one shape is which of another: functional maps refined by ZoomOut, the maps both ways.
    Correspondence(correspond::CorrespondenceCmd),
    /// Run the HTTP service (REST API under /v1, OpenAPI at /openapi.json, docs at /docs).
    Serve(crate::service::config::Config),
    /// Print the OpenAPI document.
    Openapi,
    /// Print the truth table of analyses: where each is valid (shape classes, boundary conditions, order 2,
    /// extrapolation); every other combination is refused (`unsupported`).
    Analyses {
        /// As the README's Markdown table (default: JSON, as GET /v1/analyses).
        #[arg(long)]
        markdown: bool,
    },
}

impl From<crate::analysis::AnalysisError> for Failure {
    fn from(e: crate::analysis::AnalysisError) -> Self {
        Failure { code: if e.caller_fault() { 2 } else { 1 }, message: e.to_string() }
    }
}

/// Options shared by every subcommand that reads a shape.
#[derive(Args, Debug, Clone)]
pub struct ShapeArgs {
    /// The shape file (OBJ, OFF, PLY, STL, glTF/GLB, Medit .mesh, Gmsh .msh, VTK, XYZ/CSV, JSON).
    pub file: PathBuf,
    /// Format name, overriding the extension and content sniffing.
    #[arg(long, value_parser = parse_format)]
    pub format: Option<Format>,
    /// Merge duplicate vertices: `exact` (default), `none`, or a distance tolerance such as `1e-6`.
    #[arg(long, default_value = "exact", value_parser = parse_weld)]
    pub weld: Weld,
    /// Keep zero-area faces and zero-volume tets instead of dropping them.
    #[arg(long)]
    pub keep_degenerate: bool,
}

fn parse_format(s: &str) -> Result<Format, String> {
    Format::from_name(s).ok_or_else(|| format!("unknown format '{s}'; one of: {}", Format::names()))
}

fn parse_weld(s: &str) -> Result<Weld, String> {
    match s {
        "exact" => Ok(Weld::Exact),
        "none" => Ok(Weld::None),
        t => match t.parse::<f64>() {
            Ok(v) if v > 0.0 && v.is_finite() => Ok(Weld::Tolerance(v)),
            _ => Err(format!("'{s}' is not 'exact', 'none' or a positive tolerance")),
        },
    }
}

/// A failure of a subcommand: the exit code and the one-line message.
pub struct Failure {
    pub code: i32,
    pub message: String,
}

impl From<kac_core::ShapeError> for Failure {
    fn from(e: kac_core::ShapeError) -> Self {
        Failure { code: 2, message: e.to_string() }
    }
}

impl ShapeArgs {
    pub fn load(&self) -> Result<(Validated, Format), Failure> {
        let v = ValidateOptions { weld: self.weld, drop_degenerate: !self.keep_degenerate, kind: None };
        Ok(kac_core::load(&self.file, self.format, &ReadOptions::default(), &v)?)
    }
}

/// Prints a subcommand's answer on stdout, and each of its warnings (`warnings: [{code, message}]`, the one place a
/// result says that a number is outside its domain of validity) on stderr, where a person at a terminal sees them:
/// every subcommand answers through here, so none can leave its warnings unsaid.
pub fn print_json(value: &impl serde::Serialize) -> Result<(), Failure> {
    let s = serde_json::to_string_pretty(value).map_err(|e| Failure { code: 1, message: e.to_string() })?;
    #[derive(serde::Deserialize)]
    struct Warning {
        code: String,
        message: String,
    }
    #[derive(serde::Deserialize)]
    struct Warned {
        #[serde(default)]
        warnings: Vec<Warning>,
    }
    // The answer as printed, read back for its warnings only (its field order kept in what is printed).
    if let Ok(Warned { warnings }) = serde_json::from_str::<Warned>(&s) {
        for w in warnings {
            eprintln!("kac: warning {}: {}", w.code, w.message);
        }
    }
    println!("{s}");
    Ok(())
}

pub fn run() -> i32 {
    // The hand-written subcommands, and one derived from the registry for every other analysis.
    let command = derived::commands().into_iter().fold(Cli::command(), |c, sub| c.subcommand(sub));
    let parsed = command.try_get_matches().and_then(|m| match m.subcommand() {
        Some((name, sub))
            if !derived::HANDWRITTEN.contains(&name) && crate::analysis::registry::entry(name).is_some() =>
        {
            Ok(Err((name.to_string(), sub.clone())))
        }
        _ => Cli::from_arg_matches(&m).map(Ok),
    });
    let cli = match parsed {
        Ok(Ok(c)) => c,
        Ok(Err((name, sub))) => {
            return match derived::run(&name, &sub) {
                Ok(()) => 0,
                Err(f) => {
                    eprintln!("kac: {}", f.message.replace('\n', " "));
                    f.code
                }
            }
        }
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    let result = match cli.command {
        Command::Inspect(a) => inspect::run(a),
        Command::Operator(a) => operator::run(a),
        Command::Spectrum(a) => spectrum::run(a),
        Command::Generate(a) => generate::run(a),
        Command::Hks(a) => analyses::hks(a),
        Command::Wks(a) => analyses::wks(a),
        Command::ShapeDna(a) => analyses::shape_dna(a),
        Command::Heat(a) => analyses::heat(a),
        Command::Geodesic(a) => analyses::geodesic(a),
        Command::Trees(a) => analyses::trees(a),
        Command::MeanCurvature(a) => curvature::mean_curvature(a),
        Command::HeatCurvature(a) => curvature::heat_curvature(a),
        Command::Wave(a) => evolution::wave(a),
        Command::Schrodinger(a) => evolution::schrodinger(a),
        Command::Poisson(a) => pde::poisson(a),
        Command::Diffuse(a) => pde::diffuse(a),
        Command::DirichletEnergy(a) => pde::dirichlet_energy(a),
        Command::Gradient(a) => pde::gradient(a),
        Command::Divergence(a) => pde::divergence(a),
        Command::Embed(a) => analyses::embed(a),
        Command::Smooth(a) => analyses::smooth(a),
        Command::Interpolate(a) => analyses::interpolate(a),
        Command::Compare(a) => analyses::compare(a),
        Command::Correspondence(a) => correspond::run(a),
        Command::Serve(c) => crate::service::serve(c).map_err(|message| Failure { code: 1, message }),
        Command::Openapi => {
            println!("{}", crate::service::openapi::document());
            Ok(())
        }
        Command::Analyses { markdown: true } => {
            print!("{}", crate::analysis::registry::markdown_table());
            Ok(())
        }
        Command::Analyses { markdown: false } => {
            let table = serde_json::to_string_pretty(&crate::analysis::registry::table(None)).unwrap_or_default();
            println!("{table}");
            Ok(())
        }
    };
    match result {
        Ok(()) => 0,
        Err(f) => {
            eprintln!("kac: {}", f.message.replace('\n', " "));
            f.code
        }
    }
}

/// Runs `f` on this thread made one of the global rayon pool's workers (built with `threads` workers when given,
/// `use_current_thread`). The solver's serial parts then run on the pool beside its parallel ones, and each parallel
/// step is a fork on the pool instead of a hand-off from this thread and back. This thread, not a spawned worker,
/// keeps the solve's large allocations, since glibc gives a spawned worker an arena of its own that holds more at the
/// peak (BENCHMARKS.md, "Why the code is as it is"). Where the pool was built already, `f` runs here.
pub(crate) fn on_pool<T>(threads: usize, f: impl FnOnce() -> T) -> T {
    let mut pool = rayon::ThreadPoolBuilder::new().use_current_thread();
    if threads > 0 {
        pool = pool.num_threads(threads);
    }
    let _ = pool.build_global();
    f()
}

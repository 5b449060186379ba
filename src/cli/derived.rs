//! Subcommands derived from the registry: every analysis of the registry that has no hand-written subcommand gets
//! one, built from its request's JSON Schema (the service's OpenAPI document): the shape's flags, `--out` and
//! `--threads`, the flags of the option types the request holds (the same clap flags the hand-written subcommands
//! flatten: operator, solver, signature, shape-DNA and fingerprint options), and one flag per other field of the request,
//! typed by its schema. What the flags give becomes the request's JSON, read by the same `Analysis` type the
//! service takes, so defaults and checks are the service's.
//!
//! The hand-written subcommands (`HANDWRITTEN`) keep their flags, which are a contract (file inputs such as
//! `--function FILE.npy`, `hks --scale-invariant`); an analysis added to the registry needs no CLI code.

use super::analyses::{emit, run as run_analysis, OutArgs};
use super::{Failure, ShapeArgs};
use crate::analysis::{self, Analysis, OperatorSpec, SolverSpec};
use clap::{Arg, ArgAction, ArgMatches, Args, Command, FromArgMatches};
use kac_core::descriptors::shape_dna::ShapeDnaOptions;
use kac_core::descriptors::signatures::{HksOptions, SiHksOptions, WksOptions};
use kac_core::pde::geodesic::HeatMethodOptions;
use serde_json::{Map, Value};

/// The analyses whose subcommands are written by hand (in `super::Command`), with flags of their own.
pub const HANDWRITTEN: &[&str] = &[
    "spectrum",
    "operator",
    "hks",
    "wks",
    "shape-dna",
    "heat",
    "geodesic",
    "trees",
    "mean-curvature",
    "heat-curvature",
    "wave",
    "schrodinger",
    "poisson",
    "diffuse",
    "dirichlet-energy",
    "gradient",
    "divergence",
    "embed",
    "smooth",
    "interpolate",
];

/// An option type the CLI has flags for: its schema's name, its flags, and its value from the flags given.
struct OptionType {
    schema: &'static str,
    augment: fn(Command) -> Command,
    value: fn(&ArgMatches) -> Result<Value, clap::Error>,
}

fn option_type<T: Args + FromArgMatches + serde::Serialize>(schema: &'static str) -> OptionType {
    OptionType {
        schema,
        augment: |c| T::augment_args(c),
        value: |m| T::from_arg_matches(m).map(|v| serde_json::to_value(v).unwrap_or(Value::Null)),
    }
}

fn option_types() -> Vec<OptionType> {
    vec![
        option_type::<OperatorSpec>("OperatorSpec"),
        option_type::<SolverSpec>("SolverSpec"),
        option_type::<HksOptions>("HksOptions"),
        option_type::<SiHksOptions>("SiHksOptions"),
        option_type::<WksOptions>("WksOptions"),
        option_type::<ShapeDnaOptions>("ShapeDnaOptions"),
        option_type::<analysis::FingerprintOptions>("FingerprintOptions"),
        option_type::<HeatMethodOptions>("HeatMethodOptions"),
    ]
}

fn schemas() -> &'static Map<String, Value> {
    crate::service::openapi::served()
        .pointer("/components/schemas")
        .and_then(Value::as_object)
        .expect("the OpenAPI document has its schemas")
}

/// The schema name of an analysis' request (`si-hks` → `SiHksAnalysis`).
pub fn request_schema(name: &str) -> String {
    let camel: String = name
        .split('-')
        .map(|w| {
            let mut c = w.chars();
            c.next().map(|f| f.to_uppercase().chain(c).collect::<String>()).unwrap_or_default()
        })
        .collect();
    format!("{camel}Analysis")
}

fn reference(p: &Value) -> Option<&str> {
    p.get("$ref")
        .or_else(|| p.get("oneOf").and_then(Value::as_array).and_then(|a| a.iter().find_map(|x| x.get("$ref"))))
        .and_then(Value::as_str)
        .and_then(|r| r.rsplit('/').next())
}

fn types(p: &Value) -> Vec<&str> {
    match p.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(a)) => a.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    }
}

/// The flag of one field of the request, typed by its schema; None for a field no flag can give (an object).
fn field_arg(name: &'static str, p: &Value, required: bool) -> Option<Arg> {
    let t = types(p);
    let help = p.get("description").and_then(Value::as_str).unwrap_or("").replace('\n', " ");
    let arg = Arg::new(name).long(name).help(help).required(required);
    if t.contains(&"boolean") {
        return Some(arg.action(ArgAction::SetTrue).required(false));
    }
    if t.contains(&"array") {
        let item = p.get("items").map(types).unwrap_or_default();
        let arg = arg.value_delimiter(',').num_args(1..).allow_hyphen_values(true);
        return match item.first() {
            Some(&"integer") => Some(arg.value_parser(clap::value_parser!(i64))),
            Some(&"number") => Some(arg.value_parser(clap::value_parser!(f64))),
            Some(&"string") => Some(arg),
            _ => None,
        };
    }
    if t.contains(&"integer") {
        return Some(arg.value_parser(clap::value_parser!(i64)));
    }
    if t.contains(&"number") {
        return Some(arg.value_parser(clap::value_parser!(f64)).allow_hyphen_values(true));
    }
    if t.contains(&"string") {
        return Some(match p.get("enum").and_then(Value::as_array) {
            Some(values) => {
                let names: Vec<&'static str> = values.iter().filter_map(Value::as_str).map(leak).collect();
                arg.value_parser(clap::builder::PossibleValuesParser::new(names))
            }
            None => arg,
        });
    }
    None
}

/// A leaked name: clap's ids and long flags are `&'static str`, and a subcommand is built once per process.
fn leak(s: &str) -> &'static str {
    Box::leak(s.to_string().into_boxed_str())
}

/// The derived subcommand of an analysis of the registry.
fn command(name: &str, about: &str) -> Command {
    let schema = &schemas()[&request_schema(name)];
    let required: Vec<&str> = schema
        .get("required")
        .and_then(Value::as_array)
        .map_or(vec![], |r| r.iter().filter_map(Value::as_str).collect());
    let mut c = Command::new(leak(name));
    c = ShapeArgs::augment_args(c);
    c = c
        .arg(
            Arg::new("out")
                .long("out")
                .value_parser(clap::value_parser!(std::path::PathBuf))
                .help("Write per-vertex arrays as float64 .npy (rows: input vertices) instead of into the JSON."),
        )
        .arg(
            Arg::new("threads")
                .long("threads")
                .value_parser(clap::value_parser!(usize))
                .default_value("0")
                .help("Solver threads (default: all cores)."),
        );
    let kinds = option_types();
    for (field, p) in schema.get("properties").and_then(Value::as_object).into_iter().flatten() {
        if field == "analysis" {
            continue;
        }
        match reference(p).and_then(|r| kinds.iter().find(|k| k.schema == r)) {
            Some(kind) => c = (kind.augment)(c),
            None => {
                if let Some(arg) = field_arg(leak(field), p, required.contains(&field.as_str())) {
                    let arg = if field == "k" { arg.short('k') } else { arg };
                    c = c.arg(arg);
                }
            }
        }
    }
    // Last: the option types' derives set their own descriptions as the command's.
    c.about(leak(about)).long_about(None)
}

/// The derived subcommands: one per analysis of the registry without a hand-written one.
pub fn commands() -> Vec<Command> {
    analysis::registry::REGISTRY
        .iter()
        .filter(|e| !HANDWRITTEN.contains(&e.name))
        .map(|e| command(e.name, e.summary))
        .collect()
}

/// The request an analysis' derived subcommand was given, as the service's JSON.
fn request(name: &str, m: &ArgMatches) -> Result<Value, clap::Error> {
    let schema = &schemas()[&request_schema(name)];
    let mut out = Map::new();
    out.insert("analysis".into(), name.into());
    let kinds = option_types();
    for (field, p) in schema.get("properties").and_then(Value::as_object).into_iter().flatten() {
        if field == "analysis" {
            continue;
        }
        if let Some(kind) = reference(p).and_then(|r| kinds.iter().find(|k| k.schema == r)) {
            out.insert(field.clone(), (kind.value)(m)?);
            continue;
        }
        let t = types(p);
        let id = field.as_str();
        if m.try_get_raw(id).ok().flatten().is_none() {
            continue;
        }
        let value = if t.contains(&"boolean") {
            if !m.get_flag(id) {
                continue;
            }
            Value::Bool(true)
        } else if t.contains(&"array") {
            match p.get("items").map(types).unwrap_or_default().first() {
                Some(&"integer") => m.get_many::<i64>(id).into_iter().flatten().map(|v| Value::from(*v)).collect(),
                Some(&"number") => m.get_many::<f64>(id).into_iter().flatten().map(|v| Value::from(*v)).collect(),
                _ => m.get_many::<String>(id).into_iter().flatten().map(|v| Value::from(v.as_str())).collect(),
            }
        } else if t.contains(&"integer") {
            m.get_one::<i64>(id).map_or(Value::Null, |v| Value::from(*v))
        } else if t.contains(&"number") {
            m.get_one::<f64>(id).map_or(Value::Null, |v| Value::from(*v))
        } else {
            m.get_one::<String>(id).map_or(Value::Null, |v| Value::from(v.as_str()))
        };
        out.insert(field.clone(), value);
    }
    Ok(Value::Object(out))
}

/// Runs the derived subcommand `name` with its matches: the request built, the shape read, the analysis run and
/// printed as the hand-written subcommands print theirs.
pub fn run(name: &str, m: &ArgMatches) -> Result<(), Failure> {
    let bad = |e: String| Failure { code: 2, message: e };
    let json = request(name, m).map_err(|e| bad(e.to_string()))?;
    let a: Analysis = serde_json::from_value(json).map_err(|e| bad(format!("{name}: {e}")))?;
    let shape = ShapeArgs::from_arg_matches(m).map_err(|e| bad(e.to_string()))?;
    let out = OutArgs {
        out: m.get_one::<std::path::PathBuf>("out").cloned(),
        threads: m.get_one::<usize>("threads").copied().unwrap_or(0),
        solver: SolverSpec::default(),
    };
    let (v, _) = shape.load()?;
    emit(run_analysis(&v, &a, &out)?, &out)
}

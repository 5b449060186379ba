//! `kac generate NAME [--level N] [--n N] --out FILE`: shapes with known spectra, written for other tools
//! (benchmarks feed the same file to kac and to the peers). Surfaces as OFF, everything else as kac JSON.

use super::{print_json, Failure};
use clap::Args;
use kac_core::geometry::{generate, Shape};
use kac_core::io::write;
use std::path::PathBuf;

#[derive(Args)]
pub struct GenerateCmd {
    /// icosphere, square, disk, torus, gww1, gww2 (the Gordon–Webb–Wolpert isospectral drums), cube-tets, segment,
    /// path, cycle, complete, petersen, cospectral1, cospectral2 (non-isomorphic graphs with one Laplacian spectrum)
    pub name: String,
    /// Subdivision level (icosphere).
    #[arg(long, default_value_t = 4)]
    pub level: u32,
    /// Resolution (cells, rings or vertices, by shape).
    #[arg(long, default_value_t = 16)]
    pub n: usize,
    /// Output file; the format follows the extension (.off, .obj, .ply, .json).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: GenerateCmd) -> Result<(), Failure> {
    let shape = match a.name.as_str() {
        "icosphere" => Shape::TriangleMesh(generate::icosphere(a.level)),
        "square" => Shape::TriangleMesh(generate::unit_square(a.n)),
        "disk" => Shape::TriangleMesh(generate::unit_disk(a.n)),
        "torus" => Shape::TriangleMesh(generate::torus(2.0, 0.5, 2 * a.n, a.n)),
        "gww1" => Shape::TriangleMesh(generate::gww_drum(1, a.n)),
        "gww2" => Shape::TriangleMesh(generate::gww_drum(2, a.n)),
        "cube-tets" => Shape::TetMesh(generate::unit_cube_tets(a.n)),
        "segment" => Shape::Polyline(generate::segment(a.n, 1.0)),
        "path" => Shape::Graph(generate::path_graph(a.n)),
        "cycle" => Shape::Graph(generate::cycle_graph(a.n)),
        "complete" => Shape::Graph(generate::complete_graph(a.n)),
        "petersen" => Shape::Graph(generate::petersen_graph()),
        "cospectral1" => Shape::Graph(generate::cospectral_graph(1)),
        "cospectral2" => Shape::Graph(generate::cospectral_graph(2)),
        other => return Err(Failure { code: 2, message: format!("unknown shape '{other}'") }),
    };
    // The format follows the extension (.off, .obj, .ply, .json); OFF for meshes and kac JSON otherwise by default.
    let ext = a.out.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let bytes = match (&shape, ext.as_str()) {
        (s, "obj") => write::obj(s).into_bytes(),
        (s, "ply") => write::ply(s, true, None),
        (Shape::TriangleMesh(m), "off" | "") => write::off(m).into_bytes(),
        (s, _) => serde_json::to_vec(&write::json(s)).map_err(|e| Failure { code: 1, message: e.to_string() })?,
    };
    std::fs::write(&a.out, bytes)
        .map_err(|e| Failure { code: 1, message: format!("cannot write {}: {e}", a.out.display()) })?;
    print_json(
        &serde_json::json!({ "file": a.out.display().to_string(), "kind": shape.kind(), "vertices": shape.vertex_count() }),
    )
}

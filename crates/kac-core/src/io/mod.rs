//! Readers (and writers) of every input format kac takes. Each reader turns bytes into a [`RawShape`] and
//! checks what only it can check with a precise location (syntax, finite coordinates, index ranges);
//! [`crate::geometry::validate`] repairs and reports. Readers never panic on any input: every length and count
//! read from a file is checked against the bytes that are really there before it is used.

mod gltf;
mod gmsh;
mod json;
pub mod matrix;
mod medit;
pub mod mtx;
pub mod npy;
mod obj;
mod off;
mod ply;
mod stl;
pub(crate) mod text;
mod vtk;
pub mod write;
mod xyz;

use crate::error::{Result, ShapeError};
use crate::geometry::RawShape;
use serde::Serialize;
use std::path::Path;

/// An input format.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Obj,
    Off,
    Ply,
    Stl,
    Gltf,
    Glb,
    /// Medit `.mesh` (INRIA), ASCII.
    Medit,
    /// Gmsh `.msh`, versions 2.2 and 4.1, ASCII and binary; data, entity and comment sections are skipped.
    Gmsh,
    /// Legacy VTK, ASCII.
    Vtk,
    /// Whitespace-separated point coordinates (2 or 3 columns, 6 with normals, 4 or more: points in Rⁿ).
    Xyz,
    /// Comma-separated point coordinates (as `xyz`, with an optional header line).
    Csv,
    /// kac's JSON: vertices with faces, tets, edges (+ weights), segments, or nothing (points).
    Json,
    /// Matrix Market coordinate matrix read as a weighted graph's adjacency.
    Mtx,
    /// NumPy `.npy`: an (N × n) float64 or float32 array of N points in Rⁿ (n = 2, 3 or more).
    Npy,
}

impl Format {
    /// Every format's name, comma-separated, in the order of [`Format::ALL`] (for messages that list them).
    pub fn names() -> String {
        Format::ALL.iter().map(|f| f.name()).collect::<Vec<_>>().join(", ")
    }
    pub const ALL: [Format; 14] = [
        Format::Obj,
        Format::Off,
        Format::Ply,
        Format::Stl,
        Format::Gltf,
        Format::Glb,
        Format::Medit,
        Format::Gmsh,
        Format::Vtk,
        Format::Xyz,
        Format::Csv,
        Format::Json,
        Format::Mtx,
        Format::Npy,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Format::Obj => "obj",
            Format::Off => "off",
            Format::Ply => "ply",
            Format::Stl => "stl",
            Format::Gltf => "gltf",
            Format::Glb => "glb",
            Format::Medit => "medit",
            Format::Gmsh => "gmsh",
            Format::Vtk => "vtk",
            Format::Xyz => "xyz",
            Format::Csv => "csv",
            Format::Json => "json",
            Format::Mtx => "mtx",
            Format::Npy => "npy",
        }
    }

    /// A format by name or file extension (case-insensitive): `obj`, `off`, `ply`, `stl`, `gltf`, `glb`,
    /// `mesh`/`medit`, `msh`/`gmsh`, `vtk`, `xyz`/`pts`/`txt`, `csv`, `json`, `mtx`, `npy`.
    pub fn from_name(name: &str) -> Option<Format> {
        let n = name.trim().trim_start_matches('.').to_ascii_lowercase();
        Some(match n.as_str() {
            "obj" => Format::Obj,
            "off" | "coff" | "noff" | "4off" => Format::Off,
            "ply" => Format::Ply,
            "stl" => Format::Stl,
            "gltf" => Format::Gltf,
            "glb" => Format::Glb,
            "mesh" | "medit" => Format::Medit,
            "msh" | "gmsh" => Format::Gmsh,
            "vtk" => Format::Vtk,
            "xyz" | "pts" | "txt" => Format::Xyz,
            "csv" => Format::Csv,
            "json" => Format::Json,
            "mtx" => Format::Mtx,
            "npy" => Format::Npy,
            _ => return None,
        })
    }

    /// A format from a media type (as sent in `Content-Type`), where one is registered or customary.
    pub fn from_media_type(media_type: &str) -> Option<Format> {
        let essence = media_type.split(';').next()?.trim().to_ascii_lowercase();
        Some(match essence.as_str() {
            "model/obj" | "text/x-obj" => Format::Obj,
            "model/x-off" | "text/x-off" => Format::Off,
            "model/x-ply" | "application/x-ply" | "application/ply" => Format::Ply,
            "model/stl" | "model/x.stl-binary" | "model/x.stl-ascii" | "application/sla" => Format::Stl,
            "model/gltf+json" => Format::Gltf,
            "model/gltf-binary" => Format::Glb,
            "text/csv" => Format::Csv,
            "application/json" => Format::Json,
            "model/vnd.medit-mesh" => Format::Medit,
            "model/vnd.gmsh" => Format::Gmsh,
            "model/vnd.vtk" => Format::Vtk,
            _ => {
                let sub = essence.rsplit('/').next()?;
                return Format::from_name(sub.trim_start_matches("x-"));
            }
        })
    }

    /// Guesses the format from the first bytes (and, for STL, the length).
    pub fn sniff(bytes: &[u8]) -> Option<Format> {
        if bytes.starts_with(b"glTF") {
            return Some(Format::Glb);
        }
        if bytes.starts_with(b"\x93NUMPY") {
            return Some(Format::Npy);
        }
        if stl::is_binary_by_size(bytes) {
            return Some(Format::Stl);
        }
        let head = &bytes[..bytes.len().min(4096)];
        let s = String::from_utf8_lossy(head);
        let trimmed = s.trim_start_matches('\u{feff}').trim_start();
        if trimmed.starts_with("ply") {
            return Some(Format::Ply);
        }
        // Gmsh files open with $MeshFormat, or with a comment section before it.
        if trimmed.starts_with("$MeshFormat")
            || (trimmed.starts_with('$') && trimmed.lines().any(|l| l.trim_end() == "$MeshFormat"))
        {
            return Some(Format::Gmsh);
        }
        if trimmed.starts_with("# vtk") {
            return Some(Format::Vtk);
        }
        if trimmed.starts_with("%%MatrixMarket") {
            return Some(Format::Mtx);
        }
        if trimmed.starts_with('{') {
            return Some(if trimmed.contains("\"asset\"") { Format::Gltf } else { Format::Json });
        }
        // Past the formats with a text header, bytes that are not text (a NUL, or invalid UTF-8 before the cut at
        // 4096) are a binary STL (the one headerless binary mesh format: its reader names a truncation) or nothing
        // known; never a text format guessed from noise.
        let invalid = std::str::from_utf8(head).err().is_some_and(|e| e.error_len().is_some());
        if head.contains(&0) || invalid {
            return (bytes.len() >= 84).then_some(Format::Stl);
        }
        // First meaningful line, past comments.
        let first = trimmed.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#'))?;
        let word = first.split_whitespace().next().unwrap_or("");
        if word.ends_with("OFF") && word.len() <= 6 {
            return Some(Format::Off);
        }
        if word.eq_ignore_ascii_case("MeshVersionFormatted") {
            return Some(Format::Medit);
        }
        if word.eq_ignore_ascii_case("solid") {
            return Some(Format::Stl);
        }
        let obj_words = ["v", "vt", "vn", "f", "o", "g", "s", "l", "mtllib", "usemtl", "vp", "p"];
        if obj_words.contains(&word) {
            return Some(Format::Obj);
        }
        if first.contains(',') {
            return Some(Format::Csv);
        }
        if first.split_whitespace().all(|t| t.parse::<f64>().is_ok()) {
            return Some(Format::Xyz);
        }
        None
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How to read: welding and limits that apply while parsing.
#[derive(Debug, Clone)]
pub struct ReadOptions {
    /// Refuse inputs that declare or contain more vertices than this (checked before allocating).
    pub max_vertices: usize,
    /// Refuse inputs with more elements (faces, tets, segments) than this.
    pub max_elements: usize,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions { max_vertices: 50_000_000, max_elements: 100_000_000 }
    }
}

impl ReadOptions {
    pub(crate) fn check_vertices(&self, n: u64) -> Result<()> {
        if n > self.max_vertices as u64 {
            return Err(ShapeError::LimitExceeded {
                what: "vertex count".into(),
                value: n,
                limit: self.max_vertices as u64,
            });
        }
        Ok(())
    }
    pub(crate) fn check_elements(&self, n: u64) -> Result<()> {
        if n > self.max_elements as u64 {
            return Err(ShapeError::LimitExceeded {
                what: "element count".into(),
                value: n,
                limit: self.max_elements as u64,
            });
        }
        Ok(())
    }
}

/// Chooses a format: an explicit name wins, then the file extension, then the content.
pub fn choose_format(explicit: Option<Format>, path: Option<&Path>, bytes: &[u8]) -> Result<Format> {
    if let Some(f) = explicit {
        return Ok(f);
    }
    if let Some(ext) = path.and_then(|p| p.extension()).and_then(|e| e.to_str()) {
        if let Some(f) = Format::from_name(ext) {
            return Ok(f);
        }
    }
    Format::sniff(bytes).ok_or_else(|| ShapeError::UnknownFormat {
        message: format!("no format given and the content matches none of: {}", Format::names()),
    })
}

/// Reads bytes in the given format.
pub fn read_bytes(bytes: &[u8], format: Format, options: &ReadOptions) -> Result<RawShape> {
    read_as(bytes, format, options).map_err(|e| match Format::sniff(bytes) {
        // The reader's error is about the wrong grammar when the bytes are plainly another format (OFF sent as
        // STL read a text line as a triangle count of 856 million): say which format was tried and what the
        // bytes look like instead.
        Some(other) if other != format && !same_reader(format, other) => ShapeError::FormatMismatch {
            tried: format.name(),
            looks_like: other.name(),
            head: head_of(bytes),
            reason: e.to_string(),
        },
        _ => e,
    })
}

/// Formats one reader takes, whose content sniffing cannot tell apart.
fn same_reader(a: Format, b: Format) -> bool {
    use Format::*;
    matches!((a, b), (Gltf, Glb) | (Glb, Gltf) | (Xyz, Csv) | (Csv, Xyz))
}

/// How the bytes begin, for error messages: up to 24 characters of text (escaped), or the first bytes in hex.
pub fn head_of(bytes: &[u8]) -> String {
    let head = &bytes[..bytes.len().min(24)];
    let text = head.iter().all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace());
    if text {
        format!("{:?}", String::from_utf8_lossy(head))
    } else {
        let hex: Vec<String> = bytes.iter().take(12).map(|b| format!("{b:02x}")).collect();
        format!("with the bytes {}", hex.join(" "))
    }
}

fn read_as(bytes: &[u8], format: Format, options: &ReadOptions) -> Result<RawShape> {
    match format {
        Format::Obj => obj::read(bytes, options),
        Format::Off => off::read(bytes, options),
        Format::Ply => ply::read(bytes, options),
        Format::Stl => stl::read(bytes, options),
        Format::Gltf | Format::Glb => gltf::read(bytes, options),
        Format::Medit => medit::read(bytes, options),
        Format::Gmsh => gmsh::read(bytes, options),
        Format::Vtk => vtk::read(bytes, options),
        Format::Xyz => xyz::read(bytes, options, false),
        Format::Csv => xyz::read(bytes, options, true),
        Format::Json => json::read(bytes, options),
        Format::Mtx => mtx::read_graph(bytes, options),
        Format::Npy => npy::read_points(bytes, options),
    }
}

/// Reads a file; the format comes from `explicit`, the extension or the content.
pub fn read_path(path: &Path, explicit: Option<Format>, options: &ReadOptions) -> Result<(RawShape, Format)> {
    let bytes =
        std::fs::read(path).map_err(|e| ShapeError::Io { path: path.display().to_string(), message: e.to_string() })?;
    let format = choose_format(explicit, Some(path), &bytes)?;
    Ok((read_bytes(&bytes, format, options)?, format))
}

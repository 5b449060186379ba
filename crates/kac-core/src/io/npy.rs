//! NumPy `.npy` (format version 1.0) for per-vertex arrays: little-endian f64, C order, shape (rows, cols); and
//! as an input format, an (N × n) array of points in Rⁿ.

use super::ReadOptions;
use crate::error::{Location, Result, ShapeError};
use crate::geometry::{Ambient, RawShape};

/// An (N × n) array as a point cloud: n = 2 (the plane), 3, or more (points in Rⁿ).
pub fn read_points(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let (rows, cols, data) = decode_f64(bytes).map_err(|message| ShapeError::Syntax {
        format: "npy",
        location: Location::Unknown,
        message,
    })?;
    options.check_vertices(rows as u64)?;
    if rows == 0 {
        return Err(ShapeError::Empty { what: "the npy array has no rows (points)".into() });
    }
    if cols < 2 {
        return Err(ShapeError::Syntax {
            format: "npy",
            location: Location::Unknown,
            message: format!("an ({rows} × {cols}) array; points need 2 or more coordinates per row"),
        });
    }
    let mut raw = RawShape { planar_input: cols == 2, ..Default::default() };
    raw.vertices.reserve(rows);
    for (i, r) in data.chunks_exact(cols).enumerate() {
        if let Some(j) = r.iter().position(|v| !v.is_finite()) {
            return Err(ShapeError::NonFinite {
                element: crate::error::Element::Vertex,
                index: i,
                value: format!("coordinate {}: {}", j + 1, r[j]),
                location: Location::Unknown,
            });
        }
        raw.vertices.push([r[0], r[1], if cols >= 3 { r[2] } else { 0.0 }]);
    }
    if cols >= 4 {
        raw.notes.push(format!("npy: {cols} coordinates per point: a point cloud in R^{cols}"));
        raw.ambient = Some(Ambient { dim: cols, coords: data });
    }
    Ok(raw)
}

/// The bytes of an .npy file holding `data` (row-major, rows × cols).
pub fn encode_f64(rows: usize, cols: usize, data: &[f64]) -> Vec<u8> {
    assert_eq!(data.len(), rows * cols, "npy: data does not match its shape");
    let mut out = header_f64(rows, cols);
    out.reserve(8 * data.len());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The header of a version 1.0 `.npy` of (rows × cols) little-endian f64 in C order: what [`encode_f64`] writes
/// before the data, for writers that send the data after it in pieces.
pub fn header_f64(rows: usize, cols: usize) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64, ending in \n.
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out
}

/// Reads a version 1.0–3.0 `.npy` holding little-endian f64 (`<f8`) or f32 (`<f4`) in C order, 1-D or 2-D:
/// returns (rows, cols, row-major data). Errors say what is unsupported.
pub fn decode_f64(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not an .npy file (no \\x93NUMPY magic)".into());
    }
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let header = bytes.get(start..start + hlen).ok_or("the .npy header is cut short")?;
    let header = std::str::from_utf8(header).map_err(|_| "the .npy header is not text")?;
    let field = |key: &str| -> Option<&str> {
        let i = header.find(&format!("'{key}'"))?;
        let rest = &header[i + key.len() + 2..];
        Some(rest.trim_start().strip_prefix(':')?.trim_start())
    };
    let descr = field("descr").ok_or("the .npy header has no descr")?;
    let width = if descr.starts_with("'<f8'") {
        8
    } else if descr.starts_with("'<f4'") {
        4
    } else {
        return Err(format!("unsupported .npy dtype {}", descr.split(',').next().unwrap_or("")));
    };
    if field("fortran_order").is_some_and(|f| f.starts_with("True")) {
        return Err("Fortran-ordered .npy arrays are not supported; save with C order".into());
    }
    let shape = field("shape").ok_or("the .npy header has no shape")?;
    let inner = shape.strip_prefix('(').and_then(|s| s.split(')').next()).ok_or("malformed .npy shape")?;
    let dims: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| format!("malformed .npy shape ({inner})")))
        .collect::<Result<_, _>>()?;
    let (rows, cols) = match dims.as_slice() {
        [r] => (*r, 1),
        [r, c] => (*r, *c),
        _ => return Err(format!("only 1-D and 2-D .npy arrays are supported, not shape ({inner})")),
    };
    let count = rows.checked_mul(cols).ok_or("the .npy shape overflows")?;
    let body = &bytes[start + hlen..];
    if body.len() != count * width {
        return Err(format!("the .npy data holds {} bytes, its shape needs {}", body.len(), count * width));
    }
    let data = if width == 8 {
        body.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8]))).collect()
    } else {
        body.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64).collect()
    };
    Ok((rows, cols, data))
}

//! glTF 2.0: `.gltf` with embedded (data-URI) buffers and binary `.glb`. Every triangle primitive
//! (`TRIANGLES`, `TRIANGLE_STRIP`, `TRIANGLE_FAN`) of every node of the default scene (or of every root node when
//! no scene is given) is read with its node's global transform applied; primitives of points or lines are
//! rejected, naming the mesh and primitive. glTF splits vertices wherever normals or UVs differ; validation welds
//! them by position unless told not to. Accessors are decoded here with every offset checked against the buffer.

use super::ReadOptions;
use crate::error::{Location, Result, ShapeError};
use crate::geometry::{Polygons, RawShape};
use base64::Engine;
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

const FMT: &str = "gltf";

fn syntax(pointer: String, message: impl Into<String>) -> ShapeError {
    ShapeError::Syntax { format: FMT, location: Location::pointer(pointer), message: message.into() }
}

fn unsupported(pointer: String, message: impl Into<String>) -> ShapeError {
    ShapeError::Unsupported { format: FMT, location: Location::pointer(pointer), message: message.into() }
}

type Mat4 = [[f64; 4]; 4]; // column-major: m[col][row]

fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut c = [[0.0; 4]; 4];
    for (j, cj) in c.iter_mut().enumerate() {
        for (i, cij) in cj.iter_mut().enumerate() {
            *cij = (0..4).map(|k| a[k][i] * b[j][k]).sum();
        }
    }
    c
}

const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// Splits a GLB container into its JSON chunk and optional BIN chunk, with every length checked. Done here:
/// gltf 1.4.1's `Glb::from_slice` subtracts the header size from the declared length unchecked (a panic on a
/// declared length below 12, found by fuzzing).
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>)> {
    let err =
        |offset: usize, message: String| ShapeError::Syntax { format: FMT, location: Location::byte(offset), message };
    let u32_at = |o: usize| -> Result<usize> {
        bytes.get(o..o + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize).ok_or_else(|| {
            ShapeError::Truncated {
                format: FMT,
                location: Location::byte(o),
                message: "the GLB data ends inside a header".into(),
            }
        })
    };
    let version = u32_at(4)?;
    if version != 2 {
        return Err(ShapeError::Unsupported {
            format: FMT,
            location: Location::byte(4),
            message: format!("GLB version {version}; glTF 2.0 is taken"),
        });
    }
    let length = u32_at(8)?;
    if length < 20 || length > bytes.len() {
        return Err(err(8, format!("declared length {length} does not fit the {} bytes given", bytes.len())));
    }
    let data = &bytes[..length];
    let chunk = |o: usize| -> Result<Option<(&[u8], [u8; 4])>> {
        if o >= data.len() {
            return Ok(None);
        }
        let len = u32_at(o)?;
        let kind = bytes.get(o + 4..o + 8).ok_or_else(|| err(o + 4, "truncated chunk header".into()))?;
        let body = o.checked_add(8).and_then(|s| s.checked_add(len).map(|e| (s, e))).filter(|&(_, e)| e <= data.len());
        let (s, e) = body.ok_or_else(|| err(o, format!("chunk of {len} bytes runs past the end")))?;
        Ok(Some((&data[s..e], [kind[0], kind[1], kind[2], kind[3]])))
    };
    let (json, kind) = chunk(12)?.ok_or_else(|| err(12, "no JSON chunk".into()))?;
    if &kind != b"JSON" {
        return Err(err(16, "the first chunk must be JSON".into()));
    }
    let next = (12 + 8 + json.len()).next_multiple_of(4);
    let bin = match chunk(next)? {
        Some((b, k)) if &k == b"BIN\0" => Some(b),
        _ => None,
    };
    Ok((json, bin))
}

/// Checks that every accessor a primitive names exists. gltf-json 1.4.1 indexes `accessors` with the POSITION
/// index inside its own validation without a bounds check (a panic on such files); this runs first.
fn check_accessor_references(json: &[u8]) -> Result<()> {
    let v: serde_json::Value = serde_json::from_slice(json).map_err(|e| ShapeError::Syntax {
        format: FMT,
        location: if e.line() > 0 { Location::line(e.line()) } else { Location::Unknown },
        message: format!("invalid JSON: {e}"),
    })?;
    let accessors = v.get("accessors").and_then(|a| a.as_array()).map_or(0, |a| a.len());
    let meshes = v.get("meshes").and_then(|m| m.as_array()).cloned().unwrap_or_default();
    for (mi, mesh) in meshes.iter().enumerate() {
        let prims = mesh.get("primitives").and_then(|p| p.as_array()).cloned().unwrap_or_default();
        for (pi, prim) in prims.iter().enumerate() {
            let mut refs: Vec<(String, &serde_json::Value)> = Vec::new();
            if let Some(attrs) = prim.get("attributes").and_then(|a| a.as_object()) {
                refs.extend(attrs.iter().map(|(k, v)| (format!("attributes/{k}"), v)));
            }
            if let Some(i) = prim.get("indices") {
                refs.push(("indices".into(), i));
            }
            for (path, r) in refs {
                let ok = r.as_u64().is_some_and(|i| (i as usize) < accessors);
                if !ok {
                    return Err(syntax(
                        format!("/meshes/{mi}/primitives/{pi}/{path}"),
                        format!("refers to accessor {r}, but the document has {accessors}"),
                    ));
                }
            }
        }
    }
    Ok(())
}

pub fn read(bytes: &[u8], options: &ReadOptions) -> Result<RawShape> {
    let (json, bin) = if bytes.starts_with(b"glTF") { split_glb(bytes)? } else { (bytes, None) };
    check_accessor_references(json)?;
    // Backstop: any other panic inside the gltf crate's parsing becomes a typed error, never a crash.
    let parsed = std::panic::catch_unwind(|| gltf::Gltf::from_slice(json)).map_err(|_| ShapeError::Syntax {
        format: FMT,
        location: Location::Unknown,
        message: "the glTF document is internally inconsistent".into(),
    })?;
    let mut doc = parsed.map_err(|e| ShapeError::Syntax {
        format: FMT,
        location: Location::Unknown,
        message: format!("not a valid glTF 2.0 document: {e}"),
    })?;
    doc.blob = bin.map(|b| b.to_vec());
    // Buffers: the GLB BIN chunk or data URIs.
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    for buffer in doc.buffers() {
        let ptr = format!("/buffers/{}", buffer.index());
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => doc
                .blob
                .clone()
                .ok_or_else(|| syntax(ptr.clone(), "the buffer refers to a GLB BIN chunk, but there is none"))?,
            gltf::buffer::Source::Uri(uri) => {
                let Some(rest) = uri.strip_prefix("data:") else {
                    return Err(unsupported(ptr, format!("external buffer '{uri}': only embedded (data URI) buffers and .glb are taken; pack the file as .glb")));
                };
                let (meta, payload) = rest.split_once(',').ok_or_else(|| syntax(ptr.clone(), "malformed data URI"))?;
                if !meta.ends_with(";base64") {
                    return Err(unsupported(ptr, "data URI without base64 encoding"));
                }
                base64::engine::general_purpose::STANDARD
                    .decode(payload.trim())
                    .map_err(|e| syntax(ptr.clone(), format!("invalid base64 in data URI: {e}")))?
            }
        };
        if data.len() < buffer.length() {
            return Err(ShapeError::Truncated {
                format: FMT,
                location: Location::pointer(ptr),
                message: format!("the buffer declares {} bytes but holds {}", buffer.length(), data.len()),
            });
        }
        buffers.push(data);
    }

    let roots: Vec<gltf::Node<'_>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    let mut raw = RawShape::default();
    let mut polygons = Polygons::default();
    let mut stack: Vec<(gltf::Node<'_>, Mat4, usize)> = roots.into_iter().map(|n| (n, IDENTITY, 0)).collect();
    let mut instances = 0usize;
    let mut visits = 0usize;
    while let Some((node, parent, depth)) = stack.pop() {
        visits += 1;
        if depth > 256 || visits > 1_000_000 {
            return Err(syntax(format!("/nodes/{}", node.index()), "the node hierarchy is too deep or cyclic"));
        }
        let local: Mat4 = node.transform().matrix().map(|c| c.map(f64::from));
        let global = mul(&parent, &local);
        if let Some(mesh) = node.mesh() {
            instances += 1;
            for prim in mesh.primitives() {
                read_primitive(&buffers, &mesh, &prim, &global, &mut raw, &mut polygons, options)?;
            }
        }
        for child in node.children() {
            stack.push((child, global, depth + 1));
        }
    }
    raw.notes.push(format!(
        "gltf: {instances} mesh instance(s) read with node transforms applied; vertices are not welded by the format"
    ));
    raw.polygons = polygons;
    Ok(raw)
}

/// The bytes of an accessor's elements: (data, stride, element size), checked against the buffer.
fn accessor_bytes<'b>(
    buffers: &'b [Vec<u8>],
    acc: &gltf::Accessor<'_>,
    elem: usize,
    ptr: &str,
) -> Result<(&'b [u8], usize)> {
    if acc.sparse().is_some() {
        return Err(unsupported(ptr.to_string(), "sparse accessors are not supported"));
    }
    let view = acc.view().ok_or_else(|| unsupported(ptr.to_string(), "accessor without a buffer view"))?;
    let buf = buffers
        .get(view.buffer().index())
        .ok_or_else(|| syntax(ptr.to_string(), "buffer view refers to a missing buffer"))?;
    let start = view.offset();
    let len = view.length();
    let view_bytes =
        start.checked_add(len).and_then(|end| buf.get(start..end)).ok_or_else(|| ShapeError::Truncated {
            format: FMT,
            location: Location::pointer(format!("/bufferViews/{}", view.index())),
            message: "the buffer view lies outside its buffer".into(),
        })?;
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(syntax(ptr.to_string(), format!("byteStride {stride} is smaller than the element size {elem}")));
    }
    let count = acc.count();
    if count == 0 {
        return Ok((&[], stride));
    }
    let need =
        (count - 1).checked_mul(stride).and_then(|n| n.checked_add(elem)).and_then(|n| n.checked_add(acc.offset()));
    match need {
        Some(end) if end <= view_bytes.len() => Ok((&view_bytes[acc.offset()..end], stride)),
        _ => Err(ShapeError::Truncated {
            format: FMT,
            location: Location::pointer(ptr.to_string()),
            message: format!("{count} elements do not fit in the buffer view"),
        }),
    }
}

fn read_primitive(
    buffers: &[Vec<u8>],
    mesh: &gltf::Mesh<'_>,
    prim: &gltf::Primitive<'_>,
    m: &Mat4,
    raw: &mut RawShape,
    polygons: &mut Polygons,
    options: &ReadOptions,
) -> Result<()> {
    let pptr = format!("/meshes/{}/primitives/{}", mesh.index(), prim.index());
    let mode = prim.mode();
    if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
        return Err(unsupported(
            pptr,
            format!("primitive mode {mode:?} is not a triangle primitive; kac reads triangle meshes from glTF"),
        ));
    }
    let pos = prim
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| syntax(pptr.clone(), "the primitive has no POSITION attribute"))?;
    let aptr = format!("/accessors/{}", pos.index());
    if pos.dimensions() != Dimensions::Vec3 || pos.data_type() != DataType::F32 || pos.normalized() {
        return Err(unsupported(aptr, "POSITION must be VEC3 of FLOAT (quantized positions are not supported)"));
    }
    let (data, stride) = accessor_bytes(buffers, &pos, 12, &aptr)?;
    let base = raw.vertices.len();
    options.check_vertices((base + pos.count()) as u64)?;
    raw.vertices.reserve(pos.count());
    for i in 0..pos.count() {
        let o = i * stride;
        let f = |k: usize| {
            f32::from_le_bytes([data[o + 4 * k], data[o + 4 * k + 1], data[o + 4 * k + 2], data[o + 4 * k + 3]]) as f64
        };
        let p = [f(0), f(1), f(2)];
        let q = [0, 1, 2].map(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r]);
        let w = m[0][3] * p[0] + m[1][3] * p[1] + m[2][3] * p[2] + m[3][3];
        let q = if w != 1.0 && w != 0.0 { q.map(|c| c / w) } else { q };
        let vi = raw.vertices.len();
        raw.vertices.push(super::text::check_point(q, vi, || Location::pointer(format!("{aptr}/{i}")))?);
    }
    let n = pos.count();
    let indices: Vec<u32> = match prim.indices() {
        Some(acc) => {
            let iptr = format!("/accessors/{}", acc.index());
            if acc.dimensions() != Dimensions::Scalar {
                return Err(syntax(iptr, "indices must be SCALAR"));
            }
            let size = match acc.data_type() {
                DataType::U8 => 1,
                DataType::U16 => 2,
                DataType::U32 => 4,
                other => return Err(syntax(iptr, format!("index component type {other:?} is not allowed"))),
            };
            let (d, stride) = accessor_bytes(buffers, &acc, size, &iptr)?;
            let mut out = Vec::with_capacity(acc.count());
            for i in 0..acc.count() {
                let o = i * stride;
                let v = match size {
                    1 => d[o] as u32,
                    2 => u16::from_le_bytes([d[o], d[o + 1]]) as u32,
                    _ => u32::from_le_bytes([d[o], d[o + 1], d[o + 2], d[o + 3]]),
                };
                if v as usize >= n {
                    return Err(ShapeError::IndexOutOfRange {
                        element: crate::error::Element::Face,
                        index: i / 3,
                        value: v as i64,
                        vertex_count: n,
                        location: Location::pointer(format!("{iptr}/{i}")),
                    });
                }
                out.push(v);
            }
            out
        }
        None => (0..n as u32).collect(),
    };
    let b = base as u32;
    let mut push = |t: [u32; 3]| polygons.push(&[t[0] + b, t[1] + b, t[2] + b]);
    match mode {
        Mode::Triangles => {
            if !indices.len().is_multiple_of(3) {
                return Err(syntax(pptr, format!("{} indices is not a multiple of 3", indices.len())));
            }
            indices.chunks_exact(3).for_each(|t| push([t[0], t[1], t[2]]));
        }
        Mode::TriangleStrip => {
            for i in 2..indices.len() {
                let t = if i % 2 == 0 {
                    [indices[i - 2], indices[i - 1], indices[i]]
                } else {
                    [indices[i - 1], indices[i - 2], indices[i]]
                };
                push(t);
            }
        }
        _ => {
            for i in 2..indices.len() {
                push([indices[0], indices[i - 1], indices[i]]);
            }
        }
    }
    options.check_elements(polygons.len() as u64)?;
    Ok(())
}

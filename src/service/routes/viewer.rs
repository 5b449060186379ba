//! The viewer at `/`: a small web page (plain JavaScript modules and WebGL2, `web/`) embedded in the binary at
//! build time, so it works offline; it talks only to the public `/v1` API. `/v1/shapes/{id}/geometry` gives it a
//! shape's geometry in a compact binary form.

use super::*;

/// The viewer's files: name, content type, text.
const FILES: &[(&str, &str, &str)] = &[
    ("index.html", "text/html; charset=utf-8", include_str!("../../../web/index.html")),
    ("app.js", "text/javascript; charset=utf-8", include_str!("../../../web/app.js")),
    ("render.js", "text/javascript; charset=utf-8", include_str!("../../../web/render.js")),
    ("plot.js", "text/javascript; charset=utf-8", include_str!("../../../web/plot.js")),
    ("style.css", "text/css; charset=utf-8", include_str!("../../../web/style.css")),
];

fn file(name: &str) -> Response {
    match FILES.iter().find(|f| f.0 == name) {
        Some((_, ct, body)) => {
            let mut r = (StatusCode::OK, *body).into_response();
            r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(ct));
            // The page and its scripts come from this server only.
            r.headers_mut().insert(
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(
                    "default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; frame-ancestors 'none'",
                ),
            );
            r.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
            r
        }
        None => ApiError::RouteNotFound { path: format!("/viewer/{name}") }.into_response(),
    }
}

/// The viewer.
pub(crate) async fn viewer_index() -> Response {
    file("index.html")
}

/// The viewer's scripts and style sheet.
pub(crate) async fn viewer_file(Path(name): Path<String>) -> Response {
    file(&name)
}

/// A shape's geometry for drawing, in one binary: a little-endian u32 with the length of a JSON header
/// (`{"kind", "vertices", "triangles", "segments", "input_rows"}`), the header, padding to 4 bytes, then
/// `vertices` × 3 float32 positions, `triangles` × 3 u32 vertex indices (a tet mesh's boundary faces; none for
/// point clouds), `segments` × 2 u32 (curves, and graphs drawn by their edges), and `input_rows` u32: for each
/// vertex of the upload (the rows of every per-vertex array), its index here, or 4294967295 where validation
/// dropped it. A graph without vertex positions has nothing to draw (422 `not-applicable`).
#[utoipa::path(get, path = "/v1/shapes/{id}/geometry", tag = "shapes", params(("id" = String, Path)),
    responses((status = 200, description = "the geometry (binary, see the description)", content_type = "application/octet-stream"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 422, description = "a graph without vertex positions", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn get_geometry(State(st): State<AppState>, ShapePath(id): ShapePath) -> Result<Response, ApiError> {
    let shape = st.shapes.get(&id).map_err(store_error)?.ok_or(ApiError::NotFound { what: "shape", id: id.hex() })?;
    // Building the binary is work proportional to the shape (a tet mesh's boundary is found by sorting its
    // faces): off the runtime's threads.
    let out = tokio::task::spawn_blocking(move || geometry(&shape))
        .await
        .map_err(|e| ApiError::Internal { detail: e.to_string() })??;
    Ok(out)
}

fn geometry(shape: &StoredShape) -> Result<Response, ApiError> {
    let v = &shape.validated;
    let (points, triangles, segments): (&[[f64; 3]], Vec<u32>, Vec<u32>) = match &v.shape {
        kac_core::Shape::TriangleMesh(m) => (&m.vertices, m.faces.iter().flatten().copied().collect(), vec![]),
        kac_core::Shape::TetMesh(m) => (&m.vertices, boundary_faces(&m.tets), vec![]),
        kac_core::Shape::PointCloud(c) => (&c.points, vec![], vec![]),
        kac_core::Shape::Polyline(p) => (&p.vertices, vec![], p.segments.iter().flatten().copied().collect()),
        kac_core::Shape::Graph(g) => match &g.positions {
            Some(p) => (p, vec![], g.edges.iter().flatten().copied().collect()),
            None => {
                return Err(ApiError::Analysis(analysis::AnalysisError::not_applicable(
                    "this graph has no vertex positions to draw",
                )))
            }
        },
    };
    let head = serde_json::to_vec(&json!({
        "kind": v.shape.kind().as_str(),
        "vertices": points.len(),
        "triangles": triangles.len() / 3,
        "segments": segments.len() / 2,
        "input_rows": v.vertex_map.len(),
    }))
    .unwrap_or_default();
    let mut out = Vec::with_capacity(8 + head.len() + 12 * points.len() + 4 * (triangles.len() + segments.len()));
    out.extend_from_slice(&(head.len() as u32).to_le_bytes());
    out.extend_from_slice(&head);
    while out.len() % 4 != 0 {
        out.push(b' ');
    }
    for p in points {
        for c in p {
            out.extend_from_slice(&(*c as f32).to_le_bytes());
        }
    }
    for i in triangles.iter().chain(&segments).chain(&v.vertex_map) {
        out.extend_from_slice(&i.to_le_bytes());
    }
    let etag = format!("\"{}-geometry\"", id_tag(&shape.id));
    let mut r = (StatusCode::OK, out).into_response();
    r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("application/octet-stream"));
    Ok(immutable(r, &etag))
}

fn id_tag(id: &str) -> String {
    id.chars().filter(|c| c.is_ascii_alphanumeric()).take(32).collect()
}

/// The faces of a tet mesh that belong to one tetrahedron only (its boundary), outward for positively oriented
/// tetrahedra.
fn boundary_faces(tets: &[[u32; 4]]) -> Vec<u32> {
    // Every face with its sorted corners as the key; a face met once is on the boundary.
    let mut faces: Vec<([u32; 3], [u32; 3])> = tets
        .iter()
        .flat_map(|t| [[t[1], t[2], t[3]], [t[0], t[3], t[2]], [t[0], t[1], t[3]], [t[0], t[2], t[1]]])
        .map(|f| {
            let mut key = f;
            key.sort_unstable();
            (key, f)
        })
        .collect();
    faces.sort_unstable_by_key(|f| f.0);
    let mut out = Vec::new();
    let mut i = 0;
    while i < faces.len() {
        let mut j = i + 1;
        while j < faces.len() && faces[j].0 == faces[i].0 {
            j += 1;
        }
        if j - i == 1 {
            out.extend_from_slice(&faces[i].1);
        }
        i = j;
    }
    out
}

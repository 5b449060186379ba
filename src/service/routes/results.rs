//! `/v1/results`: immutable results with strong ETags, their per-vertex arrays as `.npy`, JSON or coloured PLY.

use super::*;

#[derive(Deserialize, utoipa::IntoParams)]
pub struct ResultQuery {
    /// Include per-vertex values inline (default true; false gives the summary and the array links only).
    pub values: Option<bool>,
}

pub(crate) fn immutable(mut r: Response, etag: &str) -> Response {
    let h = r.headers_mut();
    if let Ok(v) = HeaderValue::from_str(etag) {
        h.insert(header::ETAG, v);
    }
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("public, max-age=31536000, immutable"));
    r
}

/// `If-None-Match` by the weak comparison RFC 9110 §13.1.2 prescribes: `W/"x"` matches `"x"`; every header line
/// and every member of a list counts; `*` matches any stored representation.
pub(crate) fn not_modified(headers: &HeaderMap, etag: &str) -> bool {
    let opaque = |t: &str| {
        let t = t.trim();
        t.strip_prefix("W/").unwrap_or(t).to_string()
    };
    let mine = opaque(etag);
    headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|t| t.trim() == "*" || opaque(t) == mine)
}

/// A result's body: the summary alone (`values=false`), the whole body kept in memory when small, else the
/// body written out chunk by chunk as it is sent (a large result is never held as text).
pub(crate) fn result_response(r: &Arc<StoredResult>, headers: &HeaderMap, values: bool) -> Response {
    let etag = if values { r.etag.clone() } else { format!("\"{}-summary\"", r.etag.trim_matches('"')) };
    if not_modified(headers, &etag) {
        return immutable(StatusCode::NOT_MODIFIED.into_response(), &etag);
    }
    let body = match (values, r.small_body()) {
        (false, _) => axum::body::Body::from(r.summary_body.clone()),
        (true, Some(b)) => axum::body::Body::from(b.clone()),
        (true, None) => axum::body::Body::from_stream(futures_util::stream::iter(
            r.clone().into_chunks().map(Ok::<_, std::convert::Infallible>),
        )),
    };
    let mut resp = (StatusCode::OK, body).into_response();
    resp.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json"));
    immutable(resp, &etag)
}

/// A finished result (immutable; strong ETag, `If-None-Match` → 304).
#[utoipa::path(get, path = "/v1/results/{id}", tag = "results", params(("id" = String, Path), ResultQuery),
    responses((status = 200, description = "the result JSON: every parameter used, the numbers, per-vertex arrays with .npy and .ply links", body = AnalysisResult),
              (status = 304, description = "not modified"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn get_result(
    State(st): State<AppState>,
    ResultPath(id, _): ResultPath,
    Query(q): Query<ResultQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let r = st.results.get(&id).map_err(store_error)?.ok_or(ApiError::NotFound { what: "result", id: id.hex() })?;
    Ok(result_response(&r, &headers, q.values.unwrap_or(true)))
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct ArrayQuery {
    /// PLY: which column colours the vertices (default 0).
    pub column: Option<usize>,
}

/// An array of a result: `NAME.npy` (float64, rows in the upload's vertex numbering), `NAME.json`, or
/// `NAME.ply` (the shape with one column as vertex colours, for viewing). The `operator` analysis' matrices
/// (`stiffness`, `mass`: upper-triangle triplets as .npy/.json) are also served whole as `NAME.mtx` (Matrix
/// Market, symmetric) and `NAME.npz` (`scipy.sparse.load_npz`, CSR), with rows and columns the operator's
/// unknowns (`unknown_vertices` maps them to vertices).
#[utoipa::path(get, path = "/v1/results/{id}/arrays/{file}", tag = "results",
    params(("id" = String, Path), ("file" = String, Path, description = "NAME.npy, NAME.json, NAME.ply; for matrices NAME.mtx or NAME.npz"), ArrayQuery),
    responses((status = 200, description = "the array: .npy (float64), .json (rows of numbers, null for NaN), .ply, .mtx or .npz",
               content((String = "application/octet-stream"), (Vec<Vec<Option<f64>>> = "application/json"),
                       (String = "application/x-ply"), (String = "text/plain"), (String = "application/zip"))),
              (status = 304, description = "not modified"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn get_array(
    State(st): State<AppState>,
    ResultPath(id, file): ResultPath,
    Query(q): Query<ArrayQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let file = file.unwrap_or_default();
    let r = st.results.get(&id).map_err(store_error)?.ok_or(ApiError::NotFound { what: "result", id: id.hex() })?;
    let (name, ext) = file.rsplit_once('.').ok_or(ApiError::NotFound { what: "array", id: file.clone() })?;
    let a = r.arrays.iter().find(|a| a.name == name).ok_or(ApiError::NotFound { what: "array", id: file.clone() })?;
    let col = q.column.unwrap_or(0);
    let etag = format!("\"{}-{name}-{ext}-{col}\"", r.etag.trim_matches('"'));
    if not_modified(&headers, &etag) {
        return Ok(immutable(StatusCode::NOT_MODIFIED.into_response(), &etag));
    }
    let stream = |chunks: Box<dyn Iterator<Item = Bytes> + Send>| {
        axum::body::Body::from_stream(futures_util::stream::iter(chunks.map(Ok::<_, std::convert::Infallible>)))
    };
    // Arrays are written out in pieces as they are sent, never whole beside their numbers.
    let i = r.arrays.iter().position(|x| x.name == a.name).unwrap_or(0);
    let (body, ct): (axum::body::Body, &'static str) = match ext {
        "npy" => (stream(Box::new(r.clone().array_npy_chunks(i))), "application/octet-stream"),
        "json" => (stream(Box::new(r.clone().array_json_chunks(i))), "application/json"),
        "mtx" | "npz" if analysis::MATRIX_ARRAYS.contains(&a.name) => {
            let n = r.summary["unknowns"].as_u64().unwrap_or(0) as usize;
            let comment = format!("kac: {} of result {}", a.name, r.id);
            let data = a.data.clone();
            let mtx = ext == "mtx";
            let bytes = tokio::task::spawn_blocking(move || {
                if mtx {
                    kac_core::io::matrix::matrix_market(n, &data, &comment)
                } else {
                    kac_core::io::matrix::npz_csr(n, &data)
                }
            })
            .await
            .map_err(|e| ApiError::Internal { detail: e.to_string() })?
            .map_err(|detail| ApiError::Internal { detail })?;
            (axum::body::Body::from(bytes), if mtx { "text/plain; charset=utf-8" } else { "application/zip" })
        }
        "ply" if analysis::is_per_vertex(a.name) => {
            if col >= a.cols {
                return Err(ApiError::invalid_request(format!("column {col} does not exist ({} columns)", a.cols)));
            }
            let shape = stored_shape(&st, r.summary["shape_id"].as_str().unwrap_or(""))?;
            (axum::body::Body::from(coloured_ply(&shape, a, col)), "application/x-ply")
        }
        _ => return Err(ApiError::NotFound { what: "array format", id: file }),
    };
    let mut resp = (StatusCode::OK, body).into_response();
    resp.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(ct));
    Ok(immutable(resp, &etag))
}

/// The validated shape as binary PLY with one array column mapped to colours (dark blue → yellow, a
/// viridis-like ramp over the finite range; NaN grey).
pub(crate) fn coloured_ply(shape: &StoredShape, a: &analysis::VertexArray, col: usize) -> Vec<u8> {
    let v = &shape.validated;
    let colours = kac_core::io::write::colour_ramp(&v.from_input_rows(&a.data, a.cols, col));
    kac_core::io::write::ply(&v.shape, true, Some(&colours))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn if_none_match_compares_weakly_over_every_member() {
        let etag = "\"abc\"";
        let h = |values: &[&str]| {
            let mut m = HeaderMap::new();
            for v in values {
                m.append(header::IF_NONE_MATCH, HeaderValue::from_str(v).unwrap());
            }
            not_modified(&m, etag)
        };
        for yes in [&["\"abc\""][..], &["W/\"abc\""], &["\"x\", W/\"abc\""], &["\"x\"", "\"abc\""], &["*"]] {
            assert!(h(yes), "{yes:?}");
        }
        for no in [&[][..], &["\"abcd\""], &["W/\"ab\""], &["abc"]] {
            assert!(!h(no), "{no:?}");
        }
    }
}

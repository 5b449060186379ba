//! `/v1/shapes`: uploads (raw or multipart, format by name, media type or content), parsing and validation on
//! the blocking pool, the atomic store; list, get, delete.

use super::*;

/// A stored shape.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ShapeResource {
    /// Content hash of the canonical geometry.
    pub id: String,
    /// The format it was read from.
    pub format: String,
    pub created_at: String,
    /// Size of the upload in bytes.
    pub bytes: usize,
    /// The validation summary (kind, counts, area, volume, topology, repairs), as `kac inspect` prints it.
    #[schema(value_type = kac_core::geometry::summary::Summary)]
    pub summary: Value,
    /// The tags it carries (sorted), which a search may be limited to.
    pub tags: Vec<String>,
    pub links: ShapeLinks,
}

/// Where a shape's related resources are.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ShapeLinks {
    /// `/v1/shapes/{id}`.
    #[serde(rename = "self")]
    pub self_: String,
    /// `/v1/jobs?shape_id={id}`: its jobs.
    pub jobs: String,
}

pub(crate) fn shape_resource(st: &AppState, s: &ShapeRecord) -> ShapeResource {
    ShapeResource {
        tags: st.index.tags_of(&s.id),
        id: s.id.clone(),
        format: s.format.clone(),
        created_at: s.created_at.clone(),
        bytes: s.bytes,
        summary: s.summary.clone(),
        links: ShapeLinks { self_: format!("/v1/shapes/{}", s.id), jobs: format!("/v1/jobs?shape_id={}", s.id) },
    }
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct UploadQuery {
    /// Format name; default: from the Content-Type, the multipart file name, or the content.
    #[param(value_type = Option<kac_core::io::Format>)]
    pub format: Option<String>,
    /// Tags to add to the shape, comma-separated (`tags=scan,customer:acme`); a shape already stored keeps its
    /// other tags.
    pub tags: Option<String>,
}

/// An upload: bytes, and what may tell their format.
pub(crate) struct Upload {
    bytes: Bytes,
    format: Option<Format>,
    filename: Option<String>,
    media_type: Option<String>,
    /// Other multipart text fields (the synchronous form reads `analysis` from here).
    pub(crate) fields: Vec<(String, String)>,
    /// Per-vertex inputs of the analysis sent as `.npy` parts, by field name ([`super::analyses::ARRAY_FIELDS`]).
    pub(crate) arrays: Vec<(String, Bytes)>,
}

impl Upload {
    /// A file as it is, its format from its name or its content.
    pub(crate) fn file(bytes: Bytes, filename: Option<String>) -> Upload {
        Upload { bytes, format: None, filename, media_type: None, fields: vec![], arrays: vec![] }
    }
}

pub(crate) fn parse_format(name: &str) -> Result<Format, ApiError> {
    Format::from_name(name)
        .ok_or_else(|| ApiError::invalid_request(format!("unknown format '{name}'; one of: {}", Format::names())))
}

pub(crate) async fn read_upload(st: &AppState, q_format: Option<String>, req: Request) -> Result<Upload, ApiError> {
    let ct = req.headers().get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("").to_string();
    let mut up = Upload {
        bytes: Bytes::new(),
        format: q_format.as_deref().map(parse_format).transpose()?,
        filename: None,
        media_type: None,
        fields: vec![],
        arrays: vec![],
    };
    if ct.to_ascii_lowercase().starts_with("multipart/form-data") {
        let mut mp = Multipart::from_request(req, st)
            .await
            .map_err(|e| ApiError::invalid_request(format!("multipart: {}", e.body_text())))?;
        let (mut got, mut format_part) = (false, false);
        loop {
            let field = match mp.next_field().await {
                Ok(Some(f)) => f,
                Ok(None) => break,
                Err(e) if crate::service::error::over_body_limit(e.status()) => {
                    return Err(ApiError::BodyTooLarge { limit: st.config.max_body_bytes })
                }
                Err(e) if timed_out(&e) => {
                    return Err(ApiError::BodyTimeout { seconds: st.config.body_read_timeout_s })
                }
                Err(e) if super::super::bodies::too_slow(&e).is_some() => {
                    return Err(ApiError::BodyTooSlow {
                        detail: super::super::bodies::too_slow(&e).unwrap_or_default(),
                    })
                }
                Err(e) => return Err(ApiError::invalid_request(format!("multipart: {}", e.body_text()))),
            };
            let name = field.name().unwrap_or("").to_string();
            let filename = field.file_name().map(str::to_string);
            let media = field.content_type().map(str::to_string);
            let data = field.bytes().await.map_err(|e| {
                if crate::service::error::over_body_limit(e.status()) {
                    ApiError::BodyTooLarge { limit: st.config.max_body_bytes }
                } else if timed_out(&e) {
                    ApiError::BodyTimeout { seconds: st.config.body_read_timeout_s }
                } else if let Some(detail) = super::super::bodies::too_slow(&e) {
                    ApiError::BodyTooSlow { detail }
                } else {
                    ApiError::invalid_request(format!("multipart: {}", e.body_text()))
                }
            })?;
            let named_before = up.arrays.iter().any(|(n, _)| *n == name) || up.fields.iter().any(|(n, _)| *n == name);
            let array = super::analyses::ARRAY_FIELDS.contains(&name.as_str());
            // A part named for a field (`analysis`, `format`) is that field even when sent as a file
            // (`-F analysis=@request.json`); any other part with a file name, or named `file` or `shape`, is the shape.
            let field_part = name == "analysis" || name == "format";
            let shape_part = !array && !field_part && (filename.is_some() || name == "file" || name == "shape");
            if got && shape_part {
                return Err(ApiError::InvalidParameter {
                    detail: format!(
                        "the multipart part `{name}` is a second file: send one shape per upload (many at once with \
                         /v1/shapes/bulk)"
                    ),
                    parameter: name,
                });
            }
            if named_before || (name == "format" && format_part) {
                // The second would silently replace the first, or be ignored.
                return Err(ApiError::InvalidParameter {
                    detail: format!("the multipart part `{name}` is sent more than once: send it once"),
                    parameter: name,
                });
            }
            if array {
                up.arrays.push((name, data));
            } else if shape_part {
                up.bytes = data;
                up.filename = filename;
                up.media_type = media;
                got = true;
            } else if name == "format" {
                format_part = true;
                let f = String::from_utf8_lossy(&data).trim().to_string();
                up.format = Some(parse_format(&f)?);
            } else {
                up.fields.push((name, String::from_utf8_lossy(&data).into_owned()));
            }
        }
        if !got {
            return Err(ApiError::invalid_request("the multipart body has no file part (name it 'file')"));
        }
    } else {
        up.media_type = (!ct.is_empty()).then_some(ct);
        up.bytes = Bytes::from_request(req, st).await.map_err(|e| body_error(st, e))?;
    }
    Ok(up)
}

/// Parses and validates an upload (on the blocking pool) and stores it: (created, shape).
pub(crate) async fn ingest(st: &AppState, up: Upload) -> Result<(bool, Arc<StoredShape>), ApiError> {
    if up.bytes.is_empty() {
        return Err(ApiError::invalid_request("the request body is empty; send the shape file"));
    }
    let format = match up.format {
        Some(f) => f,
        None => {
            let by_name = up
                .filename
                .as_deref()
                .and_then(|n| std::path::Path::new(n).extension())
                .and_then(|e| e.to_str())
                .and_then(Format::from_name);
            let by_media = up
                .media_type
                .as_deref()
                .filter(|m| !m.starts_with("application/octet-stream") && !m.starts_with("text/plain"))
                .and_then(Format::from_media_type);
            match by_name.or(by_media) {
                Some(f) => f,
                None => kac_core::io::choose_format(None, None, &up.bytes)?,
            }
        }
    };
    let max_vertices = st.engine.config.max_vertices;
    let bytes = up.bytes.clone();
    let v = tokio::task::spawn_blocking(move || {
        let read = ReadOptions { max_vertices, ..Default::default() };
        kac_core::load_bytes(&bytes, format, &read, &ValidateOptions::default())
    })
    .await
    .map_err(|e| ApiError::Internal { detail: format!("validation panicked: {e}") })??;
    if v.shape.vertex_count() > max_vertices {
        return Err(ApiError::Shape(kac_core::ShapeError::LimitExceeded {
            what: "the vertex count".into(),
            value: v.shape.vertex_count() as u64,
            limit: max_vertices as u64,
        }));
    }
    let summary = serde_json::to_value(v.summary()).map_err(|e| ApiError::Internal { detail: e.to_string() })?;
    let record = ShapeRecord {
        id: v.id.hex(),
        format: format.name().into(),
        created_at: jobs::now(),
        bytes: up.bytes.len(),
        summary,
    };
    let stored = StoredShape { record, validated: v };
    // Storing writes and fsyncs a file and a record: on the blocking pool, off the request threads.
    let shapes = st.shapes.clone();
    tokio::task::spawn_blocking(move || shapes.insert(stored, &up.bytes))
        .await
        .map_err(|e| ApiError::Internal { detail: format!("storing panicked: {e}") })?
        .map_err(|e| ApiError::Internal { detail: format!("the shape could not be stored: {e}") })
}

/// Upload a shape: the file as the raw body (format from `?format=`, the Content-Type, or the content) or as a
/// multipart part named `file`. Idempotent by content hash: 201 the first time, 200 after.
#[utoipa::path(post, path = "/v1/shapes", tag = "shapes", params(UploadQuery),
    request_body(content = Vec<u8>, description = "the shape file (raw or multipart/form-data with a 'file' part)", content_type = "application/octet-stream"),
    responses(
        (status = 201, description = "stored", body = ShapeResource, headers(("Location" = String))),
        (status = 200, description = "already stored", body = ShapeResource, headers(("Location" = String))),
        (status = 400, description = "bad request", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "too large", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 415, description = "unknown format", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 422, description = "invalid shape", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn upload_shape(
    State(st): State<AppState>,
    Query(q): Query<UploadQuery>,
    req: Request,
) -> Result<Response, ApiError> {
    // Tags parse before the body is read: a bad tag stores nothing.
    let tags = match q.tags.as_deref() {
        Some(t) => Tag::parse_all(&t.split(',').collect::<Vec<_>>()).map_err(ApiError::invalid_request)?,
        None => vec![],
    };
    let up = read_upload(&st, q.format, req).await?;
    let (created, shape) = ingest(&st, up).await?;
    if !tags.is_empty() {
        super::collection::add_tags(&st, &shape.id, &tags)?;
    }
    let status = if created { StatusCode::CREATED } else { StatusCode::OK };
    let loc = format!("/v1/shapes/{}", shape.id);
    Ok(with_location((status, Json(shape_resource(&st, &shape))).into_response(), &loc))
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct Page {
    /// At most this many (default 100, at most 1000).
    pub limit: Option<usize>,
    pub offset: Option<usize>,
}

/// List stored shapes (id order).
#[utoipa::path(get, path = "/v1/shapes", tag = "shapes", params(Page), responses((status = 200, description = "a page of shapes", body = ShapePage)))]
pub(crate) async fn list_shapes(
    State(st): State<AppState>,
    Query(p): Query<Page>,
) -> Result<Json<ShapePage>, ApiError> {
    let limit = p.limit.unwrap_or(100).min(1000);
    let offset = p.offset.unwrap_or(0);
    let (items, total) = st.shapes.list(offset, limit).map_err(store_error)?;
    let items: Vec<ShapeResource> = items.iter().map(|s| shape_resource(&st, s)).collect();
    Ok(Json(ShapePage { total, offset, limit, items }))
}

/// A stored shape with its validation summary.
#[utoipa::path(get, path = "/v1/shapes/{id}", tag = "shapes", params(("id" = String, Path)),
    responses((status = 200, body = ShapeResource),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn get_shape(
    State(st): State<AppState>,
    ShapePath(id): ShapePath,
) -> Result<Json<ShapeResource>, ApiError> {
    st.shapes
        .get(&id)
        .map_err(store_error)?
        .map(|s| Json(shape_resource(&st, &s)))
        .ok_or(ApiError::NotFound { what: "shape", id: id.hex() })
}

/// Delete a stored shape (its finished results stay available by id).
#[utoipa::path(delete, path = "/v1/shapes/{id}", tag = "shapes", params(("id" = String, Path)),
    responses((status = 204, description = "deleted"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn delete_shape(State(st): State<AppState>, ShapePath(id): ShapePath) -> Result<StatusCode, ApiError> {
    if st.shapes.remove(&id).map_err(store_error)? {
        st.index.remove_shape(&id.hex());
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::NotFound { what: "shape", id: id.hex() })
    }
}

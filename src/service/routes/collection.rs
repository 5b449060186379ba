//! Collections: a shape's tags (`/v1/shapes/{id}/tags`), which a search may be limited to, and bulk ingest
//! (`/v1/shapes/bulk`): many shapes in one request, each answered on its own, with their fingerprint jobs started.

use super::shapes::{ingest, shape_resource, ShapeResource, Upload};
use super::*;
use crate::service::search::MAX_TAGS;
use crate::service::store::{TagEdit, TagsOutcome};
use kac_core::descriptors::shape_dna::ShapeDnaOptions;

/// A shape's tags.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ShapeTags {
    pub id: String,
    /// Sorted, each once.
    pub tags: Vec<String>,
}

/// The tags a shape is to carry (replacing those it carries).
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct TagsBody {
    /// At most 32 tags, each 1 to 64 characters of ASCII letters, digits and `- _ . : /`.
    pub tags: Vec<String>,
}
kac_core::object_only_serde!(TagsBody);

/// The tags a stored shape carries.
#[utoipa::path(get, path = "/v1/shapes/{id}/tags", tag = "shapes", params(("id" = String, Path)),
    responses((status = 200, body = ShapeTags),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn get_tags(
    State(st): State<AppState>,
    ShapePath(id): ShapePath,
) -> Result<Json<ShapeTags>, ApiError> {
    if st.shapes.get(&id).map_err(store_error)?.is_none() {
        return Err(ApiError::NotFound { what: "shape", id: id.hex() });
    }
    let tags = st.fingerprints.tags_of(&id.hex()).map_err(store_error)?;
    Ok(Json(ShapeTags { id: id.hex(), tags }))
}

/// Set the tags of a stored shape (replacing those it carries; `[]` removes them all). Searches limited to tags
/// see the change at once, on every replica.
#[utoipa::path(put, path = "/v1/shapes/{id}/tags", tag = "shapes", params(("id" = String, Path)), request_body = TagsBody,
    responses((status = 200, body = ShapeTags),
              (status = 400, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn put_tags(
    State(st): State<AppState>,
    ShapePath(id): ShapePath,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Json<ShapeTags>, ApiError> {
    let req: TagsBody = strict_body(&st, body, "TagsBody")?;
    let tags = Tag::parse_all(&req.tags).map_err(ApiError::invalid_request)?;
    let tags = edit_tags(&st, &id.hex(), TagEdit::Replace(tags.iter().map(|t| t.as_str().to_string()).collect()))?;
    Ok(Json(ShapeTags { id: id.hex(), tags }))
}

/// Edits a shape's tags in the store, then in this replica's index; the tags it carries now.
pub(crate) fn edit_tags(st: &AppState, id: &str, edit: TagEdit) -> Result<Vec<String>, ApiError> {
    match st.fingerprints.set_tags(id, &edit).map_err(store_error)? {
        TagsOutcome::Set(tags) => {
            st.index.set_tags(id, &tags);
            Ok(tags)
        }
        TagsOutcome::NotStored => Err(ApiError::NotFound { what: "shape", id: id.to_string() }),
        TagsOutcome::TooMany(n) => Err(ApiError::invalid_request(format!(
            "the shape would carry {n} tags, at most {MAX_TAGS}: its tags are unchanged (the shape itself is stored)"
        ))),
    }
}

/// Adds tags to a shape's (an upload's `tags`: the same content uploaded with other tags carries both).
pub(crate) fn add_tags(st: &AppState, id: &str, tags: &[Tag]) -> Result<Vec<String>, ApiError> {
    let tags = tags.iter().map(|t| t.as_str().to_string()).collect();
    edit_tags(st, id, TagEdit::Add { tags, max: MAX_TAGS })
}

/// The fingerprint a bulk upload computes for each shape.
#[derive(Deserialize, Serialize, utoipa::ToSchema, Clone, Default)]
#[serde(remote = "Self")]
pub struct BulkFingerprint {
    /// The shape-DNA's options (k, normalization, reweighting, include_zero), as `/v1/search` takes them.
    #[serde(flatten)]
    pub dna: ShapeDnaOptions,
    #[serde(default)]
    pub operator: analysis::OperatorSpec,
}
kac_core::object_only_serde!(BulkFingerprint);

/// What a bulk upload does with each shape: the multipart part named `options`, as JSON.
#[derive(Deserialize, Serialize, utoipa::ToSchema, Default)]
#[serde(remote = "Self")]
pub struct BulkOptions {
    /// Tags added to every shape.
    #[serde(default)]
    pub tags: Vec<String>,
    /// The fingerprint job started for each shape (default: shape-DNA with its default options, the family a
    /// search with default options looks in); `null` starts none.
    #[serde(default = "default_fingerprint")]
    pub fingerprint: Option<BulkFingerprint>,
}
kac_core::object_only_serde!(BulkOptions);

fn default_fingerprint() -> Option<BulkFingerprint> {
    Some(BulkFingerprint::default())
}

/// One file of a bulk upload.
#[derive(Serialize, utoipa::ToSchema)]
pub struct BulkFile {
    /// The file's name (inside an archive: `archive.zip/inner/name.off`).
    pub name: String,
    /// 201 stored, 200 already stored, or the status of its problem.
    pub status: u16,
    pub shape: Option<ShapeResource>,
    /// The fingerprint job started (or found: the same job again) for it.
    pub job: Option<JobResource>,
    /// Why the file was not stored, or why its job could not start (the shape is stored then).
    pub problem: Option<crate::service::error::Problem>,
}

/// A bulk upload's answer: one entry per file, in the order sent.
#[derive(Serialize, utoipa::ToSchema)]
pub struct BulkResult {
    pub created: usize,
    pub existing: usize,
    /// Files not stored (each with its `problem`).
    pub failed: usize,
    /// Files stored whose fingerprint job could not start (the queue full, say; each with its `problem`): send them
    /// again (a stored shape answers 200 and gets its job then).
    pub unstarted: usize,
    pub files: Vec<BulkFile>,
}

/// Most files one bulk request may hold (archives' entries included).
pub const MAX_BULK_FILES: usize = 10_000;

/// Upload many shapes at once: a multipart body with a part per file (any part with a file name; a `.zip` part
/// is opened and each of its files taken), and optionally a part named `options` (JSON, [`BulkOptions`]). Each
/// file is parsed, validated and stored on its own, its tags added and its fingerprint job started; the answer
/// lists every file with its shape, job, or problem. A bad file does not stop the others; the request's limits
/// (body size, read time) apply to the whole body.
#[utoipa::path(post, path = "/v1/shapes/bulk", tag = "shapes",
    request_body(content = Vec<u8>, description = "multipart/form-data: file parts (shape files or .zip archives) and an optional 'options' part (JSON BulkOptions)", content_type = "multipart/form-data"),
    responses(
        (status = 200, description = "every file's outcome", body = BulkResult),
        (status = 400, description = "not multipart, no file part, bad options, or too many files", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "too large", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 422, description = "an unknown field in the options", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn bulk_upload(State(st): State<AppState>, req: Request) -> Result<Json<BulkResult>, ApiError> {
    let ct = req.headers().get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("").to_string();
    if !ct.to_ascii_lowercase().starts_with("multipart/form-data") {
        return Err(ApiError::invalid_request("a bulk upload is multipart/form-data: one part per file"));
    }
    let mut mp = Multipart::from_request(req, &st)
        .await
        .map_err(|e| ApiError::invalid_request(format!("multipart: {}", e.body_text())))?;
    let mut files: Vec<(String, Bytes)> = vec![];
    let mut options = BulkOptions { fingerprint: default_fingerprint(), ..Default::default() };
    // What the request's archives may expand to, together: the body limit (or 64 MiB) once.
    let mut budget = st.config.max_body_bytes.max(64 << 20);
    while let Some(field) = mp.next_field().await.map_err(|e| multipart_error(&st, &e))? {
        let name = field.name().unwrap_or("").to_string();
        let filename = field.file_name().map(str::to_string);
        let data = field.bytes().await.map_err(|e| multipart_error(&st, &e))?;
        match filename {
            Some(f) if f.to_ascii_lowercase().ends_with(".zip") => {
                files.extend(unzip(&f, &data, MAX_BULK_FILES - files.len().min(MAX_BULK_FILES), &mut budget)?)
            }
            Some(f) => files.push((f, data)),
            None if name == "options" => {
                let v: Value = serde_json::from_slice(&data)
                    .map_err(|e| ApiError::invalid_json(format!("the options part: {e}")))?;
                super::super::strict::check_body(&v, "BulkOptions").map_err(|u| ApiError::UnknownField(Box::new(u)))?;
                options = serde_json::from_value(v).map_err(|e| ApiError::invalid_json(e.to_string()))?;
            }
            None => {
                return Err(ApiError::invalid_request(format!(
                    "part '{name}' has no file name: send each shape as a file part, the options as a part named \
                     'options'"
                )))
            }
        }
        if files.len() > MAX_BULK_FILES {
            return Err(ApiError::invalid_request(format!("more than {MAX_BULK_FILES} files in one bulk upload")));
        }
    }
    if files.is_empty() {
        return Err(ApiError::invalid_request(
            "the bulk upload has no file parts (one part with a file name per shape)",
        ));
    }
    let tags = Tag::parse_all(&options.tags).map_err(ApiError::invalid_request)?;
    if let Some(fp) = &options.fingerprint {
        if fp.dna.k == 0 || fp.dna.k > st.config.max_k {
            return Err(ApiError::invalid_request(format!(
                "fingerprint k = {}: 1 to --max-k {}",
                fp.dna.k, st.config.max_k
            )));
        }
    }
    let mut out = BulkResult { created: 0, existing: 0, failed: 0, unstarted: 0, files: vec![] };
    for (name, bytes) in files {
        let up = Upload::file(bytes, Some(name.clone()));
        let (created, shape) = match ingest(&st, up).await {
            Ok(x) => x,
            Err(e) => {
                let (status, p) = e.problem();
                out.failed += 1;
                out.files.push(BulkFile { name, status: status.as_u16(), shape: None, job: None, problem: Some(p) });
                continue;
            }
        };
        if created {
            out.created += 1;
        } else {
            out.existing += 1;
        }
        // Tags first (a failure is reported, and the job still starts).
        let tagged = if tags.is_empty() { Ok(vec![]) } else { add_tags(&st, &shape.id, &tags) };
        let started = (|| -> Result<Option<JobResource>, ApiError> {
            let Some(fp) = &options.fingerprint else { return Ok(None) };
            let analysis = Analysis::ShapeDna {
                options: fp.dna.clone(),
                operator: fp.operator.clone(),
                solver: analysis::SolverSpec::default(),
            };
            let (job, _) = jobs::submit(&st.jobs, &st.config, shape.clone(), analysis)?;
            Ok(Some(job_resource(&job)))
        })();
        let (job, mut problem) = match started {
            Ok(job) => (job, None),
            Err(e) => {
                out.unstarted += 1;
                (None, Some(e.problem().1))
            }
        };
        if let Err(e) = tagged {
            problem = problem.or(Some(e.problem().1));
        }
        let file = BulkFile {
            name,
            status: if created { 201 } else { 200 },
            shape: Some(shape_resource(&st, &shape)),
            job,
            problem,
        };
        out.files.push(file);
    }
    Ok(Json(out))
}

fn multipart_error(st: &AppState, e: &axum::extract::multipart::MultipartError) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::BodyTooLarge { limit: st.config.max_body_bytes }
    } else if let Some(detail) = super::super::bodies::too_slow(e) {
        ApiError::BodyTooSlow { detail }
    } else {
        ApiError::invalid_request(format!("multipart: {}", e.body_text()))
    }
}

/// The files of a zip archive (directories skipped), named `archive/inner`; an entry that cannot be read is
/// refused with the archive, as is an archive of more than `room` files or expanding beyond what is left of the
/// request's `budget` of expanded bytes (a zip bomb), counted as read.
fn unzip(archive: &str, data: &[u8], room: usize, budget: &mut usize) -> Result<Vec<(String, Bytes)>, ApiError> {
    use std::io::Read;
    let bad =
        |e: &dyn std::fmt::Display| ApiError::invalid_request(format!("{archive}: not a readable zip archive: {e}"));
    let mut z = zip::ZipArchive::new(std::io::Cursor::new(data)).map_err(|e| bad(&e))?;
    if z.len() > room {
        return Err(ApiError::invalid_request(format!("{archive}: more than {MAX_BULK_FILES} files in the upload")));
    }
    let mut out = vec![];
    for i in 0..z.len() {
        let f = z.by_index(i).map_err(|e| bad(&e))?;
        if f.is_dir() {
            continue;
        }
        let name = format!("{archive}/{}", f.name());
        let mut buf = vec![];
        f.take(*budget as u64 + 1).read_to_end(&mut buf).map_err(|e| bad(&e))?;
        if buf.len() > *budget {
            return Err(ApiError::invalid_request(format!(
                "{archive}: the upload's archives expand beyond --max-body-bytes (or 64 MiB) together; send fewer \
                 files at a time"
            )));
        }
        *budget -= buf.len();
        out.push((name, Bytes::from(buf)));
    }
    Ok(out)
}

//! Collections: a shape's tags (`/v1/shapes/{id}/tags`), which a search may be limited to, and bulk ingest
//! (`/v1/shapes/bulk`): many shapes in one request, each answered on its own, with their fingerprint jobs started
//! in the queue's backlog lane (never refused for capacity: bounded by `--max-backlog` before anything is stored)
//! and recorded as a batch whose progress `/v1/shapes/bulk/{batch}` tells.

use super::archive::{unzip, Expansion};
use super::shapes::{ingest, shape_resource, ShapeResource, Upload};
use super::*;
use crate::service::ids::{BatchPath, JobId};
use crate::service::search::MAX_TAGS;
use crate::service::store::{TagEdit, TagsOutcome};

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

/// The fingerprint a bulk upload computes for each shape: a `fingerprint` job (every family a search reads).
#[derive(Deserialize, Serialize, utoipa::ToSchema, Clone, Default)]
#[serde(remote = "Self")]
pub struct BulkFingerprint {
    /// The fingerprint's options (k, normalization, reweighting, include_zero), as `/v1/search` takes them, with
    /// the same defaults.
    #[serde(flatten)]
    pub options: analysis::FingerprintOptions,
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
    /// The fingerprint job started for each shape (default: a `fingerprint` job with the default options, whose
    /// families a search with default options looks in); `null` starts none.
    #[serde(default = "default_fingerprint")]
    pub fingerprint: Option<BulkFingerprint>,
}
kac_core::object_only_serde!(BulkOptions);

fn default_fingerprint() -> Option<BulkFingerprint> {
    Some(BulkFingerprint::default())
}

/// The job a bulk upload starts for each stored shape: the one place that says which analysis fingerprints it.
fn fingerprint_job(fp: &BulkFingerprint) -> Analysis {
    Analysis::Fingerprint {
        options: fp.options.clone(),
        operator: fp.operator.clone(),
        solver: analysis::SolverSpec::default(),
    }
}

/// One file of a bulk upload.
#[derive(Serialize, utoipa::ToSchema)]
pub struct BulkFile {
    /// The file's name (inside an archive: `archive.zip/inner/name.off`).
    pub name: String,
    /// 201 stored, 200 already stored, or the status of its problem.
    pub status: u16,
    /// The shape stored (also for a file failed for its tags: stored, but without them).
    pub shape: Option<ShapeResource>,
    /// The fingerprint job started (or found: the same job again) for it, in the backlog lane: it may wait there
    /// behind interactive jobs and earlier uploads, and starts as workers free up.
    pub job: Option<JobResource>,
    /// Why the file was not stored, or why its job could not start (the shape is stored then).
    pub problem: Option<crate::service::error::Problem>,
}

/// A bulk upload's answer: one entry per file, in the order sent.
#[derive(Serialize, utoipa::ToSchema)]
pub struct BulkResult {
    pub created: usize,
    pub existing: usize,
    /// Files not stored, or stored without the tags asked for (each with its `problem`).
    pub failed: usize,
    /// Files stored whose fingerprint job could not be recorded: the store failed as it was written, or the
    /// fingerprint is refused for that shape (a limit, or a kind it does not apply to); each with its `problem`.
    /// Never for the queue's capacity (the jobs wait in the backlog lane). Send them again (a stored shape answers
    /// 200 and gets its job then).
    pub unstarted: usize,
    /// The batch of this upload's jobs (32 hex digits): every job started or found for its files.
    pub batch: String,
    /// Where the batch's progress is read: `/v1/shapes/bulk/{batch}`.
    pub progress: String,
    pub files: Vec<BulkFile>,
}

/// The progress of a bulk upload's fingerprint jobs.
#[utoipa::path(get, path = "/v1/shapes/bulk/{batch}", tag = "shapes", params(("batch" = String, Path)),
    responses((status = 200, body = jobs::BatchProgress),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn bulk_progress(
    State(st): State<AppState>,
    BatchPath(batch): BatchPath,
) -> Result<Json<jobs::BatchProgress>, ApiError> {
    st.jobs.batch(&batch)?.map(Json).ok_or(ApiError::NotFound { what: "batch", id: batch.hex() })
}

/// Most files one bulk request may hold (archives' entries included).
pub const MAX_BULK_FILES: usize = 10_000;

/// Upload many shapes at once: a multipart body with a part per file (any part with a file name; a `.zip` part
/// is opened and each of its files taken), and optionally one part named `options` (JSON, [`BulkOptions`]). Each
/// file is parsed, validated and stored on its own, its tags added and its fingerprint job started; the answer
/// lists every file with its shape, job, or problem. A bad file does not stop the others (a file stored whose
/// tags are refused is counted `failed`, with its problem); the request's limits (body size, read time) apply to
/// the whole body.
///
/// The fingerprint jobs wait in the queue's backlog lane, which `--queue-capacity` does not bound: they start in
/// order as workers free up, after interactive jobs, and survive a restart. The answer names the upload's batch and
/// where its progress is read. Back-pressure comes before anything is stored: when the backlog's waiting jobs plus
/// the request's files exceed `--max-backlog`, the answer is 503 `queue-full` with Retry-After and nothing is
/// stored.
///
/// Archives: the files of a request's archives expand to at most `--max-body-bytes` together (what they could
/// take sent unpacked), and the memory holding them is reserved against `--max-body-memory-bytes` as it is
/// allocated, held until the request's files are stored (503 `memory-busy` with Retry-After when the budget has no
/// room). They are expanded on the blocking pool. An archive whose central directory names an entry twice, or
/// that holds an archive (by name or content), is refused naming the entry.
#[utoipa::path(post, path = "/v1/shapes/bulk", tag = "shapes",
    request_body(content = Vec<u8>, description = "multipart/form-data: file parts (shape files or .zip archives; each with a non-empty file name) and at most one 'options' part (JSON BulkOptions). The files of the request's archives expand to at most --max-body-bytes together, their memory reserved against --max-body-memory-bytes", content_type = "multipart/form-data"),
    responses(
        (status = 200, description = "every file's outcome", body = BulkResult),
        (status = 400, description = "not multipart, no file part, a part with an empty file name, two options parts, bad options (a key twice included), too many files, or an archive that cannot be read, names an entry twice, holds an archive or expands beyond --max-body-bytes", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "too large", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 422, description = "an unknown field in the options", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "the backlog's waiting jobs plus this request's files exceed --max-backlog (queue-full; nothing stored), too many connections (too-many-connections), request bodies in flight and the files of archives being expanded hold --max-body-memory-bytes (memory-busy), with Retry-After; or the store failed (not-ready)", body = crate::service::error::Problem, content_type = "application/problem+json", headers(("Retry-After" = u64)))))]
pub(crate) async fn bulk_upload(State(st): State<AppState>, req: Request) -> Result<Json<BulkResult>, ApiError> {
    let ct = req.headers().get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("").to_string();
    if !ct.to_ascii_lowercase().starts_with("multipart/form-data") {
        return Err(ApiError::invalid_request("a bulk upload is multipart/form-data: one part per file"));
    }
    let mut mp = Multipart::from_request(req, &st)
        .await
        .map_err(|e| ApiError::invalid_request(format!("multipart: {}", e.body_text())))?;
    let mut files: Vec<(String, Bytes)> = vec![];
    let mut options: Option<BulkOptions> = None;
    // Held until the request's files are stored (dropped with this handler's frame).
    let mut expansion = Some(Expansion::new(st.config.max_body_bytes, st.bodies.reservation()));
    while let Some(field) = mp.next_field().await.map_err(|e| multipart_error(&st, &e))? {
        let name = field.name().unwrap_or("").to_string();
        let filename = field.file_name().map(str::to_string);
        // Refused before the part is read.
        if filename.as_deref() == Some("") {
            return Err(ApiError::InvalidParameter {
                detail: format!(
                    "the part '{name}' has an empty file name: give each file part its file's name (its extension \
                     tells the format)"
                ),
                parameter: name,
            });
        }
        if filename.is_none() && name == "options" && options.is_some() {
            return Err(ApiError::InvalidParameter {
                parameter: name,
                detail: "the part 'options' is sent more than once: send one (the options of the whole upload)".into(),
            });
        }
        let data = field.bytes().await.map_err(|e| multipart_error(&st, &e))?;
        match filename {
            Some(f) if f.to_ascii_lowercase().ends_with(".zip") => {
                let room = MAX_BULK_FILES - files.len().min(MAX_BULK_FILES);
                let mut exp = expansion.take().ok_or_else(|| ApiError::Internal { detail: "no expansion".into() })?;
                // Decompression is CPU work: off the async threads, so that others are served meanwhile.
                let (got, exp) = tokio::task::spawn_blocking(move || (unzip(&f, &data, room, &mut exp), exp))
                    .await
                    .map_err(|e| ApiError::Internal { detail: format!("opening an archive panicked: {e}") })?;
                expansion = Some(exp);
                match got {
                    Ok(got) => files.extend(got),
                    Err(e @ ApiError::MemoryBusy { .. }) => {
                        st.metrics.bodies_refused.fetch_add(1, Ordering::Relaxed);
                        return Err(e);
                    }
                    Err(e) => return Err(e),
                }
            }
            Some(f) => files.push((f, data)),
            None if name == "options" => {
                let v = json_value(&data, "the options part")?;
                super::super::strict::check_body(super::super::openapi::served(), &v, "BulkOptions")
                    .map_err(|u| ApiError::UnknownField(Box::new(u)))?;
                options = Some(serde_json::from_value(v).map_err(|e| ApiError::invalid_json(e.to_string()))?);
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
    let options = options.unwrap_or(BulkOptions { fingerprint: default_fingerprint(), ..Default::default() });
    let tags = Tag::parse_all(&options.tags).map_err(ApiError::invalid_request)?;
    if let Some(fp) = &options.fingerprint {
        if fp.options.k == 0 || fp.options.k > st.engine.config.max_k {
            return Err(ApiError::invalid_request(format!(
                "fingerprint k = {}: 1 to --max-k {}",
                fp.options.k, st.engine.config.max_k
            )));
        }
    }
    // Back-pressure before anything is stored: every file counts (some may fail or find their job done).
    if options.fingerprint.is_some() {
        let backlog = st.jobs.backlog()?;
        let limit = st.engine.config.max_backlog;
        if backlog.saturating_add(files.len()) > limit {
            return Err(ApiError::BacklogFull { backlog, files: files.len(), limit, retry_after_s: 5 });
        }
    }
    let mut out = BulkResult {
        created: 0,
        existing: 0,
        failed: 0,
        unstarted: 0,
        batch: String::new(),
        progress: String::new(),
        files: vec![],
    };
    let mut batch: Vec<JobId> = vec![];
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
        // Tags first: a file whose tags are refused (it would carry too many) is stored but failed, with its
        // problem, and gets no job (sent again with other tags, it answers 200 and gets it then).
        if !tags.is_empty() {
            if let Err(e) = add_tags(&st, &shape.id, &tags) {
                let (status, p) = e.problem();
                out.failed += 1;
                let shape = Some(shape_resource(&st, &shape));
                out.files.push(BulkFile { name, status: status.as_u16(), shape, job: None, problem: Some(p) });
                continue;
            }
        }
        if created {
            out.created += 1;
        } else {
            out.existing += 1;
        }
        let started = match &options.fingerprint {
            None => Ok(None),
            Some(fp) => jobs::submit_backlog(&st.jobs, &st.engine.config, shape.clone(), fingerprint_job(fp))
                .map(|(job, _)| Some(job))
                .map_err(ApiError::from),
        };
        let (job, problem) = match started {
            Ok(job) => {
                batch.extend(job.as_ref().and_then(|j| JobId::parse(&j.id)));
                (job.as_ref().map(job_resource), None)
            }
            Err(e) => {
                out.unstarted += 1;
                (None, Some(e.problem().1))
            }
        };
        let file = BulkFile {
            name,
            status: if created { 201 } else { 200 },
            shape: Some(shape_resource(&st, &shape)),
            job,
            problem,
        };
        out.files.push(file);
    }
    // Recorded once the jobs are: a store that fails here answers 503, and the upload sent again finds its shapes
    // and jobs stored (200, the same jobs) under a new batch.
    let batch = st.jobs.put_batch(&batch)?;
    out.progress = format!("/v1/shapes/bulk/{batch}");
    out.batch = batch.hex();
    drop(expansion);
    Ok(Json(out))
}

fn multipart_error(st: &AppState, e: &axum::extract::multipart::MultipartError) -> ApiError {
    if crate::service::error::over_body_limit(e.status()) {
        ApiError::BodyTooLarge { limit: st.config.max_body_bytes }
    } else if let Some(detail) = super::super::bodies::too_slow(e) {
        ApiError::BodyTooSlow { detail }
    } else {
        ApiError::invalid_request(format!("multipart: {}", e.body_text()))
    }
}

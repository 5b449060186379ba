//! The OpenAPI document, generated from the handlers and types by utoipa. Served at `/openapi.json`, committed
//! at `openapi/openapi.json` (`kac openapi > openapi/openapi.json`); a test fails when the two differ.

use utoipa::OpenApi;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "kac",
        description = "Can you hear the shape of a drum? Spectral shape analysis: upload a shape, run analyses \
(spectra, heat kernel signatures, shape-DNA, geodesics, …) as jobs, fetch immutable results. Errors are RFC 9457 \
problem+json with a stable `type` (`/problems/{code}`).",
        license(name = "MIT OR Apache-2.0")
    ),
    paths(
        super::routes::livez,
        super::routes::readyz,
        super::routes::metrics,
        super::routes::problem_doc,
        super::routes::upload_shape,
        super::routes::list_shapes,
        super::routes::get_shape,
        super::routes::delete_shape,
        super::routes::get_tags,
        super::routes::put_tags,
        super::routes::bulk_upload,
        super::routes::bulk_progress,
        super::routes::get_geometry,
        super::routes::create_job,
        super::routes::list_jobs,
        super::routes::get_job,
        super::routes::cancel_job,
        super::routes::delete_job,
        super::routes::job_events,
        super::routes::get_result,
        super::routes::get_array,
        super::routes::analyze,
        super::routes::list_analyses,
        super::routes::compare,
        super::routes::correspondence,
        super::routes::search,
        super::routes::search_audit,
    ),
    components(schemas(
        super::error::Problem,
        super::routes::ShapeResource,
        super::routes::ShapeTags,
        super::routes::TagsBody,
        super::routes::BulkOptions,
        super::routes::BulkFingerprint,
        super::routes::BulkFile,
        super::routes::BulkResult,
        super::jobs::BatchProgress,
        super::search::Method,
        super::routes::JobRequest,
        super::routes::JobForm,
        super::compare::CompareRequest,
        super::correspondence::CorrespondenceRequest,
        super::routes::SearchRequest,
        super::search::AuditReport,
        super::search::FamilyAudit,
        super::search::TagAudit,
        super::routes::JobBody,
        super::routes::JobResource,
        super::jobs::Status,
        super::jobs::JobProgress,
        crate::analysis::Analysis,
        crate::analysis::registry::AnalysesTable,
        super::routes::Liveness,
        super::routes::Readiness,
        super::routes::ProblemType,
        super::routes::JobPage,
        super::routes::ShapePage,
        super::routes::SearchResult,
        super::routes::Neighbour,
        super::routes::AnalysisResult,
        super::routes::ResultEnvelope,
        super::routes::ArrayLinks,
        crate::analysis::Summary,
        crate::analysis::ResultHead,
        crate::analysis::Warning,
        crate::analysis::registry::AnalysisSupport,
        crate::analysis::registry::ShapeClass,
        kac_core::io::Format,
    )),
    modifiers(&CommonResponses),
    tags(
        (name = "shapes", description = "Upload and inspect shapes (addressed by content hash)"),
        (name = "jobs", description = "Analyses as jobs; the synchronous form; comparisons"),
        (name = "results", description = "Immutable results and their per-vertex arrays"),
        (name = "operations", description = "Health and problem documentation"),
    )
)]
pub struct ApiDoc;

/// The document as pretty JSON (what `kac openapi` prints and `/openapi.json` serves).
/// The served document as JSON, built once: what the strict checks of bodies and queries read
/// ([`super::strict`]).
pub fn served() -> &'static serde_json::Value {
    static DOC: std::sync::OnceLock<serde_json::Value> = std::sync::OnceLock::new();
    DOC.get_or_init(|| serde_json::from_str(&document()).unwrap_or(serde_json::Value::Null))
}

pub fn document() -> String {
    let mut doc = serde_json::to_value(ApiDoc::openapi()).unwrap_or_default();
    flatten_requests(&mut doc, &["CompareRequest", "SearchRequest", "CorrespondenceRequest"]);
    close_request_schemas(&mut doc);
    name_analysis_variants(&mut doc);
    name_result_variants(&mut doc);
    type_raw_bodies(&mut doc);
    list_problem_codes(&mut doc);
    serde_json::to_string_pretty(&doc).unwrap_or_default()
}

/// The analyses as named, flat schemas with a discriminator, the construct client generators read: each `oneOf`
/// variant of `Analysis` becomes `components.schemas.{Name}Analysis` (`SpectrumAnalysis`, `HksAnalysis`, …), a
/// variant composed with `allOf` (the evolutions' flattened `InitialData`) is merged into one object with the same
/// properties and required fields, and `Analysis` maps each `analysis` value to its schema. The meaning is
/// unchanged: the same fields, the same required ones (openapi-python-client cannot read a union member composed
/// with `allOf`, and types every result of an unnamed union as one anonymous class).
fn name_analysis_variants(doc: &mut serde_json::Value) {
    use serde_json::{Map, Value};
    let Some(variants) = doc.pointer("/components/schemas/Analysis/oneOf").and_then(Value::as_array).cloned() else {
        return;
    };
    let mut refs = vec![];
    let mut mapping = Map::new();
    for v in variants {
        let mut flat = Map::new();
        let (mut props, mut required) = (Map::new(), Vec::<Value>::new());
        flatten_into(doc, &v, &mut props, &mut required);
        let Some(name) = props.get("analysis").and_then(|a| a.pointer("/enum/0")).and_then(Value::as_str) else {
            return;
        };
        let name = name.to_string();
        let component = format!("{}Analysis", pascal(&name));
        if let Some(d) = v.get("description") {
            flat.insert("description".into(), d.clone());
        }
        flat.insert("type".into(), "object".into());
        flat.insert("properties".into(), Value::Object(props));
        flat.insert("required".into(), Value::Array(required));
        let reference = format!("#/components/schemas/{component}");
        if let Some(Value::Object(schemas)) = doc.pointer_mut("/components/schemas") {
            schemas.insert(component, Value::Object(flat));
        }
        mapping.insert(name, reference.clone().into());
        refs.push(serde_json::json!({ "$ref": reference }));
    }
    // A job request is an analysis with a shape: `{Name}JobRequest` = the analysis' schema and `JobTarget`
    // (`shape_id`), one per analysis under the same discriminator (a generator cannot take `allOf` of a union).
    let target = doc.pointer("/components/schemas/JobRequest/allOf/1").cloned();
    let mut job_refs = vec![];
    let mut job_mapping = Map::new();
    if let Some(target) = target {
        if let Some(Value::Object(schemas)) = doc.pointer_mut("/components/schemas") {
            schemas.insert("JobTarget".into(), target);
            for (name, reference) in &mapping {
                let component = reference.as_str().unwrap_or_default().trim_start_matches("#/components/schemas/");
                let job = format!("{}JobRequest", component.trim_end_matches("Analysis"));
                schemas.insert(
                    job.clone(),
                    serde_json::json!({ "allOf": [{ "$ref": reference }, { "$ref": "#/components/schemas/JobTarget" }] }),
                );
                let job_ref = format!("#/components/schemas/{job}");
                job_mapping.insert(name.clone(), job_ref.clone().into());
                job_refs.push(serde_json::json!({ "$ref": job_ref }));
            }
        }
        if let Some(Value::Object(j)) = doc.pointer_mut("/components/schemas/JobRequest") {
            j.remove("allOf");
            j.insert("oneOf".into(), Value::Array(job_refs));
            j.insert("discriminator".into(), serde_json::json!({ "propertyName": "analysis", "mapping": job_mapping }));
        }
    }
    if let Some(Value::Object(a)) = doc.pointer_mut("/components/schemas/Analysis") {
        a.insert("oneOf".into(), Value::Array(refs));
        a.insert("discriminator".into(), serde_json::json!({ "propertyName": "analysis", "mapping": mapping }));
    }
}

/// Requests that flatten an option set into their top level (`CompareRequest` and `SearchRequest` take the
/// shape-DNA's options, `ShapeDnaOptions`, beside their own fields) as one flat object: the same fields and
/// required ones, which generators read as one model and which the request check closes like any object (an
/// `allOf` whose member is closed where it stands alone would refuse the other members' fields).
fn flatten_requests(doc: &mut serde_json::Value, names: &[&str]) {
    use serde_json::{Map, Value};
    for name in names {
        let pointer = format!("/components/schemas/{name}");
        let Some(schema) = doc.pointer(&pointer).cloned() else { continue };
        if schema.get("allOf").is_none() {
            continue;
        }
        let (mut props, mut required) = (Map::new(), Vec::<Value>::new());
        flatten_into(doc, &schema, &mut props, &mut required);
        let mut flat = Map::new();
        if let Some(d) = schema.get("description") {
            flat.insert("description".into(), d.clone());
        }
        flat.insert("type".into(), "object".into());
        flat.insert("properties".into(), Value::Object(props));
        if !required.is_empty() {
            flat.insert("required".into(), Value::Array(required));
        }
        if let Some(slot) = doc.pointer_mut(&pointer) {
            *slot = Value::Object(flat);
        }
    }
}

/// `spectrum` → `Spectrum`, `si-hks` → `SiHks`.
fn pascal(name: &str) -> String {
    name.split('-')
        .map(|w| {
            let mut c = w.chars();
            c.next().map(|f| f.to_ascii_uppercase().to_string() + c.as_str()).unwrap_or_default()
        })
        .collect()
}

/// The properties and required fields of an object schema, following `$ref` and `allOf` at its top (the way
/// serde's `flatten` and an internally tagged enum compose a schema).
fn flatten_into(
    doc: &serde_json::Value,
    schema: &serde_json::Value,
    props: &mut serde_json::Map<String, serde_json::Value>,
    required: &mut Vec<serde_json::Value>,
) {
    use serde_json::Value;
    if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
        if let Some(target) = doc.pointer(&r.replacen('#', "", 1)) {
            flatten_into(doc, &target.clone(), props, required);
        }
        return;
    }
    for part in schema.get("allOf").and_then(Value::as_array).into_iter().flatten() {
        flatten_into(doc, part, props, required);
    }
    if let Some(p) = schema.get("properties").and_then(Value::as_object) {
        props.extend(p.clone());
    }
    for r in schema.get("required").and_then(Value::as_array).into_iter().flatten() {
        if !required.contains(r) {
            required.push(r.clone());
        }
    }
}

/// The results as named, flat schemas under a discriminator, as the analyses are ([`name_analysis_variants`]):
/// each variant of `Summary` (an analysis' own fields, tagged by `analysis`) with the fields every result has
/// (`ResultHead`; a comparison names no one shape and has its own) and those the service adds
/// (`ResultEnvelope`: `result_id`, `arrays`) becomes `{Name}Result`, and `AnalysisResult` is their union. The
/// pieces composed are then dropped from the components: only the flat schemas name a result.
fn name_result_variants(doc: &mut serde_json::Value) {
    use serde_json::{Map, Value};
    let Some(variants) = doc.pointer("/components/schemas/Summary/oneOf").and_then(Value::as_array).cloned() else {
        return;
    };
    let head = doc.pointer("/components/schemas/ResultHead").cloned().unwrap_or(Value::Null);
    let envelope = doc.pointer("/components/schemas/ResultEnvelope").cloned().unwrap_or(Value::Null);
    let (mut refs, mut mapping, mut composed) =
        (vec![], Map::new(), vec!["Summary", "ResultHead", "ResultEnvelope", "OperatorUsed"]);
    let mut composed_names = vec![];
    let mut flats = vec![];
    for v in &variants {
        let (mut props, mut required) = (Map::new(), Vec::<Value>::new());
        flatten_into(doc, v, &mut props, &mut required);
        let Some(name) = props.get("analysis").and_then(|a| a.pointer("/enum/0")).and_then(Value::as_str) else {
            return;
        };
        let name = name.to_string();
        // The variant's own schema (its description, and to drop it afterwards).
        let own = v
            .get("allOf")
            .and_then(Value::as_array)
            .and_then(|parts| parts.iter().find_map(|p| p.get("$ref").and_then(Value::as_str)))
            .map(|r| r.trim_start_matches("#/components/schemas/").to_string());
        let description =
            own.as_ref().and_then(|o| doc.pointer(&format!("/components/schemas/{o}/description"))).cloned();
        let mut all = Map::new();
        let mut req = vec![];
        let parts: Vec<&Value> = if name == "compare" { vec![&envelope] } else { vec![&head, &envelope] };
        for part in parts {
            flatten_into(doc, part, &mut all, &mut req);
        }
        // A field of the analysis' own under a name the head or the service uses would be overwritten in the
        // stored result (a `heat` result once had a string `arrays`).
        if let Some(clash) = all.keys().find(|k| props.contains_key(*k)) {
            panic!("the {name} result's field `{clash}` is also a field every result has");
        }
        // `analysis` first, then the analysis' own fields, then the head's and the envelope's.
        let mut ordered = Map::new();
        if let Some(a) = props.remove("analysis") {
            ordered.insert("analysis".into(), a);
        }
        ordered.extend(props);
        ordered.extend(all);
        for r in req {
            if !required.contains(&r) {
                required.push(r);
            }
        }
        let component = format!("{}Result", pascal(&name));
        let mut flat = Map::new();
        if let Some(d) = description {
            flat.insert("description".into(), d);
        }
        flat.insert("type".into(), "object".into());
        flat.insert("properties".into(), Value::Object(ordered));
        flat.insert("required".into(), Value::Array(required));
        let reference = format!("#/components/schemas/{component}");
        mapping.insert(name, reference.clone().into());
        refs.push(serde_json::json!({ "$ref": reference }));
        flats.push((component, Value::Object(flat)));
        if let Some(o) = own {
            composed_names.push(o);
        }
    }
    composed.extend(composed_names.iter().map(String::as_str));
    let Some(Value::Object(schemas)) = doc.pointer_mut("/components/schemas") else { return };
    for (component, flat) in flats {
        schemas.insert(component, flat);
    }
    schemas.insert(
        "AnalysisResult".into(),
        serde_json::json!({
            "description": "A finished result: one schema per analysis, chosen by `analysis`.",
            "oneOf": refs,
            "discriminator": { "propertyName": "analysis", "mapping": mapping },
        }),
    );
    // Drop the pieces no schema refers to any more (until none goes: a piece may be referred to only by another).
    loop {
        let text = serde_json::to_string(&*schemas).unwrap_or_default();
        let unused: Vec<&str> = composed
            .iter()
            .copied()
            .filter(|name| schemas.contains_key(*name))
            .filter(|name| !text.contains(&format!("\"#/components/schemas/{name}\"")))
            .collect();
        if unused.is_empty() {
            break;
        }
        for name in unused {
            schemas.remove(name);
        }
    }
    // An untagged union whose branches can hold the same value (a heat result's `sources`: an empty list is both
    // a list of reports and a list of vertices) is `anyOf`: `oneOf` would refuse the value both branches hold.
    if let Some(Value::Object(sources)) = schemas.get_mut("HeatSources") {
        if let Some(branches) = sources.remove("oneOf") {
            sources.insert("anyOf".into(), branches);
        }
    }
}

/// Success bodies that are not JSON get the schema generators read for them: binary (`application/octet-stream`:
/// arrays, geometry, matrices) as `string`/`binary`, text (metrics) as `string`, and the server-sent events' data
/// as the job they carry.
fn type_raw_bodies(doc: &mut serde_json::Value) {
    use serde_json::Value;
    let Some(Value::Object(paths)) = doc.pointer_mut("/paths") else { return };
    for (path, item) in paths.iter_mut() {
        let Value::Object(ops) = item else { continue };
        for op in ops.values_mut() {
            // Request bodies of bytes (utoipa writes `Vec<u8>` as an array of integers): a raw shape is a binary
            // string; the one-request analysis' form is its parts, the shape file and the analysis' JSON.
            // Every request body is required (utoipa leaves it unsaid where an operation takes two media types,
            // which openapi-python-client then types as optional with a name it does not import).
            if let Some(Value::Object(body)) = op.get_mut("requestBody") {
                body.insert("required".into(), Value::Bool(true));
                // One media type per operation: openapi-python-client 0.29 generates code that does not import a
                // name it uses for an operation with two (its issue #1451). The JSON form is the one described;
                // the multipart form (`JobForm`) stays in the components and is named here.
                if let Some(Value::Object(content)) = body.get_mut("content") {
                    if content.len() > 1 && content.contains_key("application/json") {
                        let others: Vec<String> =
                            content.keys().filter(|k| *k != "application/json").cloned().collect();
                        let named: Vec<String> = others
                            .iter()
                            .map(|k| {
                                let schema = content[k].pointer("/schema/$ref").and_then(Value::as_str).unwrap_or("");
                                format!("{k} ({})", schema.trim_start_matches("#/components/schemas/"))
                            })
                            .collect();
                        content.retain(|k, _| k == "application/json");
                        let d = format!("JSON; also accepted as {}.", named.join(", "));
                        body.insert("description".into(), Value::String(d));
                    }
                }
            }
            if let Some(Value::Object(content)) = op.pointer_mut("/requestBody/content") {
                for (ct, media) in content.iter_mut() {
                    let bytes = media.pointer("/schema/items/format").and_then(Value::as_str) == Some("u-int8");
                    if !bytes {
                        continue;
                    }
                    media["schema"] = match ct.as_str() {
                        // A bulk upload: any number of file parts and the options.
                        "multipart/form-data" if path == "/v1/shapes/bulk" => serde_json::json!({
                            "type": "object",
                            "required": ["file"],
                            "properties": {
                                "file": { "type": "array", "minItems": 1, "items": { "type": "string", "format": "binary" }, "description": "the shape files (format from each name), or .zip archives of them" },
                                "options": { "type": "string", "description": "JSON BulkOptions: tags and the fingerprint job" }
                            }
                        }),
                        "multipart/form-data" => serde_json::json!({
                            "type": "object",
                            "required": ["file", "analysis"],
                            "properties": {
                                "file": { "type": "string", "format": "binary", "description": "the shape file (format from its name or `format`)" },
                                "analysis": { "type": "string", "description": "the analysis as JSON, as for POST /v1/jobs without shape_id" },
                                "format": { "type": "string", "description": "the shape's format, overriding the file name" }
                            }
                        }),
                        _ => serde_json::json!({ "type": "string", "format": "binary" }),
                    };
                }
            }
            let Some(Value::Object(responses)) = op.get_mut("responses") else { continue };
            for (code, r) in responses.iter_mut() {
                if !code.starts_with('2') {
                    continue;
                }
                let Some(Value::Object(content)) = r.get_mut("content") else { continue };
                for (ct, media) in content.iter_mut() {
                    let Value::Object(m) = media else { continue };
                    if m.contains_key("schema") {
                        continue;
                    }
                    let schema = if ct == "text/event-stream" {
                        // The job events' data: the job, as `GET /v1/jobs/{id}` shows it. Described, not referenced:
                        // schemathesis 4.32's stateful phase reads an event of a linked job without the job's
                        // fields (not reproduced by hand: every event the service writes carries them).
                        serde_json::json!({
                            "type": "object",
                            "description": "a `job` event's data: the job as GET /v1/jobs/{id} shows it (JobResource)"
                        })
                    } else if ct.starts_with("text/") {
                        serde_json::json!({ "type": "string" })
                    } else {
                        serde_json::json!({ "type": "string", "format": "binary" })
                    };
                    m.insert("schema".into(), schema);
                }
            }
        }
    }
}

/// Every problem code the service can answer with, as the `enum` of `Problem.code` (each is described at
/// `/problems/{code}`): the contract a client can switch on, and schemathesis checks every problem against it.
fn list_problem_codes(doc: &mut serde_json::Value) {
    let codes: Vec<serde_json::Value> = kac_engine::Code::ALL.iter().map(|c| c.as_str().into()).collect();
    if let Some(serde_json::Value::Array(parts)) = doc.pointer_mut("/components/schemas/Problem/allOf") {
        for p in parts {
            if let Some(serde_json::Value::Object(code)) = p.pointer_mut("/properties/code") {
                code.insert("enum".into(), serde_json::Value::Array(codes.clone()));
            }
        }
    }
}

/// Says in the document what [`super::strict`] enforces: an object schema with declared properties that a JSON
/// request body reaches takes no other field. A plain one gets `additionalProperties: false`. One composed with
/// `allOf` (a flattened struct such as `JobRequest`, whose members' fields are valid together) says so in its
/// description: its members, and the `oneOf` branches inside them, stay open, since `additionalProperties` would
/// make each member refuse the others' fields, and the keyword that states it for the whole
/// (`unevaluatedProperties: false`, JSON Schema 2020-12) stops schemathesis 4.32 from generating any case for the
/// operation. Free-form objects (no declared properties) stay free-form, as the check leaves them.
fn close_request_schemas(doc: &mut serde_json::Value) {
    use serde_json::Value;
    fn walk(
        doc: &Value,
        schema: &Value,
        composed: bool,
        out: &mut Vec<(String, &'static str)>,
        seen: &mut Vec<String>,
    ) {
        if let Some(name) =
            schema.get("$ref").and_then(Value::as_str).and_then(|r| r.strip_prefix("#/components/schemas/"))
        {
            let key = format!("{name}:{composed}");
            if seen.contains(&key) {
                return;
            }
            seen.push(key);
            if let Some(target) = doc.pointer(&format!("/components/schemas/{name}")) {
                walk_named(doc, target, Some(name), composed, out, seen);
            }
            return;
        }
        walk_named(doc, schema, None, composed, out, seen);
    }
    fn walk_named(
        doc: &Value,
        schema: &Value,
        name: Option<&str>,
        composed: bool,
        out: &mut Vec<(String, &'static str)>,
        seen: &mut Vec<String>,
    ) {
        if let Some(members) = schema.get("allOf").and_then(Value::as_array) {
            if let (Some(n), false) = (name, composed) {
                out.push((n.to_string(), "description"));
            }
            for m in members {
                walk(doc, m, true, out, seen);
            }
        }
        for key in ["oneOf", "anyOf"] {
            for b in schema.get(key).and_then(Value::as_array).into_iter().flatten() {
                walk(doc, b, composed, out, seen);
            }
        }
        if let Some(props) = schema.get("properties").and_then(Value::as_object) {
            if let (Some(n), false) = (name, composed) {
                out.push((n.to_string(), "additionalProperties"));
            }
            for p in props.values() {
                walk(doc, p, false, out, seen);
            }
        }
        if let Some(items) = schema.get("items") {
            walk(doc, items, false, out, seen);
        }
    }
    let mut marks = vec![];
    let mut seen = vec![];
    let bodies: Vec<Value> = doc
        .pointer("/paths")
        .and_then(Value::as_object)
        .into_iter()
        .flat_map(|paths| paths.values())
        .flat_map(|item| item.as_object().into_iter().flat_map(|ops| ops.values()))
        .filter_map(|op| op.pointer("/requestBody/content/application~1json/schema").cloned())
        .collect();
    for body in &bodies {
        walk(doc, body, false, &mut marks, &mut seen);
    }
    for (name, key) in marks {
        if let Some(Value::Object(s)) = doc.pointer_mut(&format!("/components/schemas/{name}")) {
            if key == "description" {
                let d = s.get(key).and_then(Value::as_str).unwrap_or("").trim_end().to_string();
                let closed = "No field other than those of its parts is accepted (422 `invalid-request`).";
                s.insert(key.to_string(), Value::String(format!("{d} {closed}").trim_start().to_string()));
            } else {
                s.insert(key.to_string(), Value::Bool(false));
            }
        }
    }
}

/// Responses every operation can give, added where an operation does not list them itself: 400 (malformed
/// parameters), 422 (unknown fields), 401/403/429 (API keys and rate limits, when configured), 500, 503 (too many
/// connections); and 408/413/415 on operations with a request body.
struct CommonResponses;

impl utoipa::Modify for CommonResponses {
    fn modify(&self, api: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::{ContentBuilder, Ref, ResponseBuilder};
        let problem = |desc: &str| {
            ResponseBuilder::new()
                .description(desc)
                .content(
                    "application/problem+json",
                    ContentBuilder::new().schema(Some(Ref::from_schema_name("Problem"))).build(),
                )
                .build()
        };
        for (path, item) in api.paths.paths.iter_mut() {
            let v1 = path.starts_with("/v1/");
            let ops =
                [item.get.as_mut(), item.post.as_mut(), item.put.as_mut(), item.delete.as_mut(), item.patch.as_mut()];
            for op in ops.into_iter().flatten() {
                let has_body = op.request_body.is_some();
                let mut add = vec![
                    ("400", "malformed parameters (invalid-request)"),
                    (
                        "422",
                        "a field or query parameter this request does not take (invalid-request, with a suggestion)",
                    ),
                    ("500", "internal error"),
                    (
                        "503",
                        "too many connections (too-many-connections) or request bodies in flight (memory-busy), \
                         with Retry-After",
                    ),
                ];
                if v1 {
                    add.push(("401", "an API key is required (unauthorized)"));
                    add.push(("403", "the API key is not accepted (forbidden)"));
                    add.push(("429", "rate limit (rate-limited), with Retry-After"));
                }
                if has_body {
                    add.push(("413", "body or limit exceeded"));
                    add.push(("415", "unsupported media type or format"));
                    add.push(("408", "the request body paused too long or came too slowly (body-timeout)"));
                }
                for (code, desc) in add {
                    op.responses.responses.entry(code.to_string()).or_insert_with(|| problem(desc).into());
                }
            }
        }
    }
}

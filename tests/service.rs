//! The service over real HTTP: the `kac serve` binary on a loopback port, driven with a plain HTTP client.
//! Uploads of every shared mesh, results equal to the library's, idempotency, cancellation, a panicking job,
//! every class of bad input with its problem code, a full queue, the OpenAPI document, and the README's curl
//! walkthrough run as written.

#[path = "support/multipart.rs"]
mod multipart_body;
use multipart_body::multipart;
#[path = "../crates/kac-core/tests/common/mod.rs"]
mod common;
#[path = "support/faults.rs"]
mod faults;

use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Server {
    child: Child,
    base: String,
    _dir: tempfile::TempDir,
}

impl Server {
    fn start(extra: &[&str]) -> Server {
        Self::start_in(tempfile::tempdir().unwrap(), extra).0
    }
    /// Starts on a given data directory; also returns the first line the server printed.
    fn start_in(dir: tempfile::TempDir, extra: &[&str]) -> (Server, Value) {
        let (extra, faults) = faults::split(extra);
        let mut child = Command::new(env!("CARGO_BIN_EXE_kac"))
            .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
            .arg(dir.path())
            .args(extra)
            .envs(faults)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let v: Value = serde_json::from_str(&line).unwrap_or_else(|_| panic!("first line: {line}"));
        let base = format!("http://{}", v["listening"].as_str().unwrap());
        (Server { child, base, _dir: dir }, v)
    }
    /// Stops the process (SIGKILL, or SIGTERM with `graceful`) and hands back its data directory.
    fn stop(mut self, graceful: bool) -> (tempfile::TempDir, std::process::ExitStatus) {
        if graceful {
            Command::new("kill").args(["-TERM", &self.child.id().to_string()]).status().unwrap();
        } else {
            self.child.kill().unwrap();
        }
        let status = self.child.wait().unwrap();
        let dir = std::mem::replace(&mut self._dir, tempfile::tempdir().unwrap());
        (dir, status)
    }
    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn agent() -> ureq::Agent {
    ureq::AgentBuilder::new().timeout(Duration::from_secs(120)).build()
}

/// (status, headers we look at, body as JSON or Null).
struct Reply {
    status: u16,
    location: Option<String>,
    content_type: String,
    etag: Option<String>,
    retry_after: Option<String>,
    body: Value,
    raw: Vec<u8>,
}

fn reply(r: Result<ureq::Response, ureq::Error>) -> Reply {
    let resp = match r {
        Ok(r) => r,
        Err(ureq::Error::Status(_, r)) => r,
        Err(e) => panic!("transport error: {e}"),
    };
    let status = resp.status();
    let location = resp.header("location").map(str::to_string);
    let content_type = resp.header("content-type").unwrap_or("").to_string();
    let etag = resp.header("etag").map(str::to_string);
    let retry_after = resp.header("retry-after").map(str::to_string);
    let mut raw = vec![];
    std::io::Read::read_to_end(&mut resp.into_reader(), &mut raw).unwrap();
    let body = serde_json::from_slice(&raw).unwrap_or(Value::Null);
    Reply { status, location, content_type, etag, retry_after, body, raw }
}

fn upload(s: &Server, bytes: &[u8], query: &str) -> Reply {
    reply(agent().post(&s.url(&format!("/v1/shapes{query}"))).send_bytes(bytes))
}

fn submit(s: &Server, req: Value) -> Reply {
    reply(agent().post(&s.url("/v1/jobs")).send_json(req))
}

fn wait_done(s: &Server, job: &str) -> Value {
    let t = Instant::now();
    loop {
        let r = reply(agent().get(&s.url(&format!("/v1/jobs/{job}"))).call());
        let st = r.body["status"].as_str().unwrap_or("").to_string();
        if ["succeeded", "failed", "canceled"].contains(&st.as_str()) {
            return r.body;
        }
        assert!(t.elapsed() < Duration::from_secs(120), "job {job} stuck in {st}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn assert_problem(r: &Reply, status: u16, code: &str) {
    assert_eq!(r.status, status, "{}", String::from_utf8_lossy(&r.raw));
    assert_eq!(r.content_type, "application/problem+json");
    assert_eq!(r.body["code"], code, "{}", r.body);
    assert_eq!(r.body["type"], format!("/problems/{code}"));
    assert_eq!(r.body["status"], status);
    assert!(r.body["title"].is_string() && r.body["detail"].is_string());
}

fn icosphere_off(level: u32) -> Vec<u8> {
    let m = kac_core::geometry::generate::icosphere(level);
    kac_core::io::write::off(&m).into_bytes()
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn every_shared_mesh_uploads_and_matches_the_library() {
    let dir = common::shared_data("every_shared_mesh_uploads_and_matches_the_library");
    let s = Server::start(&[]);
    let mut count = 0;
    for sub in ["obj", "off", "ply", "stl", "gltf", "tet", "points"] {
        let Ok(entries) = std::fs::read_dir(dir.join(sub)) else { continue };
        for e in entries.flatten() {
            let path = e.path();
            let bytes = std::fs::read(&path).unwrap();
            let ext = path.extension().and_then(|x| x.to_str()).unwrap_or("").to_lowercase();
            let lib = kac_core::load(&path, None, &Default::default(), &Default::default());
            let Some(fmt) = kac_core::Format::from_name(&ext) else { continue };
            let r = upload(&s, &bytes, &format!("?format={}", fmt.name()));
            match lib {
                Ok((v, _)) => {
                    assert!(r.status == 201 || r.status == 200, "{}: {} {}", path.display(), r.status, r.body);
                    assert_eq!(r.body["id"], v.id.hex(), "{}", path.display());
                    assert_eq!(r.body["summary"]["vertices"], v.shape.vertex_count());
                    assert_eq!(r.location.as_deref(), Some(format!("/v1/shapes/{}", v.id.hex()).as_str()));
                    count += 1;
                }
                Err(err) => assert_problem(&r, r.status, kac_engine::Code::from(&err).as_str()),
            }
        }
    }
    assert!(count >= 20, "only {count} shared meshes uploaded");
    let list = reply(agent().get(&s.url("/v1/shapes?limit=1000")).call());
    assert!(list.body["total"].as_u64().unwrap() >= 15);
}

#[test]
fn spectrum_shape_dna_and_hks_equal_the_library_and_requests_are_idempotent() {
    let s = Server::start(&[]);
    let off = icosphere_off(3);
    let first = upload(&s, &off, "?format=off");
    assert_eq!(first.status, 201);
    let again = upload(&s, &off, "");
    assert_eq!((again.status, &again.location), (200, &first.location), "idempotent upload (format sniffed)");
    let id = first.body["id"].as_str().unwrap().to_string();

    // The library on the same shape.
    let v = kac_core::load_bytes(&off, kac_core::Format::Off, &Default::default(), &Default::default()).unwrap();
    let op = kac_core::operators::build(&v.shape, &Default::default()).unwrap();
    let opts = kac_core::spectrum::EigenOptions { k: 12, ..Default::default() };
    let lib = kac_core::spectrum::eigs(&op.pair, &opts, None, Default::default()).unwrap();

    let j = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 12, "eigenvectors": true }));
    assert_eq!(j.status, 202);
    let job = j.body["id"].as_str().unwrap().to_string();
    assert_eq!(j.location.as_deref(), Some(format!("/v1/jobs/{job}").as_str()));
    let same = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 12, "eigenvectors": true }));
    assert_eq!((same.status, same.body["id"].as_str()), (200, Some(job.as_str())), "idempotent job");
    let done = wait_done(&s, &job);
    assert_eq!(done["status"], "succeeded", "{done}");
    let res = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call());
    let got: Vec<f64> = serde_json::from_value(res.body["eigenvalues"].clone()).unwrap();
    for (a, b) in got.iter().zip(&lib.values) {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
    }
    // Completeness is checked by default: the inertia count below a shift above λ₁₂ agrees with the pairs found.
    let c = &res.body["solver"]["completeness"];
    assert_eq!(c, &res.body["completeness"], "also at the top level");
    assert_eq!(c["complete"], true, "{}", res.body);
    if c["method"] == "inertia" {
        let below = c["below_shift"].as_u64().unwrap() as usize;
        assert!(below >= 12 && c["shift"].as_f64().unwrap() > got[11], "{c}");
    }
    // `solver.verify: false` is the documented escape: another job, and no check.
    let vj = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 12, "solver": { "verify": false } }));
    assert_ne!(vj.body["id"], j.body["id"], "verify is part of the request");
    let vdone = wait_done(&s, vj.body["id"].as_str().unwrap());
    let vres = reply(agent().get(&s.url(vdone["result"].as_str().unwrap())).call());
    assert!(vres.body["solver"]["completeness"].is_null(), "{}", vres.body);
    let unverified: Vec<f64> = serde_json::from_value(vres.body["eigenvalues"].clone()).unwrap();
    assert_eq!(unverified.len(), 12);
    // Immutable, with a strong ETag and 304 on If-None-Match.
    let etag = res.etag.clone().unwrap();
    assert!(etag.starts_with('"'));
    let r304 = reply(agent().get(&s.url(&format!("/v1/results/{job}"))).set("If-None-Match", &etag).call());
    assert_eq!(r304.status, 304);
    // The eigenvectors as .npy and as a coloured PLY.
    let npy = reply(agent().get(&s.url(&format!("/v1/results/{job}/arrays/eigenvectors.npy"))).call());
    assert_eq!(npy.status, 200);
    assert!(npy.raw.starts_with(b"\x93NUMPY"));
    let ply = reply(agent().get(&s.url(&format!("/v1/results/{job}/arrays/eigenvectors.ply?column=1"))).call());
    assert!(ply.raw.starts_with(b"ply\n") && String::from_utf8_lossy(&ply.raw[..400]).contains("property uchar red"));

    // Shape-DNA and HKS after the spectrum: equal to the library's, and no eigensolve needed (k ≤ 12 cached).
    let basis = kac_core::descriptors::Basis::of(&lib, &op.pair);
    let m = kac_core::descriptors::shape_dna::Measures::of(&v.summary(), None);
    let dna_opts = kac_core::descriptors::shape_dna::ShapeDnaOptions {
        k: 8,
        normalization: kac_core::descriptors::shape_dna::Normalization::Area,
        ..Default::default()
    };
    let lib_dna = kac_core::descriptors::shape_dna::shape_dna(&lib.values, basis.zero_tol, &m, &dna_opts).unwrap();
    let j =
        submit(&s, json!({ "shape_id": id, "analysis": "shape-dna", "options": { "k": 8, "normalization": "area" } }));
    let done = wait_done(&s, j.body["id"].as_str().unwrap());
    let res = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call());
    let got: Vec<f64> = serde_json::from_value(res.body["shape_dna"]["values"].clone()).unwrap();
    assert_eq!(res.body["eigenpairs_reused"], true, "shape-DNA after the spectrum solves nothing again");
    for (a, b) in got.iter().zip(&lib_dna.values) {
        assert!((a - b).abs() <= 1e-10 * b.abs(), "{a} vs {b}");
    }
    let times = [0.1, 1.0];
    let hks_opts = kac_core::descriptors::signatures::HksOptions { times: Some(times.to_vec()), ..Default::default() };
    let lib_hks = kac_core::descriptors::signatures::hks(&basis, &hks_opts).unwrap();
    let j = submit(&s, json!({ "shape_id": id, "analysis": "hks", "k": 12, "options": { "times": times } }));
    let done = wait_done(&s, j.body["id"].as_str().unwrap());
    assert_eq!(done["status"], "succeeded", "{done}");
    let res = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call());
    assert_eq!(res.body["eigenpairs_reused"], true, "HKS after the spectrum solves nothing again");
    let rows = res.body["arrays"]["hks"]["values"].as_array().unwrap();
    assert_eq!(rows.len(), 642);
    for (i, row) in rows.iter().enumerate().step_by(37) {
        for c in 0..2 {
            let (a, b) = (row[c].as_f64().unwrap(), lib_hks.values[(i, c)]);
            assert!((a - b).abs() <= 1e-10 * b.abs(), "vertex {i}: {a} vs {b}");
        }
    }
    // The synchronous form: upload + analysis in one request, the result within `wait`.
    let r = reply(
        agent()
            .post(&s.url("/v1/analyze?wait=60&format=off&analysis=%7B%22analysis%22%3A%22trees%22%7D"))
            .send_bytes(&icosphere_off(1)),
    );
    assert_eq!(r.status, 200, "{}", r.body);
    assert!(r.body["trees"]["log_count"].is_number());
    // Compare: distances between stored shapes, nearest neighbours.
    upload(&s, &icosphere_off(2), "?format=off");
    let c = reply(agent().post(&s.url("/v1/compare")).send_json(json!({ "k": 5, "normalization": "area" })));
    assert_eq!(c.status, 200, "{}", c.body);
    assert_eq!(c.body["distances"].as_array().unwrap().len(), 3);
    // Jobs list with filters.
    let l = reply(agent().get(&s.url(&format!("/v1/jobs?shape_id={id}&status=succeeded"))).call());
    assert_eq!(l.body["total"], 4, "spectrum, spectrum without verify, shape-dna, hks");
    // Progress as server-sent events ends with the finished job.
    let ev = reply(agent().get(&s.url(&format!("/v1/jobs/{job}/events"))).call());
    let text = String::from_utf8_lossy(&ev.raw);
    assert!(
        ev.content_type.starts_with("text/event-stream") && text.contains("event: job") && text.contains("succeeded")
    );
}

/// A server with one worker, room for three jobs, jobs that wait 1.5 s before computing, and `trees` jobs that
/// panic; and a stored sphere.
fn slow_server() -> (Server, String) {
    let s = Server::start(&[
        "--workers",
        "1",
        "--queue-capacity",
        "3",
        "--test-job-delay-ms",
        "1500",
        "--test-panic-analysis",
        "trees",
    ]);
    let id = upload(&s, &icosphere_off(2), "?format=off").body["id"].as_str().unwrap().to_string();
    (s, id)
}

#[test]
fn a_full_queue_answers_503_with_retry_after() {
    let (s, id) = slow_server();
    for k in 3..6 {
        assert_eq!(submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": k })).status, 202);
    }
    let d = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 6 }));
    assert_problem(&d, 503, "queue-full");
    assert!(d.retry_after.as_deref().is_some_and(|v| v.parse::<u64>().is_ok()));
}

#[test]
fn a_job_canceled_while_queued_never_runs_and_can_be_submitted_again() {
    let (s, id) = slow_server();
    let a = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 3 }));
    let b = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 4 }));
    let b_id = b.body["id"].as_str().unwrap();
    let cancel = reply(agent().post(&s.url(&format!("/v1/jobs/{b_id}/cancel"))).call());
    assert_eq!(cancel.status, 202);
    let done = wait_done(&s, b_id);
    assert_eq!((done["status"].as_str(), &done["started_at"]), (Some("canceled"), &Value::Null), "{done}");
    assert_eq!(wait_done(&s, a.body["id"].as_str().unwrap())["status"], "succeeded");
    let again = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 4 }));
    assert_eq!(again.status, 202);
    assert_eq!(wait_done(&s, b_id)["status"], "succeeded");
}

#[test]
fn a_panicking_job_fails_alone_and_the_server_keeps_serving() {
    let (s, id) = slow_server();
    let c = submit(&s, json!({ "shape_id": id, "analysis": "trees" }));
    let failed = wait_done(&s, c.body["id"].as_str().unwrap());
    assert_eq!((failed["status"].as_str(), failed["error"]["code"].as_str()), (Some("failed"), Some("job-panicked")));
    assert_eq!(reply(agent().get(&s.url("/livez")).call()).status, 200);
    let e = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 6 }));
    assert_eq!(wait_done(&s, e.body["id"].as_str().unwrap())["status"], "succeeded");
}

#[test]
fn every_class_of_bad_input_gets_its_problem() {
    let s = Server::start(&["--max-body-bytes", "20000", "--max-vertices", "100", "--max-k", "50"]);
    assert_problem(&upload(&s, b"certainly not a mesh", ""), 415, "unknown-format");
    assert_problem(
        &upload(&s, b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "?format=off"),
        422,
        "index-out-of-range",
    );
    assert_problem(
        &upload(&s, b"OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "?format=off"),
        422,
        "non-finite-value",
    );
    assert_problem(&upload(&s, b"OFF\n3 1 0\n0 0 0\n1 0 0\n", "?format=off"), 422, "truncated-input");
    assert_problem(&upload(&s, b"", "?format=off"), 400, "invalid-request");
    assert_problem(&upload(&s, b"v 0 0 0\n", "?format=nope"), 400, "invalid-request");
    assert_problem(&upload(&s, &vec![b' '; 30000], "?format=off"), 413, "body-too-large");
    assert_problem(&upload(&s, &icosphere_off(2), "?format=off"), 413, "limit-exceeded");
    let id = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    assert_problem(&submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 51 })), 413, "k-too-large");
    assert_problem(&submit(&s, json!({ "shape_id": "0000", "analysis": "spectrum" })), 404, "not-found");
    assert_problem(&submit(&s, json!({ "shape_id": id, "analysis": "sing" })), 400, "invalid-json");
    assert_problem(
        &submit(&s, json!({ "shape_id": id, "analysis": "hks", "options": { "count": "many" } })),
        400,
        "invalid-json",
    );
    let raw = reply(agent().post(&s.url("/v1/jobs")).set("content-type", "text/plain").send_string("{}"));
    assert_problem(&raw, 415, "unsupported-media-type");
    assert_problem(&reply(agent().get(&s.url("/v1/nothing")).call()), 404, "route-not-found");
    assert_problem(&reply(agent().put(&s.url("/v1/shapes")).call()), 405, "method-not-allowed");
    assert_problem(&reply(agent().get(&s.url("/v1/jobs/abc")).call()), 404, "not-found");
    assert_problem(&reply(agent().get(&s.url("/v1/results/abc")).call()), 404, "not-found");
    // An analysis that cannot apply is refused at submission, never computed: geodesics of a graph.
    let g = serde_json::to_vec(&kac_core::io::write::json(&kac_core::Shape::Graph(
        kac_core::geometry::generate::petersen_graph(),
    )))
    .unwrap();
    let gid = upload(&s, &g, "?format=json").body["id"].as_str().unwrap().to_string();
    let j = submit(&s, json!({ "shape_id": gid, "analysis": "geodesic", "sources": [0] }));
    assert_problem(&j, 422, "unsupported");
    assert!(j.body["detail"].as_str().unwrap().contains("triangle mesh"), "{}", j.body);
    // Every problem type is documented.
    let doc = reply(agent().get(&s.url("/problems/queue-full")).call());
    assert_eq!(doc.status, 200);
    assert!(doc.body["description"].is_string());
}

#[test]
fn openapi_document_is_served_committed_and_documented() {
    let s = Server::start(&[]);
    let served = reply(agent().get(&s.url("/openapi.json")).call());
    assert_eq!(served.status, 200);
    let committed: Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("openapi/openapi.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        served.body, committed,
        "openapi/openapi.json is stale: run `cargo run -- openapi > openapi/openapi.json`"
    );
    // Every $ref points at a schema the document defines.
    fn refs(v: &Value, out: &mut Vec<String>) {
        match v {
            Value::Object(m) => m.iter().for_each(|(k, x)| match (k.as_str(), x) {
                ("$ref", Value::String(r)) => out.push(r.clone()),
                _ => refs(x, out),
            }),
            Value::Array(a) => a.iter().for_each(|x| refs(x, out)),
            _ => {}
        }
    }
    let mut all = vec![];
    refs(&committed, &mut all);
    for r in &all {
        let name = r.trim_start_matches("#/components/schemas/");
        assert!(committed["components"]["schemas"][name].is_object(), "dangling reference {r}");
    }
    for path in ["/v1/shapes", "/v1/jobs", "/v1/jobs/{id}", "/v1/results/{id}", "/v1/analyze", "/v1/compare"] {
        assert!(committed["paths"][path].is_object(), "{path} is not documented");
    }
    let docs = reply(agent().get(&s.url("/docs/")).call());
    assert_eq!(docs.status, 200);
    assert!(String::from_utf8_lossy(&docs.raw).to_lowercase().contains("swagger"));
    // The UI's assets come from the binary, not from a CDN.
    let html = String::from_utf8_lossy(&docs.raw).to_string();
    assert!(!html.contains("https://"), "the docs page loads remote assets");
}

#[test]
fn readme_curl_walkthrough_runs_as_written() {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let start = readme.find("<!-- walkthrough:start -->").expect("README has a walkthrough");
    let end = readme.find("<!-- walkthrough:end -->").unwrap();
    let block = &readme[start..end];
    let script: String =
        block.split("```sh").skip(1).map(|b| b.split("```").next().unwrap_or("")).collect::<Vec<_>>().join("\n");
    let s = Server::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new("bash")
        .args(["-euo", "pipefail", "-c", &script])
        .current_dir(dir.path())
        .env("KAC", &s.base)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "walkthrough failed:\n{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("\"eigenvalues\"") && stdout.contains("\"shape_dna\""), "{stdout}");
}

#[test]
fn kill_9_mid_queue_loses_nothing_and_requeues_running_jobs() {
    let (s, _) = Server::start_in(tempfile::tempdir().unwrap(), &["--workers", "1", "--test-job-delay-ms", "400"]);
    let shape = upload(&s, &icosphere_off(3), "?format=off").body["id"].as_str().unwrap().to_string();
    let ids: Vec<String> = (3..8)
        .map(|k| {
            let r = submit(&s, json!({ "shape_id": shape, "analysis": "spectrum", "k": k }));
            assert_eq!(r.status, 202);
            r.body["id"].as_str().unwrap().to_string()
        })
        .collect();
    let first = wait_done(&s, &ids[0]);
    assert_eq!(first["status"], "succeeded");
    let before = reply(agent().get(&s.url(&format!("/v1/results/{}", ids[0]))).call());
    // The second is running or about to; the rest are queued. SIGKILL now.
    let (dir, _) = s.stop(false);
    let (s, hello) = Server::start_in(dir, &[]);
    assert!(hello["recovered_jobs"].as_u64().unwrap() >= 3, "{hello}");
    // The finished result is intact: same bytes, same ETag.
    let after = reply(agent().get(&s.url(&format!("/v1/results/{}", ids[0]))).call());
    assert_eq!((after.status, &after.raw, &after.etag), (200, &before.raw, &before.etag));
    // Every accepted job finishes.
    for id in &ids {
        let done = wait_done(&s, id);
        assert_eq!(done["status"], "succeeded", "{done}");
        let r = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call());
        assert_eq!(r.body["eigenvalues"].as_array().unwrap().len(), r.body["k"].as_u64().unwrap() as usize);
    }
    // The shape is still stored, parsed again from its upload.
    let g = reply(agent().get(&s.url(&format!("/v1/shapes/{shape}"))).call());
    assert_eq!((g.status, g.body["summary"]["vertices"].as_u64()), (200, Some(642)));
    let again = submit(&s, json!({ "shape_id": shape, "analysis": "spectrum", "k": 3 }));
    assert_eq!(again.status, 200, "the finished job is found again after the restart");
}

#[test]
fn sigterm_drains_and_the_next_start_finishes_the_queue() {
    let (s, _) = Server::start_in(
        tempfile::tempdir().unwrap(),
        &["--workers", "1", "--test-job-delay-ms", "700", "--shutdown-grace-s", "5"],
    );
    let shape = upload(&s, &icosphere_off(2), "?format=off").body["id"].as_str().unwrap().to_string();
    let a = submit(&s, json!({ "shape_id": shape, "analysis": "spectrum", "k": 3 })).body["id"]
        .as_str()
        .unwrap()
        .to_string();
    let b = submit(&s, json!({ "shape_id": shape, "analysis": "spectrum", "k": 4 })).body["id"]
        .as_str()
        .unwrap()
        .to_string();
    std::thread::sleep(Duration::from_millis(200)); // a is running, b waits
    let t = Instant::now();
    let (dir, status) = s.stop(true);
    assert!(status.success(), "SIGTERM exits cleanly: {status:?}");
    assert!(t.elapsed() < Duration::from_secs(5), "the running job finished within the grace period");
    let (s, _) = Server::start_in(dir, &[]);
    assert_eq!(wait_done(&s, &a)["status"], "succeeded", "the running job finished before exit");
    assert_eq!(wait_done(&s, &b)["status"], "succeeded", "the queued job ran after the restart");
}

#[test]
fn metrics_change_as_requests_are_served() {
    let s = Server::start(&[]);
    let metric = |name: &str| -> f64 {
        let r = reply(agent().get(&s.url("/metrics")).call());
        assert!(r.content_type.starts_with("text/plain"));
        let text = String::from_utf8_lossy(&r.raw).to_string();
        text.lines()
            .filter(|l| l.starts_with(name) && !l.starts_with('#'))
            .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
            .sum()
    };
    let before = metric("kac_http_requests_total{method=\"POST\",route=\"/v1/shapes\",status=\"201\"}");
    // 2562 vertices: the sparse eigensolver runs (the dense path has no block steps to count).
    let id = upload(&s, &icosphere_off(4), "?format=off").body["id"].as_str().unwrap().to_string();
    assert_eq!(metric("kac_http_requests_total{method=\"POST\",route=\"/v1/shapes\",status=\"201\"}"), before + 1.0);
    let j = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 5 }));
    wait_done(&s, j.body["id"].as_str().unwrap());
    let j = submit(&s, json!({ "shape_id": id, "analysis": "hks", "k": 5, "options": { "count": 4 } }));
    wait_done(&s, j.body["id"].as_str().unwrap());
    assert_eq!(metric("kac_eigensolves_total"), 1.0);
    assert!(metric("kac_eigenpair_cache_hits_total") >= 1.0);
    assert!(metric("kac_eigensolver_solves_total") > 0.0 && metric("kac_eigensolver_block_steps_total") > 0.0);
    assert_eq!(metric("kac_jobs{status=\"succeeded\"}"), 2.0);
    assert_eq!(metric("kac_job_duration_seconds_count{analysis=\"hks\",status=\"succeeded\"}"), 1.0);
    assert!(metric("kac_http_request_duration_seconds_count{route=\"/v1/jobs/{id}\"}") >= 1.0);
    assert_eq!(metric("kac_queue_depth"), 0.0);
    // Every response carries a request id; one sent is echoed.
    let r = agent().get(&s.url("/livez")).set("x-request-id", "abc-123").call().unwrap();
    assert_eq!(r.header("x-request-id"), Some("abc-123"));
}

#[test]
fn api_keys_and_rate_limits() {
    let s = Server::start(&["--api-keys", "alpha-key,beta-key", "--rate-limit-per-minute", "3"]);
    // Health, metrics and the API description stay public.
    for p in ["/livez", "/readyz", "/metrics", "/openapi.json", "/problems/unauthorized"] {
        assert_eq!(reply(agent().get(&s.url(p)).call()).status, 200, "{p}");
    }
    let r = reply(agent().get(&s.url("/v1/shapes")).call());
    assert_problem(&r, 401, "unauthorized");
    let r = reply(agent().get(&s.url("/v1/shapes")).set("Authorization", "Bearer gamma-key").call());
    assert_problem(&r, 403, "forbidden");
    for _ in 0..3 {
        assert_eq!(reply(agent().get(&s.url("/v1/shapes")).set("Authorization", "Bearer beta-key").call()).status, 200);
    }
    let r = reply(agent().get(&s.url("/v1/shapes")).set("Authorization", "Bearer beta-key").call());
    assert_problem(&r, 429, "rate-limited");
    assert!(r.retry_after.as_deref().and_then(|v| v.parse::<u64>().ok()).is_some_and(|v| v >= 1));
    // Buckets are per key.
    assert_eq!(reply(agent().get(&s.url("/v1/shapes")).set("Authorization", "Bearer alpha-key").call()).status, 200);
}

#[test]
fn a_job_past_its_time_limit_fails_with_job_timeout() {
    let s = Server::start(&["--job-timeout-s", "1", "--test-job-delay-ms", "2500"]);
    let id = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    let j = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 3 }));
    let done = wait_done(&s, j.body["id"].as_str().unwrap());
    assert_eq!(
        (done["status"].as_str(), done["error"]["code"].as_str()),
        (Some("failed"), Some("job-timeout")),
        "{done}"
    );
    // A wait longer than --max-wait-s is cut to it: the synchronous form answers 202 within the bound.
    let s = Server::start(&["--max-wait-s", "1", "--test-job-delay-ms", "3000"]);
    let t = Instant::now();
    let r = reply(
        agent()
            .post(&s.url("/v1/analyze?wait=30&format=off&analysis=%7B%22analysis%22%3A%22trees%22%7D"))
            .send_bytes(&icosphere_off(1)),
    );
    assert_eq!(r.status, 202, "{}", r.body);
    assert!(t.elapsed() < Duration::from_secs(3));
}

#[test]
fn results_and_shapes_outlive_the_memory_caches() {
    // One byte of memory cache: every result and shape is read back from the store.
    let s = Server::start(&["--store-cache-bytes", "1"]);
    let id = upload(&s, &icosphere_off(2), "?format=off").body["id"].as_str().unwrap().to_string();
    let j = submit(&s, json!({ "shape_id": id, "analysis": "hks", "k": 8, "options": { "count": 3 } }));
    let done = wait_done(&s, j.body["id"].as_str().unwrap());
    let a = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call());
    let b = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call());
    assert_eq!((a.status, &a.etag, &a.raw), (200, &b.etag, &b.raw));
    let npy = reply(agent().get(&s.url(&format!("{}/arrays/hks.npy", done["result"].as_str().unwrap()))).call());
    assert_eq!(npy.status, 200);
    let g = reply(agent().get(&s.url(&format!("/v1/shapes/{id}"))).call());
    assert_eq!(g.body["summary"]["vertices"], 162);
}

/// Strict requests: a misspelt field in every analysis is a 422 `invalid-request` naming its JSON pointer and the
/// closest valid name; a field one level too high says where it belongs; a top-level `boundary` on a spectrum job no
/// longer yields the Neumann spectrum under the same job id; compare requests, the analysis of `/v1/analyze` and
/// query parameters are checked the same way.
#[test]
fn misspelt_and_misplaced_fields_are_refused_with_a_suggestion() {
    let s = Server::start(&[]);
    let id = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    let analyses = [
        "spectrum",
        "hks",
        "si-hks",
        "wks",
        "gps",
        "shape-dna",
        "heat",
        "geodesic",
        "trees",
        "embed",
        "smooth",
        "interpolate",
    ];
    for a in analyses {
        let r = submit(&s, json!({ "shape_id": id, "analysis": a, "operatr": {} }));
        assert_problem(&r, 422, "invalid-request");
        assert_eq!(r.body["pointer"], "/operatr", "{a}: {}", r.body);
        let expected = if ["geodesic", "trees"].contains(&a) { Value::Null } else { json!("operator") };
        assert_eq!(r.body["suggestion"], expected, "{a}: {}", r.body);
    }
    // Geodesics take no operator: a misspelt field of their own gets its suggestion too.
    let r = submit(&s, json!({ "shape_id": id, "analysis": "geodesic", "sources": [0], "optoins": {} }));
    assert_eq!((r.status, r.body["suggestion"].as_str()), (422, Some("options")), "{}", r.body);
    let r = submit(&s, json!({ "shape_id": id, "analysis": "shape-dna", "options": { "normalisation": "area" } }));
    assert_problem(&r, 422, "invalid-request");
    assert_eq!(
        (r.body["pointer"].as_str(), r.body["suggestion"].as_str()),
        (Some("/options/normalisation"), Some("normalization"))
    );
    assert!(r.body["detail"].as_str().unwrap().contains("did you mean `normalization`?"), "{}", r.body);
    let r = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "boundary": "dirichlet" }));
    assert_problem(&r, 422, "invalid-request");
    assert_eq!(r.body["belongs_in"], "operator", "{}", r.body);
    assert!(r.body["detail"].as_str().unwrap().contains("`boundary` belongs in `operator`"), "{}", r.body);
    let r = submit(&s, json!({ "shape_id": id, "analysis": "hks", "scale_invariant": true }));
    assert_problem(&r, 422, "invalid-request");
    let r = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "solver": { "verfy": false } }));
    assert_eq!((r.status, r.body["pointer"].as_str()), (422, Some("/solver/verfy")), "{}", r.body);
    // Compare, the analysis of /v1/analyze, and query parameters.
    let r = reply(agent().post(&s.url("/v1/compare")).send_json(json!({ "shape_ids": [id], "normalisation": "area" })));
    assert_problem(&r, 422, "invalid-request");
    assert_eq!(r.body["suggestion"], "normalization");
    let r = reply(
        agent()
            .post(&s.url("/v1/analyze?format=off&analysis=%7B%22analysis%22%3A%22spectrum%22%2C%22kk%22%3A3%7D"))
            .send_bytes(&icosphere_off(1)),
    );
    assert_problem(&r, 422, "invalid-request");
    assert_eq!((r.body["pointer"].as_str(), r.body["suggestion"].as_str()), (Some("/kk"), Some("k")));
    let r = reply(agent().post(&s.url("/v1/analyze?wiat=1&format=off")).send_bytes(&icosphere_off(1)));
    assert_problem(&r, 422, "invalid-request");
    assert_eq!((r.body["pointer"].as_str(), r.body["suggestion"].as_str()), (Some("?wiat"), Some("wait")));
    let r = reply(agent().get(&s.url("/v1/shapes?limt=5")).call());
    assert_problem(&r, 422, "invalid-request");
    // The valid forms still work.
    let r =
        submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 3, "operator": { "boundary": "neumann" } }));
    assert_eq!(r.status, 202, "{}", r.body);
}

/// Issue 15: sixteen simultaneous uploads of one new shape, fifty rounds, a SIGKILL after every round (in every
/// other round while the uploads are still arriving). Every answer that came back is 201 for exactly one caller
/// and 200 for the rest, all naming one id and one stored format; in rounds with two formats of one mesh (OFF and
/// PLY) the stored file is the winner's. After each restart every listed shape is readable and every shape a
/// caller was told about is listed, so no accepted upload is lost and the file and the record never disagree.
#[test]
fn simultaneous_uploads_store_one_shape_and_survive_kill_9() {
    const UPLOADERS: usize = 16;
    let mut dir = tempfile::tempdir().unwrap();
    let mut accepted: Vec<String> = vec![];
    for round in 0..50 {
        let (s, _) = Server::start_in(dir, &[]);
        // What the last round left: every shape a caller was told about, each listed one readable.
        let listed = reply(agent().get(&s.url("/v1/shapes?limit=1000")).call());
        let items = listed.body["items"].as_array().unwrap_or_else(|| panic!("{}", listed.body)).clone();
        for id in &accepted {
            assert!(items.iter().any(|i| i["id"] == id.as_str()), "round {round}: accepted shape {id} is not listed");
        }
        for item in &items {
            let g = reply(agent().get(&s.url(&format!("/v1/shapes/{}", item["id"].as_str().unwrap()))).call());
            assert_eq!(g.status, 200, "round {round}: listed shape {item} is not readable: {}", g.body);
            assert_eq!(g.body["format"], item["format"], "round {round}");
        }
        let mut mesh = kac_core::geometry::generate::icosphere(2);
        for p in &mut mesh.vertices {
            p[0] += round as f64;
        }
        let off = kac_core::io::write::off(&mesh).into_bytes();
        let ply = kac_core::io::write::ply(&kac_core::Shape::TriangleMesh(mesh), round % 4 == 1, None);
        let two_formats = round % 2 == 1;
        let kill_midway = round % 2 == 0 && round > 0;
        let barrier = std::sync::Arc::new(std::sync::Barrier::new(UPLOADERS));
        let url = s.url("/v1/shapes");
        let threads: Vec<_> = (0..UPLOADERS)
            .map(|i| {
                let (barrier, url) = (barrier.clone(), url.clone());
                let (bytes, format) =
                    if two_formats && i % 2 == 1 { (ply.clone(), "ply") } else { (off.clone(), "off") };
                std::thread::spawn(move || {
                    barrier.wait();
                    match agent().post(&format!("{url}?format={format}")).send_bytes(&bytes) {
                        Ok(r) => Some((r.status(), r.into_json::<Value>().unwrap())),
                        Err(ureq::Error::Status(c, r)) => Some((c, r.into_json::<Value>().unwrap_or(Value::Null))),
                        Err(_) if kill_midway => None,
                        Err(e) => panic!("transport error: {e}"),
                    }
                })
            })
            .collect();
        let mut server = Some(s);
        let mut killed = None;
        if kill_midway {
            std::thread::sleep(Duration::from_millis(2 * (round as u64 % 7)));
            killed = server.take().map(|s| s.stop(false).0);
        }
        let answers: Vec<(u16, Value)> = threads.into_iter().filter_map(|t| t.join().unwrap()).collect();
        for (code, body) in &answers {
            assert!(*code == 200 || *code == 201, "round {round}: {code} {body}");
        }
        let created = answers.iter().filter(|(c, _)| *c == 201).count();
        if !kill_midway {
            assert_eq!(answers.len(), UPLOADERS);
            assert_eq!(created, 1, "round {round}: exactly one caller creates the shape");
        } else {
            assert!(created <= 1, "round {round}: {created} callers were told they created the shape");
        }
        if let Some((_, first)) = answers.first() {
            for (_, body) in &answers {
                assert_eq!((&body["id"], &body["format"]), (&first["id"], &first["format"]), "round {round}");
            }
            accepted.push(first["id"].as_str().unwrap().to_string());
        }
        dir = match (killed, server) {
            (Some(d), _) => d,
            (None, Some(s)) => s.stop(false).0,
            (None, None) => unreachable!("the server is killed midway or stopped here"),
        };
    }
    assert!(accepted.len() >= 25, "most rounds were answered: {}", accepted.len());
    // The last one once more, through a job: the stored file parses as its record says.
    let (s, _) = Server::start_in(dir, &[]);
    let last = accepted.last().unwrap();
    let r = submit(&s, json!({ "shape_id": last, "analysis": "spectrum", "k": 4 }));
    assert_eq!(r.status, 202, "{}", r.body);
    assert_eq!(wait_done(&s, r.body["id"].as_str().unwrap())["status"], "succeeded");
}

/// Issue 15, item 7: what a hostile client sends gets a 4xx with a useful detail, never a 5xx, a hang or a crash.
#[test]
fn hostile_requests_get_a_4xx_that_says_what_is_wrong() {
    let s = Server::start(&[]);
    let off = icosphere_off(1);
    let id = upload(&s, &off, "?format=off").body["id"].as_str().unwrap().to_string();
    // wait=NaN (and infinities) is refused before any job is queued; the server keeps answering.
    for w in ["NaN", "inf", "-inf"] {
        let r = reply(
            agent()
                .post(
                    &s.url(&format!("/v1/analyze?format=off&wait={w}&analysis=%7B%22analysis%22%3A%22spectrum%22%7D")),
                )
                .send_bytes(&off),
        );
        assert_problem(&r, 400, "invalid-request");
        assert!(r.body["detail"].as_str().unwrap().contains("finite"), "{}", r.body);
    }
    assert_eq!(reply(agent().get(&s.url("/v1/jobs")).call()).body["total"], 0, "no job was queued");
    // k = 0: one answer on every path, also once a spectrum of the shape is cached.
    let done = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 5 }));
    wait_done(&s, done.body["id"].as_str().unwrap());
    assert_problem(&submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 0 })), 422, "invalid-k");
    assert_problem(&submit(&s, json!({ "shape_id": id, "analysis": "hks", "k": 0 })), 422, "invalid-k");
    assert_problem(
        &submit(&s, json!({ "shape_id": id, "analysis": "shape-dna", "options": { "k": 0 } })),
        422,
        "invalid-k",
    );
    let r = reply(
        agent()
            .post(&s.url("/v1/analyze?format=off&analysis=%7B%22analysis%22%3A%22spectrum%22%2C%22k%22%3A0%7D"))
            .send_bytes(&off),
    );
    assert_problem(&r, 422, "invalid-k");
    // A compressed body is refused as such, not sniffed as some format.
    let r = reply(agent().post(&s.url("/v1/shapes")).set("content-encoding", "gzip").send_bytes(&[0x1f, 0x8b, 8, 0]));
    assert_problem(&r, 415, "unsupported-media-type");
    assert!(r.body["detail"].as_str().unwrap().contains("gzip"), "{}", r.body);
    let r = reply(
        agent()
            .post(&s.url("/v1/jobs"))
            .set("content-encoding", "br")
            .set("content-type", "application/json")
            .send_string("{}"),
    );
    assert_problem(&r, 415, "unsupported-media-type");
    // OFF bytes declared as STL: the format tried, what the bytes look like, how they begin (was 413
    // "element count 856307232").
    let r = reply(agent().post(&s.url("/v1/shapes")).set("content-type", "model/stl").send_bytes(&off));
    assert_problem(&r, 415, "format-mismatch");
    let detail = r.body["detail"].as_str().unwrap();
    assert!(detail.contains("not stl") && detail.contains("look like off") && detail.contains("OFF"), "{detail}");
    // A PLY declared as OBJ, likewise.
    let ply = kac_core::io::write::ply(
        &kac_core::Shape::TriangleMesh(kac_core::geometry::generate::icosphere(1)),
        true,
        None,
    );
    let r = upload(&s, &ply, "?format=obj");
    assert_problem(&r, 415, "format-mismatch");
    assert_eq!(r.body["error"]["looks_like"], "ply", "{}", r.body);
    assert_eq!(reply(agent().get(&s.url("/livez")).call()).status, 200);
}

/// Issue 15, item 4: the job clock counts running time only. One worker, jobs of 0.7 s each, a 1 s limit: the
/// fourth waits 2 s in the queue and still runs to the end.
#[test]
fn a_job_queued_longer_than_the_time_limit_still_runs() {
    let s = Server::start(&["--workers", "1", "--job-timeout-s", "1", "--test-job-delay-ms", "700"]);
    let id = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    let jobs: Vec<String> = (3..7)
        .map(|k| {
            let r = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": k }));
            assert_eq!(r.status, 202, "{}", r.body);
            r.body["id"].as_str().unwrap().to_string()
        })
        .collect();
    for j in &jobs {
        let done = wait_done(&s, j);
        assert_eq!(done["status"], "succeeded", "{done}");
        assert!(done["started_at"].is_string(), "{done}");
    }
    let last = wait_done(&s, &jobs[3]);
    let (created, started) = (last["created_at"].as_str().unwrap(), last["started_at"].as_str().unwrap());
    assert!(started > created, "the last job waited in the queue: {last}");
}

/// Issue 15, item 3: every descriptor size is checked against its limit before anything is allocated (one request
/// grew the process to 7.6 GB before), and the problem names the field and the flag that raises the limit.
#[test]
fn descriptor_sizes_and_outputs_are_bounded_at_submission() {
    let s = Server::start(&["--max-samples", "1000", "--max-output-values", "100000"]);
    let id = upload(&s, &icosphere_off(3), "?format=off").body["id"].as_str().unwrap().to_string();
    let refused = [
        (
            json!({ "analysis": "si-hks", "options": { "samples": 1_000_000_000u64 } }),
            "too-many-samples",
            "options.samples",
        ),
        (json!({ "analysis": "hks", "options": { "count": 10_000_000 } }), "too-many-samples", "options.count"),
        (
            json!({ "analysis": "wks", "options": { "energies": vec![0.5; 1001] } }),
            "too-many-samples",
            "options.energies",
        ),
        (json!({ "analysis": "heat", "sources": [0], "times": vec![0.1; 1001] }), "too-many-samples", "times"),
        (json!({ "analysis": "geodesic", "sources": vec![0; 1001] }), "too-many-samples", "sources"),
        // 642 vertices × 200 eigenvectors = 128,400 values > 100,000.
        (json!({ "analysis": "spectrum", "k": 200 }), "output-too-large", "642 vertices × 200 columns"),
        (
            json!({ "analysis": "heat", "k": 20, "sources": vec![0; 20], "times": vec![0.1; 10] }),
            "output-too-large",
            "× 200 columns",
        ),
    ];
    for (mut req, code, names) in refused {
        req["shape_id"] = json!(id);
        let r = submit(&s, req.clone());
        assert_problem(&r, 413, code);
        let detail = r.body["detail"].as_str().unwrap();
        let flag = if code == "too-many-samples" { "--max-samples" } else { "--max-output-values" };
        assert!(detail.contains(names) && detail.contains(flag), "{req}: {detail}");
    }
    assert_eq!(reply(agent().get(&s.url("/v1/jobs")).call()).body["total"], 0, "nothing was queued");
    // Within the limits the same analyses run.
    let ok = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 100 }));
    assert_eq!(ok.status, 202, "{}", ok.body);
    assert_eq!(wait_done(&s, ok.body["id"].as_str().unwrap())["status"], "succeeded");
}

/// Reads what the server sends on a raw socket until it closes the connection or `limit` passes.
fn read_until_closed(s: &mut std::net::TcpStream, limit: Duration) -> (String, bool) {
    use std::io::Read;
    s.set_read_timeout(Some(limit)).unwrap();
    let mut got = vec![];
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => return (String::from_utf8_lossy(&got).into_owned(), true),
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => {
                return (String::from_utf8_lossy(&got).into_owned(), true)
            }
            Err(_) => return (String::from_utf8_lossy(&got).into_owned(), false),
        }
    }
}

/// Issue 15, item 3: a header that never completes and a body that stalls are cut off, idle sockets cannot hold
/// more than --max-connections, and the connection over the limit gets a problem, not silence.
#[test]
fn slow_and_idle_connections_are_bounded() {
    use std::io::Write;
    let s = Server::start(&["--header-read-timeout-s", "1", "--body-read-timeout-s", "1", "--max-connections", "6"]);
    let addr = s.base.trim_start_matches("http://").to_string();
    // Half a header: closed after about a second, nothing answered.
    let t = Instant::now();
    let mut half = std::net::TcpStream::connect(&addr).unwrap();
    half.write_all(b"POST /v1/shapes HTTP/1.1\r\nHost: kac\r\n").unwrap();
    let (_, closed) = read_until_closed(&mut half, Duration::from_secs(5));
    assert!(closed && t.elapsed() < Duration::from_secs(4), "half a header held for {:?}", t.elapsed());
    // A body that stalls after 10 of 1000 bytes: 408 body-timeout.
    let mut slow = std::net::TcpStream::connect(&addr).unwrap();
    slow.write_all(b"POST /v1/shapes?format=off HTTP/1.1\r\nHost: kac\r\nContent-Length: 1000\r\n\r\nOFF\n3 1 0\n")
        .unwrap();
    let (answer, _) = read_until_closed(&mut slow, Duration::from_secs(5));
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    // Either guard may fire first (both at about a second here): the stall timeout or the rate floor, each naming
    // its flag.
    let named = answer.contains("--body-read-timeout-s") || answer.contains("--min-body-rate-bytes-per-s");
    assert!(answer.contains("body-timeout") && named, "{answer}");
    // Six idle sockets fill the limit: the seventh connection is answered 503 and closed ...
    let idle: Vec<_> = (0..6).map(|_| std::net::TcpStream::connect(&addr).unwrap()).collect();
    // The server counts a socket once it accepts it, which under load may be later than a fixed pause: probe (each
    // probe's connection closes with its answer) until the limit answers, for at most five seconds.
    let deadline = Instant::now() + Duration::from_secs(5);
    let over = loop {
        let r = reply(agent().get(&s.url("/livez")).call());
        if r.status == 503 || Instant::now() > deadline {
            break r;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_problem(&over, 503, "too-many-connections");
    assert_eq!(over.retry_after.as_deref(), Some("1"));
    // ... and once the idle ones are dropped by the header timeout, the server answers again.
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(reply(agent().get(&s.url("/livez")).call()).status, 200);
    drop(idle);
    let m = String::from_utf8(reply(agent().get(&s.url("/metrics")).call()).raw).unwrap();
    assert!(m.lines().any(|l| l.starts_with("kac_connections_refused_total ") && !l.ends_with(" 0")), "{m}");
}

/// Issue 15, item 3: wrong API keys from one address are throttled after --auth-failures-per-minute: 429 with
/// Retry-After for the rest of the minute, whatever key it sends.
#[test]
fn repeated_wrong_api_keys_are_throttled_per_address() {
    let s = Server::start(&["--api-keys", "right-key", "--auth-failures-per-minute", "3"]);
    let call =
        |key: &str| reply(agent().get(&s.url("/v1/shapes")).set("authorization", &format!("Bearer {key}")).call());
    assert_eq!(call("right-key").status, 200);
    for _ in 0..3 {
        assert_problem(&call("guess"), 403, "forbidden");
    }
    let r = call("guess");
    assert_problem(&r, 429, "rate-limited");
    assert!(r.body["detail"].as_str().unwrap().contains("--auth-failures-per-minute"), "{}", r.body);
    let wait: u64 = r.retry_after.as_deref().unwrap().parse().unwrap();
    assert!((1..=60).contains(&wait), "{wait}");
    assert_problem(&call("right-key"), 429, "rate-limited");
    // Health stays public.
    assert_eq!(reply(agent().get(&s.url("/livez")).call()).status, 200);
}

/// Issue 15, item 5: a comparison is a job in the queue: 202 and a job without `wait`, the same job for the same
/// request, its result at /v1/results, a shape that cannot be fingerprinted reported without failing the rest,
/// and the queue's capacity, the job timeout and cancel all apply.
#[test]
fn compare_runs_as_a_job_within_the_queue_limits() {
    let s = Server::start(&[]);
    let a = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    let b = upload(&s, &icosphere_off(2), "?format=off").body["id"].as_str().unwrap().to_string();
    let cloud = b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 0\n1 0 1\n0 1 1\n1 1 1\n";
    let c = upload(&s, cloud, "?format=xyz").body["id"].as_str().unwrap().to_string();
    // By shape-DNA: with one shape failed, the two left are too few for the fused distance's spreads.
    let req = json!({ "shape_ids": [a, b, c], "descriptor": "shape-dna", "k": 5, "operator": { "operator": "cotan" } });
    let r = reply(agent().post(&s.url("/v1/compare?wait=0")).send_json(req.clone()));
    assert_eq!(r.status, 202, "{}", r.body);
    let job = r.body["id"].as_str().unwrap().to_string();
    assert_eq!(r.location.as_deref(), Some(format!("/v1/jobs/{job}").as_str()));
    let done = wait_done(&s, &job);
    assert_eq!((done["status"].as_str(), done["analysis"].as_str()), (Some("succeeded"), Some("compare")), "{done}");
    let result = reply(agent().get(&s.url(done["result"].as_str().unwrap())).call()).body;
    assert_eq!(result["shape_ids"], json!([a, b]), "{result}");
    assert_eq!(result["distances"].as_array().unwrap().len(), 2);
    assert_eq!(result["nearest"][0]["nearest"][0]["shape_id"], b.as_str());
    let failures = result["failures"].as_array().unwrap();
    assert_eq!(failures.len(), 1, "{result}");
    assert_eq!(
        (failures[0]["shape_id"].as_str(), failures[0]["code"].as_str()),
        (Some(c.as_str()), Some("operator-not-applicable"))
    );
    // The same request (waiting this time) is the same job, answered with its result.
    let again = reply(agent().post(&s.url("/v1/compare")).send_json(req));
    assert_eq!((again.status, &again.body["shape_ids"]), (200, &json!([a, b])), "{}", again.body);
    assert_eq!(again.location.as_deref(), Some(format!("/v1/results/{job}").as_str()));
    // The queue's capacity applies: one slot held by a slow job, the comparison is refused.
    let s = Server::start(&["--workers", "1", "--queue-capacity", "1", "--test-job-delay-ms", "1500"]);
    let a = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    assert_eq!(submit(&s, json!({ "shape_id": a, "analysis": "trees" })).status, 202);
    let full = reply(agent().post(&s.url("/v1/compare?wait=0")).send_json(json!({ "shape_ids": [a], "k": 3 })));
    assert_problem(&full, 503, "queue-full");
    // Cancel and the job timeout apply.
    let s = Server::start(&["--job-timeout-s", "1", "--test-job-delay-ms", "2500"]);
    let a = upload(&s, &icosphere_off(1), "?format=off").body["id"].as_str().unwrap().to_string();
    let t = reply(agent().post(&s.url("/v1/compare?wait=0")).send_json(json!({ "shape_ids": [a], "k": 3 })));
    let timed = wait_done(&s, t.body["id"].as_str().unwrap());
    assert_eq!((timed["status"].as_str(), timed["error"]["code"].as_str()), (Some("failed"), Some("job-timeout")));
    let c = reply(agent().post(&s.url("/v1/compare?wait=0")).send_json(json!({ "shape_ids": [a], "k": 4 })));
    let id = c.body["id"].as_str().unwrap().to_string();
    assert_eq!(reply(agent().post(&s.url(&format!("/v1/jobs/{id}/cancel"))).call()).status, 202);
    assert_eq!(wait_done(&s, &id)["status"], "canceled");
}

fn off_of(m: &kac_core::geometry::TriangleMesh) -> Vec<u8> {
    kac_core::io::write::off(m).into_bytes()
}

/// Issue 15, item 5: search over every stored fingerprint of a family: from a stored shape (excluded from its own
/// answer) or from a fingerprint, nearest first; a shape without a shape-DNA fingerprint gets one as a shape-dna job;
/// deleted shapes drop out; the index survives a restart (it is reloaded from the store).
#[test]
fn search_finds_the_nearest_stored_shapes_by_shape_dna() {
    let (s, _) = Server::start_in(tempfile::tempdir().unwrap(), &[]);
    let coarse = kac_core::geometry::generate::icosphere(2);
    let fine = kac_core::geometry::generate::icosphere(3);
    let mut stretched = coarse.clone();
    stretched.vertices.iter_mut().for_each(|p| p[0] *= 2.0);
    let id = |m: &kac_core::geometry::TriangleMesh| {
        upload(&s, &off_of(m), "?format=off").body["id"].as_str().unwrap().to_string()
    };
    let (a, b, c) = (id(&coarse), id(&fine), id(&stretched));
    // Fingerprints are kept as shapes are analysed: a comparison of the three stores them.
    let cmp = reply(
        agent()
            .post(&s.url("/v1/compare?wait=60"))
            .send_json(json!({ "shape_ids": [a, b, c], "descriptor": "shape-dna", "k": 8, "normalization": "area", "reweighting": "none" })),
    );
    assert_eq!(cmp.status, 200, "{}", cmp.body);
    let search = |s: &Server, body: Value| reply(agent().post(&s.url("/v1/search")).send_json(body));
    let dna = json!({ "descriptor": "shape-dna", "k": 8, "normalization": "area", "reweighting": "none" });
    let with = |extra: Value| {
        let mut q = dna.clone();
        q.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
        q
    };
    let r = search(&s, with(json!({ "shape_id": a })));
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!(r.body["searched"], 3);
    let order: Vec<&str> =
        r.body["neighbours"].as_array().unwrap().iter().map(|n| n["shape_id"].as_str().unwrap()).collect();
    assert_eq!(order, [b.as_str(), c.as_str()], "the finer sphere before the ellipsoid, the query left out");
    // The same answer from the fingerprint itself (the query shape is then its own nearest, at distance 0).
    let fp = r.body["fingerprint"].clone();
    let f = search(
        &s,
        json!({ "fingerprint": fp, "k": 8, "normalization": "area", "reweighting": "none", "neighbours": 2 }),
    );
    assert_eq!(
        (f.body["neighbours"][0]["shape_id"].as_str(), f.body["neighbours"][0]["distance"].as_f64()),
        (Some(a.as_str()), Some(0.0))
    );
    assert_eq!(f.body["neighbours"].as_array().unwrap().len(), 2);
    // Another family (k = 6): the query shape's fingerprint is computed first, as a shape-dna job.
    let n = search(&s, json!({ "descriptor": "shape-dna", "shape_id": b, "k": 6, "normalization": "area" }));
    assert_eq!((n.status, n.body["searched"].as_u64()), (200, Some(1)), "{}", n.body);
    let jobs = reply(agent().get(&s.url(&format!("/v1/jobs?shape_id={b}&analysis=shape-dna"))).call());
    assert_eq!(jobs.body["total"], 1, "{}", jobs.body);
    // Bad queries.
    assert_problem(
        &search(&s, json!({ "fingerprint": [1.0, 2.0], "k": 8, "normalization": "area" })),
        400,
        "invalid-request",
    );
    assert_problem(&search(&s, json!({ "k": 8 })), 400, "invalid-request");
    assert_problem(&search(&s, json!({ "shape_id": "0000", "k": 8 })), 404, "not-found");
    // After SIGKILL and a restart the index is read back; a deleted shape drops out.
    let (dir, _) = s.stop(false);
    let (s, _) = Server::start_in(dir, &[]);
    assert_eq!(reply(agent().delete(&s.url(&format!("/v1/shapes/{c}"))).call()).status, 204);
    let r = search(&s, with(json!({ "shape_id": a })));
    assert_eq!(
        (r.body["searched"].as_u64(), r.body["neighbours"][0]["shape_id"].as_str()),
        (Some(2), Some(b.as_str())),
        "{}",
        r.body
    );
    assert_eq!(r.body["neighbours"].as_array().unwrap().len(), 1);
}

/// A shape whose file was lost while its record stayed is stored again by the next upload of it (was 500: the
/// record's UNIQUE id), and a fingerprint job that finished without its kept fingerprints still serves a search
/// from its stored result (was 202 forever).
#[test]
fn a_lost_upload_and_a_lost_fingerprint_are_recovered() {
    let (s, _) = Server::start_in(tempfile::tempdir().unwrap(), &[]);
    let off = icosphere_off(2);
    let id = upload(&s, &off, "?format=off").body["id"].as_str().unwrap().to_string();
    let j = submit(&s, json!({ "shape_id": id, "analysis": "fingerprint", "options": { "k": 6 } }));
    assert_eq!(wait_done(&s, j.body["id"].as_str().unwrap())["status"], "succeeded");
    let (dir, _) = s.stop(false);
    std::fs::remove_file(dir.path().join("shapes").join(&id)).unwrap();
    let db = rusqlite::Connection::open(dir.path().join("kac.sqlite3")).unwrap();
    assert_eq!(db.execute("DELETE FROM fingerprints", []).unwrap(), 3, "the job kept a fingerprint per family");
    drop(db);
    let (s, _) = Server::start_in(dir, &[]);
    let again = upload(&s, &off, "?format=off");
    assert!(again.status == 200 || again.status == 201, "{} {}", again.status, again.body);
    assert_eq!(reply(agent().get(&s.url(&format!("/v1/shapes/{id}"))).call()).status, 200);
    let r = reply(agent().post(&s.url("/v1/search")).send_json(json!({ "shape_id": id, "k": 6 })));
    assert_eq!((r.status, r.body["searched"].as_u64()), (200, Some(1)), "{}", r.body);
    let jobs = reply(agent().get(&s.url(&format!("/v1/jobs?shape_id={id}"))).call());
    assert_eq!(jobs.body["total"], 1, "no second job: {}", jobs.body);
}

/// Issue 50: the default search is fused over every family, each distance divided by its spread over the
/// collection: the fused distance is the weighted sum the response's own weights and spreads give, equals the
/// comparison's (whose spreads are over the same three shapes), and a uniformly scaled copy of a shape is at
/// distance 0 from it in every family (each is scale-invariant). A fused search by a raw fingerprint, or by
/// another metric, is refused.
#[test]
fn the_default_search_is_fused_over_every_family() {
    let (s, _) = Server::start_in(tempfile::tempdir().unwrap(), &[]);
    let coarse = kac_core::geometry::generate::icosphere(2);
    let mut scaled = coarse.clone();
    scaled.vertices.iter_mut().for_each(|p| p.iter_mut().for_each(|x| *x *= 3.0));
    let mut stretched = coarse.clone();
    stretched.vertices.iter_mut().for_each(|p| p[0] *= 2.0);
    let id = |m: &kac_core::geometry::TriangleMesh| {
        upload(&s, &off_of(m), "?format=off").body["id"].as_str().unwrap().to_string()
    };
    let (a, b, c) = (id(&coarse), id(&scaled), id(&stretched));
    let search = |body: Value| reply(agent().post(&s.url("/v1/search?wait=60")).send_json(body));
    // Each shape's fingerprints (the query's are computed by the search itself).
    for x in [&b, &c] {
        assert_eq!(search(json!({ "shape_id": x, "k": 12 })).status, 200);
    }
    let r = search(json!({ "shape_id": a, "k": 12 }));
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!((r.body["descriptor"].as_str(), r.body["exact"].as_bool()), (Some("fused"), Some(true)));
    assert_eq!((r.body["searched"].as_u64(), r.body["incomplete"].as_u64()), (Some(3), Some(0)), "{}", r.body);
    let fams = r.body["families"].as_array().unwrap();
    let names: Vec<&str> = fams.iter().map(|f| f["descriptor"].as_str().unwrap()).collect();
    assert_eq!(names, ["shape-dna", "heat-distribution", "gps-d2"]);
    let near = r.body["neighbours"].as_array().unwrap();
    assert_eq!(near[0]["shape_id"].as_str(), Some(b.as_str()), "the scaled copy first: {}", r.body);
    for n in near {
        let each = &n["distances"];
        let fused: f64 = fams
            .iter()
            .map(|f| {
                let d = each[f["descriptor"].as_str().unwrap()].as_f64().unwrap();
                f["weight"].as_f64().unwrap() * d / f["spread"].as_f64().unwrap()
            })
            .sum();
        let got = n["distance"].as_f64().unwrap();
        assert!((got - fused).abs() <= 1e-9 * fused.max(1.0), "{got} vs {fused}");
    }
    // Scale-invariant: the copy three times larger is at (numerically) no distance in any family, the ellipsoid
    // clearly farther. (GPS D2 sums over whole clusters of eigenvalues; within a cluster, eigenvalues a fraction of
    // a percent apart weigh its eigenvectors, which the two solves may choose differently, almost equally.)
    let (copy, other) = (near[0]["distance"].as_f64().unwrap(), near[1]["distance"].as_f64().unwrap());
    for (family, tol) in [("shape-dna", 1e-6), ("heat-distribution", 1e-6), ("gps-d2", 1e-3)] {
        let (d0, d1) = (near[0]["distances"][family].as_f64().unwrap(), near[1]["distances"][family].as_f64().unwrap());
        assert!(d0 <= tol * d1, "{family}: scaled copy at {d0}, ellipsoid at {d1}");
    }
    assert!(copy < 1e-3 * other, "scaled copy at {copy}, ellipsoid at {other}");
    // The comparison of the same three shapes: the same fused distances, and each family's matrix.
    let cmp = reply(agent().post(&s.url("/v1/compare?wait=60")).send_json(json!({ "shape_ids": [a, b, c], "k": 12 })));
    assert_eq!(cmp.status, 200, "{}", cmp.body);
    assert_eq!(cmp.body["descriptor"], "fused");
    assert_eq!(cmp.body["families"].as_array().unwrap().len(), 3);
    let d_ac = cmp.body["distances"][0][2].as_f64().unwrap();
    assert!((d_ac - other).abs() <= 1e-9 * other, "compare {d_ac} vs search {other}");
    // Refusals.
    let fp = fams[0]["fingerprint"].clone();
    assert_problem(&search(json!({ "fingerprint": fp, "k": 12, "descriptor": "fused" })), 400, "invalid-request");
    assert_problem(&search(json!({ "shape_id": a, "k": 12, "metric": "manhattan" })), 400, "invalid-request");
    // A single family by its fingerprint: the query itself first, at distance 0.
    let one = search(json!({ "fingerprint": fams[1]["fingerprint"], "k": 12, "descriptor": "heat-distribution" }));
    assert_eq!(one.status, 200, "{}", one.body);
    assert_eq!(one.body["neighbours"][0]["distance"].as_f64(), Some(0.0), "{}", one.body);
}

#[test]
fn a_second_process_on_the_same_data_directory_is_refused() {
    let (s, _) = Server::start_in(tempfile::tempdir().unwrap(), &[]);
    let dir = s._dir.path().to_path_buf();
    let out = Command::new(env!("CARGO_BIN_EXE_kac"))
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!out.status.success(), "the second server started");
    assert!(String::from_utf8_lossy(&out.stderr).contains("in use by another kac process"));
    // After the first is killed (its lock goes with it), the directory opens again.
    let (dir, _) = s.stop(false);
    let (again, hello) = Server::start_in(dir, &[]);
    assert!(hello["listening"].is_string());
    drop(again);
}

/// CORS over real HTTP: a preflight and a request from the listed origin are allowed, another origin's are not.
#[test]
fn cors_answers_real_origin_requests() {
    let s = Server::start(&["--cors-origins", "https://front.example"]);
    let preflight = |origin: &str| {
        agent()
            .request("OPTIONS", &s.url("/v1/jobs"))
            .set("Origin", origin)
            .set("Access-Control-Request-Method", "POST")
            .set("Access-Control-Request-Headers", "content-type")
            .call()
            .unwrap()
    };
    let ok = preflight("https://front.example");
    assert_eq!(ok.header("access-control-allow-origin"), Some("https://front.example"));
    assert!(ok.header("access-control-allow-methods").unwrap_or("").contains("POST"));
    assert_eq!(preflight("https://evil.example").header("access-control-allow-origin"), None);
    let up = agent()
        .post(&s.url("/v1/shapes?format=off"))
        .set("Origin", "https://front.example")
        .send_bytes(&icosphere_off(1))
        .unwrap();
    assert_eq!(up.status(), 201);
    assert_eq!(up.header("access-control-allow-origin"), Some("https://front.example"));
    assert!(up.header("access-control-expose-headers").unwrap_or("").to_lowercase().contains("location"));
}

/// Issue 33, items 3 and 4: a collection uploaded in one request (files and a zip archive of more), each file
/// answered on its own with nothing lost for the bad ones, tagged, fingerprinted by the jobs the upload starts; a
/// search limited to a tag sees only the shapes carrying it, and an edit of the tags or a deletion at once.
#[test]
fn a_collection_is_uploaded_in_bulk_tagged_and_searched_within_a_tag() {
    let (s, _) = Server::start_in(tempfile::tempdir().unwrap(), &[]);
    let sphere = |level: u32, stretch: f64| {
        let mut m = kac_core::geometry::generate::icosphere(level);
        m.vertices.iter_mut().for_each(|p| p[0] *= stretch);
        off_of(&m)
    };
    let mut zipped = std::io::Cursor::new(vec![]);
    {
        let mut z = zip::ZipWriter::new(&mut zipped);
        let o = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
        z.add_directory("inner/", o).unwrap();
        z.start_file("inner/long.off", o).unwrap();
        std::io::Write::write_all(&mut z, &sphere(2, 1.6)).unwrap();
        z.start_file("broken.off", o).unwrap();
        std::io::Write::write_all(&mut z, b"OFF\n3 1 0\n0 0 0\n").unwrap();
        z.finish().unwrap();
    }
    let zipped = zipped.into_inner();
    let options = json!({ "tags": ["set:a"], "fingerprint": { "k": 8, "normalization": "area" } }).to_string();
    let (a, b, c) = (sphere(2, 1.0), sphere(3, 1.0), sphere(2, 1.3));
    let (ct, body) = multipart(&[
        ("options", None, options.as_bytes()),
        ("file", Some("a.off"), &a),
        ("file", Some("b.off"), &b),
        ("file", Some("garbage.off"), b"not a shape"),
        ("file", Some("c.off"), &c),
        ("file", Some("more.zip"), &zipped),
    ]);
    let r = reply(agent().post(&s.url("/v1/shapes/bulk")).set("content-type", &ct).send_bytes(&body));
    assert_eq!(r.status, 200, "{}", r.body);
    let files = r.body["files"].as_array().unwrap();
    let got: Vec<(&str, u64)> =
        files.iter().map(|f| (f["name"].as_str().unwrap(), f["status"].as_u64().unwrap())).collect();
    assert_eq!(got[..3], [("a.off", 201), ("b.off", 201), ("garbage.off", got[2].1)]);
    assert!(got[2].1 >= 400 && files[2]["problem"]["type"].is_string(), "{}", files[2]);
    assert_eq!(got[3..], [("c.off", 201), ("more.zip/inner/long.off", 201), ("more.zip/broken.off", got[5].1)]);
    assert!(got[5].1 >= 400, "{}", files[5]);
    assert_eq!(
        (r.body["created"].as_u64(), r.body["failed"].as_u64(), r.body["unstarted"].as_u64()),
        (Some(4), Some(2), Some(0))
    );
    let ids: Vec<String> =
        [0, 1, 3, 4].iter().map(|&i| files[i]["shape"]["id"].as_str().unwrap().to_string()).collect();
    for i in [0, 1, 3, 4] {
        assert_eq!(files[i]["shape"]["tags"], json!(["set:a"]), "{}", files[i]);
        let job = files[i]["job"]["id"].as_str().unwrap();
        assert_eq!(wait_done(&s, job)["status"], "succeeded");
    }
    // The same file again: 200, and its job is the same job.
    let (ct2, again) = multipart(&[("options", None, options.as_bytes()), ("file", Some("a.off"), &a)]);
    let r2 = reply(agent().post(&s.url("/v1/shapes/bulk")).set("content-type", &ct2).send_bytes(&again));
    assert_eq!((r2.body["files"][0]["status"].as_u64(), r2.body["existing"].as_u64()), (Some(200), Some(1)));
    assert_eq!(r2.body["files"][0]["job"]["id"], files[0]["job"]["id"]);
    // Tags: one shape moved to another set; one shape uploaded alone with a tag of the first set.
    let lone = upload(&s, &sphere(1, 1.0), "?format=off&tags=set:a,extra").body;
    assert_eq!(lone["tags"], json!(["extra", "set:a"]));
    let put =
        reply(agent().put(&s.url(&format!("/v1/shapes/{}/tags", ids[1]))).send_json(json!({ "tags": ["set:b"] })));
    assert_eq!((put.status, &put.body["tags"]), (200, &json!(["set:b"])), "{}", put.body);
    let get = reply(agent().get(&s.url(&format!("/v1/shapes/{}", ids[1]))).call());
    assert_eq!(get.body["tags"], json!(["set:b"]));
    let search = |body: Value| reply(agent().post(&s.url("/v1/search")).send_json(body));
    let within = |tags: Value| {
        let r = search(json!({ "shape_id": ids[0], "k": 8, "normalization": "area", "tags": tags }));
        assert_eq!(r.status, 200, "{}", r.body);
        let mut n: Vec<String> = r.body["neighbours"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| n["shape_id"].as_str().unwrap().to_string())
            .collect();
        n.sort();
        (n, r.body)
    };
    let mut want = vec![ids[2].clone(), ids[3].clone()];
    want.sort();
    let (set_a, body) = within(json!(["set:a"]));
    assert_eq!(set_a, want, "the lone shape has no fingerprint of this family; the moved one is out");
    assert_eq!((body["exact"].as_bool(), body["method"].as_str()), (Some(true), Some("scan")));
    assert_eq!(within(json!(["set:b"])).0, vec![ids[1].clone()]);
    assert!(within(json!(["set:a", "set:b"])).0.is_empty());
    // exact: true is a scan of the whole family.
    let all = search(json!({ "shape_id": ids[0], "k": 8, "normalization": "area", "exact": true }));
    assert_eq!((all.body["exact"].as_bool(), all.body["probed"].as_u64()), (Some(true), Some(3)), "{}", all.body);
    // Deleted: gone from the tag at once.
    assert_eq!(reply(agent().delete(&s.url(&format!("/v1/shapes/{}", ids[2]))).call()).status, 204);
    assert_eq!(within(json!(["set:a"])).0, vec![ids[3].clone()]);
    // Refused: bad tags (nothing stored), tags of an unknown shape, a body that is not multipart, bad options.
    assert_problem(&upload(&s, &sphere(1, 2.0), "?format=off&tags=bad%20tag"), 400, "invalid-request");
    assert_eq!(reply(agent().get(&s.url("/v1/shapes")).call()).body["total"], 4);
    let unknown = "0".repeat(64);
    let r = reply(agent().put(&s.url(&format!("/v1/shapes/{unknown}/tags"))).send_json(json!({ "tags": ["x"] })));
    assert_problem(&r, 404, "not-found");
    assert_problem(&search(json!({ "fingerprint": vec![1.0; 8], "k": 8, "tags": ["é"] })), 400, "invalid-request");
    // (Small bodies, or the refusing part last: a refusal answers before the rest of the body is read.)
    let r = reply(agent().post(&s.url("/v1/shapes/bulk")).send_bytes(b"OFF"));
    assert_problem(&r, 400, "invalid-request");
    let (ct0, none) = multipart(&[("options", None, br#"{"tags": ["ok"]}"#)]);
    let r = reply(agent().post(&s.url("/v1/shapes/bulk")).set("content-type", &ct0).send_bytes(&none));
    assert_problem(&r, 400, "invalid-request");
    let (ct3, bad) = multipart(&[("file", Some("a.off"), &a), ("options", None, br#"{"tags": ["ok"], "colour": 1}"#)]);
    let r = reply(agent().post(&s.url("/v1/shapes/bulk")).set("content-type", &ct3).send_bytes(&bad));
    assert_eq!((r.status, r.body["field"].as_str()), (422, Some("colour")), "{}", r.body);
    // A queue too small for the upload's jobs: every file stored and given its job (in the backlog lane).
    let s = Server::start(&["--workers", "1", "--queue-capacity", "1", "--test-job-delay-ms", "1500"]);
    let (ct4, three) =
        multipart(&[("file", Some("a.off"), &a), ("file", Some("b.off"), &b), ("file", Some("c.off"), &c)]);
    let r = reply(agent().post(&s.url("/v1/shapes/bulk")).set("content-type", &ct4).send_bytes(&three));
    assert_eq!((r.body["created"].as_u64(), r.body["unstarted"].as_u64()), (Some(3), Some(0)), "{}", r.body);
    assert!(r.body["files"].as_array().unwrap().iter().all(|f| f["job"]["id"].is_string()), "{}", r.body);
}

/// `count` icospheres (level 2) that differ by one vertex's x coordinate, so that each is a shape of its own.
fn distinct_spheres(count: usize) -> Vec<(String, Vec<u8>)> {
    (0..count)
        .map(|i| {
            let mut m = kac_core::geometry::generate::icosphere(2);
            m.vertices[0][0] += 0.01 * (i + 1) as f64;
            (format!("s{i}.off"), off_of(&m))
        })
        .collect()
}

/// A bulk upload of `files` with small fingerprints (k = 8).
fn bulk_upload(s: &Server, files: &[(String, Vec<u8>)]) -> Reply {
    let options = json!({ "fingerprint": { "k": 8 } }).to_string();
    let mut parts: Vec<(&str, Option<&str>, &[u8])> = vec![("options", None, options.as_bytes())];
    parts.extend(files.iter().map(|(name, bytes)| ("file", Some(name.as_str()), bytes.as_slice())));
    let (ct, body) = multipart(&parts);
    reply(agent().post(&s.url("/v1/shapes/bulk")).set("content-type", &ct).send_bytes(&body))
}

/// A batch's progress, polled until every job has ended (at most `limit`).
fn batch_done(s: &Server, progress: &str, limit: Duration) -> Value {
    let t = Instant::now();
    loop {
        let r = reply(agent().get(&s.url(progress)).call());
        assert_eq!(r.status, 200, "{}", r.body);
        if r.body["done"] == json!(true) {
            return r.body;
        }
        assert!(t.elapsed() < limit, "batch {progress} not done: {}", r.body);
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Issue 50, item 3: a bulk upload larger than the queue's capacity gets a job for every file (in the backlog
/// lane), none `unstarted`; its batch's progress reaches done with every job succeeded; an interactive job
/// submitted meanwhile runs before the backlog waiting ahead of it.
#[test]
fn a_bulk_upload_beyond_the_queue_s_capacity_starts_every_job_and_interactive_jobs_go_first() {
    let s = Server::start(&["--workers", "1", "--queue-capacity", "2", "--test-job-delay-ms", "300"]);
    let lone = upload(&s, &icosphere_off(2), "?format=off").body["id"].as_str().unwrap().to_string();
    let files = distinct_spheres(20);
    let r = bulk_upload(&s, &files);
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!((r.body["created"].as_u64(), r.body["unstarted"].as_u64()), (Some(20), Some(0)), "{}", r.body);
    let jobs: Vec<&str> =
        r.body["files"].as_array().unwrap().iter().map(|f| f["job"]["id"].as_str().unwrap()).collect();
    assert_eq!(jobs.iter().collect::<std::collections::HashSet<_>>().len(), 20, "one job per file");
    let batch = r.body["batch"].as_str().unwrap();
    let progress = r.body["progress"].as_str().unwrap();
    assert_eq!((batch.len(), progress), (32, format!("/v1/shapes/bulk/{batch}").as_str()));
    // An interactive job, submitted behind 20 backlog jobs of 300 ms or more each on one worker: it runs next.
    let j = submit(&s, json!({ "shape_id": lone, "analysis": "spectrum", "k": 5 }));
    assert_eq!(j.status, 202, "{}", j.body);
    let done = wait_done(&s, j.body["id"].as_str().unwrap());
    assert_eq!(done["status"], "succeeded", "{done}");
    let p = reply(agent().get(&s.url(progress)).call()).body;
    assert!(p["enqueued"].as_u64().unwrap() >= 8, "the interactive job waited behind the backlog: {p}");
    // The backlog finishes, every job succeeded; each started after the interactive job but the few claimed while
    // the upload was being stored and the interactive job submitted.
    let p = batch_done(&s, progress, Duration::from_secs(120));
    let counts = ["total", "succeeded", "failed", "canceled", "enqueued", "processing"].map(|c| p[c].as_u64().unwrap());
    assert_eq!((counts, &p["failed_jobs"]), ([20, 20, 0, 0, 0, 0], &json!([])), "{p}");
    let started = |id: &str| reply(agent().get(&s.url(&format!("/v1/jobs/{id}"))).call()).body["started_at"].clone();
    let mine = done["started_at"].as_str().unwrap().to_string();
    let before = jobs.iter().filter(|id| started(id).as_str().unwrap() < mine.as_str()).count();
    assert!(before <= 6, "{before} backlog jobs started before the interactive one");
    // Unknown batches: 404, an id that is not one included.
    assert_problem(
        &reply(agent().get(&s.url(&format!("/v1/shapes/bulk/{}", "0".repeat(32)))).call()),
        404,
        "not-found",
    );
    assert_problem(&reply(agent().get(&s.url("/v1/shapes/bulk/nothex")).call()), 404, "not-found");
    let metrics = String::from_utf8(reply(agent().get(&s.url("/metrics")).call()).raw).unwrap();
    assert!(metrics.lines().any(|l| l == "kac_queue_backlog 0"), "{metrics}");
}

/// Issue 50, item 3: back-pressure before anything is stored: an upload that would take the backlog beyond
/// --max-backlog is refused 503 with Retry-After, and none of its shapes is stored.
#[test]
fn a_bulk_upload_beyond_the_backlog_limit_is_refused_before_anything_is_stored() {
    let s = Server::start(&["--workers", "1", "--max-backlog", "5", "--test-job-delay-ms", "5000"]);
    let files = distinct_spheres(10);
    let shapes = || reply(agent().get(&s.url("/v1/shapes")).call()).body["total"].as_u64().unwrap();
    let r = bulk_upload(&s, &files[..6]);
    assert_problem(&r, 503, "queue-full");
    assert!(r.retry_after.is_some() && r.body["detail"].as_str().unwrap().contains("--max-backlog"), "{}", r.body);
    assert_eq!((r.body["max_backlog"].as_u64(), shapes()), (Some(5), 0));
    // Three fit; four more do not (two or three of the first wait: the one worker holds one for 5 s).
    let r = bulk_upload(&s, &files[..3]);
    assert_eq!((r.status, r.body["unstarted"].as_u64()), (200, Some(0)), "{}", r.body);
    let r = bulk_upload(&s, &files[3..7]);
    assert_problem(&r, 503, "queue-full");
    assert_eq!(r.body["backlog"].as_u64().map(|b| (2..=3).contains(&b)), Some(true), "{}", r.body);
    assert_eq!(shapes(), 3, "the refused upload stored nothing");
}

/// Issue 50, item 3: backlog jobs are in the store: a server killed with an upload's jobs waiting finishes them when
/// it starts again on the same data directory.
#[test]
fn a_killed_server_finishes_a_bulk_upload_s_backlog_after_a_restart() {
    let s = Server::start(&["--workers", "1", "--test-job-delay-ms", "1000"]);
    let r = bulk_upload(&s, &distinct_spheres(6));
    assert_eq!((r.status, r.body["unstarted"].as_u64()), (200, Some(0)), "{}", r.body);
    let progress = r.body["progress"].as_str().unwrap().to_string();
    let p = reply(agent().get(&s.url(&progress)).call()).body;
    assert!(p["enqueued"].as_u64().unwrap() >= 4 && p["done"] == json!(false), "{p}");
    let (dir, _) = s.stop(false);
    let (s, _) = Server::start_in(dir, &["--workers", "1"]);
    let p = batch_done(&s, &progress, Duration::from_secs(120));
    assert_eq!((p["total"].as_u64(), p["succeeded"].as_u64()), (Some(6), Some(6)), "{p}");
}

/// A job cut into spectrum slices borrows the server's idle workers, one slice at a time: on two workers with one
/// thread per solve, one job's slices run on both workers, its eigenvalues are those of the same job in one run,
/// and the lent worker is given back (`kac_workers_lent` is 0 after the job).
#[test]
fn idle_workers_solve_slices_of_a_running_job() {
    let s = Server::start(&["--workers", "2", "--solver-threads", "1"]);
    let id = upload(&s, &icosphere_off(6), "?format=off").body["id"].as_str().unwrap().to_string();
    // The one-run solve asks a tighter tolerance: the eigenpair cache shares an entry between requests that differ
    // only in how the pairs are found (slices among them), and this one must be solved again.
    let run = |slices: usize| {
        let solver = if slices == 1 { json!({ "slices": 1, "tol": 1e-11 }) } else { json!({ "slices": slices }) };
        let j = submit(&s, json!({ "shape_id": id, "analysis": "spectrum", "k": 150, "solver": solver }));
        assert_eq!(j.status, 202, "{}", j.body);
        let done = wait_done(&s, j.body["id"].as_str().unwrap());
        assert_eq!(done["status"], "succeeded", "{done}");
        reply(agent().get(&s.url(done["result"].as_str().unwrap())).call()).body
    };
    let sliced = run(4);
    let reports = sliced["solver"]["slices"].as_array().unwrap();
    assert_eq!(reports.len(), 4, "{}", sliced["solver"]);
    let workers: std::collections::BTreeSet<u64> = reports.iter().map(|r| r["worker"].as_u64().unwrap()).collect();
    assert_eq!(workers.len(), 2, "one job's slices on both workers: {reports:?}");
    // Given back: no worker is lent once the job is over.
    let metrics = String::from_utf8(reply(agent().get(&s.url("/metrics")).call()).raw).unwrap();
    assert!(metrics.lines().any(|l| l == "kac_workers_lent 0"), "{metrics}");
    let one = run(1);
    assert!(one["solver"].get("slices").is_none(), "{}", one["solver"]);
    let (a, b): (Vec<f64>, Vec<f64>) = (
        serde_json::from_value(sliced["eigenvalues"].clone()).unwrap(),
        serde_json::from_value(one["eigenvalues"].clone()).unwrap(),
    );
    assert_eq!(a.len(), 150);
    for (j, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!((x - y).abs() <= 1e-8 * y.abs().max(1.0), "λ{j}: sliced {x}, one run {y}");
    }
}

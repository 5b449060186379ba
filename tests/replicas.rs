//! Many replicas on one PostgreSQL, as real processes: `kac serve` binaries sharing a throwaway cluster started by
//! the test. Replicas are killed with SIGKILL at random moments and restarted, the database is restarted once,
//! and every accepted job still succeeds once with the result a single process computes; a cancel or an event
//! stream on one replica reaches a job running on another.

#[path = "support/faults.rs"]
mod faults;
#[path = "support/pg.rs"]
mod pg;

use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Replica {
    child: Child,
    base: String,
    _dir: tempfile::TempDir,
}

impl Replica {
    fn start(store: Option<&str>, extra: &[&str]) -> Replica {
        let dir = tempfile::tempdir().unwrap();
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_kac"));
        cmd.args(["serve", "--addr", "127.0.0.1:0", "--data-dir"]).arg(dir.path());
        if let Some(url) = store {
            cmd.args(["--store", url]);
        }
        let (extra, faults) = faults::split(extra);
        let mut child = cmd
            .args(extra)
            .envs(faults)
            .env("RUST_LOG", "error")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let v: Value = serde_json::from_str(&line).unwrap_or_else(|_| panic!("first line: {line}"));
        Replica { child, base: format!("http://{}", v["listening"].as_str().unwrap()), _dir: dir }
    }
    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }
    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        self.kill();
    }
}

fn agent() -> ureq::Agent {
    ureq::AgentBuilder::new().timeout(Duration::from_secs(30)).build()
}

/// (status, body) or None when the replica cannot be reached (killed, restarting).
fn call(r: Result<ureq::Response, ureq::Error>) -> Option<(u16, Value, Vec<u8>)> {
    let resp = match r {
        Ok(r) => r,
        Err(ureq::Error::Status(_, r)) => r,
        Err(_) => return None,
    };
    let status = resp.status();
    let mut raw = vec![];
    std::io::Read::read_to_end(&mut resp.into_reader(), &mut raw).ok()?;
    Some((status, serde_json::from_slice(&raw).unwrap_or(Value::Null), raw))
}

fn off(level: u32) -> Vec<u8> {
    kac_core::io::write::off(&kac_core::geometry::generate::icosphere(level)).into_bytes()
}

/// What varies between two computations of the same request: the timings a result records. Everything else
/// must be identical, byte for byte. (The replicas and the single process run without the eigenpair cache: a
/// result computed from cached pairs of a larger k may differ in the last bits where k cuts an eigenvalue cluster,
/// and says so with `eigenpairs_reused: true`.)
fn strip_volatile(v: &mut Value) {
    match v {
        Value::Object(m) => {
            for k in ["timings", "seconds"] {
                m.remove(k);
            }
            m.values_mut().for_each(strip_volatile);
        }
        Value::Array(a) => a.iter_mut().for_each(strip_volatile),
        _ => {}
    }
}

/// 60 requests of three analyses on three shapes.
fn requests(shapes: &[String]) -> Vec<Value> {
    let mut out = vec![];
    for (i, s) in shapes.iter().enumerate() {
        for k in 0..7 {
            out.push(json!({ "shape_id": s, "analysis": "spectrum", "k": 3 + k + i }));
            out.push(json!({ "shape_id": s, "analysis": "shape-dna", "options": { "k": 4 + k } }));
            out.push(json!({ "shape_id": s, "analysis": "hks", "k": 5 + k, "options": { "count": 4 } }));
        }
    }
    out.truncate(60);
    out
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn replicas_killed_and_a_database_restart_lose_no_job_and_run_each_once() {
    let cluster = pg::Cluster::start("replicas");
    let url = cluster.database("kac");
    let flags = [
        "--workers",
        "1",
        "--lease-s",
        "2",
        "--test-job-delay-ms",
        "250",
        "--queue-capacity",
        "200",
        "--cache-bytes",
        "0",
    ];
    let mut replicas: Vec<Replica> = (0..3).map(|_| Replica::start(Some(&url), &flags)).collect();
    let shapes: Vec<String> = [1, 2, 3]
        .iter()
        .map(|&l| {
            let (st, b, _) = call(agent().post(&replicas[0].url("/v1/shapes?format=off")).send_bytes(&off(l))).unwrap();
            assert_eq!(st, 201, "{b}");
            b["id"].as_str().unwrap().to_string()
        })
        .collect();
    let reqs = requests(&shapes);
    assert_eq!(reqs.len(), 60);
    // Submitted round-robin; a replica that cannot be reached or answers 503 (the database restarting) is
    // skipped for the next one.
    let mut ids = vec![];
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let t0 = Instant::now();
    let mut kills = 0;
    let mut db_restarted = false;
    for (i, req) in reqs.iter().enumerate() {
        let mut r = i % 3;
        let id = loop {
            if let Some((st, b, _)) = call(agent().post(&replicas[r].url("/v1/jobs")).send_json(req.clone())) {
                if st == 202 || st == 200 {
                    break b["id"].as_str().unwrap().to_string();
                }
                assert_eq!(st, 503, "{b}");
            }
            r = (r + 1) % 3;
            std::thread::sleep(Duration::from_millis(100));
            assert!(t0.elapsed() < Duration::from_secs(120), "no replica accepted {req}");
        };
        ids.push(id);
        // Faults while the queue runs: a SIGKILL and restart every eighth job, the database restarted once.
        if i % 8 == 7 {
            let victim = (next() % 3) as usize;
            replicas[victim].kill();
            replicas[victim] = Replica::start(Some(&url), &flags);
            kills += 1;
        }
        if i == 30 {
            cluster.restart();
            db_restarted = true;
        }
    }
    assert!(kills >= 6 && db_restarted);
    // One more kill in the thick of it, and the queue is left to drain.
    std::thread::sleep(Duration::from_millis(400));
    let victim = (next() % 3) as usize;
    replicas[victim].kill();
    replicas[victim] = Replica::start(Some(&url), &flags);
    let mut finished: Vec<Value> = vec![];
    for id in &ids {
        let done = loop {
            let r = (next() % 3) as usize;
            if let Some((200, b, _)) = call(agent().get(&replicas[r].url(&format!("/v1/jobs/{id}"))).call()) {
                if ["succeeded", "failed", "canceled"].contains(&b["status"].as_str().unwrap_or("")) {
                    break b;
                }
            }
            assert!(t0.elapsed() < Duration::from_secs(240), "job {id} did not finish");
            std::thread::sleep(Duration::from_millis(100));
        };
        assert_eq!(done["status"], "succeeded", "{done}");
        finished.push(done);
    }
    // Exactly once: one succeeded row per job, one stored result per job, and no job left to run.
    assert_eq!(cluster.query("kac", "SELECT count(*) FROM jobs WHERE status = 'succeeded'"), "60");
    assert_eq!(cluster.query("kac", "SELECT count(*) FROM results"), "60");
    assert_eq!(cluster.query("kac", "SELECT count(*) FROM jobs WHERE status <> 'succeeded'"), "0");
    assert_eq!(cluster.query("kac", "SELECT count(*) FROM shapes"), "3", "no shape lost");
    // The faults mattered: some jobs were claimed again after their replica died or their lease ran out.
    let taken_over: usize = cluster.query("kac", "SELECT count(*) FROM jobs WHERE claims > 1").parse().unwrap();
    assert!(taken_over >= 1, "no job was taken over from a killed replica");
    eprintln!("replicas: {kills} kills, 1 database restart, {taken_over} jobs claimed more than once");
    // Every result equals a single process's result for the same request (timings and cache use aside).
    let single = Replica::start(None, &["--workers", "1", "--cache-bytes", "0"]);
    for l in [1, 2, 3] {
        call(agent().post(&single.url("/v1/shapes?format=off")).send_bytes(&off(l))).unwrap();
    }
    for (req, id) in reqs.iter().zip(&ids) {
        let (st, job, _) = call(agent().post(&single.url("/v1/jobs")).send_json(req.clone())).unwrap();
        assert!(st == 202 || st == 200, "{job}");
        let own = loop {
            let (_, b, _) = call(agent().get(&single.url(&format!("/v1/jobs/{id}"))).call()).unwrap();
            if b["status"] == "succeeded" {
                break b;
            }
            assert_ne!(b["status"], "failed", "{b}");
            std::thread::sleep(Duration::from_millis(50));
        };
        let r = (next() % 3) as usize;
        let (_, mut shared, _) = call(agent().get(&replicas[r].url(&format!("/v1/results/{id}"))).call()).unwrap();
        let (_, mut alone, _) = call(agent().get(&single.url(own["result"].as_str().unwrap())).call()).unwrap();
        strip_volatile(&mut shared);
        strip_volatile(&mut alone);
        assert_eq!(
            serde_json::to_vec(&shared).unwrap(),
            serde_json::to_vec(&alone).unwrap(),
            "the result of {req} differs from a single process's"
        );
    }
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn a_cancel_and_the_events_on_one_replica_reach_a_job_running_on_another() {
    let cluster = pg::Cluster::start("cancel");
    let url = cluster.database("kac");
    let a = Replica::start(Some(&url), &["--workers", "1", "--test-job-delay-ms", "20000"]);
    let (_, shape, _) = call(agent().post(&a.url("/v1/shapes?format=off")).send_bytes(&off(2))).unwrap();
    let req = json!({ "shape_id": shape["id"], "analysis": "spectrum", "k": 4 });
    let (st, job, _) = call(agent().post(&a.url("/v1/jobs")).send_json(req)).unwrap();
    assert_eq!(st, 202);
    let id = job["id"].as_str().unwrap().to_string();
    // A claims it (it is alone); B starts afterwards and never holds it.
    let t = Instant::now();
    while call(agent().get(&a.url(&format!("/v1/jobs/{id}"))).call()).unwrap().1["status"] != "processing" {
        assert!(t.elapsed() < Duration::from_secs(10));
        std::thread::sleep(Duration::from_millis(20));
    }
    let b = Replica::start(Some(&url), &["--workers", "1"]);
    // B streams the job's events while it runs on A: the first says processing; after the cancel on B, the
    // last says canceled.
    let events = std::thread::spawn({
        let u = b.url(&format!("/v1/jobs/{id}/events"));
        move || {
            let resp = agent().get(&u).call().unwrap();
            let mut text = String::new();
            std::io::Read::read_to_string(&mut resp.into_reader(), &mut text).unwrap();
            text
        }
    });
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    let (st, _, _) = call(agent().post(&b.url(&format!("/v1/jobs/{id}/cancel"))).call()).unwrap();
    assert_eq!(st, 202);
    let done = loop {
        let (_, v, _) = call(agent().get(&a.url(&format!("/v1/jobs/{id}"))).call()).unwrap();
        if v["status"] == "canceled" {
            break v;
        }
        assert!(t.elapsed() < Duration::from_secs(5), "the job on A did not stop: {v}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(done["error"]["code"], "canceled");
    let stopped_in = t.elapsed();
    assert!(stopped_in < Duration::from_secs(2), "stopped {stopped_in:?} after the cancel on another replica");
    let text = events.join().unwrap();
    let views: Vec<Value> =
        text.lines().filter_map(|l| l.strip_prefix("data: ")).map(|d| serde_json::from_str(d).unwrap()).collect();
    assert_eq!(views.first().map(|v| v["status"].clone()), Some(json!("processing")), "{text}");
    assert_eq!(views.last().map(|v| v["status"].clone()), Some(json!("canceled")), "{text}");
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn readiness_follows_the_database_and_a_stopped_database_is_503_not_404() {
    let cluster = pg::Cluster::start("ready");
    let url = cluster.database("kac");
    let r = Replica::start(Some(&url), &["--workers", "1"]);
    let (_, shape, _) = call(agent().post(&r.url("/v1/shapes?format=off")).send_bytes(&off(1))).unwrap();
    let id = shape["id"].as_str().unwrap().to_string();
    assert_eq!(call(agent().get(&r.url("/readyz")).call()).unwrap().0, 200);
    let metrics = call(agent().get(&r.url("/metrics")).call()).unwrap().2;
    assert!(String::from_utf8_lossy(&metrics).contains("kac_store_pool_connections{state=\"idle\"}"));
    cluster.stop();
    let (st, p, _) = call(agent().get(&r.url("/readyz")).call()).unwrap();
    assert_eq!((st, p["code"].as_str()), (503, Some("not-ready")), "{p}");
    // A stored shape is not reported missing while the database is away (the parsed copy may still answer).
    let (st, p, _) = call(agent().get(&r.url("/v1/shapes?limit=5")).call()).unwrap();
    assert_eq!(st, 503, "{p}");
    cluster.start_again();
    let t = Instant::now();
    while call(agent().get(&r.url("/readyz")).call()).unwrap().0 != 200 {
        assert!(t.elapsed() < Duration::from_secs(15), "not ready again after the database came back");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(call(agent().get(&r.url(&format!("/v1/shapes/{id}"))).call()).unwrap().0, 200);
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn a_search_on_one_replica_sees_fingerprints_and_removals_made_on_another() {
    let cluster = pg::Cluster::start("search");
    let url = cluster.database("kac");
    let a = Replica::start(Some(&url), &["--workers", "1"]);
    let b = Replica::start(Some(&url), &["--workers", "1"]);
    // Shapes and their fingerprints made through A, after B loaded its (empty) index.
    let mut ids = vec![];
    for l in [1, 2, 3] {
        let (_, s, _) = call(agent().post(&a.url("/v1/shapes?format=off")).send_bytes(&off(l))).unwrap();
        let id = s["id"].as_str().unwrap().to_string();
        // Every family (the fused search B answers by default reads all three).
        let req = json!({ "analysis": "fingerprint", "options": { "k": 5 } });
        let uri = format!(
            "/v1/analyze?wait=60&format=off&analysis={}",
            form_urlencoded::byte_serialize(req.to_string().as_bytes()).collect::<String>()
        );
        let (st, r, _) = call(agent().post(&a.url(&uri)).send_bytes(&off(l))).unwrap();
        assert_eq!(st, 200, "{r}");
        ids.push(id);
    }
    let search = |shape: &str| {
        let (st, r, _) =
            call(agent().post(&b.url("/v1/search")).send_json(json!({ "shape_id": shape, "k": 5 }))).unwrap();
        assert_eq!(st, 200, "{r}");
        r
    };
    let r = search(&ids[2]);
    assert_eq!(r["searched"], 3, "{r}");
    let found: Vec<&str> =
        r["neighbours"].as_array().unwrap().iter().map(|n| n["shape_id"].as_str().unwrap()).collect();
    assert_eq!(found.len(), 2, "{r}");
    // Removed through A: gone from B's answers.
    let (st, _, _) = call(agent().delete(&a.url(&format!("/v1/shapes/{}", ids[0]))).call()).unwrap();
    assert_eq!(st, 204);
    let r = search(&ids[2]);
    assert_eq!(r["searched"], 2, "{r}");
    assert!(!r.to_string().contains(&ids[0]), "{r}");
    // Tags set through A limit B's searches at once; a replica started later reads them from the tables.
    let (st, t, _) =
        call(agent().put(&a.url(&format!("/v1/shapes/{}/tags", ids[1]))).send_json(json!({ "tags": ["kept"] })))
            .unwrap();
    assert_eq!(st, 200, "{t}");
    let within = |r: &Replica, tag: &str| {
        let body = json!({ "shape_id": ids[2], "k": 5, "tags": [tag] });
        let (st, r, _) = call(agent().post(&r.url("/v1/search")).send_json(body)).unwrap();
        assert_eq!(st, 200, "{r}");
        r["neighbours"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| n["shape_id"].as_str().unwrap().to_string())
            .collect::<Vec<_>>()
    };
    assert_eq!(within(&b, "kept"), vec![ids[1].clone()]);
    assert!(within(&b, "other").is_empty());
    let c = Replica::start(Some(&url), &["--workers", "1"]);
    assert_eq!(within(&c, "kept"), vec![ids[1].clone()]);
    let (_, shape, _) = call(agent().get(&c.url(&format!("/v1/shapes/{}", ids[1]))).call()).unwrap();
    assert_eq!(shape["tags"], json!(["kept"]));
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn slices_of_one_job_are_solved_on_another_replica() {
    let cluster = pg::Cluster::start("slices");
    let url = cluster.database("kac");
    // One worker each: the replica that claims the job is busy with it, so a slice solved by a slice job was solved
    // by the other replica.
    let flags = ["--workers", "1", "--solver-threads", "1", "--cache-bytes", "0"];
    let a = Replica::start(Some(&url), &flags);
    let b = Replica::start(Some(&url), &flags);
    let single = Replica::start(None, &flags);
    let (_, shape, _) = call(agent().post(&a.url("/v1/shapes?format=off")).send_bytes(&off(5))).unwrap();
    call(agent().post(&single.url("/v1/shapes?format=off")).send_bytes(&off(5))).unwrap();
    let spectrum = |slices: usize| {
        json!({ "shape_id": shape["id"], "analysis": "spectrum", "k": 400, "eigenvectors": false,
                "solver": { "slices": slices } })
    };
    // Submitted to `to`, followed on `on`: the result (its values left out).
    let solve = |to: &Replica, on: &Replica, req: Value| {
        let (st, job, _) = call(agent().post(&to.url("/v1/jobs")).send_json(req)).unwrap();
        assert!(st == 202 || st == 200, "{job}");
        let id = job["id"].as_str().unwrap().to_string();
        let t = Instant::now();
        let done = loop {
            let (_, v, _) = call(agent().get(&on.url(&format!("/v1/jobs/{id}"))).call()).unwrap();
            if v["status"] != "enqueued" && v["status"] != "processing" {
                break v;
            }
            assert!(t.elapsed() < Duration::from_secs(300), "the job did not finish: {v}");
            std::thread::sleep(Duration::from_millis(100));
        };
        assert_eq!(done["status"], "succeeded", "{done}");
        call(agent().get(&on.url(done["result"].as_str().unwrap())).call()).unwrap().1
    };
    let result = solve(&a, &b, spectrum(4));
    let solver = &result["solver"];
    let slices = solver["slices"].as_array().unwrap_or_else(|| panic!("no slices: {solver}"));
    assert_eq!(slices.len(), 4, "{solver}");
    let elsewhere: Vec<&Value> = slices.iter().filter(|s| !s["solved_by"].is_null()).collect();
    let jobs = cluster.query("kac", "SELECT status, view::jsonb->>'analysis', claims, owner FROM jobs ORDER BY seq");
    assert!(!elsewhere.is_empty(), "no slice was solved on the other replica: {solver}\n{jobs}");
    for s in &elsewhere {
        assert!(s["worker"].is_null() && s["pairs"].as_u64().unwrap() > 0, "{s}");
    }
    assert_eq!(solver["completeness"]["complete"], true, "{solver}");
    // The slice jobs are not listed, each ended (succeeded on the other replica, or taken back), and none runs on.
    let (_, list, _) = call(agent().get(&a.url("/v1/jobs")).call()).unwrap();
    let listed: Vec<&str> = list["items"].as_array().unwrap().iter().map(|j| j["analysis"].as_str().unwrap()).collect();
    assert_eq!(listed, vec!["spectrum"], "{list}");
    let open = cluster.query("kac", "SELECT count(*) FROM jobs WHERE status IN ('enqueued', 'processing')");
    assert_eq!(open, "0");
    let solved = cluster.query(
        "kac",
        "SELECT count(*) FROM jobs WHERE view::jsonb->>'analysis' = 'spectrum-slice' AND status = 'succeeded'",
    );
    assert_eq!(solved.parse::<usize>().unwrap(), elsewhere.len());
    // The slices' pairs leave the store once read (on a thread of their own): the job's own result is the only one
    // kept.
    let t = Instant::now();
    while cluster.query("kac", "SELECT count(*) FROM results") != "1" {
        assert!(t.elapsed() < Duration::from_secs(10), "the slices' pairs are still stored");
        std::thread::sleep(Duration::from_millis(50));
    }
    let rid = result["result_id"].as_str().unwrap();
    let others = format!("SELECT count(*) FROM blobs WHERE kind = 'values' AND id <> '{rid}'");
    assert_eq!(cluster.query("kac", &others), "0", "numbers of a slice are left");
    // The same eigenvalues as one process solving all four slices itself, and as one run, to 10⁻⁸.
    let values =
        |r: &Value| -> Vec<f64> { r["eigenvalues"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    let shared = values(&result);
    let by_one = values(&solve(&single, &single, spectrum(4)));
    let one_run = values(&solve(&single, &single, spectrum(1)));
    assert_eq!((shared.len(), by_one.len(), one_run.len()), (400, 400, 400));
    for ((x, y), z) in shared.iter().zip(&by_one).zip(&one_run) {
        assert!((x - y).abs() <= 1e-8 * y.abs().max(1.0), "{x} against {y} in one process");
        assert!((x - z).abs() <= 1e-8 * z.abs().max(1.0), "{x} against {z} in one run");
    }
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn a_canceled_job_cancels_its_slices_on_another_replica() {
    let cluster = pg::Cluster::start("slice-cancel");
    let url = cluster.database("kac");
    // A holds the job 5 s before computing, so that B (started once A has claimed the job) is up when the slices
    // are offered; B holds every job it claims 20 s (in steps that see a cancel), so its slice job is still running
    // when the job is canceled.
    let a = Replica::start(Some(&url), &["--workers", "1", "--solver-threads", "1", "--test-job-delay-ms", "5000"]);
    let (_, shape, _) = call(agent().post(&a.url("/v1/shapes?format=off")).send_bytes(&off(5))).unwrap();
    let req = json!({ "shape_id": shape["id"], "analysis": "spectrum", "k": 400, "eigenvectors": false,
                      "solver": { "slices": 4 } });
    let (st, job, _) = call(agent().post(&a.url("/v1/jobs")).send_json(req)).unwrap();
    assert_eq!(st, 202, "{job}");
    let id = job["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    while call(agent().get(&a.url(&format!("/v1/jobs/{id}"))).call()).unwrap().1["status"] != "processing" {
        assert!(t.elapsed() < Duration::from_secs(10), "A did not claim the job");
        std::thread::sleep(Duration::from_millis(20));
    }
    let b = Replica::start(Some(&url), &["--workers", "1", "--solver-threads", "1", "--test-job-delay-ms", "20000"]);
    let slices = |status: &str| {
        let q = format!(
            "SELECT count(*) FROM jobs WHERE view::jsonb->>'analysis' = 'spectrum-slice' AND status IN ({status})"
        );
        cluster.query("kac", &q).parse::<usize>().unwrap()
    };
    let t = Instant::now();
    while slices("'processing'") == 0 {
        assert!(t.elapsed() < Duration::from_secs(30), "B claimed no slice job");
        std::thread::sleep(Duration::from_millis(20));
    }
    // The job waits for B's slice; canceled on B, it ends canceled, and so does every slice job it offered.
    let (st, _, _) = call(agent().post(&b.url(&format!("/v1/jobs/{id}/cancel"))).call()).unwrap();
    assert_eq!(st, 202);
    let t = Instant::now();
    loop {
        let (_, v, _) = call(agent().get(&a.url(&format!("/v1/jobs/{id}"))).call()).unwrap();
        if v["status"] == "canceled" && slices("'enqueued', 'processing'") == 0 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(10), "still running 10 s after the cancel: {v}");
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(slices("'canceled'") >= 1);
    assert_eq!(slices("'succeeded'"), 0, "B's slice never ran past its hold");
}

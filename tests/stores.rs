//! The store conformance tests: one behaviour list run against each backend (the embedded SQLite store here, a
//! real PostgreSQL cluster started by the test for the shared one). Shapes are stored once per id and read back
//! parsed; fingerprints only for stored shapes; results written once; the job queue admits one job per id within
//! its capacity, hands each job to one claim, fences a finish by its claim, cancels, requeues expired claims and
//! announces every change.

#[path = "support/pg.rs"]
mod pg;

#[path = "support/stored.rs"]
mod stored;

use clap::Parser;
use kac::analysis::VertexArray;
use kac::service::ids::{BatchId, JobId, ShapeId};
use kac::service::jobs::{JobProgress, JobView, Status};
use kac::service::store::{self, Backend, Enqueued, Lane, Lease, StoredResult, StoredShape};
use kac_engine::{Code, EngineConfig, Failure};
use serde_json::json;
use std::sync::Arc;
use std::time::Duration;

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    config: EngineConfig,
}

fn backend(dir: &std::path::Path, store_url: Option<&str>) -> Backend {
    let mut args = vec!["kac".to_string(), "--data-dir".into(), dir.display().to_string()];
    if let Some(url) = store_url {
        args.extend(["--store".into(), url.to_string()]);
    }
    store::open(&Args::parse_from(args).config).unwrap()
}

fn shape(level: u32) -> (StoredShape, Vec<u8>) {
    stored::stored(&kac_core::geometry::generate::icosphere(level))
}

fn job(id: &str) -> JobView {
    JobView {
        id: id.into(),
        shape_id: "s".into(),
        analysis: "spectrum".into(),
        status: Status::Enqueued,
        progress: JobProgress { phase: "queued".into(), converged: 0, wanted: 0 },
        created_at: "2026-01-01T00:00:00.000Z".into(),
        started_at: None,
        finished_at: None,
        error: None,
        result: None,
        request: json!({ "analysis": "spectrum", "k": 3 }),
    }
}

/// A test's job name as a job id (its bytes in hex, padded to 32 digits): stores take typed ids only.
fn h(name: &str) -> String {
    format!("{:0<32}", name.bytes().map(|b| format!("{b:02x}")).collect::<String>())
}

fn jid_of(hex: &str) -> JobId {
    JobId::parse(hex).expect("a job id")
}

fn jid(name: &str) -> JobId {
    JobId::parse(&h(name)).expect("a job id")
}

fn problem() -> Failure {
    Failure::canceled()
}

/// Every behaviour of the store interface, on one backend. `reopen` opens the same store again (a restart, or
/// another replica).
fn conformance(b: &Backend, reopen: &dyn Fn() -> Backend) {
    // Shapes: stored once per id, read back (parsed again by a fresh store), listed, removed.
    let (s, off) = shape(2);
    let id = s.id.clone();
    let sid = ShapeId::parse(&id).expect("a shape id");
    let (new, stored) = b.shapes.insert(s, &off).unwrap();
    assert!(new);
    let (again, existing) = b.shapes.insert(shape(2).0, &off).unwrap();
    assert!(!again, "a second insert of the same id stores nothing");
    assert_eq!(existing.id, stored.id);
    let other = reopen();
    let read = other.shapes.get(&sid).unwrap().expect("read back by a fresh store");
    assert_eq!(read.validated.shape.vertex_count(), 162);
    let (page, total) = other.shapes.list(0, 10).unwrap();
    assert_eq!((page.len(), total, page[0].id.as_str()), (1, 1, id.as_str()));
    assert!(b.shapes.healthy());

    // Fingerprints: kept for stored shapes only, replaced per (family, shape), gone with the shape; every change
    // logged for other replicas' indexes.
    // An identity drawn once per store: the same through another connection or a reopening.
    let identity = b.fingerprints.store_identity().unwrap();
    assert!(identity.len() >= 16, "{identity}");
    assert_eq!(other.fingerprints.store_identity().unwrap(), identity);
    assert_eq!(reopen().fingerprints.store_identity().unwrap(), identity);
    let log = b.fingerprints.fingerprint_log_end().unwrap();
    assert!(b.fingerprints.put_fingerprint("fam", &id, &[1.0, 2.5]).unwrap());
    assert!(b.fingerprints.put_fingerprint("fam", &id, &[1.0, 3.5]).unwrap());
    assert!(!b.fingerprints.put_fingerprint("fam", "not-stored", &[1.0]).unwrap());
    let all = |f: &dyn kac::service::store::FingerprintStore| {
        let mut v = vec![];
        f.for_each_fingerprint(&mut |fam, id, x| v.push((fam.to_string(), id.to_string(), x.to_vec()))).unwrap();
        v
    };
    assert_eq!(all(&*other.fingerprints), vec![("fam".into(), id.clone(), vec![1.0, 3.5])]);
    let got = other.fingerprints.fingerprints_of("fam", &[id.clone(), "not-stored".into()]).unwrap();
    assert_eq!((got.len(), &got[&id]), (1, &vec![1.0, 3.5]));
    // Tags: set whole on stored shapes only, read back sorted by another connection, logged.
    use kac::service::store::{TagEdit, TagsOutcome};
    let set = |t: &[&str]| TagEdit::Replace(t.iter().map(|s| s.to_string()).collect());
    assert_eq!(
        b.fingerprints.set_tags(&id, &set(&["b", "a"])).unwrap(),
        TagsOutcome::Set(vec!["a".into(), "b".into()])
    );
    assert_eq!(b.fingerprints.set_tags("not-stored", &set(&["a"])).unwrap(), TagsOutcome::NotStored);
    assert_eq!(other.fingerprints.tags_of(&id).unwrap(), ["a", "b"]);
    // Added, in one transaction: the union, or nothing when it would be too many.
    let add = |t: &[&str], max| TagEdit::Add { tags: t.iter().map(|s| s.to_string()).collect(), max };
    assert_eq!(
        b.fingerprints.set_tags(&id, &add(&["c", "a"], 3)).unwrap(),
        TagsOutcome::Set(vec!["a".into(), "b".into(), "c".into()])
    );
    assert_eq!(b.fingerprints.set_tags(&id, &add(&["d"], 3)).unwrap(), TagsOutcome::TooMany(4));
    assert_eq!(
        b.fingerprints.set_tags(&id, &set(&["b", "a"])).unwrap(),
        TagsOutcome::Set(vec!["a".into(), "b".into()])
    );
    let mut pairs = vec![];
    other.fingerprints.for_each_tag(&mut |s, t| pairs.push((s.to_string(), t.to_string()))).unwrap();
    pairs.sort();
    assert_eq!(pairs, [(id.clone(), "a".to_string()), (id.clone(), "b".to_string())]);

    // Results: written once; a second write of the id changes nothing; read back by a fresh store, numbers exact
    // (NaN included), body and ETag the same; a large one (several blob chunks, a streamed body) as well.
    let result = |id: &str, rows: usize, shift: f64| {
        let data: Vec<f64> = (0..rows * 2).map(|i| if i == 3 { f64::NAN } else { (i as f64).sqrt() + shift }).collect();
        let a = VertexArray { name: "eigenvectors", rows, cols: 2, data, columns: Some(vec![0.0, 2.0]) };
        let summary = json!({ "k": 2, "eigenvalues": [0.0, 2.0], "arrays": { "eigenvectors": { "rows": rows, "cols": 2, "columns": [0.0, 2.0] } } });
        Arc::new(StoredResult::new(id, summary, vec![a]))
    };
    let body = |r: &StoredResult| r.chunks().flat_map(|c| c.to_vec()).collect::<Vec<u8>>();
    for (id, rows) in [(h("abc1"), 3), (h("abc3"), 300_000)] {
        let id = id.as_str();
        let first = result(id, rows, 0.0);
        let first_body = body(&first);
        let stored = b.results.put(first.clone()).unwrap();
        assert_eq!(stored.etag, first.etag);
        let again = b.results.put(result(id, rows, 1.0)).unwrap();
        assert_eq!(again.etag, first.etag, "the first write stays");
        let back = reopen().results.get(&jid_of(id)).unwrap().expect("read back");
        assert_eq!(back.etag, first.etag);
        let (x, y) = (&back.arrays[0].data, &first.arrays[0].data);
        assert!(x.iter().zip(y).all(|(a, b)| a.to_bits() == b.to_bits()) && x.len() == y.len());
        assert_eq!(body(&back), first_body);
        let parsed: serde_json::Value = serde_json::from_slice(&first_body).unwrap();
        assert_eq!(parsed["arrays"]["eigenvectors"]["values"][1][1], json!(null), "NaN is null");
        assert_eq!(parsed["arrays"]["eigenvectors"]["values"].as_array().unwrap().len(), rows);
        assert_eq!(first.small_body().is_some(), first_body.len() <= kac::service::store::SMALL_BODY);
    }
    assert!(reopen().results.get(&jid("abc2")).unwrap().is_none());
    // Removed (a slice job's pairs, once read): gone for every reader, numbers included; a second removal finds none.
    // Kept unhashed (a slice job's pairs): read back with the same ETag and numbers, the body written as any.
    let r = result(&h("abc4"), 300_000, 0.0);
    let gone = Arc::new(StoredResult::unhashed(&r.id, r.summary.clone(), r.arrays.clone()));
    assert!(gone.etag.contains(&r.id) && gone.etag != r.etag);
    b.results.put(gone.clone()).unwrap();
    let back = reopen().results.get(&jid("abc4")).unwrap().expect("read back");
    assert_eq!(back.etag, gone.etag);
    assert!(back.arrays[0].data.iter().zip(&r.arrays[0].data).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert_eq!(body(&back), body(&r), "the same body as a hashed result's");
    assert!(b.results.get(&jid("abc4")).unwrap().is_some());
    assert!(b.results.remove(&jid("abc4")).unwrap());
    assert!(b.results.get(&jid("abc4")).unwrap().is_none(), "removed where it was cached too");
    assert!(reopen().results.get(&jid("abc4")).unwrap().is_none());
    assert!(!reopen().results.remove(&jid("abc4")).unwrap());

    // Removal takes the shape's fingerprints with it.
    assert!(b.shapes.remove(&sid).unwrap());
    assert!(!b.shapes.remove(&sid).unwrap());
    assert!(reopen().shapes.get(&sid).unwrap().is_none());
    assert!(all(&*reopen().fingerprints).is_empty());
    assert!(reopen().fingerprints.tags_of(&id).unwrap().is_empty(), "tags go with the shape");
    let (changes, end) = reopen().fingerprints.fingerprint_changes(log).unwrap();
    use kac::service::store::FingerprintChange as C;
    assert_eq!(
        changes,
        vec![
            C::Kept { family: "fam".into(), shape_id: id.clone(), values: vec![1.0, 2.5] },
            C::Kept { family: "fam".into(), shape_id: id.clone(), values: vec![1.0, 3.5] },
            C::Tagged { shape_id: id.clone(), tags: vec!["a".into(), "b".into()] },
            C::Tagged { shape_id: id.clone(), tags: vec!["a".into(), "b".into(), "c".into()] },
            C::Tagged { shape_id: id.clone(), tags: vec!["a".into(), "b".into()] },
            C::Removed { shape_id: id.clone() },
        ]
    );
    assert_eq!(b.fingerprints.fingerprint_log_end().unwrap(), end);
    assert_eq!(b.fingerprints.fingerprint_changes(end).unwrap(), (vec![], end));

    // The queue: one job per id, within capacity.
    let q = &b.queue;
    let mut changes = q.changes();
    assert!(matches!(q.enqueue(job(&h("j1")), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert!(
        matches!(q.enqueue(job(&h("j1")), Lane::Run, 2).unwrap(), Enqueued::Existing(v) if v.status == Status::Enqueued)
    );
    assert!(matches!(q.enqueue(job(&h("j2")), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert!(matches!(q.enqueue(job(&h("j3")), Lane::Run, 2).unwrap(), Enqueued::Full));
    assert_eq!(q.depth().unwrap(), (2, 0));
    // Claims in submission order, each job to one claim.
    let lease = Duration::from_secs(30);
    let c1 = q.claim("r1:1", lease).unwrap().unwrap();
    assert_eq!((c1.id.clone(), c1.status, c1.started_at.is_some()), (h("j1"), Status::Processing, true));
    let c2 = reopen().queue.claim("r2:1", lease).unwrap().unwrap();
    assert_eq!(c2.id, h("j2"), "another replica gets the next job, not the claimed one");
    assert!(q.claim("r1:2", lease).unwrap().is_none());
    // Heartbeats carry progress and see a cancel asked for anywhere.
    let p = JobProgress { phase: "iterating".into(), converged: 2, wanted: 3 };
    assert_eq!(q.heartbeat(&h("j1"), "r1:1", &p, lease).unwrap(), Lease::Held { cancel: false });
    assert_eq!(reopen().queue.get(&jid("j1")).unwrap().unwrap().progress.converged, 2);
    assert_eq!(q.heartbeat(&h("j1"), "r9:9", &p, lease).unwrap(), Lease::Lost, "not this claim's job");
    let v = reopen().queue.cancel(&jid("j2"), &problem()).unwrap().unwrap();
    assert_eq!(v.status, Status::Processing, "a running job is asked to stop");
    assert_eq!(q.heartbeat(&h("j2"), "r2:1", &p, lease).unwrap(), Lease::Held { cancel: true });
    // A finish is fenced by its claim.
    let mut done = c1.clone();
    done.status = Status::Succeeded;
    done.result = Some(format!("/v1/results/{}", h("j1")));
    assert!(!q.finish(&h("j1"), "r2:1", &done).unwrap(), "another claim cannot finish it");
    assert!(q.finish(&h("j1"), "r1:1", &done).unwrap());
    assert!(!q.finish(&h("j1"), "r1:1", &done).unwrap(), "finished once");
    assert_eq!(reopen().queue.get(&jid("j1")).unwrap().unwrap().status, Status::Succeeded);
    assert!(
        matches!(q.enqueue(job(&h("j1")), Lane::Run, 9).unwrap(), Enqueued::Existing(v) if v.status == Status::Succeeded)
    );
    // An enqueued job is canceled at once, and may be enqueued again.
    assert!(matches!(q.enqueue(job(&h("j4")), Lane::Run, 9).unwrap(), Enqueued::New(_)));
    let v = q.cancel(&jid("j4"), &problem()).unwrap().unwrap();
    assert_eq!((v.status, v.error.as_ref().map(|p| p.code.as_str())), (Status::Canceled, Some("canceled")));
    assert!(q.cancel(&jid("nope"), &problem()).unwrap().is_none());
    assert!(
        matches!(q.enqueue(job(&h("j4")), Lane::Run, 9).unwrap(), Enqueued::New(v) if v.status == Status::Enqueued)
    );
    // An expired claim goes back in the queue; its holder has lost it.
    let c4 = q.claim("r1:3", Duration::from_millis(200)).unwrap().unwrap();
    assert_eq!(c4.id, h("j4"));
    std::thread::sleep(Duration::from_millis(1200));
    let kept = reopen().queue.requeue_expired(&["r1:3".to_string()]).unwrap();
    assert!(kept.is_empty(), "a claim its replica still holds is not taken back: {kept:?}");
    assert_eq!(reopen().queue.requeue_expired(&["r2:9".to_string()]).unwrap(), vec![h("j4")]);
    assert_eq!(q.heartbeat(&h("j4"), "r1:3", &p, lease).unwrap(), Lease::Lost);
    assert!(!q.finish(&h("j4"), "r1:3", &done).unwrap());
    assert_eq!(q.claim("r2:2", lease).unwrap().unwrap().id, h("j4"), "claimed again");
    // A cancel asked for while a job runs is kept if its claim ends without a finish: released, it ends canceled.
    assert!(matches!(q.enqueue(job(&h("j5")), Lane::Run, 9).unwrap(), Enqueued::New(_)));
    let c5 = q.claim("r1:4", Duration::from_millis(200)).unwrap().unwrap();
    assert_eq!(c5.id, h("j5"));
    assert_eq!(reopen().queue.cancel(&jid("j5"), &problem()).unwrap().unwrap().status, Status::Processing);
    std::thread::sleep(Duration::from_millis(1200));
    assert_eq!(q.requeue_expired(&[]).unwrap(), vec![h("j5")]);
    let v = reopen().queue.get(&jid("j5")).unwrap().unwrap();
    assert_eq!((v.status, v.error.map(|p| p.code)), (Status::Canceled, Some(Code::Canceled)));
    assert!(q.claim("r1:5", lease).unwrap().is_none(), "a canceled job is not claimed again");
    // A job claimed by its id (a job taking back its own slice job), by one claim only, and only while enqueued.
    assert!(matches!(q.enqueue(job(&h("j6")), Lane::Run, 9).unwrap(), Enqueued::New(_)));
    let mut slice = job(&h("j7"));
    slice.analysis = "spectrum-slice".into();
    assert!(matches!(q.enqueue(slice, Lane::Run, 9).unwrap(), Enqueued::New(_)));
    // Waiting jobs, slice jobs aside or not.
    assert_eq!((q.waiting("spectrum-slice").unwrap(), q.waiting("spectrum").unwrap()), (1, 1));
    assert!(q.claim_id(&h("j5"), "r1:6", lease).unwrap().is_none(), "canceled");
    let c7 = reopen().queue.claim_id(&h("j7"), "r2:3", lease).unwrap().unwrap();
    assert_eq!((c7.id.clone(), c7.status), (h("j7"), Status::Processing));
    assert!(q.claim_id(&h("j7"), "r1:6", lease).unwrap().is_none(), "claimed once");
    assert_eq!(q.claim("r1:6", lease).unwrap().unwrap().id, h("j6"), "the older job was left to a claim");
    // Counts and the list.
    let counts = q.counts().unwrap();
    let of = |s: &str| counts.iter().find(|(n, _)| n == s).map_or(0, |c| c.1);
    assert_eq!((of("succeeded"), of("processing"), of("canceled")), (1, 4, 1));
    let ids: Vec<String> = q.list().unwrap().into_iter().map(|v| v.id).collect();
    assert_eq!(ids.len(), 6);
    // Every transition was announced.
    let mut seen = std::collections::HashSet::new();
    let t = std::time::Instant::now();
    while seen.len() < 3 && t.elapsed() < Duration::from_secs(5) {
        match changes.try_recv() {
            Ok(id) => {
                seen.insert(id);
            }
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    assert!(["j1", "j2", "j4"].iter().all(|id| seen.contains(&h(id))), "announced: {seen:?}");

    // Lanes: backlog jobs are never refused and do not count against the capacity (four run jobs are processing
    // here: a capacity of 6 leaves room for two); a backlog job a run request asks for moves to the run lane while
    // it has room; the run lane is claimed first; a recovered claim keeps its lane. Batches: read by any replica.
    for n in ["b1", "b2", "b3"] {
        assert!(matches!(q.enqueue(job(&h(n)), Lane::Backlog, 6).unwrap(), Enqueued::New(_)));
    }
    assert!(matches!(q.enqueue(job(&h("r1")), Lane::Run, 6).unwrap(), Enqueued::New(_)));
    assert_eq!(reopen().queue.backlog().unwrap(), 3);
    assert!(
        matches!(q.enqueue(job(&h("b3")), Lane::Run, 6).unwrap(), Enqueued::Existing(v) if v.status == Status::Enqueued)
    );
    assert!(matches!(q.enqueue(job(&h("r2")), Lane::Run, 6).unwrap(), Enqueued::Full), "b3 counts in the run lane");
    assert!(matches!(q.enqueue(job(&h("b4")), Lane::Backlog, 6).unwrap(), Enqueued::New(_)), "never full");
    assert_eq!(reopen().queue.backlog().unwrap(), 3);
    let batch = BatchId::draw(b"stores");
    q.put_batch(&batch, &[jid("b1"), jid("b2"), jid("r1"), jid("b1")]).unwrap();
    let p = reopen().queue.batch(&batch).unwrap().expect("another replica reads the batch");
    assert_eq!((p.total, p.enqueued, p.done), (3, 3, false));
    assert!(reopen().queue.batch(&BatchId::draw(b"none")).unwrap().is_none());
    // The run lane in submission order (b3 was submitted before r1), then the backlog's oldest.
    assert_eq!(q.claim("r1:7", lease).unwrap().unwrap().id, h("b3"));
    assert_eq!(reopen().queue.claim("r2:4", lease).unwrap().unwrap().id, h("r1"));
    assert_eq!(q.claim("r1:8", Duration::from_millis(200)).unwrap().unwrap().id, h("b1"));
    assert_eq!(reopen().queue.backlog().unwrap(), 2);
    let p = reopen().queue.batch(&batch).unwrap().unwrap();
    assert_eq!((p.enqueued, p.processing), (1, 2));
    // A restart: b1's claim (expired) is taken back into the backlog, ahead of b2 and b4.
    std::thread::sleep(Duration::from_millis(1200));
    let restarted = reopen();
    restarted.queue.recover().unwrap();
    assert_eq!(restarted.queue.backlog().unwrap(), 3, "b1 is back in the backlog lane");
    let mut order = vec![];
    while let Some(v) = restarted.queue.claim(&format!("r3:{}", order.len()), lease).unwrap() {
        order.push(v.id);
    }
    assert_eq!(order[order.len() - 3..], [h("b1"), h("b2"), h("b4")], "the backlog last, oldest first: {order:?}");
}

#[test]
fn the_embedded_store_conforms() {
    let dir = tempfile::tempdir().unwrap();
    let b = backend(dir.path(), None);
    conformance(&b, &|| backend(dir.path(), None));
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn the_postgres_store_conforms() {
    let cluster = pg::Cluster::start("conformance");
    let url = cluster.database("conformance");
    let dir = tempfile::tempdir().unwrap();
    let b = backend(dir.path(), Some(&url));
    conformance(&b, &|| backend(dir.path(), Some(&url)));
}

#[test]
#[ignore = "needs PostgreSQL's server (scripts/test-all.sh installs it and runs this)"]
fn replicas_starting_together_migrate_once() {
    let cluster = pg::Cluster::start("migrate");
    let url = cluster.database("migrate");
    let dir = tempfile::tempdir().unwrap();
    let opened: Vec<Backend> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..3).map(|_| s.spawn(|| backend(dir.path(), Some(&url)))).collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    // Every open succeeded (a second run of a migration would fail on its tables), each version applied once.
    assert_eq!(opened.len(), 3);
    assert_eq!(
        cluster.query("migrate", "SELECT string_agg(version::text, ',' ORDER BY version) FROM schema_migrations"),
        "1,2,3,4,5"
    );
}

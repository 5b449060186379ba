//! The job engine in process, on a clock the tests move: the queue's transitions (the in-memory queue and the
//! SQLite one held to the same behaviour), and the supervisor's leases, heartbeats, cancels, lost claims and
//! timeouts on jobs that run as long as a test says. No server, no sleeping for leases to pass.

use super::*;
use crate::store::{Database, MemoryQueue};
use std::collections::HashSet;

const LEASE: Duration = Duration::from_secs(30);
const TIMEOUT: Duration = Duration::from_secs(600);

fn view(n: u8) -> JobView {
    let id = JobId::from_digest(&[n; 32]).hex();
    JobView {
        id,
        shape_id: "s".repeat(64),
        analysis: "spectrum".into(),
        status: Status::Enqueued,
        progress: JobProgress { phase: "queued".into(), converged: 0, wanted: 0 },
        created_at: now(),
        started_at: None,
        finished_at: None,
        error: None,
        result: None,
        request: serde_json::json!({ "analysis": "spectrum", "k": n }),
    }
}

fn jid(v: &JobView) -> JobId {
    JobId::parse(&v.id).unwrap()
}

fn progress(phase: &str) -> JobProgress {
    JobProgress { phase: phase.into(), converged: 0, wanted: 0 }
}

/// Every queue: the same answers to the same transitions.
fn conformance(q: &dyn JobQueue, clock: &ManualClock) {
    let (a, b, c) = (view(1), view(2), view(3));
    // Enqueue: new, then the same id again is that job; a full queue refuses.
    assert!(matches!(q.enqueue(a.clone(), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert!(matches!(q.enqueue(a.clone(), Lane::Run, 2).unwrap(), Enqueued::Existing(v) if v.id == a.id));
    assert!(matches!(q.enqueue(b.clone(), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert!(matches!(q.enqueue(c.clone(), Lane::Run, 2).unwrap(), Enqueued::Full));
    assert_eq!(q.depth().unwrap(), (2, 0));
    // Claims take the oldest first, for one owner each.
    let got = q.claim("w:1", LEASE).unwrap().unwrap();
    assert_eq!((got.id.as_str(), got.status), (a.id.as_str(), Status::Processing));
    assert!(got.started_at.is_some());
    assert_eq!(q.depth().unwrap(), (1, 1));
    // A heartbeat renews the holder's lease; another owner's is refused.
    assert_eq!(q.heartbeat(&a.id, "w:1", &progress("iterating"), LEASE).unwrap(), Lease::Held { cancel: false });
    assert_eq!(q.heartbeat(&a.id, "w:9", &progress("iterating"), LEASE).unwrap(), Lease::Lost);
    assert_eq!(q.get(&jid(&a)).unwrap().unwrap().progress.phase, "iterating");
    // Within the renewed lease nothing expires; past it the job goes back to the queue (at the front: oldest).
    clock.advance(LEASE - Duration::from_secs(1));
    assert!(q.requeue_expired(&[]).unwrap().is_empty());
    clock.advance(Duration::from_secs(2));
    // A claim the replica still holds (its supervisor renews it) is not taken back, however late the beat.
    assert!(q.requeue_expired(&["w:1".to_string()]).unwrap().is_empty());
    assert_eq!(q.requeue_expired(&["w:7".to_string()]).unwrap(), vec![a.id.clone()]);
    let requeued = q.get(&jid(&a)).unwrap().unwrap();
    assert_eq!((requeued.status, requeued.progress.phase.as_str()), (Status::Enqueued, "requeued"));
    assert!(requeued.started_at.is_none());
    // The old holder lost its claim: its beat says so and its finish writes nothing.
    assert_eq!(q.heartbeat(&a.id, "w:1", &progress("iterating"), LEASE).unwrap(), Lease::Lost);
    let mut done = requeued.clone();
    done.status = Status::Succeeded;
    assert!(!q.finish(&a.id, "w:1", &done).unwrap());
    // A new claim takes it (still the oldest) and finishes it.
    let again = q.claim("w:2", LEASE).unwrap().unwrap();
    assert_eq!(again.id, a.id);
    assert!(q.finish(&a.id, "w:2", &done).unwrap());
    assert_eq!(q.get(&jid(&a)).unwrap().unwrap().status, Status::Succeeded);
    assert!(
        matches!(q.enqueue(a.clone(), Lane::Run, 2).unwrap(), Enqueued::Existing(v) if v.status == Status::Succeeded)
    );
    // Cancel: an enqueued job at once, with the problem given.
    let problem = canceled();
    let v = q.cancel(&jid(&b), &problem).unwrap().unwrap();
    assert_eq!((v.status, v.error.map(|p| p.code)), (Status::Canceled, Some(problem.code)));
    // A canceled job enqueued again goes to the back of the queue.
    assert!(matches!(q.enqueue(c.clone(), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert!(matches!(q.enqueue(b.clone(), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert_eq!(q.claim("w:3", LEASE).unwrap().unwrap().id, c.id);
    // A processing job: the cancel is a request its holder sees at its next beat.
    let v = q.cancel(&jid(&c), &problem).unwrap().unwrap();
    assert_eq!(v.status, Status::Processing);
    assert_eq!(q.heartbeat(&c.id, "w:3", &progress("iterating"), LEASE).unwrap(), Lease::Held { cancel: true });
    // Its lease expiring with the cancel asked for: canceled, not requeued (a cancel is never lost).
    clock.advance(LEASE * 2);
    assert_eq!(q.requeue_expired(&[]).unwrap(), vec![c.id.clone()]);
    assert_eq!(q.get(&jid(&c)).unwrap().unwrap().status, Status::Canceled);
    // Unknown jobs: none.
    assert!(q.cancel(&jid(&view(9)), &problem).unwrap().is_none() && q.get(&jid(&view(9))).unwrap().is_none());
    // At a start, the jobs a dead process held go back in the queue.
    let held = q.claim("w:4", LEASE).unwrap().unwrap();
    assert_eq!(held.id, b.id);
    assert_eq!(q.recover().unwrap(), 1);
    assert_eq!(q.get(&jid(&b)).unwrap().unwrap().status, Status::Enqueued);
    // A job claimed by its id: taken though an older one waits, once; one not enqueued is not claimed.
    let d = view(4);
    assert!(matches!(q.enqueue(d.clone(), Lane::Run, 2).unwrap(), Enqueued::New(_)));
    assert!(q.claim_id(&a.id, "w:5", LEASE).unwrap().is_none(), "succeeded");
    assert!(q.claim_id(&c.id, "w:5", LEASE).unwrap().is_none(), "canceled");
    let mine = q.claim_id(&d.id, "w:5", LEASE).unwrap().unwrap();
    assert_eq!((mine.id.as_str(), mine.status), (d.id.as_str(), Status::Processing));
    assert!(q.claim_id(&d.id, "w:6", LEASE).unwrap().is_none(), "claimed once");
    assert_eq!(q.heartbeat(&d.id, "w:5", &progress("iterating"), LEASE).unwrap(), Lease::Held { cancel: false });
    assert_eq!(q.get(&jid(&b)).unwrap().unwrap().status, Status::Enqueued, "the older job waits on");
    // Submission order, every job listed.
    let order: Vec<String> = q.list().unwrap().into_iter().map(|v| v.id).collect();
    assert_eq!(order, vec![a.id.clone(), c.id.clone(), b.id.clone(), d.id.clone()]);
}

#[test]
fn the_memory_queue_keeps_the_queues_contract() {
    let clock = Arc::new(ManualClock::default());
    conformance(&MemoryQueue::new(clock.clone()), &clock);
}

#[test]
fn the_sqlite_queue_keeps_the_queues_contract() {
    let dir = tempfile::tempdir().unwrap();
    let clock = Arc::new(ManualClock::default());
    let db = Database::open_with_clock(dir.path(), 1000, 1 << 20, clock.clone()).unwrap();
    conformance(&db, &clock);
}

/// The lanes, on every queue: backlog jobs are never refused and do not count against the capacity; claims take
/// the run lane first, each lane oldest first; a backlog job a run request asks for again moves to the run lane when
/// it has room; requeued and recovered jobs keep their lane; a batch's progress follows its jobs and survives a
/// restart. `reopen`: the same store opened again (a restart).
fn lanes(q: Arc<dyn JobQueue>, clock: &ManualClock, reopen: &dyn Fn() -> Arc<dyn JobQueue>) {
    let id = |n: u8| view(n).id;
    let new = |n: u8, lane: Lane| matches!(q.enqueue(view(n), lane, 2).unwrap(), Enqueued::New(_));
    let claim = |q: &dyn JobQueue, owner: &str| q.claim(owner, LEASE).unwrap().map(|v| v.id);
    let end = |n: u8, owner: &str, status: Status| {
        let mut v = q.get(&jid(&view(n))).unwrap().unwrap();
        v.status = status;
        assert!(q.finish(&v.id.clone(), owner, &v).unwrap(), "{n} finished by {owner}");
    };
    // Five backlog jobs, then the run lane filled to its capacity of 2: the backlog counted in neither.
    for n in 10..15 {
        assert!(new(n, Lane::Backlog));
    }
    assert!(new(1, Lane::Run) && new(2, Lane::Run));
    assert!(matches!(q.enqueue(view(3), Lane::Run, 2).unwrap(), Enqueued::Full));
    assert!(new(15, Lane::Backlog), "the backlog takes jobs while the run lane is full");
    assert_eq!((q.backlog().unwrap(), q.depth().unwrap()), (6, (8, 0)));
    // A batch of three of them (one named twice).
    let batch = BatchId::draw(b"lanes");
    q.put_batch(&batch, &[jid(&view(10)), jid(&view(11)), jid(&view(10)), jid(&view(12))]).unwrap();
    let p = q.batch(&batch).unwrap().unwrap();
    assert_eq!((p.total, p.enqueued, p.done, p.batch.clone()), (3, 3, false, batch.hex()));
    // A run request for a backlog job while the run lane is full: the same job, left in the backlog.
    assert!(matches!(q.enqueue(view(13), Lane::Run, 2).unwrap(), Enqueued::Existing(v) if v.id == id(13)));
    assert_eq!(q.backlog().unwrap(), 6);
    // The run lane first, though the backlog is older; then the backlog's oldest. A processing backlog job does not
    // count against the capacity; processing run jobs do.
    assert_eq!(claim(&*q, "w:1"), Some(id(1)));
    assert_eq!(claim(&*q, "w:2"), Some(id(2)));
    assert_eq!(claim(&*q, "w:10"), Some(id(10)));
    assert!(matches!(q.enqueue(view(3), Lane::Run, 2).unwrap(), Enqueued::Full));
    assert_eq!(q.backlog().unwrap(), 5);
    let p = q.batch(&batch).unwrap().unwrap();
    assert_eq!((p.enqueued, p.processing), (2, 1));
    // Room in the run lane: the backlog job asked for moves there and is claimed before older backlog jobs.
    end(1, "w:1", Status::Succeeded);
    assert!(
        matches!(q.enqueue(view(13), Lane::Run, 2).unwrap(), Enqueued::Existing(v) if v.status == Status::Enqueued)
    );
    assert_eq!(q.backlog().unwrap(), 4);
    assert!(matches!(q.enqueue(view(3), Lane::Run, 2).unwrap(), Enqueued::Full), "the moved job counts");
    assert_eq!(claim(&*q, "w:13"), Some(id(13)));
    end(2, "w:2", Status::Succeeded);
    assert!(new(4, Lane::Run));
    // Expired claims go back to their own lane: 13 before 4 (older, both run), 10 after them (backlog).
    clock.advance(LEASE * 2);
    let mut requeued = q.requeue_expired(&[]).unwrap();
    requeued.sort();
    let mut want = vec![id(10), id(13)];
    want.sort();
    assert_eq!(requeued, want);
    assert_eq!(q.backlog().unwrap(), 5);
    // A restart with a run job processing: recovered to the run lane, the backlog still behind it, the batch kept.
    assert_eq!(claim(&*q, "w:13b"), Some(id(13)));
    let q2 = reopen();
    assert_eq!(q2.recover().unwrap(), 7);
    assert_eq!(q2.backlog().unwrap(), 5);
    assert_eq!(q2.batch(&batch).unwrap().unwrap().enqueued, 3);
    let order: Vec<Option<String>> = (0..7).map(|i| claim(&*q2, &format!("r:{i}"))).collect();
    let want: Vec<Option<String>> = [13, 4, 10, 11, 12, 14, 15].iter().map(|&n| Some(id(n))).collect();
    assert_eq!(order, want);
    assert_eq!((q2.backlog().unwrap(), claim(&*q2, "r:8")), (0, None));
    // The batch's jobs end: its progress says so, the failed one named. A batch is recorded once.
    for (n, owner, status) in
        [(10, "r:2", Status::Failed), (11, "r:3", Status::Succeeded), (12, "r:4", Status::Canceled)]
    {
        let mut v = q2.get(&jid(&view(n))).unwrap().unwrap();
        v.status = status;
        assert!(q2.finish(&v.id.clone(), owner, &v).unwrap());
    }
    q2.put_batch(&batch, &[jid(&view(1))]).unwrap();
    let p = reopen().batch(&batch).unwrap().unwrap();
    let counts = (p.total, p.enqueued, p.processing, p.succeeded, p.failed, p.canceled, p.done);
    assert_eq!((counts, p.failed_jobs), ((3, 0, 0, 1, 1, 1, true), vec![id(10)]));
    assert!(q2.batch(&BatchId::draw(b"other")).unwrap().is_none());
    let empty = BatchId::draw(b"empty");
    q2.put_batch(&empty, &[]).unwrap();
    assert!(q2.batch(&empty).unwrap().is_some_and(|p| p.total == 0 && p.done));
}

#[test]
fn the_memory_queue_keeps_the_lanes() {
    let clock = Arc::new(ManualClock::default());
    let q: Arc<dyn JobQueue> = Arc::new(MemoryQueue::new(clock.clone()));
    let same = q.clone();
    lanes(q, &clock, &move || same.clone());
}

#[test]
fn the_sqlite_queue_keeps_the_lanes() {
    let dir = tempfile::tempdir().unwrap();
    let clock = Arc::new(ManualClock::default());
    let open = {
        let (path, clock) = (dir.path().to_path_buf(), clock.clone());
        move || -> Arc<dyn JobQueue> {
            Arc::new(Database::open_with_clock(&path, 1000, 1 << 20, clock.clone()).unwrap())
        }
    };
    lanes(open(), &clock, &open);
}

/// A data directory of a version without lanes: its jobs ran in the run lane, and go on in it after the migration.
#[test]
fn a_jobs_table_without_lanes_is_migrated_to_the_run_lane() {
    let dir = tempfile::tempdir().unwrap();
    {
        let c = rusqlite::Connection::open(dir.path().join("kac.sqlite3")).unwrap();
        c.execute_batch(
            "CREATE TABLE jobs (seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL, view TEXT NOT NULL,
                 status TEXT NOT NULL DEFAULT 'enqueued', owner TEXT, lease_until INTEGER NOT NULL DEFAULT 0,
                 cancel INTEGER NOT NULL DEFAULT 0);",
        )
        .unwrap();
        let v = view(1);
        c.execute("INSERT INTO jobs (id, view) VALUES (?1, ?2)", [&v.id, &serde_json::to_string(&v).unwrap()]).unwrap();
    }
    let clock = Arc::new(ManualClock::default());
    let db = Database::open_with_clock(dir.path(), 1000, 1 << 20, clock.clone()).unwrap();
    assert_eq!(db.backlog().unwrap(), 0);
    assert!(matches!(db.enqueue(view(2), Lane::Backlog, 1).unwrap(), Enqueued::New(_)));
    assert!(matches!(db.enqueue(view(3), Lane::Run, 1).unwrap(), Enqueued::Full), "the old job is a run job");
    assert_eq!(db.claim("w", LEASE).unwrap().map(|v| v.id), Some(view(1).id));
    drop(db);
    // Opened again: the migration is not run twice.
    let db = Database::open_with_clock(dir.path(), 1000, 1 << 20, clock).unwrap();
    assert_eq!(db.backlog().unwrap(), 1);
}

/// An engine on an in-memory queue and a manual clock, with no workers: the tests run its jobs by hand.
fn engine() -> (Arc<Jobs>, Arc<ManualClock>) {
    let clock = Arc::new(ManualClock::default());
    let queue = Arc::new(MemoryQueue::new(clock.clone()));
    (Arc::new(Jobs::new(1, 8, queue, LEASE, TIMEOUT, clock.clone())), clock)
}

/// Claims the next job as the dispatcher would, and marks it running here (its work is the test's to do).
fn start(jobs: &Jobs) -> Arc<Job> {
    let owner = jobs.next_owner();
    let view = jobs.queue.claim(&owner, jobs.lease).unwrap().expect("a job to claim");
    let id = view.id.clone();
    let job = Arc::new(Job {
        view: watch::Sender::new(view),
        stop: AtomicBool::new(false),
        timed_out: AtomicBool::new(false),
        lost: AtomicBool::new(false),
        finishing: AtomicBool::new(false),
        name: "spectrum",
        owner,
        started: jobs.clock.elapsed(),
    });
    jobs.running.lock().unwrap().insert(id, job.clone());
    job
}

fn submit(jobs: &Jobs, n: u8) -> JobView {
    let v = view(n);
    let (got, new) = jobs.enqueue(v.id.clone(), v.shape_id.clone(), "spectrum", v.request.clone()).unwrap();
    assert!(new);
    got
}

#[test]
fn the_supervisor_keeps_a_running_job_s_lease() {
    let (jobs, clock) = engine();
    let v = submit(&jobs, 1);
    let job = start(&jobs);
    let mut beats = Beats::new();
    let quiet = HashSet::new();
    // Ten leases pass with the supervisor beating every few seconds: the claim is never lost.
    for _ in 0..100 {
        clock.advance(LEASE / 10 + Duration::from_millis(1));
        jobs.supervise_once(&mut beats, &quiet);
        assert!(jobs.queue.requeue_expired(&[]).unwrap().is_empty(), "a beaten lease expired");
    }
    assert!(!job.stop.load(Ordering::SeqCst) && !job.lost.load(Ordering::SeqCst));
    assert_eq!(jobs.queue.get(&jid(&v)).unwrap().unwrap().status, Status::Processing);
    // Progress reaches the queue with the beats (other replicas read it there).
    job.view.send_modify(|v| v.progress = progress("ritz-vectors"));
    clock.advance(LEASE / 3);
    jobs.supervise_once(&mut beats, &quiet);
    assert_eq!(jobs.queue.get(&jid(&v)).unwrap().unwrap().progress.phase, "ritz-vectors");
}

#[test]
fn a_job_that_runs_past_the_timeout_is_stopped_as_timed_out() {
    let (jobs, clock) = engine();
    submit(&jobs, 1);
    let job = start(&jobs);
    let mut beats = Beats::new();
    let quiet = HashSet::new();
    clock.advance(TIMEOUT - Duration::from_secs(1));
    jobs.supervise_once(&mut beats, &quiet);
    assert!(!job.stop.load(Ordering::SeqCst), "stopped before its time");
    clock.advance(Duration::from_secs(1));
    jobs.supervise_once(&mut beats, &quiet);
    assert!(job.stop.load(Ordering::SeqCst) && job.timed_out.load(Ordering::SeqCst));
    // Its time counts from when it started running, not from when it was queued.
    submit(&jobs, 2);
    clock.advance(TIMEOUT * 2);
    let late = start(&jobs);
    jobs.supervise_once(&mut beats, &quiet);
    assert!(!late.stop.load(Ordering::SeqCst), "a job's time in the queue counted against it");
}

#[test]
fn a_canceled_job_stops_and_is_not_marked_timed_out() {
    let (jobs, clock) = engine();
    let queued = submit(&jobs, 1);
    let running = submit(&jobs, 2);
    let job = start(&jobs);
    assert_eq!(job.snapshot().id, queued.id);
    // A running job: stopped here at once.
    let v = jobs.cancel(&jid(&queued)).unwrap().unwrap();
    assert_eq!(v.status, Status::Processing);
    assert!(job.stop.load(Ordering::SeqCst));
    clock.advance(TIMEOUT * 2);
    jobs.supervise_once(&mut Beats::new(), &HashSet::new());
    assert!(!job.timed_out.load(Ordering::SeqCst), "the timer relabelled a cancel");
    // An enqueued job: canceled in the queue at once.
    let v = jobs.cancel(&jid(&running)).unwrap().unwrap();
    assert_eq!(v.status, Status::Canceled);
    assert!(jobs.cancel(&jid(&view(9))).unwrap().is_none());
}

#[test]
fn a_cancel_asked_on_another_replica_reaches_the_running_job_at_its_next_beat() {
    let (jobs, clock) = engine();
    let v = submit(&jobs, 1);
    let job = start(&jobs);
    let mut beats = Beats::new();
    jobs.supervise_once(&mut beats, &HashSet::new());
    // Another replica writes the request to the shared queue (not through this engine).
    jobs.queue.cancel(&jid(&v), &canceled()).unwrap();
    // Announced: the supervisor beats at once and stops the job.
    clock.advance(Duration::from_millis(100));
    jobs.supervise_once(&mut beats, &HashSet::from([v.id.clone()]));
    assert!(job.stop.load(Ordering::SeqCst) && !job.lost.load(Ordering::SeqCst));
}

#[test]
fn a_job_whose_claim_was_lost_is_stopped_without_a_result() {
    let (jobs, clock) = engine();
    let v = submit(&jobs, 1);
    let job = start(&jobs);
    let mut beats = Beats::new();
    jobs.supervise_once(&mut beats, &HashSet::new());
    // The replica stalls past its lease: another one requeues the job and claims it.
    clock.advance(LEASE * 2);
    assert_eq!(jobs.queue.requeue_expired(&[]).unwrap(), vec![v.id.clone()]);
    let other = jobs.queue.claim("other:1", LEASE).unwrap().unwrap();
    assert_eq!(other.id, v.id);
    // This replica's next beat finds the claim gone: the job stops and will write nothing.
    jobs.supervise_once(&mut beats, &HashSet::new());
    assert!(job.lost.load(Ordering::SeqCst) && job.stop.load(Ordering::SeqCst));
    let mut done = job.snapshot();
    done.status = Status::Succeeded;
    assert!(!jobs.queue.finish(&v.id, &job.owner, &done).unwrap());
    assert!(jobs.queue.finish(&v.id, "other:1", &done).unwrap());
}

/// A beat between the queue's write of a job's outcome (which ends its claim) and the job's own view of it finds no
/// claim: the job is finishing, not lost, and nothing is stopped or logged as lost.
#[test]
fn a_beat_during_the_outcome_s_write_does_not_take_the_claim_for_lost() {
    let (jobs, clock) = engine();
    let v = submit(&jobs, 1);
    let job = start(&jobs);
    let mut beats = Beats::new();
    // The runner marks the job finishing, then the queue holds its outcome; the live view has not changed yet.
    job.finishing.store(true, Ordering::SeqCst);
    let mut done = job.snapshot();
    done.status = Status::Succeeded;
    assert!(jobs.queue.finish(&v.id, &job.owner, &done).unwrap());
    clock.advance(LEASE);
    jobs.supervise_once(&mut beats, &HashSet::from([v.id.clone()]));
    assert!(!job.lost.load(Ordering::SeqCst) && !job.stop.load(Ordering::SeqCst));
    // Without the mark, the same beat takes the claim for lost (the fault this guards against).
    job.finishing.store(false, Ordering::SeqCst);
    jobs.supervise_once(&mut beats, &HashSet::from([v.id.clone()]));
    assert!(job.lost.load(Ordering::SeqCst));
}

#[test]
fn a_full_queue_refuses_and_a_repeated_request_is_the_same_job() {
    let (jobs, _) = engine();
    for n in 0..8 {
        submit(&jobs, n);
    }
    let v = view(8);
    let full = jobs.enqueue(v.id.clone(), v.shape_id.clone(), "spectrum", v.request.clone());
    assert!(matches!(full, Err(JobError::QueueFull { capacity: 8 })));
    let again = view(3);
    let (got, new) = jobs.enqueue(again.id.clone(), again.shape_id, "spectrum", again.request).unwrap();
    assert_eq!((got.id, new), (again.id, false));
    assert_eq!(jobs.submitted.load(Ordering::Relaxed), 8);
}

/// Idle workers are lent, never the ones running a job (with its solver threads), set aside for a claim or lent
/// already, nor any while a job waits in the queue; a worker given back can be lent again; and a loan is wanted back
/// while a job waits.
#[test]
fn only_idle_workers_are_lent() {
    use kac_core::spectrum::Lender;
    let clock = Arc::new(ManualClock::default());
    let mut jobs = Jobs::new(4, 8, Arc::new(MemoryQueue::new(clock.clone())), LEASE, TIMEOUT, clock);
    jobs.solver_threads = 1;
    submit(&jobs, 1);
    start(&jobs);
    // One job on four workers: three idle, two granted of two asked, then one, then none.
    assert_eq!(jobs.borrow(2), 2);
    assert_eq!((jobs.lent(), jobs.idle_in(&jobs.running.lock().unwrap())), (2, 1));
    assert!(jobs.reserve(), "the last idle worker is set aside for a claim");
    assert_eq!(jobs.borrow(5), 0, "a worker set aside is not lent");
    assert!(!jobs.reserve());
    jobs.claimed();
    assert_eq!(jobs.borrow(5), 1);
    assert_eq!(jobs.borrow(5), 0);
    jobs.give_back();
    assert_eq!(jobs.lent(), 2);
    assert!(!jobs.wanted_back(), "nothing waits in the queue");
    // A slice job waiting (a job's slices offered to other replicas) is no reason to take a worker back: a lent
    // worker does the same work without building the operator again.
    let slice = view(9);
    jobs.enqueue(slice.id.clone(), slice.shape_id.clone(), SLICE_JOB, slice.request.clone()).unwrap();
    assert_eq!(jobs.queue.depth().unwrap().0, 1);
    assert!(!jobs.wanted_back(), "only a slice job waits");
    let owner = jobs.next_owner();
    assert!(jobs.queue.claim_id(&slice.id, &owner, LEASE).unwrap().is_some());
    submit(&jobs, 2);
    assert!(jobs.wanted_back(), "a job waits in the queue");
    assert_eq!(jobs.borrow(5), 0, "nothing is lent while a job waits");
    jobs.give_back();
    jobs.give_back();
    assert_eq!(jobs.lent(), 0);
    // The waiting job runs (the slice job, claimed by its id, holds no worker of this replica's: another replica's
    // claim). A job's solver threads are busy: two jobs of two threads fill the four workers, of one thread leave two.
    start(&jobs);
    jobs.solver_threads = 2;
    assert_eq!(jobs.borrow(5), 0);
    jobs.solver_threads = 1;
    assert_eq!(jobs.borrow(5), 2);
}

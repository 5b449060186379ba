//! The job queue in memory: the same transitions as the SQLite and PostgreSQL queues, on a map under one lock,
//! with leases read from the engine's [`Clock`]. The job engine's in-process tests run on it (and the queue's
//! conformance tests hold it and the SQLite queue to the same behaviour).

use super::queue::{distinct, release, Enqueued, JobQueue, Lane, Lease};
use crate::clock::Clock;
use crate::failure::Failure;
use crate::ids::{BatchId, JobId};
use crate::record::{now, BatchProgress, JobProgress, JobView, Status};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::broadcast;

struct Row {
    seq: u64,
    lane: Lane,
    view: JobView,
    owner: Option<String>,
    lease_until: i64,
    cancel: bool,
}

#[derive(Default)]
struct Rows {
    next_seq: u64,
    jobs: HashMap<String, Row>,
    /// Batches: when recorded, and their jobs in order.
    batches: HashMap<BatchId, (String, Vec<String>)>,
}

impl Rows {
    /// The run lane's enqueued and processing jobs (what the capacity bounds).
    fn running_lane(&self) -> usize {
        self.jobs
            .values()
            .filter(|r| r.lane == Lane::Run && matches!(r.view.status, Status::Enqueued | Status::Processing))
            .count()
    }
}

pub struct MemoryQueue {
    clock: Arc<dyn Clock>,
    rows: Mutex<Rows>,
    changes: broadcast::Sender<String>,
}

impl MemoryQueue {
    pub fn new(clock: Arc<dyn Clock>) -> Self {
        Self { clock, rows: Mutex::new(Rows::default()), changes: broadcast::channel(1024).0 }
    }
    fn rows(&self) -> std::sync::MutexGuard<'_, Rows> {
        self.rows.lock().unwrap_or_else(|e| e.into_inner())
    }
    fn announce(&self, id: &str) {
        let _ = self.changes.send(id.to_string());
    }
    /// Claims the oldest enqueued job of the run lane, else of the backlog, or `only` if it is enqueued.
    fn claim_where(&self, only: Option<&str>, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        let mut rows = self.rows();
        let until = self.clock.wall_ms() + lease.as_millis() as i64;
        let Some(row) = rows
            .jobs
            .values_mut()
            .filter(|r| r.view.status == Status::Enqueued && only.is_none_or(|id| r.view.id == id))
            .min_by_key(|r| (r.lane.rank(), r.seq))
        else {
            return Ok(None);
        };
        row.view.status = Status::Processing;
        row.view.started_at = Some(now());
        row.view.progress = JobProgress { phase: "operator".into(), converged: 0, wanted: 0 };
        row.owner = Some(owner.to_string());
        row.lease_until = until;
        let view = row.view.clone();
        drop(rows);
        self.announce(&view.id);
        Ok(Some(view))
    }
    fn requeue_if(&self, expired: impl Fn(&Row) -> bool) -> Vec<String> {
        let mut rows = self.rows();
        let mut ids = vec![];
        for (id, row) in rows.jobs.iter_mut() {
            if row.view.status == Status::Processing && expired(row) {
                release(&mut row.view, row.cancel);
                row.owner = None;
                row.lease_until = 0;
                ids.push(id.clone());
            }
        }
        drop(rows);
        ids.sort();
        for id in &ids {
            self.announce(id);
        }
        ids
    }
}

impl JobQueue for MemoryQueue {
    fn enqueue(&self, view: JobView, lane: Lane, capacity: usize) -> std::io::Result<Enqueued> {
        let mut rows = self.rows();
        let room = rows.running_lane() < capacity;
        if let Some(old) = rows.jobs.get_mut(&view.id) {
            if !matches!(old.view.status, Status::Failed | Status::Canceled) {
                if lane == Lane::Run && old.lane == Lane::Backlog && old.view.status == Status::Enqueued && room {
                    old.lane = Lane::Run;
                }
                return Ok(Enqueued::Existing(old.view.clone()));
            }
        }
        if lane == Lane::Run && !room {
            return Ok(Enqueued::Full);
        }
        // A failed or canceled job enqueued again goes to the back of the queue.
        rows.next_seq += 1;
        let seq = rows.next_seq;
        let row = Row { seq, lane, view: view.clone(), owner: None, lease_until: 0, cancel: false };
        rows.jobs.insert(view.id.clone(), row);
        drop(rows);
        self.announce(&view.id);
        Ok(Enqueued::New(view))
    }
    fn claim(&self, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(None, owner, lease)
    }
    fn claim_id(&self, id: &str, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(Some(id), owner, lease)
    }
    fn heartbeat(&self, id: &str, owner: &str, progress: &JobProgress, lease: Duration) -> std::io::Result<Lease> {
        let mut rows = self.rows();
        let until = self.clock.wall_ms() + lease.as_millis() as i64;
        match rows.jobs.get_mut(id) {
            Some(row) if row.view.status == Status::Processing && row.owner.as_deref() == Some(owner) => {
                row.view.progress = progress.clone();
                row.lease_until = until;
                Ok(Lease::Held { cancel: row.cancel })
            }
            _ => Ok(Lease::Lost),
        }
    }
    fn finish(&self, id: &str, owner: &str, view: &JobView) -> std::io::Result<bool> {
        let mut rows = self.rows();
        match rows.jobs.get_mut(id) {
            Some(row) if row.view.status == Status::Processing && row.owner.as_deref() == Some(owner) => {
                row.view = view.clone();
                row.owner = None;
                drop(rows);
                self.announce(id);
                Ok(true)
            }
            _ => Ok(false),
        }
    }
    fn cancel(&self, id: &JobId, problem: &Failure) -> std::io::Result<Option<JobView>> {
        let id = id.hex();
        let mut rows = self.rows();
        let Some(row) = rows.jobs.get_mut(&*id) else { return Ok(None) };
        match row.view.status {
            Status::Enqueued => {
                row.view.status = Status::Canceled;
                row.view.finished_at = Some(now());
                row.view.error = Some(problem.clone());
            }
            Status::Processing => row.cancel = true,
            _ => return Ok(Some(row.view.clone())),
        }
        let view = row.view.clone();
        drop(rows);
        self.announce(&id);
        Ok(Some(view))
    }
    fn requeue_expired(&self, held: &[String]) -> std::io::Result<Vec<String>> {
        let now = self.clock.wall_ms();
        Ok(self.requeue_if(|r| r.lease_until < now && !r.owner.as_ref().is_some_and(|o| held.contains(o))))
    }
    fn recover(&self) -> std::io::Result<usize> {
        // A queue in memory belongs to this process: no other worker can hold a claim.
        self.requeue_if(|_| true);
        Ok(self.depth()?.0)
    }
    fn get(&self, id: &JobId) -> std::io::Result<Option<JobView>> {
        Ok(self.rows().jobs.get(&*id.hex()).map(|r| r.view.clone()))
    }
    fn list(&self) -> std::io::Result<Vec<JobView>> {
        let rows = self.rows();
        let mut all: Vec<&Row> = rows.jobs.values().collect();
        all.sort_by_key(|r| r.seq);
        Ok(all.into_iter().map(|r| r.view.clone()).collect())
    }
    fn counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        let mut counts: HashMap<&'static str, usize> = HashMap::new();
        for r in self.rows().jobs.values() {
            *counts.entry(r.view.status.name()).or_default() += 1;
        }
        Ok(counts.into_iter().map(|(s, n)| (s.to_string(), n)).collect())
    }
    fn waiting(&self, except: &str) -> std::io::Result<usize> {
        Ok(self.rows().jobs.values().filter(|r| r.view.status == Status::Enqueued && r.view.analysis != except).count())
    }
    fn backlog(&self) -> std::io::Result<usize> {
        Ok(self.rows().jobs.values().filter(|r| r.lane == Lane::Backlog && r.view.status == Status::Enqueued).count())
    }
    fn put_batch(&self, batch: &BatchId, jobs: &[JobId]) -> std::io::Result<()> {
        self.rows().batches.entry(*batch).or_insert_with(|| (now(), distinct(jobs)));
        Ok(())
    }
    fn batch(&self, batch: &BatchId) -> std::io::Result<Option<BatchProgress>> {
        let rows = self.rows();
        let Some((created_at, ids)) = rows.batches.get(batch) else { return Ok(None) };
        let statuses = ids.iter().filter_map(|id| rows.jobs.get(id).map(|r| (id.as_str(), r.view.status)));
        Ok(Some(BatchProgress::tally(batch, created_at.clone(), statuses)))
    }
    fn changes(&self) -> broadcast::Receiver<String> {
        self.changes.subscribe()
    }
}

//! The embedded store's job queue: one row per job, claims with leases.

use super::*;

pub(super) fn view_of(text: &str) -> std::io::Result<JobView> {
    serde_json::from_str(text).map_err(std::io::Error::other)
}

pub(super) fn status_name(v: &JobView) -> &'static str {
    v.status.name()
}

/// The job queue on SQLite: one row per job (its view as JSON beside the columns the queue works on), every
/// transition one statement or transaction under the connection's lock.
impl JobQueue for Database {
    fn enqueue(&self, view: JobView, lane: Lane, capacity: usize) -> std::io::Result<Enqueued> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let running: i64 = tx
            .query_row("SELECT COUNT(*) FROM jobs WHERE status IN ('enqueued', 'processing') AND lane = 0", [], |r| {
                r.get(0)
            })
            .map_err(db_err)?;
        let room = (running as usize) < capacity;
        let existing: Option<(String, i64)> = tx
            .query_row("SELECT view, lane FROM jobs WHERE id = ?1", [&view.id], |r| Ok((r.get(0)?, r.get(1)?)))
            .optional()
            .map_err(db_err)?;
        if let Some((text, old_lane)) = &existing {
            let old = view_of(text)?;
            if !matches!(old.status, Status::Failed | Status::Canceled) {
                if lane == Lane::Run
                    && Lane::of_rank(*old_lane) == Lane::Backlog
                    && old.status == Status::Enqueued
                    && room
                {
                    tx.execute("UPDATE jobs SET lane = 0 WHERE id = ?1 AND status = 'enqueued'", [&view.id])
                        .map_err(db_err)?;
                    tx.commit().map_err(db_err)?;
                }
                return Ok(Enqueued::Existing(old));
            }
        }
        if lane == Lane::Run && !room {
            return Ok(Enqueued::Full);
        }
        let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
        // A failed or canceled job enqueued again goes to the back of the queue (a new row, a new seq).
        tx.execute("DELETE FROM jobs WHERE id = ?1", [&view.id]).map_err(db_err)?;
        tx.execute(
            "INSERT INTO jobs (id, view, status, owner, lease_until, cancel, lane)
             VALUES (?1, ?2, 'enqueued', NULL, 0, 0, ?3)",
            rusqlite::params![view.id, text, lane.rank()],
        )
        .map_err(db_err)?;
        tx.commit().map_err(db_err)?;
        drop(c);
        let _ = self.changes.send(view.id.clone());
        Ok(Enqueued::New(view))
    }
    fn claim(&self, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(None, owner, lease)
    }
    fn claim_id(&self, id: &str, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(Some(id), owner, lease)
    }
    fn heartbeat(&self, id: &str, owner: &str, progress: &JobProgress, lease: Duration) -> std::io::Result<Lease> {
        let c = self.conn();
        let row: Option<(String, i64)> = c
            .query_row(
                "SELECT view, cancel FROM jobs WHERE id = ?1 AND owner = ?2 AND status = 'processing'",
                [id, owner],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(db_err)?;
        let Some((text, cancel)) = row else { return Ok(Lease::Lost) };
        let mut view = view_of(&text)?;
        view.progress = progress.clone();
        let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
        c.execute(
            "UPDATE jobs SET lease_until = ?3, view = ?4 WHERE id = ?1 AND owner = ?2",
            rusqlite::params![id, owner, self.clock.wall_ms() + lease.as_millis() as i64, text],
        )
        .map_err(db_err)?;
        Ok(Lease::Held { cancel: cancel != 0 })
    }
    fn finish(&self, id: &str, owner: &str, view: &JobView) -> std::io::Result<bool> {
        let text = serde_json::to_string(view).map_err(std::io::Error::other)?;
        let n = self
            .conn()
            .execute(
                "UPDATE jobs SET status = ?3, view = ?4, owner = NULL WHERE id = ?1 AND owner = ?2 AND status = 'processing'",
                rusqlite::params![id, owner, status_name(view), text],
            )
            .map_err(db_err)?;
        if n > 0 {
            let _ = self.changes.send(id.to_string());
        }
        Ok(n > 0)
    }
    fn cancel(&self, id: &JobId, problem: &Failure) -> std::io::Result<Option<JobView>> {
        let id = &*id.hex();
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let row: Option<String> =
            tx.query_row("SELECT view FROM jobs WHERE id = ?1", [id], |r| r.get(0)).optional().map_err(db_err)?;
        let Some(text) = row else { return Ok(None) };
        let mut view = view_of(&text)?;
        match view.status {
            Status::Enqueued => {
                view.status = Status::Canceled;
                view.finished_at = Some(now());
                view.error = Some(problem.clone());
                let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
                tx.execute("UPDATE jobs SET status = 'canceled', view = ?2 WHERE id = ?1", rusqlite::params![id, text])
                    .map_err(db_err)?;
            }
            Status::Processing => {
                tx.execute("UPDATE jobs SET cancel = 1 WHERE id = ?1", [id]).map_err(db_err)?;
            }
            _ => return Ok(Some(view)),
        }
        tx.commit().map_err(db_err)?;
        drop(c);
        let _ = self.changes.send(id.to_string());
        Ok(Some(view))
    }
    fn requeue_expired(&self, held: &[String]) -> std::io::Result<Vec<String>> {
        self.requeue_where("lease_until < ?1", self.clock.wall_ms(), held)
    }
    fn recover(&self) -> std::io::Result<usize> {
        // The data directory belongs to this process: no other worker can hold a claim.
        self.requeue_where("?1 = ?1", 0, &[])?;
        Ok(self.depth()?.0)
    }
    fn get(&self, id: &JobId) -> std::io::Result<Option<JobView>> {
        let id = &*id.hex();
        let text: Option<String> = self
            .conn()
            .query_row("SELECT view FROM jobs WHERE id = ?1", [id], |r| r.get(0))
            .optional()
            .map_err(db_err)?;
        text.map(|t| view_of(&t)).transpose()
    }
    fn list(&self) -> std::io::Result<Vec<JobView>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT view FROM jobs ORDER BY seq").map_err(db_err)?;
        let rows = st.query_map([], |r| r.get::<_, String>(0)).map_err(db_err)?;
        Ok(rows.flatten().filter_map(|v| serde_json::from_str(&v).ok()).collect())
    }
    fn counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT status, COUNT(*) FROM jobs GROUP BY status").map_err(db_err)?;
        let rows = st.query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, i64>(1)? as usize))).map_err(db_err)?;
        Ok(rows.flatten().collect())
    }
    fn waiting(&self, except: &str) -> std::io::Result<usize> {
        let c = self.conn();
        let n: i64 = c
            .query_row(
                "SELECT COUNT(*) FROM jobs WHERE status = 'enqueued' AND json_extract(view, '$.analysis') <> ?1",
                [except],
                |r| r.get(0),
            )
            .map_err(db_err)?;
        Ok(n as usize)
    }
    fn backlog(&self) -> std::io::Result<usize> {
        let n: i64 = self
            .conn()
            .query_row("SELECT COUNT(*) FROM jobs WHERE status = 'enqueued' AND lane = 1", [], |r| r.get(0))
            .map_err(db_err)?;
        Ok(n as usize)
    }
    fn put_batch(&self, batch: &BatchId, jobs: &[JobId]) -> std::io::Result<()> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let id = batch.hex();
        let new = tx
            .execute("INSERT OR IGNORE INTO batches (id, created_at) VALUES (?1, ?2)", [&id, &now()])
            .map_err(db_err)?;
        if new > 0 {
            let mut st =
                tx.prepare("INSERT INTO batch_jobs (batch, position, job) VALUES (?1, ?2, ?3)").map_err(db_err)?;
            for (position, job) in crate::store::queue::distinct(jobs).iter().enumerate() {
                st.execute(rusqlite::params![id, position as i64, job]).map_err(db_err)?;
            }
        }
        tx.commit().map_err(db_err)
    }
    fn batch(&self, batch: &BatchId) -> std::io::Result<Option<BatchProgress>> {
        let c = self.conn();
        let id = batch.hex();
        let created: Option<String> = c
            .query_row("SELECT created_at FROM batches WHERE id = ?1", [&id], |r| r.get(0))
            .optional()
            .map_err(db_err)?;
        let Some(created) = created else { return Ok(None) };
        let mut st = c
            .prepare(
                "SELECT b.job, j.status FROM batch_jobs b JOIN jobs j ON j.id = b.job
                 WHERE b.batch = ?1 ORDER BY b.position",
            )
            .map_err(db_err)?;
        let rows = st
            .query_map([&id], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))
            .map_err(db_err)?
            .collect::<Result<Vec<_>, _>>()
            .map_err(db_err)?;
        let statuses = rows.iter().filter_map(|(job, s)| Some((job.as_str(), Status::from_name(s)?)));
        Ok(Some(BatchProgress::tally(batch, created, statuses)))
    }
    fn changes(&self) -> tokio::sync::broadcast::Receiver<String> {
        self.changes.subscribe()
    }
}

impl Database {
    /// Claims the oldest enqueued job of the run lane, else of the backlog, or `only` if it is enqueued.
    fn claim_where(&self, only: Option<&str>, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let next: Option<(String, String)> = tx
            .query_row(
                "SELECT id, view FROM jobs WHERE status = 'enqueued' AND (?1 IS NULL OR id = ?1)
                 ORDER BY lane, seq LIMIT 1",
                [only],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(db_err)?;
        let Some((id, text)) = next else { return Ok(None) };
        let mut view = view_of(&text)?;
        view.status = Status::Processing;
        view.started_at = Some(now());
        view.progress = JobProgress { phase: "operator".into(), converged: 0, wanted: 0 };
        let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
        tx.execute(
            "UPDATE jobs SET status = 'processing', owner = ?2, lease_until = ?3, view = ?4 WHERE id = ?1",
            rusqlite::params![id, owner, self.clock.wall_ms() + lease.as_millis() as i64, text],
        )
        .map_err(db_err)?;
        tx.commit().map_err(db_err)?;
        drop(c);
        let _ = self.changes.send(id);
        Ok(Some(view))
    }
    /// Requeues the processing jobs that meet `condition` (on `arg`), except those whose owner is in `held`.
    fn requeue_where(&self, condition: &str, arg: i64, held: &[String]) -> std::io::Result<Vec<String>> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let rows: Vec<(String, String, i64, Option<String>)> = {
            let mut st = tx
                .prepare(&format!(
                    "SELECT id, view, cancel, owner FROM jobs WHERE status = 'processing' AND {condition}"
                ))
                .map_err(db_err)?;
            let rows = st.query_map([arg], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?))).map_err(db_err)?;
            rows.collect::<Result<_, _>>().map_err(db_err)?
        };
        let mut ids = vec![];
        for (id, text, cancel, owner) in rows {
            if owner.is_some_and(|o| held.contains(&o)) {
                continue;
            }
            let mut view = view_of(&text)?;
            let status = crate::store::queue::release(&mut view, cancel != 0);
            let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
            tx.execute(
                "UPDATE jobs SET status = ?3, owner = NULL, lease_until = 0, view = ?2 WHERE id = ?1",
                rusqlite::params![id, text, status.name()],
            )
            .map_err(db_err)?;
            ids.push(id);
        }
        tx.commit().map_err(db_err)?;
        drop(c);
        for id in &ids {
            let _ = self.changes.send(id.clone());
        }
        Ok(ids)
    }
}

//! The shared store's job queue: claims with leases, cancels and changes announced by NOTIFY.

use super::*;

/// `UPDATE … SET lease_until = now() + lease`: the lease in seconds as a bind parameter.
pub(super) fn secs(d: Duration) -> f64 {
    d.as_secs_f64()
}

impl JobQueue for Postgres {
    fn enqueue(&self, view: JobView, lane: Lane, capacity: usize) -> std::io::Result<Enqueued> {
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            // Admissions one at a time, so that the capacity holds across replicas.
            tx.execute("SELECT pg_advisory_xact_lock($1)", &[&ENQUEUE_LOCK]).await.map_err(pg)?;
            let running: i64 = tx
                .query_one("SELECT COUNT(*) FROM jobs WHERE status IN ('enqueued', 'processing') AND lane = 0", &[])
                .await
                .map_err(pg)?
                .get(0);
            let room = (running as usize) < capacity;
            if let Some(row) =
                tx.query_opt("SELECT view, lane FROM jobs WHERE id = $1 FOR UPDATE", &[&view.id]).await.map_err(pg)?
            {
                let old = view_of(row.get(0))?;
                let old_lane = Lane::of_rank(row.get::<_, i16>(1).into());
                if !matches!(old.status, Status::Failed | Status::Canceled) {
                    if lane == Lane::Run && old_lane == Lane::Backlog && old.status == Status::Enqueued && room {
                        tx.execute("UPDATE jobs SET lane = 0 WHERE id = $1 AND status = 'enqueued'", &[&view.id])
                            .await
                            .map_err(pg)?;
                        tx.commit().await.map_err(pg)?;
                    }
                    return Ok(Enqueued::Existing(old));
                }
            }
            if lane == Lane::Run && !room {
                return Ok(Enqueued::Full);
            }
            tx.execute(
                "INSERT INTO jobs (id, status, view, lane) VALUES ($1, 'enqueued', $2, $3)
                 ON CONFLICT (id) DO UPDATE SET status = 'enqueued', view = excluded.view, owner = NULL,
                 lease_until = NULL, cancel = false, lane = excluded.lane, seq = nextval('jobs_order')",
                &[&view.id, &text_of(&view)?, &lane.rank()],
            )
            .await
            .map_err(pg)?;
            tx.execute("SELECT pg_notify('kac_jobs', $1)", &[&view.id]).await.map_err(pg)?;
            tx.commit().await.map_err(pg)?;
            Ok(Enqueued::New(view))
        })
    }
    fn claim(&self, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(None, owner, lease)
    }
    fn claim_id(&self, id: &str, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(Some(id), owner, lease)
    }
    fn heartbeat(&self, id: &str, owner: &str, progress: &JobProgress, lease: Duration) -> std::io::Result<Lease> {
        let (id, owner, progress) = (id.to_string(), owner.to_string(), progress.clone());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let Some(row) = tx
                .query_opt(
                    "SELECT view, cancel FROM jobs WHERE id = $1 AND owner = $2 AND status = 'processing' FOR UPDATE",
                    &[&id, &owner],
                )
                .await
                .map_err(pg)?
            else {
                return Ok(Lease::Lost);
            };
            let mut view = view_of(row.get(0))?;
            let cancel: bool = row.get(1);
            let moved = view.progress.phase != progress.phase || view.progress.converged != progress.converged;
            view.progress = progress;
            tx.execute(
                "UPDATE jobs SET view = $2, lease_until = now() + make_interval(secs => $3) WHERE id = $1",
                &[&id, &text_of(&view)?, &secs(lease)],
            )
            .await
            .map_err(pg)?;
            if moved {
                tx.execute("SELECT pg_notify('kac_jobs', $1)", &[&id]).await.map_err(pg)?;
            }
            tx.commit().await.map_err(pg)?;
            Ok(Lease::Held { cancel })
        })
    }
    fn finish(&self, id: &str, owner: &str, view: &JobView) -> std::io::Result<bool> {
        let (id, owner, view) = (id.to_string(), owner.to_string(), view.clone());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let n = tx
                .execute(
                    "UPDATE jobs SET status = $3, view = $4, owner = NULL, lease_until = NULL
                     WHERE id = $1 AND owner = $2 AND status = 'processing'",
                    &[&id, &owner, &view.status.name(), &text_of(&view)?],
                )
                .await
                .map_err(pg)?;
            if n > 0 {
                tx.execute("SELECT pg_notify('kac_jobs', $1)", &[&id]).await.map_err(pg)?;
            }
            tx.commit().await.map_err(pg)?;
            Ok(n > 0)
        })
    }
    fn cancel(&self, id: &JobId, problem: &Failure) -> std::io::Result<Option<JobView>> {
        let id = &*id.hex();
        let (id, problem) = (id.to_string(), problem.clone());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let Some(row) = tx.query_opt("SELECT view FROM jobs WHERE id = $1 FOR UPDATE", &[&id]).await.map_err(pg)?
            else {
                return Ok(None);
            };
            let mut view = view_of(row.get(0))?;
            match view.status {
                Status::Enqueued => {
                    view.status = Status::Canceled;
                    view.finished_at = Some(now());
                    view.error = Some(problem);
                    tx.execute(
                        "UPDATE jobs SET status = 'canceled', view = $2 WHERE id = $1",
                        &[&id, &text_of(&view)?],
                    )
                    .await
                    .map_err(pg)?;
                }
                Status::Processing => {
                    tx.execute("UPDATE jobs SET cancel = true WHERE id = $1", &[&id]).await.map_err(pg)?;
                }
                _ => return Ok(Some(view)),
            }
            tx.execute("SELECT pg_notify('kac_jobs', $1)", &[&id]).await.map_err(pg)?;
            tx.commit().await.map_err(pg)?;
            Ok(Some(view))
        })
    }
    fn requeue_expired(&self, held: &[String]) -> std::io::Result<Vec<String>> {
        let held = held.to_vec();
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let rows = tx
                .query(
                    "SELECT id, view, cancel FROM jobs WHERE status = 'processing' AND lease_until < now()
                     AND (owner IS NULL OR owner <> ALL($1::text[])) FOR UPDATE SKIP LOCKED",
                    &[&held],
                )
                .await
                .map_err(pg)?;
            let mut ids = vec![];
            for row in rows {
                let id: String = row.get(0);
                let mut view = view_of(row.get(1))?;
                let status = crate::store::queue::release(&mut view, row.get(2));
                tx.execute(
                    "UPDATE jobs SET status = $3, owner = NULL, lease_until = NULL, view = $2 WHERE id = $1",
                    &[&id, &text_of(&view)?, &status.name()],
                )
                .await
                .map_err(pg)?;
                tx.execute("SELECT pg_notify('kac_jobs', $1)", &[&id]).await.map_err(pg)?;
                ids.push(id);
            }
            tx.commit().await.map_err(pg)?;
            Ok(ids)
        })
    }
    fn recover(&self) -> std::io::Result<usize> {
        // Other replicas may be running jobs: only claims whose lease expired are taken back.
        self.requeue_expired(&[])?;
        Ok(self.depth()?.0)
    }
    fn get(&self, id: &JobId) -> std::io::Result<Option<JobView>> {
        let id = &*id.hex();
        let id = id.to_string();
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let row = c.query_opt("SELECT view FROM jobs WHERE id = $1", &[&id]).await.map_err(pg)?;
            row.map(|r| view_of(r.get(0))).transpose()
        })
    }
    fn list(&self) -> std::io::Result<Vec<JobView>> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let rows = c.query("SELECT view FROM jobs ORDER BY seq", &[]).await.map_err(pg)?;
            Ok(rows.iter().filter_map(|r| view_of(r.get(0)).ok()).collect())
        })
    }
    fn counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let rows = c.query("SELECT status, COUNT(*) FROM jobs GROUP BY status", &[]).await.map_err(pg)?;
            Ok(rows.iter().map(|r| (r.get::<_, String>(0), r.get::<_, i64>(1) as usize)).collect())
        })
    }
    fn waiting(&self, except: &str) -> std::io::Result<usize> {
        let except = except.to_string();
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let row = c
                .query_one(
                    "SELECT count(*) FROM jobs WHERE status = 'enqueued' AND view::jsonb->>'analysis' <> $1",
                    &[&except],
                )
                .await
                .map_err(pg)?;
            Ok(row.get::<_, i64>(0) as usize)
        })
    }
    fn backlog(&self) -> std::io::Result<usize> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let row = c
                .query_one("SELECT count(*) FROM jobs WHERE status = 'enqueued' AND lane = 1", &[])
                .await
                .map_err(pg)?;
            Ok(row.get::<_, i64>(0) as usize)
        })
    }
    fn put_batch(&self, batch: &BatchId, jobs: &[JobId]) -> std::io::Result<()> {
        let (id, jobs) = (batch.hex(), crate::store::queue::distinct(jobs));
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let new = tx
                .execute(
                    "INSERT INTO batches (id, created_at) VALUES ($1, $2) ON CONFLICT (id) DO NOTHING",
                    &[&id, &now()],
                )
                .await
                .map_err(pg)?;
            if new > 0 {
                // One statement for the whole batch (10,000 files at most): positions from the array's order.
                let positions: Vec<i32> = (0..jobs.len() as i32).collect();
                tx.execute(
                    "INSERT INTO batch_jobs (batch, position, job) SELECT $1, p, j FROM unnest($2::int[], $3::text[]) AS t(p, j)",
                    &[&id, &positions, &jobs],
                )
                .await
                .map_err(pg)?;
            }
            tx.commit().await.map_err(pg)?;
            Ok(())
        })
    }
    fn batch(&self, batch: &BatchId) -> std::io::Result<Option<BatchProgress>> {
        let (b, id) = (*batch, batch.hex());
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let Some(row) = c.query_opt("SELECT created_at FROM batches WHERE id = $1", &[&id]).await.map_err(pg)?
            else {
                return Ok(None);
            };
            let rows = c
                .query(
                    "SELECT b.job, j.status FROM batch_jobs b JOIN jobs j ON j.id = b.job
                     WHERE b.batch = $1 ORDER BY b.position",
                    &[&id],
                )
                .await
                .map_err(pg)?;
            let statuses: Vec<(String, Status)> = rows
                .iter()
                .filter_map(|r| Some((r.get::<_, String>(0), Status::from_name(r.get::<_, &str>(1))?)))
                .collect();
            Ok(Some(BatchProgress::tally(&b, row.get(0), statuses.iter().map(|(j, s)| (j.as_str(), *s)))))
        })
    }
    fn changes(&self) -> broadcast::Receiver<String> {
        self.changes.subscribe()
    }
}

//! The shared backend: PostgreSQL holds shapes, fingerprints, results and the job queue for any number of
//! replicas. Uploads and results are blobs in 1 MiB chunks (rows of `blobs`), written in the transaction that
//! records them, so a record never names a missing blob. Jobs are claimed with `FOR UPDATE SKIP LOCKED` and a
//! lease; every transition is announced with `NOTIFY kac_jobs, id` in its transaction, and each replica LISTENs on
//! a connection of its own. Schema migrations are versioned and applied at start under an advisory lock, so
//! replicas starting together migrate once.
//!
//! The service calls the store synchronously (handlers and workers alike); the client runs on a runtime of its
//! own, and a call waits for its answer (inside the service's runtime by `block_in_place`, so the runtime's
//! other tasks go on).

use super::*;
use crate::failure::Failure;
use crate::ids::{BatchId, JobId};
use crate::record::{now, BatchProgress, JobProgress, Status};
use deadpool_postgres::{Manager, ManagerConfig, Pool, RecyclingMethod};
use std::future::Future;
use std::time::Duration;

use tokio::sync::broadcast;
use tokio_postgres::NoTls;

mod fingerprints;
mod queue;
mod results;
mod shapes;
use queue::secs;
use shapes::lock_log_and_hold;

/// Bytes per blob row.
const CHUNK: usize = 1 << 20;

/// The longest one store call may take (a 500 MB result's write included); statements are bounded by the server
/// too (`statement_timeout`), and idle connections probed (TCP keepalives).
const CALL_TIMEOUT: Duration = Duration::from_secs(300);

/// The schema, one migration per version, applied in order and recorded in `schema_migrations`.
const MIGRATIONS: &[(i32, &str)] = &[
    (
        1,
        "CREATE TABLE shapes (
         id text PRIMARY KEY, format text NOT NULL, created_at text NOT NULL, bytes bigint NOT NULL,
         summary text NOT NULL);
     CREATE TABLE blobs (
         kind text NOT NULL, id text NOT NULL, seq integer NOT NULL, data bytea NOT NULL,
         PRIMARY KEY (kind, id, seq));
     CREATE TABLE results (
         id text PRIMARY KEY, meta text NOT NULL, values_count bigint NOT NULL, chunks integer NOT NULL,
         etag text NOT NULL, created_at timestamptz NOT NULL DEFAULT now());
     CREATE TABLE fingerprints (
         family text NOT NULL, shape_id text NOT NULL, fingerprint bytea NOT NULL,
         PRIMARY KEY (family, shape_id));
     CREATE SEQUENCE jobs_order;
     CREATE TABLE jobs (
         id text PRIMARY KEY, seq bigint NOT NULL DEFAULT nextval('jobs_order'), status text NOT NULL,
         view text NOT NULL, owner text, lease_until timestamptz, cancel boolean NOT NULL DEFAULT false,
         claims integer NOT NULL DEFAULT 0);
     CREATE INDEX jobs_enqueued ON jobs (seq) WHERE status = 'enqueued';
     CREATE INDEX jobs_processing ON jobs (lease_until) WHERE status = 'processing';
     CREATE INDEX jobs_status ON jobs (status);",
    ),
    (
        2,
        "CREATE TABLE fingerprint_log (
             seq bigserial PRIMARY KEY, family text NOT NULL, shape_id text NOT NULL, fingerprint bytea);",
    ),
    (3, "CREATE TABLE shape_tags (shape_id text NOT NULL, tag text NOT NULL, PRIMARY KEY (shape_id, tag));"),
    (
        4,
        "CREATE TABLE meta (key text PRIMARY KEY, value text NOT NULL);
         INSERT INTO meta (key, value) VALUES ('store_id', md5(random()::text || clock_timestamp()::text));",
    ),
    (
        5,
        // Lanes (0 run, 1 backlog: `Lane::rank`; the jobs before them ran in the run lane), the claim's order on one
        // index, and bulk uploads' batches.
        "ALTER TABLE jobs ADD COLUMN lane smallint NOT NULL DEFAULT 0;
         DROP INDEX jobs_enqueued;
         CREATE INDEX jobs_claim ON jobs (lane, seq) WHERE status = 'enqueued';
         CREATE TABLE batches (id text PRIMARY KEY, created_at text NOT NULL);
         CREATE TABLE batch_jobs (
             batch text NOT NULL, position integer NOT NULL, job text NOT NULL, PRIMARY KEY (batch, position));",
    ),
];

/// The advisory lock that serializes migrations (and queue admissions, as a transaction lock of its own key).
const MIGRATION_LOCK: i64 = 0x6b61_6301;
const ENQUEUE_LOCK: i64 = 0x6b61_6302;
const LOG_LOCK: i64 = 0x6b61_6303;

type PgResult<T> = std::result::Result<T, String>;

fn pg(e: impl std::fmt::Display) -> String {
    format!("postgres: {e}")
}

pub struct Postgres {
    rt: Option<tokio::runtime::Runtime>,
    pool: Pool,
    changes: broadcast::Sender<String>,
    parsed: Mutex<ByteLru<StoredShape>>,
    results: Mutex<ByteLru<StoredResult>>,
    max_vertices: usize,
}

impl Drop for Postgres {
    fn drop(&mut self) {
        // Allowed anywhere, also inside another runtime.
        if let Some(rt) = self.rt.take() {
            rt.shutdown_background();
        }
    }
}

impl Postgres {
    /// Claims the oldest enqueued job of the run lane, else of the backlog, or `only` if it is enqueued.
    fn claim_where(&self, only: Option<&str>, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        let (only, owner) = (only.map(str::to_string), owner.to_string());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let Some(row) = tx
                .query_opt(
                    "SELECT id, view FROM jobs WHERE status = 'enqueued' AND ($1::text IS NULL OR id = $1)
                     ORDER BY lane, seq LIMIT 1 FOR UPDATE SKIP LOCKED",
                    &[&only],
                )
                .await
                .map_err(pg)?
            else {
                return Ok(None);
            };
            let id: String = row.get(0);
            let mut view = view_of(row.get(1))?;
            view.status = Status::Processing;
            view.started_at = Some(now());
            view.progress = JobProgress { phase: "operator".into(), converged: 0, wanted: 0 };
            tx.execute(
                "UPDATE jobs SET status = 'processing', owner = $2, view = $3, claims = claims + 1,
                 lease_until = now() + make_interval(secs => $4) WHERE id = $1",
                &[&id, &owner, &text_of(&view)?, &secs(lease)],
            )
            .await
            .map_err(pg)?;
            tx.execute("SELECT pg_notify('kac_jobs', $1)", &[&id]).await.map_err(pg)?;
            tx.commit().await.map_err(pg)?;
            Ok(Some(view))
        })
    }
    /// Connects (a pool of `pool_size`, and one connection that listens), and migrates the schema.
    pub fn open(url: &str, pool_size: usize, max_vertices: usize, cache_bytes: usize) -> std::io::Result<Self> {
        let mut config: tokio_postgres::Config =
            url.parse().map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("{url}: {e}")))?;
        config
            .options("-c statement_timeout=300000")
            .keepalives(true)
            .keepalives_idle(Duration::from_secs(30))
            .connect_timeout(Duration::from_secs(5));
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("kac-postgres")
            .enable_all()
            .build()?;
        let manager =
            Manager::from_config(config.clone(), NoTls, ManagerConfig { recycling_method: RecyclingMethod::Fast });
        let pool = Pool::builder(manager)
            .max_size(pool_size.max(1))
            .runtime(deadpool_postgres::Runtime::Tokio1)
            .wait_timeout(Some(Duration::from_secs(10)))
            .create_timeout(Some(Duration::from_secs(5)))
            .recycle_timeout(Some(Duration::from_secs(5)))
            .build()
            .map_err(std::io::Error::other)?;
        let changes = broadcast::channel(4096).0;
        let store = Postgres {
            rt: Some(rt),
            pool,
            changes,
            parsed: Mutex::new(ByteLru::new(cache_bytes)),
            results: Mutex::new(ByteLru::new(cache_bytes)),
            max_vertices,
        };
        store.run(|pool| async move { migrate(&pool).await })?;
        let (tx, rt) = (store.changes.clone(), store.rt.as_ref().expect("the runtime lives as long as the store"));
        rt.spawn(listen(config, tx));
        Ok(store)
    }

    /// Runs `f` with the pool on the store's runtime and waits for its answer.
    fn run<T, F, Fut>(&self, f: F) -> std::io::Result<T>
    where
        T: Send + 'static,
        F: FnOnce(Pool) -> Fut,
        Fut: Future<Output = PgResult<T>> + Send + 'static,
    {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        let fut = f(self.pool.clone());
        self.rt.as_ref().expect("the runtime lives as long as the store").spawn(async move {
            // Bounded: a connection that stopped answering (a half-open socket) cannot hold a caller forever.
            let answer = tokio::time::timeout(CALL_TIMEOUT, fut)
                .await
                .unwrap_or_else(|_| Err(format!("postgres: no answer in {} s", CALL_TIMEOUT.as_secs())));
            let _ = tx.send(answer);
        });
        blocking(|| rx.recv())
            .map_err(|_| std::io::Error::other("postgres: the query's task ended"))?
            .map_err(std::io::Error::other)
    }

    /// Whether a shape's record exists.
    fn stored(&self, id: &str) -> std::io::Result<bool> {
        let key = id.to_string();
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            Ok(c.query_opt("SELECT 1 FROM shapes WHERE id = $1", &[&key]).await.map_err(pg)?.is_some())
        })
    }

    /// The pool's size, idle connections and callers waiting (for `/metrics`).
    pub fn pool_status(&self) -> (usize, usize, usize) {
        let s = self.pool.status();
        (s.size, s.available, s.waiting)
    }
}

/// Applies the missing migrations, one transaction each, under the migration lock.
async fn migrate(pool: &Pool) -> PgResult<()> {
    let mut c = pool.get().await.map_err(pg)?;
    c.execute("SELECT pg_advisory_lock($1)", &[&MIGRATION_LOCK]).await.map_err(pg)?;
    let result = async {
        c.batch_execute(
            "CREATE TABLE IF NOT EXISTS schema_migrations (
                 version integer PRIMARY KEY, applied_at timestamptz NOT NULL DEFAULT now())",
        )
        .await
        .map_err(pg)?;
        for &(version, sql) in MIGRATIONS {
            let done = c
                .query_opt("SELECT 1 FROM schema_migrations WHERE version = $1", &[&version])
                .await
                .map_err(pg)?
                .is_some();
            if done {
                continue;
            }
            let tx = c.transaction().await.map_err(pg)?;
            tx.batch_execute(sql).await.map_err(|e| format!("migration {version}: {e}"))?;
            tx.execute("INSERT INTO schema_migrations (version) VALUES ($1)", &[&version]).await.map_err(pg)?;
            tx.commit().await.map_err(pg)?;
            tracing::info!(version, "applied a schema migration");
        }
        Ok(())
    }
    .await;
    let _ = c.execute("SELECT pg_advisory_unlock($1)", &[&MIGRATION_LOCK]).await;
    result
}

/// Listens for `kac_jobs` notifications on a connection of its own and forwards the job ids; reconnects (every
/// half second) while the server is away, and announces `*` after a reconnection (changes may have been missed).
async fn listen(config: tokio_postgres::Config, tx: broadcast::Sender<String>) {
    loop {
        match config.connect(NoTls).await {
            Ok((client, mut connection)) => {
                let (ntx, mut nrx) = tokio::sync::mpsc::unbounded_channel();
                let conn = tokio::spawn(async move {
                    let mut messages = futures_util::stream::poll_fn(move |cx| connection.poll_message(cx));
                    use futures_util::StreamExt;
                    while let Some(Ok(m)) = messages.next().await {
                        if let tokio_postgres::AsyncMessage::Notification(n) = m {
                            let _ = ntx.send(n.payload().to_string());
                        }
                    }
                });
                if client.batch_execute("LISTEN kac_jobs").await.is_ok() {
                    let _ = tx.send("*".into());
                    while let Some(id) = nrx.recv().await {
                        let _ = tx.send(id);
                    }
                }
                conn.abort();
            }
            Err(e) => tracing::warn!(error = %e, "cannot listen for job changes; retrying"),
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
}

fn to_i64(n: usize) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}

fn view_of(text: &str) -> PgResult<JobView> {
    serde_json::from_str(text).map_err(|e| format!("a stored job view does not parse: {e}"))
}

fn text_of(v: &JobView) -> PgResult<String> {
    serde_json::to_string(v).map_err(|e| e.to_string())
}

/// A blob's chunks, inserted in the caller's transaction.
async fn put_blob(tx: &deadpool_postgres::Transaction<'_>, kind: &str, id: &str, bytes: &[u8]) -> PgResult<i32> {
    let st = tx.prepare_cached("INSERT INTO blobs (kind, id, seq, data) VALUES ($1, $2, $3, $4)").await.map_err(pg)?;
    let mut n = 0i32;
    for chunk in bytes.chunks(CHUNK) {
        tx.execute(&st, &[&kind, &id, &n, &chunk]).await.map_err(pg)?;
        n += 1;
    }
    Ok(n)
}

async fn get_blob(c: &deadpool_postgres::Client, kind: &str, id: &str) -> PgResult<Vec<u8>> {
    let rows =
        c.query("SELECT data FROM blobs WHERE kind = $1 AND id = $2 ORDER BY seq", &[&kind, &id]).await.map_err(pg)?;
    let mut out = Vec::with_capacity(rows.iter().map(|r| r.get::<_, &[u8]>(0).len()).sum());
    for r in &rows {
        out.extend_from_slice(r.get::<_, &[u8]>(0));
    }
    Ok(out)
}

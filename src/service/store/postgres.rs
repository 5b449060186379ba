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
use crate::service::ids::JobId;
use crate::service::jobs::{now, JobProgress, Status};
use crate::service::problem::Problem;
use deadpool_postgres::{Manager, ManagerConfig, Pool, RecyclingMethod};
use std::future::Future;
use std::time::Duration;
use tokio::sync::broadcast;
use tokio_postgres::NoTls;

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
    /// Claims the oldest enqueued job, or `only` if it is enqueued.
    fn claim_where(&self, only: Option<&str>, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        let (only, owner) = (only.map(str::to_string), owner.to_string());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let Some(row) = tx
                .query_opt(
                    "SELECT id, view FROM jobs WHERE status = 'enqueued' AND ($1::text IS NULL OR id = $1)
                     ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED",
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

fn record_of(r: &tokio_postgres::Row) -> ShapeRecord {
    ShapeRecord {
        id: r.get(0),
        format: r.get(1),
        created_at: r.get(2),
        bytes: r.get::<_, i64>(3) as usize,
        summary: serde_json::from_str(r.get::<_, &str>(4)).unwrap_or(Value::Null),
    }
}

impl ShapeStore for Postgres {
    fn insert(&self, shape: StoredShape, original: &[u8]) -> std::io::Result<(bool, Arc<StoredShape>)> {
        let r = shape.record.clone();
        let bytes = original.to_vec();
        // The record and its upload in one transaction; a concurrent upload of the same id waits on the key and
        // then finds it stored.
        let inserted = self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let n = tx
                .execute(
                    "INSERT INTO shapes (id, format, created_at, bytes, summary) VALUES ($1, $2, $3, $4, $5)
                     ON CONFLICT (id) DO NOTHING",
                    &[&r.id, &r.format, &r.created_at, &to_i64(r.bytes), &r.summary.to_string()],
                )
                .await
                .map_err(pg)?;
            if n == 0 {
                return Ok(false);
            }
            tx.execute("DELETE FROM blobs WHERE kind = 'shape' AND id = $1", &[&r.id]).await.map_err(pg)?;
            put_blob(&tx, "shape", &r.id, &bytes).await?;
            tx.commit().await.map_err(pg)?;
            Ok(true)
        })?;
        if inserted {
            let s = Arc::new(shape);
            self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(&s.id, s.clone(), shape_size(&s));
            return Ok((true, s));
        }
        match ShapeStore::get(self, &shape.validated.id)? {
            Some(s) => Ok((false, s)),
            None => Err(std::io::Error::other("the stored shape was removed while it was stored again")),
        }
    }
    fn get(&self, id: &ShapeId) -> std::io::Result<Option<Arc<StoredShape>>> {
        let id = &*id.hex();
        let cached = self.parsed.lock().unwrap_or_else(|e| e.into_inner()).get(id);
        if let Some(s) = cached {
            // Another replica may have removed it: the record is checked (one indexed query), the parse is not redone.
            if self.stored(id)? {
                return Ok(Some(s));
            }
            self.parsed.lock().unwrap_or_else(|e| e.into_inner()).remove(id);
            return Ok(None);
        }
        let key = id.to_string();
        let stored = self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let Some(row) = c
                .query_opt("SELECT id, format, created_at, bytes, summary FROM shapes WHERE id = $1", &[&key])
                .await
                .map_err(pg)?
            else {
                return Ok(None);
            };
            Ok(Some((record_of(&row), get_blob(&c, "shape", &key).await?)))
        })?;
        let Some((record, bytes)) = stored else { return Ok(None) };
        let Some(s) = parse_shape(record, &bytes, self.max_vertices) else {
            // Removed between the two reads, or not readable under this replica's limits: not a shape here.
            tracing::warn!(shape = %id, "a stored shape could not be read back");
            return Ok(None);
        };
        let s = Arc::new(s);
        // Cached only if still stored: a removal that ran meanwhile must not be undone by the cache.
        if !self.stored(id)? {
            return Ok(None);
        }
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(id, s.clone(), shape_size(&s));
        Ok(Some(s))
    }
    fn list(&self, offset: usize, limit: usize) -> std::io::Result<(Vec<ShapeRecord>, usize)> {
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let total: i64 = c.query_one("SELECT COUNT(*) FROM shapes", &[]).await.map_err(pg)?.get(0);
            let rows = c
                .query(
                    "SELECT id, format, created_at, bytes, summary FROM shapes ORDER BY id LIMIT $1 OFFSET $2",
                    &[&to_i64(limit), &to_i64(offset)],
                )
                .await
                .map_err(pg)?;
            Ok((rows.iter().map(record_of).collect(), total as usize))
        })
    }
    fn remove(&self, id: &ShapeId) -> std::io::Result<bool> {
        let id = &*id.hex();
        let key = id.to_string();
        let removed = self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            tx.execute("SELECT pg_advisory_xact_lock($1)", &[&LOG_LOCK]).await.map_err(pg)?;
            let n = tx.execute("DELETE FROM shapes WHERE id = $1", &[&key]).await.map_err(pg)?;
            tx.execute("DELETE FROM blobs WHERE kind = 'shape' AND id = $1", &[&key]).await.map_err(pg)?;
            tx.execute("DELETE FROM fingerprints WHERE shape_id = $1", &[&key]).await.map_err(pg)?;
            tx.execute("DELETE FROM shape_tags WHERE shape_id = $1", &[&key]).await.map_err(pg)?;
            if n > 0 {
                tx.execute("INSERT INTO fingerprint_log (family, shape_id) VALUES ('', $1)", &[&key])
                    .await
                    .map_err(pg)?;
            }
            tx.commit().await.map_err(pg)?;
            Ok(n > 0)
        })?;
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).remove(id);
        Ok(removed)
    }
    fn healthy(&self) -> bool {
        self.run(|pool| async move {
            let probe = async {
                let c = pool.get().await.map_err(pg)?;
                c.query_one("SELECT 1", &[]).await.map_err(pg)?;
                Ok(())
            };
            tokio::time::timeout(Duration::from_secs(2), probe)
                .await
                .map_err(|_| "postgres: no answer in 2 s".to_string())?
        })
        .is_ok()
    }
    fn pool_status(&self) -> Option<(usize, usize, usize)> {
        Some(Postgres::pool_status(self))
    }
}

/// Takes the log's lock for the transaction, so that log entries are written one transaction at a time (their
/// numbers in commit order: a replica that has read up to one number has seen every entry below it), and holds the
/// shape while the transaction writes about it (a removal waits for it); false when the shape is not stored.
async fn lock_log_and_hold(tx: &tokio_postgres::Transaction<'_>, shape_id: &str) -> PgResult<bool> {
    tx.execute("SELECT pg_advisory_xact_lock($1)", &[&LOG_LOCK]).await.map_err(pg)?;
    Ok(tx.query_opt("SELECT 1 FROM shapes WHERE id = $1 FOR KEY SHARE", &[&shape_id]).await.map_err(pg)?.is_some())
}

impl FingerprintStore for Postgres {
    fn put_fingerprint(&self, family: &str, shape_id: &str, values: &[f64]) -> std::io::Result<bool> {
        let blob: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let (family, shape_id) = (family.to_string(), shape_id.to_string());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            if !lock_log_and_hold(&tx, &shape_id).await? {
                return Ok(false);
            }
            let n = tx
                .execute(
                    "INSERT INTO fingerprints (family, shape_id, fingerprint) VALUES ($1, $2, $3)
                     ON CONFLICT (family, shape_id) DO UPDATE SET fingerprint = excluded.fingerprint",
                    &[&family, &shape_id, &blob],
                )
                .await
                .map_err(pg)?;
            if n > 0 {
                tx.execute(
                    "INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES ($1, $2, $3)",
                    &[&family, &shape_id, &blob],
                )
                .await
                .map_err(pg)?;
            }
            tx.commit().await.map_err(pg)?;
            Ok(n > 0)
        })
    }
    fn fingerprint_counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let rows = c.query("SELECT family, COUNT(*) FROM fingerprints GROUP BY family", &[]).await.map_err(pg)?;
            Ok(rows.iter().map(|r| (r.get(0), r.get::<_, i64>(1) as usize)).collect())
        })
    }
    fn for_each_fingerprint(&self, f: &mut dyn FnMut(&str, &str, &[f64])) -> std::io::Result<()> {
        // Pages in key order, so that a large table is never held whole.
        const PAGE: i64 = 10_000;
        let mut after = (String::new(), String::new());
        loop {
            let key = after.clone();
            let rows = self.run(move |pool| async move {
                let c = pool.get().await.map_err(pg)?;
                c.query(
                    "SELECT family, shape_id, fingerprint FROM fingerprints WHERE (family, shape_id) > ($1, $2)
                     ORDER BY family, shape_id LIMIT $3",
                    &[&key.0, &key.1, &PAGE],
                )
                .await
                .map_err(pg)
            })?;
            for r in &rows {
                f(r.get(0), r.get(1), &f64s_of(r.get(2)));
            }
            match rows.last() {
                Some(r) if rows.len() as i64 == PAGE => after = (r.get(0), r.get(1)),
                _ => return Ok(()),
            }
        }
    }
    fn fingerprints_of(&self, family: &str, shape_ids: &[String]) -> std::io::Result<HashMap<String, Vec<f64>>> {
        let (family, ids) = (family.to_string(), shape_ids.to_vec());
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let rows = c
                .query(
                    "SELECT shape_id, fingerprint FROM fingerprints WHERE family = $1 AND shape_id = ANY($2)",
                    &[&family, &ids],
                )
                .await
                .map_err(pg)?;
            Ok(rows.iter().map(|r| (r.get(0), f64s_of(r.get(1)))).collect())
        })
    }
    fn set_tags(&self, shape_id: &str, edit: &TagEdit) -> std::io::Result<TagsOutcome> {
        let (shape_id, edit) = (shape_id.to_string(), edit.clone());
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            // The log's lock also orders edits of tags: one at a time, read and written in one transaction.
            if !lock_log_and_hold(&tx, &shape_id).await? {
                return Ok(TagsOutcome::NotStored);
            }
            let rows = tx.query("SELECT tag FROM shape_tags WHERE shape_id = $1", &[&shape_id]).await.map_err(pg)?;
            let tags = match edit.apply(rows.iter().map(|r| r.get(0)).collect()) {
                Ok(t) => t,
                Err(n) => return Ok(TagsOutcome::TooMany(n)),
            };
            tx.execute("DELETE FROM shape_tags WHERE shape_id = $1", &[&shape_id]).await.map_err(pg)?;
            tx.execute("INSERT INTO shape_tags (shape_id, tag) SELECT $1, unnest($2::text[])", &[&shape_id, &tags])
                .await
                .map_err(pg)?;
            tx.execute(
                "INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES ($1, $2, $3)",
                &[&TAGS_ENTRY, &shape_id, &tags_blob(&tags)],
            )
            .await
            .map_err(pg)?;
            tx.commit().await.map_err(pg)?;
            Ok(TagsOutcome::Set(tags))
        })
    }
    fn tags_of(&self, shape_id: &str) -> std::io::Result<Vec<String>> {
        let shape_id = shape_id.to_string();
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let rows = c
                .query("SELECT tag FROM shape_tags WHERE shape_id = $1 ORDER BY tag", &[&shape_id])
                .await
                .map_err(pg)?;
            Ok(rows.iter().map(|r| r.get(0)).collect())
        })
    }
    fn for_each_tag(&self, f: &mut dyn FnMut(&str, &str)) -> std::io::Result<()> {
        let rows = self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            c.query("SELECT shape_id, tag FROM shape_tags", &[]).await.map_err(pg)
        })?;
        for r in &rows {
            f(r.get(0), r.get(1));
        }
        Ok(())
    }
    fn fingerprint_log_end(&self) -> std::io::Result<i64> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            Ok(c.query_one("SELECT COALESCE(MAX(seq), 0) FROM fingerprint_log", &[]).await.map_err(pg)?.get(0))
        })
    }
    fn tag_count(&self) -> std::io::Result<usize> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let n: i64 = c.query_one("SELECT COUNT(*) FROM shape_tags", &[]).await.map_err(pg)?.get(0);
            Ok(n as usize)
        })
    }
    fn store_identity(&self) -> std::io::Result<String> {
        self.run(|pool| async move {
            let c = pool.get().await.map_err(pg)?;
            Ok(c.query_one("SELECT value FROM meta WHERE key = 'store_id'", &[]).await.map_err(pg)?.get(0))
        })
    }
    fn fingerprint_log_entry(&self, seq: i64) -> std::io::Result<Option<String>> {
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let row = c.query_opt("SELECT shape_id FROM fingerprint_log WHERE seq = $1", &[&seq]).await.map_err(pg)?;
            Ok(row.map(|r| r.get(0)))
        })
    }
    fn fingerprint_changes(&self, after: i64) -> std::io::Result<(Vec<FingerprintChange>, i64)> {
        self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let rows = c
                .query(
                    "SELECT seq, family, shape_id, fingerprint FROM fingerprint_log WHERE seq > $1 ORDER BY seq",
                    &[&after],
                )
                .await
                .map_err(pg)?;
            let end = rows.last().map_or(after, |r| r.get(0));
            let changes = rows
                .iter()
                .map(|r| FingerprintChange::of_row(r.get(1), r.get(2), r.get::<_, Option<&[u8]>>(3)))
                .collect();
            Ok((changes, end))
        })
    }
}

/// A result is a row (its ETag, summary and arrays' shapes) and its numbers as `values` blobs: little-endian
/// float64 in 1 MiB chunks, written in the row's transaction and read back chunk by chunk into the arrays.
impl ResultStore for Postgres {
    fn put(&self, result: Arc<StoredResult>) -> std::io::Result<Arc<StoredResult>> {
        // The numbers are turned into chunks here, one at a time, and handed to the transaction on the store's
        // runtime through a small channel: never all at once in memory, nor converted on the runtime's threads.
        let (chunks_tx, mut chunks_rx) = tokio::sync::mpsc::channel::<Vec<u8>>(2);
        let (done_tx, done_rx) = std::sync::mpsc::sync_channel::<PgResult<bool>>(1);
        let (id, meta, count, etag) =
            (result.id.clone(), result.meta().to_string(), result.values(), result.etag.clone());
        let pool = self.pool.clone();
        self.rt.as_ref().expect("the runtime lives as long as the store").spawn(async move {
            let write = async {
                let mut c = pool.get().await.map_err(pg)?;
                let tx = c.transaction().await.map_err(pg)?;
                let chunks = (count * 8).div_ceil(CHUNK) as i32;
                // Written once: a second write of the same id (the same request computed again after a lost
                // claim) finds the row and writes nothing.
                let n = tx
                    .execute(
                        "INSERT INTO results (id, meta, values_count, chunks, etag) VALUES ($1, $2, $3, $4, $5)
                         ON CONFLICT (id) DO NOTHING",
                        &[&id, &meta, &to_i64(count), &chunks, &etag],
                    )
                    .await
                    .map_err(pg)?;
                if n == 0 {
                    return Ok(false);
                }
                let st = tx
                    .prepare_cached("INSERT INTO blobs (kind, id, seq, data) VALUES ('values', $1, $2, $3)")
                    .await
                    .map_err(pg)?;
                let mut seq = 0i32;
                while let Some(chunk) = chunks_rx.recv().await {
                    tx.execute(&st, &[&id, &seq, &chunk]).await.map_err(pg)?;
                    seq += 1;
                }
                tx.commit().await.map_err(pg)?;
                Ok(true)
            };
            let answer = tokio::time::timeout(CALL_TIMEOUT, write)
                .await
                .unwrap_or_else(|_| Err(format!("postgres: no answer in {} s", CALL_TIMEOUT.as_secs())));
            let _ = done_tx.send(answer);
        });
        let written = blocking(|| {
            for chunk in result.value_chunks(CHUNK) {
                // A closed channel: the transaction ended (the id was stored already, or an error) — its answer says.
                if chunks_tx.blocking_send(chunk).is_err() {
                    break;
                }
            }
            drop(chunks_tx);
            done_rx.recv()
        })
        .map_err(|_| std::io::Error::other("postgres: the write's task ended"))?
        .map_err(std::io::Error::other)?;
        if written {
            self.results.lock().unwrap_or_else(|e| e.into_inner()).put(
                &result.id,
                result.clone(),
                result_size(&result),
            );
            return Ok(result);
        }
        let id = JobId::parse(&result.id).ok_or_else(|| std::io::Error::other("a result id that is not a job id"))?;
        ResultStore::get(self, &id)?.ok_or_else(|| std::io::Error::other("the stored result went missing"))
    }
    fn get(&self, id: &ResultId) -> std::io::Result<Option<Arc<StoredResult>>> {
        let id = &*id.hex();
        if let Some(r) = self.results.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            return Ok(Some(r));
        }
        let key = id.to_string();
        let Some(meta) = self.run(move |pool| async move {
            let c = pool.get().await.map_err(pg)?;
            let row = c.query_opt("SELECT meta FROM results WHERE id = $1", &[&key]).await.map_err(pg)?;
            Ok(row.map(|r| r.get::<_, String>(0)))
        })?
        else {
            return Ok(None);
        };
        let meta: Value = serde_json::from_str(&meta).map_err(std::io::Error::other)?;
        // The numbers arrive chunk by chunk and are copied into the arrays as they come: never the whole twice.
        let (tx, rx) = tokio::sync::mpsc::channel::<PgResult<Vec<u8>>>(2);
        let key = id.to_string();
        let pool = self.pool.clone();
        self.rt.as_ref().expect("the runtime lives as long as the store").spawn(async move {
            let stream = async {
                let c = pool.get().await.map_err(pg)?;
                let rows = c
                    .query_raw(
                        "SELECT data FROM blobs WHERE kind = 'values' AND id = $1 ORDER BY seq",
                        std::iter::once(&key as &(dyn tokio_postgres::types::ToSql + Sync)),
                    )
                    .await
                    .map_err(pg)?;
                use futures_util::StreamExt;
                let mut rows = std::pin::pin!(rows);
                while let Some(row) = rows.next().await {
                    let row = row.map_err(pg)?;
                    if tx.send(Ok(row.get::<_, Vec<u8>>(0))).await.is_err() {
                        return Ok(());
                    }
                }
                Ok::<(), String>(())
            };
            if let Err(e) =
                tokio::time::timeout(CALL_TIMEOUT, stream).await.unwrap_or_else(|_| Err("postgres: timed out".into()))
            {
                let _ = tx.send(Err(e)).await;
            }
        });
        let mut reader = ChunkReader { rx, chunk: vec![], at: 0 };
        let r = blocking(|| StoredResult::from_meta(id, &meta, |data| super::sqlite::read_values(&mut reader, data)))?;
        let r = Arc::new(r);
        self.results.lock().unwrap_or_else(|e| e.into_inner()).put(id, r.clone(), result_size(&r));
        Ok(Some(r))
    }
    fn remove(&self, id: &ResultId) -> std::io::Result<bool> {
        let key = id.hex();
        self.results.lock().unwrap_or_else(|e| e.into_inner()).remove(&key);
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            let n = tx.execute("DELETE FROM results WHERE id = $1", &[&key]).await.map_err(pg)?;
            tx.execute("DELETE FROM blobs WHERE kind = 'values' AND id = $1", &[&key]).await.map_err(pg)?;
            tx.commit().await.map_err(pg)?;
            Ok(n > 0)
        })
    }
}

/// The bytes of blob chunks as they arrive, as a reader (outside the store's runtime).
struct ChunkReader {
    rx: tokio::sync::mpsc::Receiver<PgResult<Vec<u8>>>,
    chunk: Vec<u8>,
    at: usize,
}

impl std::io::Read for ChunkReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.at == self.chunk.len() {
            match self.rx.blocking_recv() {
                Some(Ok(c)) => (self.chunk, self.at) = (c, 0),
                Some(Err(e)) => return Err(std::io::Error::other(e)),
                None => return Ok(0),
            }
        }
        let n = buf.len().min(self.chunk.len() - self.at);
        buf[..n].copy_from_slice(&self.chunk[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// `UPDATE … SET lease_until = now() + lease`: the lease in seconds as a bind parameter.
fn secs(d: Duration) -> f64 {
    d.as_secs_f64()
}

impl JobQueue for Postgres {
    fn enqueue(&self, view: JobView, capacity: usize) -> std::io::Result<Enqueued> {
        self.run(move |pool| async move {
            let mut c = pool.get().await.map_err(pg)?;
            let tx = c.transaction().await.map_err(pg)?;
            // Admissions one at a time, so that the capacity holds across replicas.
            tx.execute("SELECT pg_advisory_xact_lock($1)", &[&ENQUEUE_LOCK]).await.map_err(pg)?;
            if let Some(row) =
                tx.query_opt("SELECT view FROM jobs WHERE id = $1 FOR UPDATE", &[&view.id]).await.map_err(pg)?
            {
                let old = view_of(row.get(0))?;
                if !matches!(old.status, Status::Failed | Status::Canceled) {
                    return Ok(Enqueued::Existing(old));
                }
            }
            let active: i64 = tx
                .query_one("SELECT COUNT(*) FROM jobs WHERE status IN ('enqueued', 'processing')", &[])
                .await
                .map_err(pg)?
                .get(0);
            if active as usize >= capacity {
                return Ok(Enqueued::Full);
            }
            tx.execute(
                "INSERT INTO jobs (id, status, view) VALUES ($1, 'enqueued', $2)
                 ON CONFLICT (id) DO UPDATE SET status = 'enqueued', view = excluded.view, owner = NULL,
                 lease_until = NULL, cancel = false, seq = nextval('jobs_order')",
                &[&view.id, &text_of(&view)?],
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
    fn cancel(&self, id: &JobId, problem: &Problem) -> std::io::Result<Option<JobView>> {
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
                let status = super::queue::release(&mut view, row.get(2));
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
    fn changes(&self) -> broadcast::Receiver<String> {
        self.changes.subscribe()
    }
}

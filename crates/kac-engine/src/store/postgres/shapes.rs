//! The shared store's shapes.

use super::*;

pub(super) fn record_of(r: &tokio_postgres::Row) -> ShapeRecord {
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
pub(super) async fn lock_log_and_hold(tx: &tokio_postgres::Transaction<'_>, shape_id: &str) -> PgResult<bool> {
    tx.execute("SELECT pg_advisory_xact_lock($1)", &[&LOG_LOCK]).await.map_err(pg)?;
    Ok(tx.query_opt("SELECT 1 FROM shapes WHERE id = $1 FOR KEY SHARE", &[&shape_id]).await.map_err(pg)?.is_some())
}

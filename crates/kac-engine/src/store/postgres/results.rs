//! The shared store's results, their arrays in chunks.

use super::*;

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
pub(super) struct ChunkReader {
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

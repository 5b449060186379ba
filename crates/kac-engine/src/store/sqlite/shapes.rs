//! The embedded store's shapes: records in SQLite, canonical files beside it.

use super::*;

pub(super) fn row_record(r: &rusqlite::Row<'_>) -> rusqlite::Result<ShapeRecord> {
    let summary: String = r.get(4)?;
    Ok(ShapeRecord {
        id: r.get(0)?,
        format: r.get(1)?,
        created_at: r.get(2)?,
        bytes: r.get::<_, i64>(3)? as usize,
        summary: serde_json::from_str(&summary).unwrap_or(Value::Null),
    })
}

impl ShapeStore for Database {
    fn insert(&self, shape: StoredShape, original: &[u8]) -> std::io::Result<(bool, Arc<StoredShape>)> {
        let path = file_in(&self.shape_dir, &shape.id)?;
        // Twice at most: a shape stored under this id (record and file) is returned as it is; if it cannot be
        // read back (its file lost or unreadable, or removed in between), the second round stores this upload.
        for force in [false, true] {
            {
                // One writer per id from the check to the record: the first upload's file and record win
                // together, and every other caller gets the stored shape (in the first one's format) back.
                let _id = self.id_lock(&shape.id);
                if force || self.record(&shape.id)?.is_none() || !path.exists() {
                    // The upload first (atomically), then its record: a crash between leaves an unreferenced file
                    // only, which the next upload of that id replaces.
                    write_atomic(&path, original)?;
                    let r = &shape.record;
                    self.conn()
                        .execute(
                            "INSERT INTO shapes (id, format, created_at, bytes, summary) VALUES (?1, ?2, ?3, ?4, ?5)
                             ON CONFLICT(id) DO UPDATE SET format = excluded.format, bytes = excluded.bytes,
                             summary = excluded.summary",
                            rusqlite::params![r.id, r.format, r.created_at, r.bytes as i64, r.summary.to_string()],
                        )
                        .map_err(db_err)?;
                    let s = Arc::new(shape);
                    self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(&s.id, s.clone(), shape_size(&s));
                    return Ok((true, s));
                }
            }
            if let Some(existing) = ShapeStore::get(self, &shape.validated.id)? {
                return Ok((false, existing));
            }
        }
        unreachable!("the forced round stores the shape or returns its error")
    }
    fn get(&self, id: &ShapeId) -> std::io::Result<Option<Arc<StoredShape>>> {
        let id = &*id.hex();
        if let Some(s) = self.parsed.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            return Ok(Some(s));
        }
        let Some(record) = self.record(id)? else { return Ok(None) };
        // A record whose upload was lost (or no longer parses) is not a stored shape: the next upload of the id
        // stores it again.
        let bytes = match std::fs::read(file_in(&self.shape_dir, id)?) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e),
        };
        let Some(s) = parse_shape(record, &bytes, self.max_vertices) else { return Ok(None) };
        let s = Arc::new(s);
        // Cached only if still stored: a removal that ran while this parsed must not be undone by the cache.
        let _id = self.id_lock(id);
        if self.record(id)?.is_none() {
            return Ok(None);
        }
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(id, s.clone(), shape_size(&s));
        Ok(Some(s))
    }
    fn list(&self, offset: usize, limit: usize) -> std::io::Result<(Vec<ShapeRecord>, usize)> {
        let c = self.conn();
        let total: i64 = c.query_row("SELECT COUNT(*) FROM shapes", [], |r| r.get(0)).map_err(db_err)?;
        let mut st = c
            .prepare("SELECT id, format, created_at, bytes, summary FROM shapes ORDER BY id LIMIT ?1 OFFSET ?2")
            .map_err(db_err)?;
        let rows = st.query_map([limit as i64, offset as i64], row_record).map_err(db_err)?;
        Ok((rows.collect::<Result<_, _>>().map_err(db_err)?, total as usize))
    }
    fn remove(&self, id: &ShapeId) -> std::io::Result<bool> {
        let id = &*id.hex();
        let _id = self.id_lock(id);
        let n = {
            let mut c = self.conn();
            let tx = c.transaction().map_err(db_err)?;
            let n = tx.execute("DELETE FROM shapes WHERE id = ?1", [id]).map_err(db_err)?;
            tx.execute("DELETE FROM fingerprints WHERE shape_id = ?1", [id]).map_err(db_err)?;
            tx.execute("DELETE FROM shape_tags WHERE shape_id = ?1", [id]).map_err(db_err)?;
            if n > 0 {
                tx.execute("INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES ('', ?1, NULL)", [id])
                    .map_err(db_err)?;
            }
            tx.commit().map_err(db_err)?;
            n
        };
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).remove(id);
        let _ = std::fs::remove_file(file_in(&self.shape_dir, id)?);
        Ok(n > 0)
    }
    fn healthy(&self) -> bool {
        self.conn().query_row("SELECT 1", [], |r| r.get::<_, i64>(0)).is_ok()
    }
}

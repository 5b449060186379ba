//! The embedded store's fingerprints, tags and their log of changes.

use super::*;

impl FingerprintStore for Database {
    fn put_fingerprint(&self, family: &str, shape_id: &str, values: &[f64]) -> std::io::Result<bool> {
        // Little-endian f64s: 8 bytes a value, exact. Under the shape's lock and only while it is stored, so a
        // shape deleted while its analysis ran leaves no fingerprint behind.
        let blob: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let _id = self.id_lock(shape_id);
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let n = tx
            .execute(
                "INSERT INTO fingerprints (family, shape_id, fingerprint)
                 SELECT ?1, ?2, ?3 WHERE EXISTS (SELECT 1 FROM shapes WHERE id = ?2)
                 ON CONFLICT(family, shape_id) DO UPDATE SET fingerprint = excluded.fingerprint",
                rusqlite::params![family, shape_id, blob],
            )
            .map_err(db_err)?;
        if n > 0 {
            tx.execute(
                "INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES (?1, ?2, ?3)",
                rusqlite::params![family, shape_id, blob],
            )
            .map_err(db_err)?;
        }
        tx.commit().map_err(db_err)?;
        Ok(n > 0)
    }
    fn fingerprint_counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT family, COUNT(*) FROM fingerprints GROUP BY family").map_err(db_err)?;
        let rows = st.query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as usize))).map_err(db_err)?;
        rows.collect::<Result<_, _>>().map_err(db_err)
    }
    fn for_each_fingerprint(&self, f: &mut dyn FnMut(&str, &str, &[f64])) -> std::io::Result<()> {
        let c = self.conn();
        let mut st = c.prepare("SELECT family, shape_id, fingerprint FROM fingerprints").map_err(db_err)?;
        let mut rows = st.query([]).map_err(db_err)?;
        let mut values = vec![];
        while let Some(r) = rows.next().map_err(db_err)? {
            let (family, id) = (r.get_ref(0).map_err(db_err)?, r.get_ref(1).map_err(db_err)?);
            let (family, id) =
                (family.as_str().map_err(std::io::Error::other)?, id.as_str().map_err(std::io::Error::other)?);
            let blob = r.get_ref(2).map_err(db_err)?.as_blob().map_err(std::io::Error::other)?;
            values.clear();
            values.extend(blob.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))));
            f(family, id, &values);
        }
        Ok(())
    }
    fn fingerprints_of(&self, family: &str, shape_ids: &[String]) -> std::io::Result<HashMap<String, Vec<f64>>> {
        let c = self.conn();
        let mut st = c
            .prepare_cached("SELECT fingerprint FROM fingerprints WHERE family = ?1 AND shape_id = ?2")
            .map_err(db_err)?;
        let mut out = HashMap::new();
        for id in shape_ids {
            let blob: Option<Vec<u8>> =
                st.query_row(rusqlite::params![family, id], |r| r.get(0)).optional().map_err(db_err)?;
            if let Some(b) = blob {
                out.insert(id.clone(), f64s_of(&b));
            }
        }
        Ok(out)
    }
    fn set_tags(&self, shape_id: &str, edit: &TagEdit) -> std::io::Result<TagsOutcome> {
        let _id = self.id_lock(shape_id);
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let stored = tx
            .query_row("SELECT 1 FROM shapes WHERE id = ?1", [shape_id], |_| Ok(()))
            .optional()
            .map_err(db_err)?
            .is_some();
        if !stored {
            return Ok(TagsOutcome::NotStored);
        }
        let current: Vec<String> = {
            let mut st = tx.prepare("SELECT tag FROM shape_tags WHERE shape_id = ?1").map_err(db_err)?;
            let rows = st.query_map([shape_id], |r| r.get(0)).map_err(db_err)?;
            rows.collect::<Result<_, _>>().map_err(db_err)?
        };
        let tags = match edit.apply(current) {
            Ok(t) => t,
            Err(n) => return Ok(TagsOutcome::TooMany(n)),
        };
        tx.execute("DELETE FROM shape_tags WHERE shape_id = ?1", [shape_id]).map_err(db_err)?;
        for t in &tags {
            tx.execute("INSERT INTO shape_tags (shape_id, tag) VALUES (?1, ?2)", [shape_id, t]).map_err(db_err)?;
        }
        tx.execute(
            "INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES (?1, ?2, ?3)",
            rusqlite::params![TAGS_ENTRY, shape_id, tags_blob(&tags)],
        )
        .map_err(db_err)?;
        tx.commit().map_err(db_err)?;
        Ok(TagsOutcome::Set(tags))
    }
    fn tags_of(&self, shape_id: &str) -> std::io::Result<Vec<String>> {
        let c = self.conn();
        let mut st = c.prepare_cached("SELECT tag FROM shape_tags WHERE shape_id = ?1 ORDER BY tag").map_err(db_err)?;
        let rows = st.query_map([shape_id], |r| r.get(0)).map_err(db_err)?;
        rows.collect::<Result<_, _>>().map_err(db_err)
    }
    fn for_each_tag(&self, f: &mut dyn FnMut(&str, &str)) -> std::io::Result<()> {
        let c = self.conn();
        let mut st = c.prepare("SELECT shape_id, tag FROM shape_tags").map_err(db_err)?;
        let mut rows = st.query([]).map_err(db_err)?;
        while let Some(r) = rows.next().map_err(db_err)? {
            f(
                r.get_ref(0).map_err(db_err)?.as_str().map_err(std::io::Error::other)?,
                r.get_ref(1).map_err(db_err)?.as_str().map_err(std::io::Error::other)?,
            );
        }
        Ok(())
    }
    fn fingerprint_log_end(&self) -> std::io::Result<i64> {
        self.conn().query_row("SELECT COALESCE(MAX(seq), 0) FROM fingerprint_log", [], |r| r.get(0)).map_err(db_err)
    }
    fn tag_count(&self) -> std::io::Result<usize> {
        let n: i64 = self.conn().query_row("SELECT COUNT(*) FROM shape_tags", [], |r| r.get(0)).map_err(db_err)?;
        Ok(n as usize)
    }
    fn store_identity(&self) -> std::io::Result<String> {
        self.conn().query_row("SELECT value FROM meta WHERE key = 'store_id'", [], |r| r.get(0)).map_err(db_err)
    }
    fn fingerprint_log_entry(&self, seq: i64) -> std::io::Result<Option<String>> {
        self.conn()
            .query_row("SELECT shape_id FROM fingerprint_log WHERE seq = ?1", [seq], |r| r.get(0))
            .optional()
            .map_err(db_err)
    }
    fn fingerprint_changes(&self, after: i64) -> std::io::Result<(Vec<FingerprintChange>, i64)> {
        let c = self.conn();
        let mut st = c
            .prepare("SELECT seq, family, shape_id, fingerprint FROM fingerprint_log WHERE seq > ?1 ORDER BY seq")
            .map_err(db_err)?;
        let mut end = after;
        let rows = st
            .query_map([after], |r| {
                let blob: Option<Vec<u8>> = r.get(3)?;
                Ok((r.get::<_, i64>(0)?, FingerprintChange::of_row(r.get(1)?, r.get(2)?, blob.as_deref())))
            })
            .map_err(db_err)?;
        let mut out = vec![];
        for row in rows {
            let (seq, change) = row.map_err(db_err)?;
            end = seq;
            out.push(change);
        }
        Ok((out, end))
    }
}

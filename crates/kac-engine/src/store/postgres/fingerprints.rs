//! The shared store's fingerprints, tags and their log of changes.

use super::*;

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

//! Fused search: the nearest shapes by a weighted sum of several families' distances, each divided by its spread
//! over the collection ([`Family::spread`]), so that a family measured in larger units or over more values does not
//! outweigh the others. Every shape holding all the families is compared (a scan: the sum of distances has no
//! cells to probe), by its single-precision rows with their rounding bounds, and the candidates that may be among
//! the nearest are ranked by their exact stored values: the answer is exact by construction.

use super::*;

/// One family of a fused search: the query's values in it and its weight.
pub struct Member<'a> {
    pub family: &'a str,
    pub values: &'a [f64],
    pub weight: f64,
}

/// A fused search.
pub struct FusedQuery<'a> {
    pub members: &'a [Member<'a>],
    pub count: usize,
    /// A shape left out of the answer (the query shape).
    pub exclude: Option<ShapeId>,
    /// Only shapes carrying every one of these tags.
    pub tags: &'a [Tag],
}

/// A fused search's answer.
#[derive(Debug, Default)]
pub struct FusedFound {
    /// Nearest first, ties by id: (shape id, fused distance, each member's exact distance in the members' order).
    pub neighbours: Vec<(String, f64, Vec<f64>)>,
    /// Each member's spread over the collection (what its distance was divided by; a family of one fingerprint
    /// has none and counts unscaled).
    pub spreads: Vec<f64>,
    /// Shapes holding every member family (those compared when no tag narrows them).
    pub searched: usize,
    /// Shapes whose fused distance was computed.
    pub probed: usize,
    /// Shapes holding some of the families but not all (not comparable: their fingerprint jobs have not finished,
    /// or they were fingerprinted by one family only).
    pub incomplete: usize,
    /// Whether the neighbours are proven exact (every candidate's exact values were found in the store).
    pub exact: bool,
}

impl Index {
    /// The `count` nearest shapes by the fused distance Σ wᵢ dᵢ / sᵢ (Euclidean distances dᵢ, spreads sᵢ).
    pub fn nearest_fused(&self, q: &FusedQuery, fetch: Fetch) -> Result<FusedFound, SearchError> {
        let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
        let mut members: Vec<&Family> = Vec::with_capacity(q.members.len());
        for m in q.members {
            let Some(f) = fams.get(m.family).filter(|f| f.len() > 0) else {
                // A family nobody holds: no shape is comparable.
                return Ok(FusedFound { exact: true, ..Default::default() });
            };
            if m.values.len() != f.k {
                return Err(SearchError::Length(format!(
                    "the query has {} values in family {}; its fingerprints have {}",
                    m.values.len(),
                    m.family,
                    f.k
                )));
            }
            members.push(f);
        }
        if members.is_empty() || q.count == 0 {
            return Ok(FusedFound { exact: true, ..Default::default() });
        }
        let spreads: Vec<f64> = members.iter().map(|f| f.spread().unwrap_or(0.0)).collect();
        let scales: Vec<f64> = q
            .members
            .iter()
            .zip(&spreads)
            .map(|(m, &s)| if s > 0.0 && s.is_finite() { m.weight / s } else { m.weight })
            .collect();
        let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
        let sets: Option<Vec<&IdSet>> = q.tags.iter().map(|t| tags.by_tag.get(t)).collect();
        let Some(mut sets) = sets else {
            // A tag no shape carries.
            return Ok(FusedFound { spreads, exact: true, ..Default::default() });
        };
        sets.sort_by_key(|s| s.len());
        let base = (0..members.len()).min_by_key(|&i| members[i].len()).unwrap_or(0);
        // The fused distance of a shape by its rows (its row in the base family given), with its rounding bound;
        // None when it lacks a family.
        let approx = |id: &ShapeId, base_row: Option<usize>| -> Option<(f64, f64)> {
            let (mut d, mut err) = (0.0, 0.0);
            for (i, f) in members.iter().enumerate() {
                let r = match (i == base, base_row) {
                    (true, Some(r)) => r,
                    _ => *f.row.get(id)? as usize,
                };
                d += scales[i] * approx_distance(q.members[i].values, f.row_of(r), Metric::Euclidean);
                err += scales[i] * f.err[r] as f64;
            }
            Some((d, err))
        };
        let mut c = Collector::new(q.count);
        let (mut searched, mut incomplete) = (0, 0);
        // The shapes offered, by the number the collector keeps.
        let mut offered: Vec<ShapeId> = vec![];
        let admits = |id: &ShapeId| Some(id) != q.exclude.as_ref() && sets.iter().all(|s| s.contains(id));
        match sets.first().filter(|s| s.len() < members[base].len()) {
            // A tag narrower than the family: its shapes, each looked up.
            Some(few) => {
                for id in few.iter().filter(|id| admits(id)) {
                    match approx(id, None) {
                        Some((d, e)) => {
                            searched += 1;
                            c.offer(d, e, offered.len() as u32);
                            offered.push(*id);
                        }
                        None => incomplete += usize::from(members.iter().any(|f| f.row.contains_key(id))),
                    }
                }
            }
            None => {
                let fam = members[base];
                for r in 0..fam.len() {
                    let id = &fam.ids[r];
                    if !admits(id) {
                        // Counted as held, not compared: no distance is computed for it.
                        searched += usize::from(members.iter().all(|f| f.row.contains_key(id)));
                        continue;
                    }
                    match approx(id, Some(r)) {
                        Some((d, e)) => {
                            searched += 1;
                            c.offer(d, e, offered.len() as u32);
                            offered.push(*id);
                        }
                        None => incomplete += 1,
                    }
                }
                // Shapes of the other families that the base family lacks (each once).
                let mut lacking: IdSet = Default::default();
                for f in members.iter().filter(|f| !std::ptr::eq(**f, fam)) {
                    lacking.extend(f.ids.iter().filter(|id| !fam.row.contains_key(*id) && admits(id)));
                }
                incomplete += lacking.len();
            }
        }
        let probed = c.offered;
        let ids: Vec<String> = c.rows().into_iter().map(|i| offered[i as usize].hex()).collect();
        drop(tags);
        drop(fams);
        let mut exact_values = Vec::with_capacity(q.members.len());
        for m in q.members {
            exact_values.push(fetch(m.family, &ids).map_err(SearchError::Store)?);
        }
        let n_candidates = ids.len();
        let mut scored: Vec<(String, f64, Vec<f64>)> = ids
            .into_iter()
            .filter_map(|id| {
                let each: Vec<f64> = q
                    .members
                    .iter()
                    .zip(&exact_values)
                    .map(|(m, got)| shape_dna::distance(m.values, got.get(&id)?, Metric::Euclidean).ok())
                    .collect::<Option<_>>()?;
                let fused = each.iter().zip(&scales).map(|(d, s)| d * s).sum();
                Some((id, fused, each))
            })
            .collect();
        // A candidate the store no longer holds may have crowded out another: the answer is then not proven.
        let exact = scored.len() == n_candidates;
        scored.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        scored.truncate(q.count);
        Ok(FusedFound { neighbours: scored, spreads, searched, probed, incomplete, exact })
    }

    /// A family's spread over the collection (its fingerprints' root-mean-square distance), if it holds any.
    pub fn spread(&self, family: &str) -> Option<f64> {
        self.spread_of(family).map(|s| s.0)
    }
    /// A family's spread and the number of fingerprints it is over, if it holds any.
    pub fn spread_of(&self, family: &str) -> Option<(f64, usize)> {
        let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
        fams.get(family).and_then(|f| f.spread().map(|s| (s, f.len())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::search::tests::sid;

    /// The fused answer equals a brute-force ranking by Σ wᵢ dᵢ / sᵢ with the spreads computed independently in
    /// double precision from the definition (the mean squared distance over all ordered pairs, the pair with
    /// itself included), and a shape lacking one family is left out and counted.
    #[test]
    fn fused_search_ranks_by_the_scaled_sum_and_skips_incomplete_shapes() {
        let index = Index::default();
        let n = 300;
        let mut x = 12345u64;
        let mut rnd = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        // Two families of different units and lengths: a (5 values around 1000) and b (3 values around 0.01).
        let a: Vec<Vec<f64>> =
            (0..n).map(|_| (0..5).map(|j| 1000.0 * (1.0 + j as f64) * (1.0 + rnd())).collect()).collect();
        let b: Vec<Vec<f64>> = (0..n).map(|_| (0..3).map(|_| 0.01 * rnd()).collect()).collect();
        for i in 0..n {
            index.insert(&Fingerprint { family: "a".into(), shape_id: sid(i).hex(), values: a[i].clone() });
            if i != 7 {
                index.insert(&Fingerprint { family: "b".into(), shape_id: sid(i).hex(), values: b[i].clone() });
            }
        }
        let spread = |rows: &[&Vec<f64>]| -> f64 {
            let m = rows.len() as f64;
            let mut s = 0.0;
            for p in rows {
                for q in rows {
                    s += p.iter().zip(q.iter()).map(|(u, v)| (u - v).powi(2)).sum::<f64>();
                }
            }
            (s / (m * m)).sqrt()
        };
        let (sa, sb) = (
            spread(&a.iter().collect::<Vec<_>>()),
            spread(&b.iter().enumerate().filter(|(i, _)| *i != 7).map(|p| p.1).collect::<Vec<_>>()),
        );
        let (qa, qb) = (a[3].clone(), b[3].clone());
        let members =
            [Member { family: "a", values: &qa, weight: 0.25 }, Member { family: "b", values: &qb, weight: 0.75 }];
        let store_a: HashMap<String, Vec<f64>> = (0..n).map(|i| (sid(i).hex(), a[i].clone())).collect();
        let store_b: HashMap<String, Vec<f64>> =
            (0..n).filter(|&i| i != 7).map(|i| (sid(i).hex(), b[i].clone())).collect();
        let fetch = |family: &str, ids: &[String]| -> std::io::Result<HashMap<String, Vec<f64>>> {
            let s = if family == "a" { &store_a } else { &store_b };
            Ok(ids.iter().filter_map(|id| s.get(id).map(|v| (id.clone(), v.clone()))).collect())
        };
        let found = index
            .nearest_fused(&FusedQuery { members: &members, count: 10, exclude: Some(sid(3)), tags: &[] }, &fetch)
            .unwrap();
        assert_eq!(found.incomplete, 1);
        assert!(found.exact);
        for (got, want) in found.spreads.iter().zip([sa, sb]) {
            assert!((got - want).abs() < 1e-5 * want, "spread {got} vs {want}");
        }
        let d = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt();
        let mut brute: Vec<(String, f64)> = (0..n)
            .filter(|&i| i != 3 && i != 7)
            .map(|i| (sid(i).hex(), 0.25 * d(&a[i], &qa) / sa + 0.75 * d(&b[i], &qb) / sb))
            .collect();
        brute.sort_by(|p, q| p.1.total_cmp(&q.1));
        let got: Vec<&String> = found.neighbours.iter().map(|x| &x.0).collect();
        let want: Vec<&String> = brute.iter().take(10).map(|x| &x.0).collect();
        assert_eq!(got, want);
        for (g, w) in found.neighbours.iter().zip(&brute) {
            assert!((g.1 - w.1).abs() < 1e-5 * w.1, "{} vs {}", g.1, w.1);
        }
    }
}

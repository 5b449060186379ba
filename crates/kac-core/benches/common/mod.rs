//! Shared by the bench targets: the median and the icosphere levels to run.

/// The median of `v` (upper middle for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Icosphere levels from `KAC_LEVELS=5,6,7` (else `default`), or `None` when cargo only lists or tests the bench
/// targets (`--list`, `--test`: nothing to run).
pub fn levels(default: &[u32]) -> Option<Vec<u32>> {
    if std::env::args().any(|a| a == "--list" || a == "--test") {
        return None;
    }
    Some(
        std::env::var("KAC_LEVELS")
            .ok()
            .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
            .unwrap_or_else(|| default.to_vec()),
    )
}

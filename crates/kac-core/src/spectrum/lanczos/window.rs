//! A slice's window of the spectrum and the choice of a run's pairs among the Ritz candidates.

use super::block::Ritz;

/// The part of the spectrum one slice returns: the pairs with λ in [lo, hi), found by shift-invert around `sigma`.
/// In JSON (a slice solved on another machine) an open end is null, since JSON has no infinities.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Window {
    /// −∞ for the lowest slice.
    #[serde(serialize_with = "open_end", deserialize_with = "from_below")]
    pub lo: f64,
    /// +∞ for the top slice, which returns pairs up to a count instead (`total`).
    #[serde(serialize_with = "open_end", deserialize_with = "from_above")]
    pub hi: f64,
    pub sigma: f64,
    /// Top slice: the pairs wanted counted from the bottom of the spectrum (deflated ones included, guards too):
    /// the slice returns its pairs from `lo` up to the `total`-th eigenvalue, Sylvester's inertia at σ telling how
    /// many lie below σ.
    pub total: Option<usize>,
    /// The eigenvalues in [lo, hi) when known (Sylvester's inertia at both ends): the slice is done once that many
    /// converged pairs lie in the window, without guards beyond it.
    pub count: Option<usize>,
    /// The eigenvalues below `lo` (deflated ones included; Sylvester's inertia at `lo`): the top slice checks that it
    /// holds every eigenvalue in [lo, σ) against its own inertia at σ.
    pub below_lo: usize,
}

/// A window's end as JSON: null where it is open (infinite).
fn open_end<S: serde::Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
    serde::Serialize::serialize(&x.is_finite().then_some(*x), s)
}

/// A lower end back from JSON: null is −∞.
fn from_below<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::NEG_INFINITY))
}

/// An upper end back from JSON: null is +∞.
fn from_above<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// Where a run's wanted pairs lie among the Ritz candidates sorted by ascending λ: the pairs returned are
/// `start..end`; those that must have converged (with a guard on each side of a window) are `req_start..req_end`.
pub(super) struct Selection {
    pub(super) start: usize,
    pub(super) end: usize,
    pub(super) req_start: usize,
    pub(super) req_end: usize,
    /// Whether the candidates reach as far as the window asks.
    pub(super) enough: bool,
}

pub(super) fn select(
    cand: &[(f64, Ritz, f64)],
    sigma: f64,
    want: usize,
    window: Option<&Window>,
    below: Option<usize>,
) -> Selection {
    let len = cand.len();
    let Some(w) = window else {
        let end = want.min(len);
        return Selection { start: 0, end, req_start: 0, req_end: end, enough: want <= len };
    };
    let lam = |c: &(f64, Ritz, f64)| sigma + 1.0 / c.0;
    let start = if w.lo == f64::NEG_INFINITY { 0 } else { cand.partition_point(|c| lam(c) < w.lo) };
    let (end, req_end, enough) = match w.total {
        Some(total) => {
            // λ < σ exactly where θ < 0, which the ascending order puts first; the `total`-th eigenvalue may lie below
            // σ as well as above it.
            let at_sigma = cand.partition_point(|c| c.0 < 0.0);
            let end = (at_sigma as isize + total as isize - below.unwrap_or(0) as isize).max(start as isize) as usize;
            // Every eigenvalue in [lo, σ) must be among the candidates (a cluster member not met yet would let the
            // pair past the `total`-th take its place).
            let all_below = below.is_some_and(|b| at_sigma.checked_sub(start) == b.checked_sub(w.below_lo));
            (end.min(len), end.min(len), end <= len && all_below)
        }
        None => {
            let end = cand.partition_point(|c| lam(c) < w.hi).max(start);
            match w.count {
                Some(count) => (end, end, end - start == count),
                None => (end, (end + 1).min(len), end < len),
            }
        }
    };
    let req_start = if w.lo == f64::NEG_INFINITY || w.count.is_some() { start } else { start.saturating_sub(1) };
    Selection { start, end, req_start, req_end, enough }
}

//! Ids that can only be ids. Every id a client sends (a path segment, a body field) is parsed here into a typed
//! value before it reaches a store, a file name or SQL; what does not parse names nothing (the HTTP layer answers
//! 404 `not-found` with the rule it breaks). Stores take these types only, so no text from a request can become
//! a path.
//!
//! - a shape id ([`ShapeId`]): the SHA-256 of the canonical shape, 64 lowercase hex digits;
//! - a job id ([`JobId`]), which is also its result's id: the first 16 bytes of SHA-256 over the request, 32
//!   lowercase hex digits;
//! - a batch id ([`BatchId`]), a bulk upload's: 16 bytes drawn when the upload is recorded, 32 lowercase hex digits.

pub use kac_core::geometry::hash::ShapeId;
use std::fmt;

/// A job's id, and the id of the result it stores: 16 bytes, written as 32 lowercase hex digits.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct JobId(pub [u8; 16]);

/// A result's id is its job's id.
pub type ResultId = JobId;

fn lower_hex(s: &str, out: &mut [u8]) -> bool {
    if s.len() != 2 * out.len() || !s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')) {
        return false;
    }
    for (i, o) in out.iter_mut().enumerate() {
        match u8::from_str_radix(&s[2 * i..2 * i + 2], 16) {
            Ok(b) => *o = b,
            Err(_) => return false,
        }
    }
    true
}

impl JobId {
    /// The id its 32 lowercase hex digits name; nothing else parses.
    pub fn parse(s: &str) -> Option<JobId> {
        let mut b = [0u8; 16];
        lower_hex(s, &mut b).then_some(JobId(b))
    }
    /// The first 16 bytes of a digest.
    pub fn from_digest(d: &[u8]) -> JobId {
        let mut b = [0u8; 16];
        b.copy_from_slice(&d[..16]);
        JobId(b)
    }
    pub fn hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }
}

impl fmt::Display for JobId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.hex())
    }
}

impl fmt::Debug for JobId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "JobId({})", self.hex())
    }
}

/// A bulk upload's batch: 16 bytes, written as 32 lowercase hex digits. Drawn, not a content hash: two uploads of
/// the same files are two batches, each with its own progress.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BatchId(pub [u8; 16]);

impl BatchId {
    /// The id its 32 lowercase hex digits name; nothing else parses.
    pub fn parse(s: &str) -> Option<BatchId> {
        let mut b = [0u8; 16];
        lower_hex(s, &mut b).then_some(BatchId(b))
    }
    /// A new id: SHA-256 over the time, the process, a counter of this process and `seed` (the batch's jobs), so
    /// that no two batches of any replica share one without a random source.
    pub fn draw(seed: &[u8]) -> BatchId {
        use sha2::{Digest, Sha256};
        use std::sync::atomic::{AtomicU64, Ordering};
        static DRAWN: AtomicU64 = AtomicU64::new(0);
        let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        let mut h = Sha256::new();
        h.update(t.as_nanos().to_le_bytes());
        h.update(std::process::id().to_le_bytes());
        h.update(DRAWN.fetch_add(1, Ordering::Relaxed).to_le_bytes());
        h.update(seed);
        let mut b = [0u8; 16];
        b.copy_from_slice(&h.finalize()[..16]);
        BatchId(b)
    }
    pub fn hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }
}

impl fmt::Display for BatchId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.hex())
    }
}

impl fmt::Debug for BatchId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "BatchId({})", self.hex())
    }
}

/// How a text that is not an id is described (quoted, at most 80 characters, control characters escaped), so
/// that a problem document never echoes a long or binary path back whole.
pub fn shown(s: &str) -> String {
    let mut t: String = s.chars().take(80).flat_map(char::escape_debug).collect();
    if s.chars().count() > 80 {
        t.push('…');
    }
    format!("'{t}'")
}

/// A shape id a client sent, or 404 naming the rule it breaks.
pub fn file_in(dir: &std::path::Path, name: &str) -> std::io::Result<std::path::PathBuf> {
    let ok = !name.is_empty()
        && name != "."
        && name != ".."
        && name.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'-' | b'_'))
        && !name.starts_with('.');
    if !ok {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{} is not a file name inside the store's directory", shown(name)),
        ));
    }
    Ok(dir.join(name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_lowercase_hex_of_the_exact_length_is_an_id() {
        let job = "0123456789abcdef0123456789abcdef";
        assert_eq!(JobId::parse(job).map(|j| j.hex()), Some(job.to_string()));
        let shape = format!("{job}{job}");
        assert_eq!(ShapeId::parse(&shape).map(|s| s.hex()), Some(shape.clone()));
        for bad in [
            "",
            "..",
            "../kac.sqlite3",
            "..%2Fkac.sqlite3",
            "%2e%2e",
            "/etc/passwd",
            "0123456789ABCDEF0123456789ABCDEF",
            "0123456789abcdef0123456789abcde",
            "0123456789abcdef0123456789abcdef0",
            "0123456789abcdef0123456789abcde\0",
            "0123456789abcdef0123456789abcdeg",
            "0123456789abcdef0123456789abcdé",
        ] {
            assert!(JobId::parse(bad).is_none(), "{bad:?}");
            assert!(ShapeId::parse(&format!("{bad}{bad}")).is_none(), "{bad:?}");
        }
        assert!(ShapeId::parse("..%2Fx").is_none() && JobId::parse(&shape).is_none());
        assert_eq!(BatchId::parse(job).map(|b| b.hex()), Some(job.to_string()));
        assert!(BatchId::parse(&shape).is_none() && BatchId::parse("0123456789ABCDEF0123456789ABCDEF").is_none());
        let (a, b) = (BatchId::draw(b"x"), BatchId::draw(b"x"));
        assert!(a != b && BatchId::parse(&a.hex()) == Some(a), "drawn twice, two ids");
    }

    #[test]
    fn file_names_never_leave_their_directory() {
        let d = std::path::Path::new("/data/results");
        assert_eq!(file_in(d, "ab12.result.json").unwrap(), d.join("ab12.result.json"));
        for bad in ["", ".", "..", "../x", "a/b", "/abs", ".hidden", "a\0b", "a\\b", "é"] {
            assert!(file_in(d, bad).is_err(), "{bad:?}");
        }
    }
}

//! A finished result as it is kept: its summary without the arrays' values, the arrays as numbers, and the strong
//! ETag of its JSON body. The body itself (the summary with every array's values inline) is written out per
//! response, chunk by chunk, so a large result is never held as text beside its numbers; small bodies (at most
//! [`SMALL_BODY`]) are kept whole to answer at once. Stores keep the summary as JSON and the arrays as raw
//! little-endian float64, one after another, so reading a result back is a copy of its numbers, not a parse.

use super::*;
use bytes::Bytes;
use serde_json::json;

/// Bodies up to this size are kept whole in memory.
pub const SMALL_BODY: usize = 1 << 20;

/// Values of an array written per chunk of a streamed body (a few hundred kilobytes of text).
const VALUES_PER_CHUNK: usize = 16_384;

/// Rows of an array per chunk: about `VALUES_PER_CHUNK` values, at least one row.
fn rows_per_chunk(a: &VertexArray) -> usize {
    (VALUES_PER_CHUNK / a.cols.max(1)).max(1)
}

/// A finished result: the JSON summary without values, per-vertex arrays, and its body's strong ETag.
pub struct StoredResult {
    pub id: String,
    /// The result without its arrays' values (each array keeps `rows`, `cols`, `columns` and its links).
    pub summary: Value,
    pub arrays: Vec<VertexArray>,
    pub etag: String,
    /// The body without per-vertex values (`?values=false`), made once.
    pub summary_body: Bytes,
    /// The whole body, when small.
    small_body: Option<Bytes>,
    /// The serialized summary with a place for each array's values: (text before, the array that follows).
    template: Vec<(Bytes, Option<usize>)>,
}

/// The text that stands for array `i`'s values in the template (a JSON string nothing else can contain).
fn sentinel(i: usize) -> String {
    serde_json::to_string(&format!("\u{0}kac-values-{i}\u{0}")).unwrap_or_default()
}

/// One array's values as JSON rows `[[a,b],[c,d]]` (NaN and ±∞ as null), rows `from..to`, with the brackets that
/// open and close the whole list.
fn rows_json(a: &VertexArray, from: usize, to: usize, out: &mut Vec<u8>) {
    let cols = a.cols.max(1);
    if from == 0 {
        out.push(b'[');
    }
    for r in from..to {
        if r > 0 {
            out.push(b',');
        }
        out.push(b'[');
        for (j, v) in a.data[r * cols..(r + 1) * cols].iter().enumerate() {
            if j > 0 {
                out.push(b',');
            }
            if v.is_finite() {
                let _ = serde_json::to_writer(&mut *out, v);
            } else {
                out.extend_from_slice(b"null");
            }
        }
        out.push(b']');
    }
    if to == a.rows {
        out.push(b']');
    }
}

/// The ETag prefix of a result stored without hashing its body ([`StoredResult::unhashed`]).
const UNHASHED: &str = "\"unhashed-";

impl StoredResult {
    /// A result kept for one internal reader (a slice job's pairs, read once by the job that offered it and then
    /// removed): its ETag is its id's (the content hash of the request that made it), not the SHA-256 of its body,
    /// whose writing (every number as text, 20 million of them for 160 pairs at 164k vertices) took seconds on
    /// each side. Its body, if asked for, is written as any result's.
    pub fn unhashed(id: &str, summary: Value, arrays: Vec<VertexArray>) -> Self {
        Self::with_etag(id, summary, arrays, format!("{UNHASHED}{id}\""))
    }

    /// A result from its summary (whose `arrays` object names each array, without values) and its arrays; the ETag
    /// is the SHA-256 of the body the result answers with, computed by writing it once.
    pub fn new(id: &str, summary: Value, arrays: Vec<VertexArray>) -> Self {
        let mut r = Self::with_etag(id, summary, arrays, String::new());
        use sha2::Digest;
        let mut hash = sha2::Sha256::new();
        let mut size = 0;
        let mut small = vec![];
        for chunk in r.chunks() {
            hash.update(&chunk);
            size += chunk.len();
            if size <= SMALL_BODY {
                small.extend_from_slice(&chunk);
            }
        }
        r.etag = format!("\"{}\"", hash.finalize().iter().take(16).map(|b| format!("{b:02x}")).collect::<String>());
        if size <= SMALL_BODY {
            r.small_body = Some(small.into());
        }
        r
    }

    /// A result with the body's template made and the ETag given (no small body kept).
    fn with_etag(id: &str, summary: Value, arrays: Vec<VertexArray>, etag: String) -> Self {
        let summary_body: Bytes = serde_json::to_vec(&summary).unwrap_or_default().into();
        let mut with_places = summary.clone();
        if let Some(map) = with_places.get_mut("arrays").and_then(Value::as_object_mut) {
            for (i, a) in arrays.iter().enumerate() {
                if let Some(o) = map.get_mut(a.name).and_then(Value::as_object_mut) {
                    o.insert("values".into(), Value::String(format!("\u{0}kac-values-{i}\u{0}")));
                }
            }
        }
        let text = serde_json::to_vec(&with_places).unwrap_or_default();
        // Split the text at each array's place, in the order the places appear.
        let mut places: Vec<(usize, usize, usize)> = (0..arrays.len())
            .filter_map(|i| {
                let s = sentinel(i);
                find(&text, s.as_bytes()).map(|at| (at, s.len(), i))
            })
            .collect();
        places.sort();
        let mut template = vec![];
        let mut at = 0;
        for (start, len, i) in places {
            template.push((Bytes::copy_from_slice(&text[at..start]), Some(i)));
            at = start + len;
        }
        template.push((Bytes::copy_from_slice(&text[at..]), None));
        StoredResult { id: id.to_string(), summary, arrays, etag, summary_body, small_body: None, template }
    }

    /// The body, as one piece when it is small.
    pub fn small_body(&self) -> Option<&Bytes> {
        self.small_body.as_ref()
    }

    /// The pieces of the body, in order: (template part, None) for its text, (part, Some(p)) for the p-th batch of
    /// rows of the array that follows it.
    fn pieces(&self) -> Vec<(usize, Option<usize>)> {
        let mut out = vec![];
        for (k, (_, array)) in self.template.iter().enumerate() {
            out.push((k, None));
            if let Some(i) = array {
                let a = &self.arrays[*i];
                out.extend((0..a.rows.div_ceil(rows_per_chunk(a)).max(1)).map(|p| (k, Some(p))));
            }
        }
        out
    }

    fn render(&self, (k, piece): (usize, Option<usize>)) -> Bytes {
        let (text, array) = &self.template[k];
        match (piece, array) {
            (Some(p), Some(i)) => {
                let a = &self.arrays[*i];
                let per = rows_per_chunk(a);
                let (from, to) = (p * per, ((p + 1) * per).min(a.rows));
                let mut out = Vec::with_capacity((to - from) * a.cols.max(1) * 20 + 2);
                rows_json(a, from, to, &mut out);
                Bytes::from(out)
            }
            _ => text.clone(),
        }
    }

    /// The body in chunks: the summary's text, and each array's rows a few thousand at a time.
    pub fn chunks(&self) -> impl Iterator<Item = Bytes> + '_ {
        self.pieces().into_iter().map(|p| self.render(p))
    }

    /// The body in chunks for a response, owning the result (a stream needs `'static`).
    pub fn into_chunks(self: Arc<Self>) -> impl Iterator<Item = Bytes> + Send + 'static {
        self.pieces().into_iter().map(move |p| self.render(p))
    }

    /// Array `i` alone as JSON (`{"cols", "columns", "rows", "values"}`), in chunks.
    pub fn array_json_chunks(self: Arc<Self>, i: usize) -> impl Iterator<Item = Bytes> + Send + 'static {
        let a = &self.arrays[i];
        let head =
            serde_json::to_vec(&json!({ "rows": a.rows, "cols": a.cols, "columns": a.columns })).unwrap_or_default();
        // `values` sorts after the other keys: the object is closed after it.
        let head = Bytes::from([&head[..head.len() - 1], b",\"values\":"].concat());
        let per = rows_per_chunk(a);
        let pieces = a.rows.div_ceil(per).max(1);
        std::iter::once(head)
            .chain((0..pieces).map(move |p| {
                let a = &self.arrays[i];
                let (from, to) = (p * per, ((p + 1) * per).min(a.rows));
                let mut out = vec![];
                rows_json(a, from, to, &mut out);
                Bytes::from(out)
            }))
            .chain(std::iter::once(Bytes::from_static(b"}")))
    }

    /// Array `i` as `.npy`, in chunks of a megabyte.
    pub fn array_npy_chunks(self: Arc<Self>, i: usize) -> impl Iterator<Item = Bytes> + Send + 'static {
        let a = &self.arrays[i];
        let head = Bytes::from(kac_core::io::npy::header_f64(a.rows, a.cols));
        let pieces = a.data.len().div_ceil(1 << 17);
        std::iter::once(head).chain((0..pieces).map(move |p| {
            let d = &self.arrays[i].data;
            let part = &d[p << 17..((p + 1) << 17).min(d.len())];
            Bytes::from(part.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>())
        }))
    }

    /// What a store keeps besides the numbers: the ETag, the summary and the arrays' shapes (JSON).
    pub fn meta(&self) -> Value {
        json!({
            "etag": self.etag,
            "summary": self.summary,
            "arrays": self.arrays.iter().map(|a| json!({ "name": a.name, "rows": a.rows, "cols": a.cols, "columns": a.columns })).collect::<Vec<_>>(),
        })
    }

    /// Values a store keeps: every array's numbers one after another.
    pub fn values(&self) -> usize {
        self.arrays.iter().map(|a| a.data.len()).sum()
    }

    /// The numbers as little-endian float64 bytes, `chunk` bytes at a time (a multiple of 8), without a copy of
    /// the whole.
    pub fn value_chunks(&self, chunk: usize) -> impl Iterator<Item = Vec<u8>> + '_ {
        let per = (chunk / 8).max(1);
        self.arrays
            .iter()
            .flat_map(move |a| a.data.chunks(per).map(|c| c.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()))
    }

    /// A result back from its meta (see [`StoredResult::meta`]) and a reader of its numbers.
    pub fn from_meta(
        id: &str,
        meta: &Value,
        mut read: impl FnMut(&mut [f64]) -> std::io::Result<()>,
    ) -> std::io::Result<Self> {
        let bad = || std::io::Error::other(format!("the stored result {id} is damaged"));
        let mut arrays = vec![];
        for a in meta["arrays"].as_array().ok_or_else(bad)? {
            let name = a["name"].as_str().ok_or_else(bad)?;
            let Some(name) = crate::analysis::ARRAY_NAMES.iter().copied().find(|n| *n == name) else {
                return Err(bad());
            };
            let rows = a["rows"].as_u64().ok_or_else(bad)? as usize;
            let cols = a["cols"].as_u64().ok_or_else(bad)? as usize;
            let columns = a["columns"].as_array().map(|c| c.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect());
            let mut data = vec![0.0; rows.checked_mul(cols).ok_or_else(bad)?];
            read(&mut data)?;
            arrays.push(VertexArray { name, rows, cols, data, columns });
        }
        if meta["etag"].as_str().is_some_and(|e| e.starts_with(UNHASHED)) {
            return Ok(StoredResult::unhashed(id, meta["summary"].clone(), arrays));
        }
        let r = StoredResult::new(id, meta["summary"].clone(), arrays);
        if meta["etag"].as_str() != Some(r.etag.as_str()) {
            // The body is written anew from the numbers; if it no longer has the bytes it had when stored (a
            // change of number formatting), it is served under the ETag of what is sent.
            tracing::warn!(result = %id, "a stored result's body differs from when it was stored; new ETag");
        }
        Ok(r)
    }

    /// A body written by an earlier version (the summary with every array's values inline), read back.
    pub fn parse_legacy(id: &str, body: &[u8]) -> Option<Self> {
        let mut summary: Value = serde_json::from_slice(body).ok()?;
        let mut arrays = vec![];
        if let Some(map) = summary.get_mut("arrays").and_then(Value::as_object_mut) {
            for (name, a) in map.iter_mut() {
                let rows = a["rows"].as_u64()? as usize;
                let cols = a["cols"].as_u64()? as usize;
                let data: Vec<f64> = a["values"]
                    .as_array()?
                    .iter()
                    .flat_map(|r| r.as_array().cloned().unwrap_or_default())
                    .map(|v| v.as_f64().unwrap_or(f64::NAN))
                    .collect();
                let columns =
                    a["columns"].as_array().map(|c| c.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect());
                a.as_object_mut()?.remove("values");
                let Some(name) = crate::analysis::ARRAY_NAMES.iter().copied().find(|n| n == name) else { continue };
                arrays.push(VertexArray { name, rows, cols, data, columns });
            }
        }
        Some(StoredResult::new(id, summary, arrays))
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Bytes a result holds in memory, about.
pub(crate) fn result_size(r: &StoredResult) -> usize {
    if r.etag.starts_with(UNHASHED) {
        // Read once by one job and then removed: kept out of the stores' caches (too large for any, so skipped).
        return usize::MAX;
    }
    r.summary_body.len()
        + r.small_body.as_ref().map_or(0, Bytes::len)
        + r.template.iter().map(|t| t.0.len()).sum::<usize>()
        + r.arrays.iter().map(|a| 8 * a.data.len()).sum::<usize>()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The streamed body is byte for byte what serializing the summary with every array's values inline gives (the
    /// format results always had), for small and chunked arrays, NaN and ±∞ as null; a body of that format read
    /// back (a result stored by an earlier version) keeps its bytes and ETag.
    #[test]
    fn the_streamed_body_is_the_inline_serialization() {
        for rows in [0, 1, 5, VALUES_PER_CHUNK / 3, VALUES_PER_CHUNK + 7] {
            let data: Vec<f64> = (0..rows * 3)
                .map(|i| match i % 11 {
                    4 => f64::NAN,
                    7 => f64::NEG_INFINITY,
                    _ => (i as f64).sin() * 1e-3 + i as f64,
                })
                .collect();
            let a = VertexArray { name: "hks", rows, cols: 3, data, columns: Some(vec![0.1, 1.0, 10.0]) };
            let b = VertexArray { name: "gps", rows, cols: 1, data: vec![0.5; rows], columns: None };
            let meta = |a: &VertexArray| json!({ "rows": a.rows, "cols": a.cols, "columns": a.columns, "npy": "x" });
            let summary = json!({ "k": 3, "z": "last", "arrays": { "hks": meta(&a), "gps": meta(&b) } });
            let mut inline = summary.clone();
            inline["arrays"]["hks"]["values"] = a.to_json();
            inline["arrays"]["gps"]["values"] = b.to_json();
            let expected = serde_json::to_vec(&inline).unwrap();
            let r = StoredResult::new("r", summary, vec![a, b]);
            let streamed: Vec<u8> = r.chunks().flat_map(|c| c.to_vec()).collect();
            assert_eq!(String::from_utf8_lossy(&streamed), String::from_utf8_lossy(&expected), "rows = {rows}");
            use sha2::Digest;
            let etag = format!(
                "\"{}\"",
                sha2::Sha256::digest(&expected).iter().take(16).map(|b| format!("{b:02x}")).collect::<String>()
            );
            assert_eq!(r.etag, etag);
            let r = Arc::new(r);
            for (i, arr) in r.arrays.iter().enumerate() {
                let whole = serde_json::to_vec(
                    &json!({ "rows": arr.rows, "cols": arr.cols, "columns": arr.columns, "values": arr.to_json() }),
                )
                .unwrap();
                let json: Vec<u8> = r.clone().array_json_chunks(i).flat_map(|c| c.to_vec()).collect();
                assert_eq!(json, whole);
                let npy: Vec<u8> = r.clone().array_npy_chunks(i).flat_map(|c| c.to_vec()).collect();
                assert_eq!(npy, kac_core::io::npy::encode_f64(arr.rows, arr.cols, &arr.data));
            }
            let legacy = StoredResult::parse_legacy("r", &expected).unwrap();
            assert_eq!(legacy.etag, etag);
            assert_eq!(legacy.chunks().flat_map(|c| c.to_vec()).collect::<Vec<u8>>(), expected);
        }
    }
}

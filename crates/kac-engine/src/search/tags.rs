//! Tags: parsed at the boundary, and the index's maps of tags by shape and shapes by tag.

use super::*;

/// A tag: 1 to 64 characters of ASCII letters, digits and `-_.:/` (so a tag is the same in a URL, a JSON body and a
/// log line). Parsed at the boundary; what does not parse is refused.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct Tag(String);

/// At most this many tags on one shape, and in one search's filter.
pub const MAX_TAGS: usize = 32;

impl Tag {
    pub fn parse(s: &str) -> Result<Tag, String> {
        let ok = |b: u8| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b':' | b'/');
        if s.is_empty() || s.len() > 64 || !s.bytes().all(ok) {
            let shown: String = s.chars().take(70).flat_map(char::escape_debug).collect();
            return Err(format!("tag '{shown}': a tag is 1 to 64 characters of ASCII letters, digits and - _ . : /"));
        }
        Ok(Tag(s.to_string()))
    }
    /// Tags given as a list: each parsed, repeats dropped, sorted; at most [`MAX_TAGS`].
    pub fn parse_all<S: AsRef<str>>(items: &[S]) -> Result<Vec<Tag>, String> {
        let mut tags = items.iter().map(|s| Tag::parse(s.as_ref())).collect::<Result<Vec<_>, _>>()?;
        tags.sort();
        tags.dedup();
        if tags.len() > MAX_TAGS {
            return Err(format!("{} tags: at most {MAX_TAGS}", tags.len()));
        }
        Ok(tags)
    }
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// Tags by shape and shapes by tag.
#[derive(Default)]
pub(crate) struct Tags {
    pub(crate) by_tag: HashMap<Tag, IdSet>,
    pub(crate) by_shape: IdMap<Vec<Tag>>,
}

impl Tags {
    pub(crate) fn set(&mut self, id: ShapeId, tags: Vec<Tag>) {
        for old in self.by_shape.remove(&id).unwrap_or_default() {
            if let Some(set) = self.by_tag.get_mut(&old) {
                set.remove(&id);
                if set.is_empty() {
                    self.by_tag.remove(&old);
                }
            }
        }
        for t in &tags {
            self.by_tag.entry(t.clone()).or_default().insert(id);
        }
        if !tags.is_empty() {
            self.by_shape.insert(id, tags);
        }
    }
}

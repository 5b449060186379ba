//! Small tokenizing helpers shared by the text readers: lines with 1-based numbers, whitespace tokens, and
//! number parsing that turns failures into located [`ShapeError`]s.

use crate::error::{Element, Location, Result, ShapeError};
use crate::geometry::Point;

/// Iterates over lines (without `\n` / `\r\n`) with 1-based line numbers.
pub struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
        Lines { bytes, pos: 0, line: 0 }
    }
    /// Byte offset of the next unread line.
    pub fn offset(&self) -> usize {
        self.pos
    }
    /// Line number of the last line returned.
    pub fn line(&self) -> usize {
        self.line
    }
    /// Everything not yet read.
    pub fn rest(&self) -> &'a [u8] {
        &self.bytes[self.pos..]
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);
    fn next(&mut self) -> Option<Self::Item> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        let (mut line, advance) = match memchr(b'\n', rest) {
            Some(i) => (&rest[..i], i + 1),
            None => (rest, rest.len()),
        };
        if let Some(stripped) = line.strip_suffix(b"\r") {
            line = stripped;
        }
        self.pos += advance;
        self.line += 1;
        Some((self.line, line))
    }
}

#[inline]
fn memchr(needle: u8, hay: &[u8]) -> Option<usize> {
    hay.iter().position(|&b| b == needle)
}

/// Whitespace-separated tokens of a line.
#[inline]
pub fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty())
}

/// The line without a trailing `#` comment, trimmed.
pub fn strip_comment(line: &[u8]) -> &[u8] {
    let end = memchr(b'#', line).unwrap_or(line.len());
    line[..end].trim_ascii()
}

/// Parses a float token.
#[inline]
pub fn parse_f64(tok: &[u8]) -> Option<f64> {
    // Every byte of a float literal is ASCII, so a non-UTF-8 token fails here as it should.
    std::str::from_utf8(tok).ok()?.parse::<f64>().ok()
}

/// Parses a signed integer token.
#[inline]
pub fn parse_i64(tok: &[u8]) -> Option<i64> {
    std::str::from_utf8(tok).ok()?.parse::<i64>().ok()
}

/// Shows a token in an error message (bounded, lossless for ASCII).
pub fn show(tok: &[u8]) -> String {
    let s = String::from_utf8_lossy(&tok[..tok.len().min(40)]).into_owned();
    if tok.len() > 40 {
        format!("{s}…")
    } else {
        s
    }
}

/// A located syntax error.
pub fn syntax(format: &'static str, line: usize, message: impl Into<String>) -> ShapeError {
    ShapeError::Syntax { format, location: Location::line(line), message: message.into() }
}

/// Reads a float token or reports which field was expected.
pub fn expect_f64(format: &'static str, line: usize, tok: Option<&[u8]>, what: &str) -> Result<f64> {
    match tok {
        Some(t) => parse_f64(t)
            .ok_or_else(|| syntax(format, line, format!("expected a number for {what}, found '{}'", show(t)))),
        None => Err(syntax(format, line, format!("missing {what}"))),
    }
}

/// Reads a non-negative integer token or reports which field was expected.
pub fn expect_usize(format: &'static str, line: usize, tok: Option<&[u8]>, what: &str) -> Result<usize> {
    match tok {
        Some(t) => match parse_i64(t) {
            Some(v) if v >= 0 => Ok(v as usize),
            _ => Err(syntax(format, line, format!("expected a non-negative integer for {what}, found '{}'", show(t)))),
        },
        None => Err(syntax(format, line, format!("missing {what}"))),
    }
}

/// Checks that a vertex is finite; names the vertex and where it was read.
#[inline]
pub fn check_point(p: Point, vertex: usize, location: impl FnOnce() -> Location) -> Result<Point> {
    if p.iter().all(|c| c.is_finite()) {
        Ok(p)
    } else {
        let bad = p.iter().copied().find(|c| !c.is_finite()).unwrap_or(f64::NAN);
        Err(ShapeError::NonFinite {
            element: Element::Vertex,
            index: vertex,
            value: bad.to_string(),
            location: location(),
        })
    }
}

/// Checks a 0-based index against the vertex count.
#[inline]
pub fn check_index(
    value: i64,
    vertex_count: usize,
    element: Element,
    index: usize,
    location: impl FnOnce() -> Location,
) -> Result<u32> {
    if value >= 0 && (value as u64) < vertex_count as u64 {
        Ok(value as u32)
    } else {
        Err(ShapeError::IndexOutOfRange { element, index, value, vertex_count, location: location() })
    }
}

/// A capacity hint that cannot be inflated by a lying header: at most one element per `min_bytes` of input.
#[inline]
pub fn capacity(declared: usize, input_len: usize, min_bytes: usize) -> usize {
    declared.min(input_len / min_bytes.max(1) + 1)
}

/// Whitespace-separated tokens across lines, with the line of each token; `#` starts a comment to the end of
/// the line when `comments` is set.
pub struct Tokens<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
    comments: bool,
}

impl<'a> Tokens<'a> {
    pub fn new(bytes: &'a [u8], comments: bool) -> Self {
        let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
        Tokens { bytes, pos: 0, line: 1, comments }
    }
    /// The line of the last token returned (or where reading stopped).
    pub fn line(&self) -> usize {
        self.line
    }
    pub fn next_token(&mut self) -> Option<(usize, &'a [u8])> {
        let b = self.bytes;
        loop {
            while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
                if b[self.pos] == b'\n' {
                    self.line += 1;
                }
                self.pos += 1;
            }
            if self.pos >= b.len() {
                return None;
            }
            if self.comments && b[self.pos] == b'#' {
                while self.pos < b.len() && b[self.pos] != b'\n' {
                    self.pos += 1;
                }
                continue;
            }
            let start = self.pos;
            while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            return Some((self.line, &b[start..self.pos]));
        }
    }
    pub fn f64(&mut self, format: &'static str, what: &str) -> Result<f64> {
        let t = self.next_token();
        let line = t.map(|t| t.0).unwrap_or(self.line);
        expect_f64(format, line, t.map(|t| t.1), what)
    }
    pub fn usize(&mut self, format: &'static str, what: &str) -> Result<usize> {
        let t = self.next_token();
        let line = t.map(|t| t.0).unwrap_or(self.line);
        expect_usize(format, line, t.map(|t| t.1), what)
    }
    pub fn i64(&mut self, format: &'static str, what: &str) -> Result<i64> {
        match self.next_token() {
            Some((line, t)) => parse_i64(t)
                .ok_or_else(|| syntax(format, line, format!("expected an integer for {what}, found '{}'", show(t)))),
            None => Err(syntax(format, self.line, format!("missing {what}"))),
        }
    }
}

//! The cursor over a `.msh` file: lines and tokens of text, binary words in the file's byte order and size_t.

use super::*;

pub(super) struct Scanner<'a> {
    pub(super) b: &'a [u8],
    pub(super) pos: usize,
    /// The 1-based line of `pos`.
    pub(super) line: usize,
    /// Set by `$MeshFormat`: binary file, its byte order, and the width of its `size_t` (4.1).
    pub(super) binary: bool,
    pub(super) big: bool,
    pub(super) word: usize,
}

impl<'a> Scanner<'a> {
    pub(super) fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.b.len() {
            return None;
        }
        let rest = &self.b[self.pos..];
        let line = self.line;
        let end = match rest.iter().position(|&c| c == b'\n') {
            Some(end) => {
                self.line += 1;
                end
            }
            None => rest.len(),
        };
        self.pos += (end + 1).min(rest.len());
        Some((line, rest[..end].trim_ascii()))
    }
    pub(super) fn skip_space(&mut self) {
        while self.pos < self.b.len() && self.b[self.pos].is_ascii_whitespace() {
            if self.b[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }
    pub(super) fn token(&mut self) -> Option<(usize, &'a [u8])> {
        self.skip_space();
        if self.pos >= self.b.len() {
            return None;
        }
        let s = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some((self.line, &self.b[s..self.pos]))
    }
    /// Where the next read starts: a byte offset in a binary file, a line in an ASCII one.
    pub(super) fn here(&self) -> Location {
        if self.binary {
            Location::byte(self.pos)
        } else {
            Location::line(self.line)
        }
    }
    pub(super) fn f64(&mut self, what: &str) -> Result<f64> {
        let t = self.token();
        text::expect_f64(FMT, t.map_or(self.line, |t| t.0), t.map(|t| t.1), what)
    }
    pub(super) fn i64(&mut self, what: &str) -> Result<i64> {
        match self.token() {
            Some((l, t)) => text::parse_i64(t)
                .ok_or_else(|| text::syntax(FMT, l, format!("expected an integer for {what}, found '{}'", show(t)))),
            None => Err(text::syntax(FMT, self.line, format!("missing {what}"))),
        }
    }
    pub(super) fn count(&mut self, what: &str) -> Result<usize> {
        let t = self.token();
        text::expect_usize(FMT, t.map_or(self.line, |t| t.0), t.map(|t| t.1), what)
    }
    pub(super) fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.b.len()).ok_or_else(|| ShapeError::Truncated {
            format: FMT,
            location: Location::byte(self.pos),
            message: format!("the binary data ends inside {what}"),
        })?;
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    /// `n` records of `size` bytes; the declared count is checked against the bytes left before anything is read.
    pub(super) fn records(&mut self, n: u64, size: usize, what: &str) -> Result<&'a [u8]> {
        let left = self.b.len() - self.pos;
        match usize::try_from(n).ok().and_then(|n| n.checked_mul(size)) {
            Some(total) if total <= left => self.take(total, what),
            _ => Err(ShapeError::Truncated {
                format: FMT,
                location: Location::byte(self.pos),
                message: format!("{what}: {n} × {size} bytes declared, {left} left"),
            }),
        }
    }
    /// A binary `int`.
    pub(super) fn int(&mut self, what: &str) -> Result<i32> {
        let big = self.big;
        self.take(4, what).map(|r| rd_i32(r, big))
    }
    /// A binary `size_t` of the file's width.
    pub(super) fn size(&mut self, what: &str) -> Result<u64> {
        let (word, big) = (self.word, self.big);
        self.take(word, what).map(|r| rd_size(r, word, big))
    }
    /// Skips to the line after `$End<name>`; `header` is where the section starts.
    pub(super) fn skip_lines(&mut self, name: &[u8], header: &Location) -> Result<()> {
        let mut end = b"$End".to_vec();
        end.extend_from_slice(name);
        while let Some((_, l)) = self.next_line() {
            if l == end.as_slice() {
                return Ok(());
            }
        }
        Err(ShapeError::Truncated {
            format: FMT,
            location: header.clone(),
            message: format!("section ${} is not closed", show(name)),
        })
    }
    pub(super) fn expect_end(&mut self, name: &str) -> Result<()> {
        // Gmsh writes a newline between binary data and `$End...`; other writers (MshIO) none.
        self.skip_space();
        let at = self.here();
        match self.token() {
            Some((_, t)) if t.strip_prefix(b"$End") == Some(name.as_bytes()) => Ok(()),
            Some((_, t)) => Err(ShapeError::Syntax {
                format: FMT,
                location: at,
                message: format!("expected $End{name} after the declared content of ${name}, found '{}'", show(t)),
            }),
            None => Err(ShapeError::Truncated { format: FMT, location: at, message: format!("missing $End{name}") }),
        }
    }
    /// The next line of a section's ASCII header, with where it starts.
    pub(super) fn header_line(&mut self, section: &str, what: &str) -> Result<(Location, &'a [u8])> {
        let at = self.here();
        match self.next_line() {
            Some((_, l)) if !l.starts_with(b"$End") => Ok((at, l)),
            Some((_, l)) => Err(ShapeError::Syntax {
                format: FMT,
                location: at,
                message: format!("{section} ends before its {what}: found '{}'", show(l)),
            }),
            None => Err(ShapeError::Truncated {
                format: FMT,
                location: at,
                message: format!("the input ends in the header of {section}, before its {what}"),
            }),
        }
    }
    /// A header line holding a non-negative integer (the first token, as Gmsh reads it).
    pub(super) fn header_count(&mut self, section: &str, what: &str) -> Result<u64> {
        let (at, l) = self.header_line(section, what)?;
        let t = text::tokens(l).next().unwrap_or(b"");
        text::parse_i64(t).and_then(|v| u64::try_from(v).ok()).ok_or_else(|| ShapeError::Syntax {
            format: FMT,
            location: at,
            message: format!("expected a non-negative integer for the {what} of {section}, found '{}'", show(t)),
        })
    }
}

pub(super) fn rd_i32(b: &[u8], big: bool) -> i32 {
    let a = [b[0], b[1], b[2], b[3]];
    if big {
        i32::from_be_bytes(a)
    } else {
        i32::from_le_bytes(a)
    }
}

pub(super) fn rd_f64(b: &[u8], big: bool) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[..8]);
    if big {
        f64::from_be_bytes(a)
    } else {
        f64::from_le_bytes(a)
    }
}

/// A `size_t` of 4 or 8 bytes.
pub(super) fn rd_size(b: &[u8], word: usize, big: bool) -> u64 {
    if word == 4 {
        rd_i32(b, big) as u32 as u64
    } else {
        let mut a = [0u8; 8];
        a.copy_from_slice(&b[..8]);
        if big {
            u64::from_be_bytes(a)
        } else {
            u64::from_le_bytes(a)
        }
    }
}

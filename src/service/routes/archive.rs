//! The `.zip` archives of a bulk upload, opened inside the request's bounds: the central directory read first
//! (entry count, names, each name once), then each entry expanded within what the request's archives may expand
//! to together (`--max-body-bytes`, what the same files would take sent unpacked) and with every byte of buffer
//! capacity reserved against `--max-body-memory-bytes` before it is allocated. An archive inside an archive is
//! refused by name, never read as a shape. Synchronous: the handler runs it on the blocking pool. Knows the zip
//! format (APPNOTE 6.3.10, §4.3) and the service's errors, nothing of HTTP.

use super::super::bodies::Reservation;
use super::super::error::ApiError;
use axum::body::Bytes;
use std::collections::HashSet;
use std::io::Read;

/// The signatures that begin a zip archive: a local file header, an empty archive's end record, a spanned
/// archive's marker.
const ZIP_MAGIC: [&[u8; 4]; 3] = [b"PK\x03\x04", b"PK\x05\x06", b"PK\x07\x08"];
const END_OF_CENTRAL_DIRECTORY: u32 = 0x0605_4b50;
const ZIP64_END_LOCATOR: u32 = 0x0706_4b50;
const ZIP64_END_OF_CENTRAL_DIRECTORY: u32 = 0x0606_4b50;
const CENTRAL_FILE_HEADER: u32 = 0x0201_4b50;

/// What a request's archives may still expand to, and the memory their expanded bytes hold.
pub(crate) struct Expansion {
    /// Bytes the request's archives may still expand to: --max-body-bytes, less what they expanded to so far.
    pub(crate) left: usize,
    /// The limit `left` started from (named in refusals).
    pub(crate) limit: usize,
    /// Reserved against --max-body-memory-bytes: the capacity of every buffer of expanded bytes still held.
    pub(crate) reservation: Reservation,
    /// The capacity allocated so far.
    held: usize,
}

impl Expansion {
    pub(crate) fn new(limit: usize, reservation: Reservation) -> Expansion {
        Expansion { left: limit, limit, reservation, held: 0 }
    }

    /// Grows `buf` to a capacity of at least `to` bytes, the growth reserved before it is allocated (and the
    /// allocator's extra, if it gives more, after).
    fn grow(&mut self, buf: &mut Vec<u8>, to: usize) -> Result<(), ApiError> {
        let before = buf.capacity();
        if to <= before {
            return Ok(());
        }
        self.reservation.cover(self.held + (to - before))?;
        buf.reserve_exact(to - buf.len());
        self.held += buf.capacity() - before;
        self.reservation.cover(self.held)
    }
}

/// Whether bytes begin as a zip archive does.
pub(crate) fn is_zip(bytes: &[u8]) -> bool {
    ZIP_MAGIC.iter().any(|m| bytes.starts_with(*m))
}

fn u16_at(d: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(d.get(at..at.checked_add(2)?)?.try_into().ok()?))
}

fn u32_at(d: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(d.get(at..at.checked_add(4)?)?.try_into().ok()?))
}

fn u64_at(d: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(d.get(at..at.checked_add(8)?)?.try_into().ok()?))
}

/// Where the central directory is and how many entries it lists: `(entries, start, end)`, from the end of
/// central directory record (the last one whose comment ends the data) and, where a zip64 locator precedes it
/// (writers add one when a count, size or offset overflows the classic record, and some always), the zip64 record
/// it names. The directory ends where that record begins, so an archive with data before it (offsets relative to a
/// shorter file) is read too.
fn central_directory(d: &[u8]) -> Result<(u64, usize, usize), String> {
    let last = d.len().checked_sub(22).ok_or("shorter than an end of central directory record")?;
    let eocd = (last.saturating_sub(u16::MAX as usize)..=last)
        .rev()
        .find(|&i| {
            u32_at(d, i) == Some(END_OF_CENTRAL_DIRECTORY)
                && u16_at(d, i + 20).is_some_and(|c| i + 22 + c as usize == d.len())
        })
        .ok_or("no end of central directory record")?;
    let field = |at: usize| u32_at(d, eocd + at).ok_or("a cut end of central directory record");
    let (disk, cd_disk) = (u16_at(d, eocd + 4).unwrap_or(0), u16_at(d, eocd + 6).unwrap_or(0));
    let (on_disk, total) = (u16_at(d, eocd + 8).unwrap_or(0), u16_at(d, eocd + 10).unwrap_or(0));
    let (size, offset) = (field(12)?, field(16)?);
    let (mut entries, mut size, mut offset, mut end) = (u64::from(total), u64::from(size), u64::from(offset), eocd);
    let overflows = total == u16::MAX || size == u32::MAX as u64 || offset == u32::MAX as u64;
    let located = eocd.checked_sub(20).filter(|&l| u32_at(d, l) == Some(ZIP64_END_LOCATOR));
    if overflows || located.is_some() {
        let locator = located.ok_or("zip64 sizes without a zip64 locator")?;
        // The zip64 record ends where the locator begins (its recorded offset may be shifted like the others').
        let record = (|| {
            let at = usize::try_from(u64_at(d, locator + 8)?).ok()?;
            if u32_at(d, at) == Some(ZIP64_END_OF_CENTRAL_DIRECTORY) {
                return Some(at);
            }
            let at = locator.checked_sub(56)?;
            (u32_at(d, at) == Some(ZIP64_END_OF_CENTRAL_DIRECTORY)).then_some(at)
        })()
        .ok_or("no zip64 end of central directory record")?;
        let cut = "a cut zip64 end of central directory record";
        entries = u64_at(d, record + 32).ok_or(cut)?;
        size = u64_at(d, record + 40).ok_or(cut)?;
        offset = u64_at(d, record + 48).ok_or(cut)?;
        end = record;
    } else if disk != 0 || cd_disk != 0 || on_disk != total {
        return Err("a multi-disk (spanned) archive".into());
    }
    let size = usize::try_from(size).map_err(|_| "a central directory larger than the archive")?;
    let start = end.checked_sub(size).ok_or("a central directory larger than the archive")?;
    // Offsets count from the archive's first byte; with data before it the directory is where it ends.
    let recorded = usize::try_from(offset).ok().filter(|&o| u32_at(d, o) == Some(CENTRAL_FILE_HEADER));
    Ok((entries, recorded.filter(|&o| o + size == end).unwrap_or(start), end))
}

/// The names the central directory lists, in its order (at most `room`: more is refused before any is read).
fn listed_names(d: &[u8], archive: &str, room: usize) -> Result<Vec<Vec<u8>>, ApiError> {
    let bad = |why: &str| ApiError::invalid_request(format!("{archive}: not a readable zip archive: {why}"));
    let (entries, mut at, end) = central_directory(d).map_err(|e| bad(&e))?;
    if entries > room as u64 {
        return Err(too_many(archive));
    }
    let mut names = Vec::with_capacity(entries as usize);
    for _ in 0..entries {
        if at + 46 > end || u32_at(d, at) != Some(CENTRAL_FILE_HEADER) {
            return Err(bad("its central directory holds fewer entries than it declares"));
        }
        let len = |o: usize| u16_at(d, at + o).unwrap_or(0) as usize;
        let (name, extra, comment) = (len(28), len(30), len(32));
        let next = at + 46 + name + extra + comment;
        if next > end {
            return Err(bad("a central directory entry runs past the directory"));
        }
        names.push(d[at + 46..at + 46 + name].to_vec());
        at = next;
    }
    Ok(names)
}

fn too_many(archive: &str) -> ApiError {
    ApiError::invalid_request(format!("{archive}: more than {} files in the upload", super::collection::MAX_BULK_FILES))
}

/// The files of a zip archive (directories skipped), named `archive/inner`, in the central directory's order.
/// Refused with the archive (400 `invalid-request`): an archive that cannot be read, more than `room` entries, an
/// entry name listed twice (a zip reader would keep one and drop the other), an entry that is an archive (by its
/// name or its first bytes), and entries expanding beyond what is left of the request's expansion (a zip bomb),
/// known from the declared size before anything is read, or counted as read. The expanded bytes' buffers are
/// reserved in `exp` as they grow (503 `memory-busy` when the budget has no room).
pub(crate) fn unzip(
    archive: &str,
    data: &[u8],
    room: usize,
    exp: &mut Expansion,
) -> Result<Vec<(String, Bytes)>, ApiError> {
    let bad =
        |e: &dyn std::fmt::Display| ApiError::invalid_request(format!("{archive}: not a readable zip archive: {e}"));
    // The directory as written, before a reader that keeps one entry per name sees it.
    let names = listed_names(data, archive, room)?;
    let mut seen: HashSet<&[u8]> = HashSet::new();
    for name in &names {
        if !seen.insert(name) && !name.ends_with(b"/") {
            return Err(ApiError::invalid_request(format!(
                "{archive}: the entry '{}' is listed more than once: give each file of an archive its own name",
                String::from_utf8_lossy(name)
            )));
        }
    }
    let mut z = zip::ZipArchive::new(std::io::Cursor::new(data)).map_err(|e| bad(&e))?;
    if z.len() != seen.len() {
        return Err(bad(&format!(
            "its central directory lists {} names but {} entries are read from it (names that read the same?)",
            seen.len(),
            z.len()
        )));
    }
    let mut out = vec![];
    for i in 0..z.len() {
        let mut f = z.by_index(i).map_err(|e| bad(&e))?;
        if f.is_dir() {
            continue;
        }
        let entry = format!("{archive}/{}", f.name());
        if f.name().to_ascii_lowercase().ends_with(".zip") {
            return Err(nested(&entry));
        }
        let limit = exp.limit;
        let beyond = || {
            ApiError::invalid_request(format!(
                "{entry}: the upload's archives expand beyond --max-body-bytes ({limit} bytes) together; send \
                 fewer files at a time"
            ))
        };
        if f.size() > exp.left as u64 {
            return Err(beyond());
        }
        let declared = f.size() as usize;
        let bytes = expand(&mut f, declared, exp).map_err(|e| match e {
            Expanded::Beyond => beyond(),
            Expanded::Nested => nested(&entry),
            Expanded::Unreadable(e) => bad(&e),
            Expanded::Busy(e) => e,
        })?;
        exp.left -= bytes.len();
        out.push((entry, Bytes::from(bytes)));
    }
    Ok(out)
}

fn nested(entry: &str) -> ApiError {
    ApiError::invalid_request(format!(
        "{entry}: an archive inside an archive is not opened (nor read as a shape): put its files in the outer \
         archive, or send it as a part of its own"
    ))
}

/// Why an entry was not expanded.
enum Expanded {
    /// Beyond what the request's archives may still expand to.
    Beyond,
    /// Its first bytes are an archive's.
    Nested,
    Unreadable(std::io::Error),
    /// The memory budget has no room.
    Busy(ApiError),
}

/// Reads an entry whole, `declared` bytes expected (the first buffer that size, when it fits), never more than
/// `exp.left`, every growth of the buffer reserved before it is allocated.
fn expand(r: &mut impl Read, declared: usize, exp: &mut Expansion) -> Result<Vec<u8>, Expanded> {
    let mut buf = Vec::new();
    exp.grow(&mut buf, declared.min(exp.left)).map_err(Expanded::Busy)?;
    let mut chunk = vec![0u8; 64 << 10];
    loop {
        let n = match r.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(Expanded::Unreadable(e)),
        };
        let len = buf.len() + n;
        if len > exp.left {
            return Err(Expanded::Beyond);
        }
        if len > buf.capacity() {
            // Doubling (a declared size that lied), never past what may still be expanded.
            let to = (buf.capacity() * 2).max(len).min(exp.left);
            exp.grow(&mut buf, to).map_err(Expanded::Busy)?;
        }
        let was = buf.len();
        buf.extend_from_slice(&chunk[..n]);
        if was < 4 && buf.len() >= 4 && is_zip(&buf) {
            return Err(Expanded::Nested);
        }
    }
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::bodies::BodyBudget;
    use std::io::Write;

    fn archive(entries: &[(&str, &[u8])]) -> Vec<u8> {
        let mut out = std::io::Cursor::new(vec![]);
        let mut z = zip::ZipWriter::new(&mut out);
        let o = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
        for (name, bytes) in entries {
            z.start_file(*name, o).unwrap();
            z.write_all(bytes).unwrap();
        }
        z.finish().unwrap();
        out.into_inner()
    }

    fn detail(e: ApiError) -> String {
        e.problem().1.detail
    }

    #[test]
    fn entries_are_read_in_order_within_the_budget() {
        let budget = BodyBudget::new(1 << 20);
        let mut exp = Expansion::new(1000, budget.reservation());
        let z = archive(&[("a.off", b"OFF\n"), ("dir/b.off", &[7u8; 500])]);
        let files = unzip("x.zip", &z, 10, &mut exp).unwrap();
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["x.zip/a.off", "x.zip/dir/b.off"]);
        assert_eq!((exp.left, exp.held), (1000 - 504, 504), "buffers of the declared sizes");
        assert_eq!(exp.reservation.bytes(), 1024);
        // What is left for the request's next archive is 496 bytes.
        let err = unzip("y.zip", &archive(&[("c.off", &[1u8; 497])]), 10, &mut exp).unwrap_err();
        assert!(detail(err).contains("expand beyond --max-body-bytes (1000 bytes)"));
    }

    #[test]
    fn the_memory_budget_refuses_what_it_cannot_hold() {
        let budget = BodyBudget::new(8 << 10);
        let _held = {
            let mut r = budget.reservation();
            r.cover(6 << 10).unwrap();
            r
        };
        let mut exp = Expansion::new(1 << 20, budget.reservation());
        let err = unzip("x.zip", &archive(&[("a.off", &[0u8; 4 << 10])]), 10, &mut exp).unwrap_err();
        assert!(matches!(err, ApiError::MemoryBusy { .. }), "{err:?}");
    }

    #[test]
    fn an_entry_declared_too_large_is_refused_before_it_is_read() {
        let z = archive(&[("a.off", &[b'x'; 5000])]);
        let budget = BodyBudget::new(1 << 20);
        let mut exp = Expansion::new(100, budget.reservation());
        assert!(detail(unzip("x.zip", &z, 10, &mut exp).unwrap_err()).contains("expand beyond"));
        assert_eq!(exp.held, 0);
    }

    #[test]
    fn a_declared_size_that_lies_is_counted_as_read() {
        // A deflated entry of 5000 bytes whose headers say 10: refused once more than the limit has come, and no
        // buffer ever larger than the limit.
        let mut z = archive(&[("a.off", &[b'x'; 5000])]);
        let (_, start, _) = central_directory(&z).unwrap();
        z[start + 24..start + 28].copy_from_slice(&10u32.to_le_bytes());
        z[22..26].copy_from_slice(&10u32.to_le_bytes());
        let budget = BodyBudget::new(1 << 20);
        let mut exp = Expansion::new(100, budget.reservation());
        assert!(unzip("x.zip", &z, 10, &mut exp).is_err());
        assert!(exp.held <= 100, "{}", exp.held);
    }

    #[test]
    fn an_archive_inside_an_archive_is_refused_by_name() {
        let inner = archive(&[("a.off", b"OFF\n")]);
        let budget = BodyBudget::new(1 << 20);
        for (name, bytes) in [("inner.ZIP", &b"anything"[..]), ("inner.stl", &inner[..]), ("e.bin", b"PK\x05\x06")] {
            let mut exp = Expansion::new(1 << 20, budget.reservation());
            let err = unzip("x.zip", &archive(&[("ok.off", b"OFF\n"), (name, bytes)]), 10, &mut exp).unwrap_err();
            let d = detail(err);
            assert!(d.contains(&format!("x.zip/{name}")) && d.contains("archive inside an archive"), "{d}");
        }
    }

    /// The central directory as written, with the second entry's name changed to the first's (same length).
    fn with_repeated_name() -> Vec<u8> {
        let mut z = archive(&[("a.off", b"OFF\n1"), ("b.off", b"OFF\n2")]);
        let (_, start, _) = central_directory(&z).unwrap();
        let first = start + 46;
        let second = first + 5 + u16_at(&z, start + 30).unwrap() as usize + 46;
        assert_eq!(&z[second..second + 5], b"b.off");
        z[second] = b'a';
        z
    }

    #[test]
    fn a_name_listed_twice_is_refused_by_name() {
        let z = with_repeated_name();
        // The zip library keeps one entry per name: one of the two would be dropped without a word.
        assert_eq!(zip::ZipArchive::new(std::io::Cursor::new(&z[..])).unwrap().len(), 1);
        let budget = BodyBudget::new(1 << 20);
        let mut exp = Expansion::new(1 << 20, budget.reservation());
        let d = detail(unzip("x.zip", &z, 10, &mut exp).unwrap_err());
        assert!(d.contains("'a.off' is listed more than once"), "{d}");
    }

    #[test]
    fn more_entries_than_room_are_refused_before_reading() {
        let z = archive(&[("a.off", b"1"), ("b.off", b"2"), ("c.off", b"3")]);
        let budget = BodyBudget::new(1 << 20);
        let mut exp = Expansion::new(1 << 20, budget.reservation());
        assert!(detail(unzip("x.zip", &z, 2, &mut exp).unwrap_err()).contains("more than"));
        assert_eq!(exp.held, 0);
    }

    #[test]
    fn data_before_the_archive_and_a_comment_are_read() {
        let mut z = b"#!/bin/sh\nexit 0\n".to_vec();
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(vec![]));
        w.set_comment("a comment PK\x05\x06 with a signature in it");
        w.start_file("a.off", zip::write::SimpleFileOptions::default()).unwrap();
        w.write_all(b"OFF\n").unwrap();
        z.extend(w.finish().unwrap().into_inner());
        let names = listed_names(&z, "x.zip", 10).unwrap();
        assert_eq!(names, [b"a.off".to_vec()]);
    }

    #[test]
    fn zip64_directories_are_read() {
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(vec![]));
        // A zip64 comment makes the writer add the zip64 records.
        w.set_zip64_comment(Some("zip64"));
        for name in ["a.off", "b.off"] {
            w.start_file(name, zip::write::SimpleFileOptions::default()).unwrap();
            w.write_all(b"OFF\n").unwrap();
        }
        let mut z = w.finish().unwrap().into_inner();
        assert!(z.windows(4).any(|w| w == ZIP64_END_LOCATOR.to_le_bytes()), "a zip64 directory");
        // As the writer made it: the classic record holds the real values too, and the directory ends where the
        // zip64 record begins.
        assert_eq!(listed_names(&z, "x.zip", 10).unwrap(), [b"a.off".to_vec(), b"b.off".to_vec()]);
        // The classic record says to look there: count, size and offset at their overflow values.
        let eocd = z.len() - 22;
        z[eocd + 8..eocd + 12].copy_from_slice(&[0xff; 4]);
        z[eocd + 12..eocd + 20].copy_from_slice(&[0xff; 8]);
        assert_eq!(listed_names(&z, "x.zip", 10).unwrap(), [b"a.off".to_vec(), b"b.off".to_vec()]);
        let budget = BodyBudget::new(1 << 20);
        let files = unzip("x.zip", &z, 10, &mut Expansion::new(1 << 20, budget.reservation())).unwrap();
        assert_eq!(files.len(), 2);
    }

    /// Every prefix, and every byte of the directory changed, is read or refused: never a panic, never more
    /// memory than the limit.
    #[test]
    fn damaged_archives_are_refused_without_panicking() {
        let z = archive(&[("a.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), ("b/c.off", &[9u8; 300])]);
        let budget = BodyBudget::new(1 << 20);
        let mut cases: Vec<Vec<u8>> = (0..z.len()).map(|n| z[..n].to_vec()).collect();
        for i in 0..z.len() {
            for flip in [0x01u8, 0x80, 0xff] {
                let mut m = z.clone();
                m[i] ^= flip;
                cases.push(m);
            }
        }
        for case in cases {
            let mut exp = Expansion::new(4096, budget.reservation());
            let _ = unzip("x.zip", &case, 10, &mut exp);
            assert!(exp.held <= 4096);
        }
    }
}

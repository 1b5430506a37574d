//! The fast path of [`super::parse_table`] and [`super::read_table`] for plain numeric
//! CSV (ASCII, no quotes, `,` between cells, `\n` or `\r\n` at line ends). It returns
//! `None` (and the caller falls back to the general reader) for anything it does not
//! handle exactly as the `csv` crate with `Trim::All` and `f64::from_str` would.
//!
//! A file is read in blocks into one reused buffer per thread (never whole), and a large
//! one is parsed on two threads, each taking whole lines of one half.

use std::fs::File;
use std::os::unix::fs::FileExt;

/// Header, columns, file line of each row.
pub(super) type Parsed = (Vec<String>, Vec<Vec<f64>>, Vec<usize>);

/// Files (bodies) at least this large are parsed on two threads.
const PARALLEL_BYTES: usize = 1 << 20;

/// Bytes read from a file at a time.
const BLOCK: usize = 1 << 18;

/// `csv`'s `Trim::All` trims ASCII whitespace; `\r` and `\n` are left in a cell so
/// that a bare carriage return (a record end for `csv`) fails the parse and sends the
/// file to the general reader.
fn trim(cell: &str) -> &str {
    let pad = |b: &u8| matches!(b, b' ' | b'\t' | b'\x0C');
    let b = cell.as_bytes();
    let start = b.iter().position(|c| !pad(c)).unwrap_or(b.len());
    let end = b.iter().rposition(|c| !pad(c)).map_or(start, |e| e + 1);
    // The fast path only sees ASCII text, so every byte index is a char boundary.
    cell.get(start..end).unwrap_or("")
}

/// Text the fast path may take: ASCII without quotes.
fn plain(bytes: &[u8]) -> bool {
    bytes.is_ascii() && !bytes.contains(&b'"')
}

/// The header from the first line (without its `\n`), or `None` for what the general
/// reader must decide: an empty first line, a bare CR or a vertical tab (which a
/// Unicode trim would remove from a name).
fn header(first: &str) -> Option<Vec<String>> {
    let first = first.strip_suffix('\r').unwrap_or(first);
    if trim(first).is_empty() || first.contains(['\r', '\x0B']) {
        return None;
    }
    Some(first.split(',').map(|h| trim(h).to_string()).collect())
}

/// Rows parsed so far: columns, the 0-based line (within the text fed) of each row, and
/// the lines fed.
struct Rows {
    columns: Vec<Vec<f64>>,
    lines: Vec<usize>,
    count: usize,
}

impl Rows {
    /// Room for about `rows` rows of `width` columns.
    fn new(width: usize, rows: usize) -> Self {
        Self {
            columns: (0..width).map(|_| Vec::with_capacity(rows)).collect(),
            lines: Vec::with_capacity(rows),
            count: 0,
        }
    }

    /// A guess of the rows in `len` bytes whose first line is `first` long.
    fn guess(len: usize, first: Option<usize>) -> usize {
        first.map_or(1, |i| len / (i + 1).max(1) + 16)
    }

    /// Parse whole lines (`text` ends with `\n`, or is the last piece of the input);
    /// `None` for anything the general reader must decide.
    fn feed(&mut self, text: &str) -> Option<()> {
        let width = self.columns.len();
        let bytes = text.as_bytes();
        let mut pos = 0;
        while pos < bytes.len() {
            let i = self.count;
            self.count += 1;
            // Cells and the line end by one pass over the line's bytes. A `\r` right
            // before the line end is not part of the last cell.
            let mut j = 0;
            let mut start = pos;
            let mut blank = true;
            let mut at = pos;
            loop {
                while at < bytes.len() && bytes[at] != b',' && bytes[at] != b'\n' {
                    at += 1;
                }
                let line_end = at == bytes.len() || bytes[at] == b'\n';
                let mut cell_end = at;
                if line_end && cell_end > start && bytes[cell_end - 1] == b'\r' {
                    cell_end -= 1;
                }
                if j == width {
                    return None; // more cells than the header
                }
                let cell = trim(text.get(start..cell_end)?);
                let v = if cell.is_empty() {
                    f64::NAN
                } else {
                    blank = false;
                    let v: f64 = cell.parse().ok()?;
                    if v.is_infinite() {
                        return None;
                    }
                    v
                };
                self.columns[j].push(v);
                j += 1;
                start = at + 1;
                if line_end {
                    break;
                }
                at += 1;
            }
            pos = at + 1;
            if j != width || (width == 1 && blank) {
                if j == 1 && blank && width > 1 {
                    // Blank line: skipped, as the general reader does.
                    self.columns[0].pop();
                    continue;
                }
                // Too few cells, or an empty cell in a one-column file (blank line or
                // missing value): the general reader decides.
                return None;
            }
            self.lines.push(i);
        }
        Some(())
    }

    /// Append the rows of the text that followed (its lines numbered after ours).
    fn append(&mut self, more: Rows) {
        for (c, m) in self.columns.iter_mut().zip(more.columns) {
            c.extend_from_slice(&m);
        }
        let offset = self.count;
        self.lines
            .extend(more.lines.into_iter().map(|l| l + offset));
        self.count += more.count;
    }

    /// The parse result, with 1-based file lines (the header is line 1).
    fn finish(self, header: Vec<String>) -> Parsed {
        let lines = self.lines.into_iter().map(|l| l + 2).collect();
        (header, self.columns, lines)
    }
}

/// Parse CSV bytes held in memory.
pub(super) fn parse(bytes: &[u8]) -> Option<Parsed> {
    if !plain(bytes) {
        return None;
    }
    let text = std::str::from_utf8(bytes).ok()?;
    let (first, body) = match text.find('\n') {
        Some(i) => (&text[..i], &text[i + 1..]),
        None => (text, ""),
    };
    let header = header(first)?;
    let width = header.len();
    let rows = |part: &str| -> Option<Rows> {
        let mut r = Rows::new(width, Rows::guess(part.len(), part.find('\n')));
        r.feed(part)?;
        Some(r)
    };
    let rows = if body.len() >= PARALLEL_BYTES {
        // Split at a line end near the middle; each half counts its own lines.
        let mid = body.len() / 2;
        let cut = body[mid..].find('\n').map_or(body.len(), |i| mid + i + 1);
        let (a, b) = body.split_at(cut);
        let (ra, rb) = std::thread::scope(|s| {
            let hb = s.spawn(|| rows(b));
            (rows(a), hb.join().ok().flatten())
        });
        let mut ra = ra?;
        ra.append(rb?);
        ra
    } else {
        rows(body)?
    };
    Some(rows.finish(header))
}

/// Read `file` (`len` bytes) and parse it, as [`parse`] would parse its bytes. `None`
/// also on a read error or a file that changes length (the caller then reads it whole
/// and reports what is wrong).
pub(super) fn read(file: &File, len: usize) -> Option<Parsed> {
    let mut buf = Vec::with_capacity(BLOCK.min(len));
    // The header line, read in blocks until its end.
    let mut at = 0;
    let first_end = loop {
        let got = read_block(file, at, len, &mut buf)?;
        if let Some(i) = buf.iter().position(|&b| b == b'\n') {
            break i;
        }
        if got == 0 {
            break buf.len();
        }
        at += got;
    };
    if !plain(&buf[..first_end]) {
        return None;
    }
    let header = header(std::str::from_utf8(&buf[..first_end]).ok()?)?;
    let width = header.len();
    let body = (first_end + 1).min(len);
    let rows = if len - body >= PARALLEL_BYTES {
        // Split at the first line end at or after the middle.
        let mid = body + (len - body) / 2;
        let cut = line_end_from(file, mid, len, &mut buf)?;
        let (ra, rb) = std::thread::scope(|s| {
            let hb = s.spawn(|| read_rows(file, cut, len, width, &mut Vec::new()));
            (
                read_rows(file, body, cut, width, &mut buf),
                hb.join().ok().flatten(),
            )
        });
        let mut ra = ra?;
        ra.append(rb?);
        ra
    } else {
        read_rows(file, body, len, width, &mut buf)?
    };
    Some(rows.finish(header))
}

/// Append bytes of `file` from `at` (up to `end`, at most [`BLOCK`]) to `buf`; how many.
fn read_block(file: &File, at: usize, end: usize, buf: &mut Vec<u8>) -> Option<usize> {
    let want = BLOCK.min(end.saturating_sub(at));
    let old = buf.len();
    buf.resize(old + want, 0);
    let mut got = 0;
    while got < want {
        match file.read_at(&mut buf[old + got..], (at + got) as u64) {
            Ok(0) => return None, // shorter than it was
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return None,
        }
    }
    Some(got)
}

/// The offset just past the first `\n` at or after `from` (or `end`).
fn line_end_from(file: &File, from: usize, end: usize, buf: &mut Vec<u8>) -> Option<usize> {
    let mut at = from;
    while at < end {
        buf.clear();
        let got = read_block(file, at, end, buf)?;
        if let Some(i) = buf.iter().position(|&b| b == b'\n') {
            return Some(at + i + 1);
        }
        at += got;
    }
    Some(end)
}

/// Rows of the whole lines in `start..end` of `file`, read a block at a time into `buf`.
fn read_rows(
    file: &File,
    start: usize,
    end: usize,
    width: usize,
    buf: &mut Vec<u8>,
) -> Option<Rows> {
    buf.clear();
    let mut at = start;
    let mut rows: Option<Rows> = None;
    while at < end {
        let kept = buf.len();
        let got = read_block(file, at, end, buf)?;
        at += got;
        if !plain(&buf[kept..]) {
            return None;
        }
        let r = rows.get_or_insert_with(|| {
            let first = buf.iter().position(|&b| b == b'\n');
            Rows::new(width, Rows::guess(end - start, first))
        });
        // Whole lines now; the rest of the last line waits for the next block.
        let whole = if at == end {
            buf.len()
        } else {
            buf.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1)
        };
        r.feed(std::str::from_utf8(&buf[..whole]).ok()?)?;
        buf.drain(..whole);
    }
    Some(rows.unwrap_or_else(|| Rows::new(width, 0)))
}

//! Stanford PLY: ascii, binary little-endian and binary big-endian.
//!
//! # References
//! - Greg Turk, *The PLY Polygon File Format* (1994): the header (`element`, `property`,
//!   `property list`), the three encodings, the `vertex` and `face` elements.
//!
//! Read: the `vertex` element's `x`, `y`, `z` (any scalar type; other vertex properties such as
//! `confidence`, `intensity` or colors are skipped), and the `face` element's `vertex_indices` (or
//! `vertex_index`) list of any integer type, fan-triangulated. Without a `face` element, a
//! `tristrips` element (`vertex_indices` with `-1` restarts, as in some Stanford scans) is read
//! as triangle strips. Every other element is read past and ignored.
//!
//! The header is parsed by `ply-rs-bw`; then, **before** anything is allocated, each declared
//! element count is checked against the bytes after the header (an element takes at least one
//! byte per scalar in binary, two characters per value in ascii), so a header claiming 10^12
//! vertices is an error, not an allocation attempt. Binary payloads are read here too, from
//! layouts fixed by the header straight into the mesh's arrays (`binary.rs`); the ascii payload
//! is tokenized here (see the module doc of `load`), so that errors name the line and the
//! element and extra or missing values on a line are caught.
//! Truncated data, data after the last declared element, non-finite coordinates and indices out
//! of range are errors.
//!
//! Warnings (one line per kind, with a count and the first place): header lines that are not
//! PLY statements (some exporters write a bare line of text; blank lines too) are read as
//! comments, except a line whose first word is a near miss of `format`, `element`, `property`
//! or `end_header` (`elment vertex 8`), which stays an error with its line and column; faces
//! of fewer than three corners are skipped.

mod binary;

use std::io::Cursor;
use std::path::Path;

use occult_core::Vec3;
use ply_rs_bw::parser::{ParseError, Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, ElementDef, Encoding, Header, PropertyType, ScalarType};

use super::{fan_triangulate, file_stem, quoted, read_bytes, scene_of_meshes, LoadError, LoadedScene, Location};
use super::{WarningKind, Warnings, SHORT_FACE};

/// Names of the vertex index list, in order of preference.
const INDEX_LIST_NAMES: [&str; 2] = ["vertex_indices", "vertex_index"];

/// The words that open a header line.
const HEADER_KEYWORDS: [&[u8]; 7] = [
    b"ply",
    b"format",
    b"comment",
    b"obj_info",
    b"element",
    b"property",
    b"end_header",
];

/// Keywords whose misspellings stay errors: a line that looks like a typo of one of them is
/// most likely a broken definition, not an exporter's note.
const STRUCTURAL_KEYWORDS: [&str; 4] = ["format", "element", "property", "end_header"];

const HEADER_TEXT: WarningKind = WarningKind {
    one: "a header line that is not a PLY keyword read as a comment",
    many: "header lines that are not PLY keywords read as comments",
};

/// Loads a PLY file as one mesh.
///
/// # Errors
/// [`LoadError::Io`]; [`LoadError::Parse`] for a malformed header or value;
/// [`LoadError::AbsurdCount`] when the header declares more elements than the file can hold;
/// [`LoadError::Truncated`] when the data ends early; [`LoadError::CountMismatch`] for extra
/// values on an ascii line or data after the last element; [`LoadError::NonFinite`];
/// [`LoadError::IndexOutOfRange`]; [`LoadError::Unsupported`] for an index list of floats;
/// [`LoadError::Empty`] without faces.
pub fn load_ply(path: &Path) -> Result<LoadedScene, LoadError> {
    ply_from_bytes(path, &read_bytes(path)?)
}

/// [`load_ply`] of bytes in memory; `path` names them.
pub(super) fn ply_from_bytes(path: &Path, data: &[u8]) -> Result<LoadedScene, LoadError> {
    let parser = Parser::<DefaultElement>::new();
    let mut warnings = Warnings::default();
    let scan = HeaderScan::of(data);
    let header_len;
    let header = if let Some((line, text)) = &scan.first_bare_line {
        let count = scan.bare_lines.len() as u64;
        warnings.add_count(path, HEADER_TEXT, count, Location::Line(*line), quoted(text));
        // The bare lines become `comment` lines, so line numbers in errors stay those of the file.
        let mut reader = Reader::new(Cursor::new(scan.rewritten(data)));
        header_len = scan.end;
        parser.read_header(&mut reader)
    } else {
        let mut reader = Reader::new(Cursor::new(data));
        let header = parser.read_header(&mut reader);
        // The cursor stops right after `end_header\n`: `read_header` reads line by line.
        header_len = usize::try_from(reader.get_ref().position())
            .unwrap_or(data.len())
            .min(data.len());
        header
    }
    .map_err(|e| header_error(path, e))?;
    let payload = &data[header_len..];
    let layout = Layout::of(path, &header)?;
    check_declared_counts(path, &header, payload.len())?;
    if u32::try_from(layout.vertex_count).is_err() {
        return Err(LoadError::Unsupported {
            path: path.to_path_buf(),
            location: Location::Part("element 'vertex'".into()),
            message: format!("{} vertices, more than 32-bit indices address", layout.vertex_count),
        });
    }

    let mut sink = MeshSink::new(path, &layout);
    match header.encoding {
        Encoding::Ascii => {
            let header_line_count = data[..header_len].iter().filter(|&&b| b == b'\n').count() as u64;
            read_ascii(path, &header, &layout, payload, header_line_count, &mut sink)?;
        }
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            binary::read_binary(path, &header, &layout, payload, &mut sink)?;
        }
    }

    if let Some(first) = sink.first_short_face.take() {
        warnings.add_count(path, SHORT_FACE, sink.short_face_count, first, "");
    }
    let name = file_stem(path);
    let mesh = occult_core::Mesh::new(sink.positions, sink.triangles).map_err(|source| LoadError::Core {
        path: path.to_path_buf(),
        part: "mesh".into(),
        source,
    })?;
    let scene = scene_of_meshes(path, &name, vec![(name.clone(), mesh)])?;
    Ok(LoadedScene {
        scene,
        warnings: warnings.into_lines(),
    })
}

/// The header as read before `ply-rs-bw` parses it: lines whose first word is no PLY keyword
/// (a bare text line some exporters write, a blank line) are read as comments. A first word
/// within two edits of a structural keyword (`elment`, `Property`) is a typo, left for the
/// parser to report as an error with its line and column.
struct HeaderScan {
    /// The byte just past the `end_header` line, or the data's length without one.
    end: usize,
    /// The 1-based numbers of the bare lines.
    bare_lines: Vec<u64>,
    /// The first bare line and its text.
    first_bare_line: Option<(u64, String)>,
}

impl HeaderScan {
    fn of(data: &[u8]) -> Self {
        let mut scan = Self {
            end: data.len(),
            bare_lines: Vec::new(),
            first_bare_line: None,
        };
        let mut start = 0;
        let mut line_number = 0u64;
        while start < data.len() {
            let end = data[start..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(data.len(), |i| start + i + 1);
            let line = &data[start..end];
            start = end;
            line_number += 1;
            // The magic line is the parser's to check.
            if line_number == 1 {
                continue;
            }
            let first_word = line.split(|b| b.is_ascii_whitespace()).find(|w| !w.is_empty());
            match first_word {
                Some(b"end_header") => {
                    scan.end = end;
                    break;
                }
                Some(word) if HEADER_KEYWORDS.contains(&word) || is_keyword_typo(word) => {}
                _ => {
                    scan.bare_lines.push(line_number);
                    if scan.first_bare_line.is_none() {
                        let text = String::from_utf8_lossy(line.trim_ascii()).into_owned();
                        scan.first_bare_line = Some((line_number, text));
                    }
                }
            }
        }
        scan
    }

    /// The header (`data` up to [`HeaderScan::end`]) with each bare line replaced by `comment`
    /// and its own line end.
    fn rewritten(&self, data: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.end);
        let mut bare = self.bare_lines.iter().peekable();
        for (index, line) in data[..self.end].split_inclusive(|&b| b == b'\n').enumerate() {
            if bare.next_if_eq(&&(index as u64 + 1)).is_some() {
                out.extend_from_slice(b"comment");
                let ending = if line.ends_with(b"\r\n") {
                    &b"\r\n"[..]
                } else if line.ends_with(b"\n") {
                    &b"\n"[..]
                } else {
                    &[]
                };
                out.extend_from_slice(ending);
            } else {
                out.extend_from_slice(line);
            }
        }
        out
    }
}

/// Whether `word` is a structural keyword written with another case or within two edits of
/// one (Levenshtein distance).
fn is_keyword_typo(word: &[u8]) -> bool {
    // Longer words are more than two edits from every keyword.
    if word.len() > 12 {
        return false;
    }
    let word = word.to_ascii_lowercase();
    STRUCTURAL_KEYWORDS
        .iter()
        .any(|keyword| edit_distance(&word, keyword.as_bytes()) <= 2)
}

/// The Levenshtein distance of `a` and `b` (insertions, deletions and substitutions).
fn edit_distance(a: &[u8], b: &[u8]) -> usize {
    let mut previous: Vec<usize> = (0..=b.len()).collect();
    let mut current = vec![0; b.len() + 1];
    for (i, &ca) in a.iter().enumerate() {
        current[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let substitution = previous[j] + usize::from(ca != cb);
            current[j + 1] = substitution.min(previous[j + 1] + 1).min(current[j] + 1);
        }
        std::mem::swap(&mut previous, &mut current);
    }
    previous[b.len()]
}

/// What the loader takes from the header.
struct Layout {
    vertex_count: usize,
    /// The element holding the polygons, and whether it is triangle strips.
    polygons: Option<(String, bool)>,
}

impl Layout {
    fn of(path: &Path, header: &Header) -> Result<Self, LoadError> {
        let location = |kind: &str| Location::Part(format!("element '{kind}'"));
        let vertex_count = header.elements.get("vertex").map_or(0, |e| e.count);
        if let Some(vertex) = header.elements.get("vertex") {
            for axis in ["x", "y", "z"] {
                match vertex.properties.get(axis).map(|p| &p.data_type) {
                    Some(PropertyType::Scalar(_)) => {}
                    Some(PropertyType::List(..)) => {
                        return Err(LoadError::Unsupported {
                            path: path.to_path_buf(),
                            location: location("vertex"),
                            message: format!("property '{axis}' is a list"),
                        })
                    }
                    None => {
                        return Err(LoadError::Parse {
                            path: path.to_path_buf(),
                            location: location("vertex"),
                            message: format!("no property '{axis}'"),
                        })
                    }
                }
            }
        }
        let mut polygons = None;
        for (name, strips) in [("face", false), ("tristrips", true)] {
            let Some(element) = header.elements.get(name) else {
                continue;
            };
            match index_list(element).map(|p| &p.data_type) {
                Some(PropertyType::List(_, ScalarType::Float | ScalarType::Double)) => {
                    return Err(LoadError::Unsupported {
                        path: path.to_path_buf(),
                        location: location(name),
                        message: "vertex indices stored as floating point".into(),
                    })
                }
                Some(PropertyType::List(..)) => {
                    polygons = Some((name.to_string(), strips));
                    break;
                }
                _ => {
                    return Err(LoadError::Parse {
                        path: path.to_path_buf(),
                        location: location(name),
                        message: "no list property 'vertex_indices' or 'vertex_index'".into(),
                    })
                }
            }
        }
        let has_polygons = polygons
            .as_ref()
            .and_then(|(name, _)| header.elements.get(name))
            .is_some_and(|e| e.count > 0);
        if !has_polygons {
            return Err(LoadError::Empty {
                path: path.to_path_buf(),
                reason: "no 'face' or 'tristrips' element, or zero faces (a point cloud?)".into(),
            });
        }
        Ok(Self { vertex_count, polygons })
    }

    fn role(&self, element_name: &str) -> Role {
        match &self.polygons {
            _ if element_name == "vertex" => Role::Vertex,
            Some((name, strips)) if name == element_name => {
                if *strips {
                    Role::Strips
                } else {
                    Role::Faces
                }
            }
            _ => Role::Other,
        }
    }
}

/// The index list property of a polygon element.
fn index_list(element: &ElementDef) -> Option<&ply_rs_bw::ply::PropertyDef> {
    INDEX_LIST_NAMES.iter().find_map(|name| element.properties.get(*name))
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Vertex,
    Faces,
    Strips,
    Other,
}

fn scalar_size(t: &ScalarType) -> u64 {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// Refuses a header whose element counts need more bytes than `available` (the bytes after the
/// header), before anything is allocated for them: [`LoadError::Truncated`] when the need is
/// within twice what is there, [`LoadError::AbsurdCount`] beyond.
fn check_declared_counts(path: &Path, header: &Header, available: usize) -> Result<(), LoadError> {
    let ascii = header.encoding == Encoding::Ascii;
    // An ascii file may end without a newline after its last value.
    let available = available as u128 + u128::from(ascii);
    let mut needed: u128 = 0;
    for (name, element) in &header.elements {
        let min_bytes = if ascii {
            // Every property is at least one value (a list at least its count): a character and a
            // separator each.
            2 * element.properties.len() as u64
        } else {
            element
                .properties
                .values()
                .map(|p| match &p.data_type {
                    PropertyType::Scalar(t) => scalar_size(t),
                    PropertyType::List(count_type, _) => scalar_size(count_type),
                })
                .sum()
        }
        .max(1);
        let element_bytes = element.count as u128 * u128::from(min_bytes);
        if needed + element_bytes > available {
            // Within twice the bytes present, the file was most likely cut short; beyond, the
            // header lies. Either way nothing has been allocated.
            if needed + element_bytes <= 2 * available + 64 {
                return Err(LoadError::Truncated {
                    path: path.to_path_buf(),
                    location: Location::element(name.as_str(), 0),
                    message: format!(
                        "the header declares {} '{name}' elements, which need at least {} bytes; {} bytes are left",
                        element.count,
                        element_bytes,
                        available.saturating_sub(needed)
                    ),
                });
            }
            return Err(LoadError::AbsurdCount {
                path: path.to_path_buf(),
                what: format!("element '{name}'"),
                count: element.count as u64,
                min_bytes,
                available_bytes: u64::try_from(available.saturating_sub(needed)).unwrap_or(u64::MAX),
            });
        }
        needed += element_bytes;
    }
    Ok(())
}

/// Positions and triangles as they are read, with the checks that name the element.
struct MeshSink<'p> {
    path: &'p Path,
    vertex_count: usize,
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    corners: Vec<u32>,
    short_face_count: u64,
    /// Where the first face of fewer than three corners is.
    first_short_face: Option<Location>,
}

impl<'p> MeshSink<'p> {
    fn new(path: &'p Path, layout: &Layout) -> Self {
        // Bounded: `check_declared_counts` held the count to the file size.
        Self {
            path,
            vertex_count: layout.vertex_count,
            positions: Vec::with_capacity(layout.vertex_count),
            triangles: Vec::new(),
            corners: Vec::new(),
            short_face_count: 0,
            first_short_face: None,
        }
    }

    fn vertex(&mut self, xyz: [f64; 3], location: impl Fn() -> Location) -> Result<(), LoadError> {
        let p = Vec3::new(xyz[0] as f32, xyz[1] as f32, xyz[2] as f32);
        if let Some(&value) = p.to_array().iter().find(|v| !v.is_finite()) {
            return Err(LoadError::NonFinite {
                path: self.path.to_path_buf(),
                location: location(),
                value,
            });
        }
        self.positions.push(p);
        Ok(())
    }

    /// Checks `indices` and keeps them as the corners of the current polygon.
    fn take_corners(
        &mut self,
        indices: &[i64],
        strips: bool,
        location: &impl Fn() -> Location,
    ) -> Result<(), LoadError> {
        self.corners.clear();
        for &index in indices {
            match u32::try_from(index) {
                Ok(i) if (i as usize) < self.vertex_count => self.corners.push(i),
                _ if strips && index == -1 => self.corners.push(u32::MAX),
                _ => {
                    return Err(LoadError::IndexOutOfRange {
                        path: self.path.to_path_buf(),
                        location: location(),
                        index,
                        vertex_count: self.vertex_count as u64,
                    })
                }
            }
        }
        Ok(())
    }

    fn face(&mut self, indices: &[i64], location: impl Fn() -> Location) -> Result<(), LoadError> {
        self.take_corners(indices, false, &location)?;
        if self.corners.len() < 3 {
            self.short_face_count += 1;
            self.first_short_face.get_or_insert_with(location);
        }
        fan_triangulate(&self.corners, &mut self.triangles);
        Ok(())
    }

    /// Triangle strips separated by `-1`; odd triangles flipped to keep the winding; triangles
    /// with a repeated corner (the strips' swaps) dropped.
    fn strips(&mut self, indices: &[i64], location: impl Fn() -> Location) -> Result<(), LoadError> {
        self.take_corners(indices, true, &location)?;
        for strip in self.corners.split(|&i| i == u32::MAX) {
            for (k, w) in strip.windows(3).enumerate() {
                let t = if k % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[1], w[0], w[2]]
                };
                if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                    self.triangles.push(t);
                }
            }
        }
        Ok(())
    }

    fn record(&mut self, role: Role, record: &PlyRecord, location: impl Fn() -> Location) -> Result<(), LoadError> {
        match role {
            Role::Vertex => self.vertex(record.xyz, location),
            Role::Faces => self.face(&record.indices, location),
            Role::Strips => self.strips(&record.indices, location),
            Role::Other => Ok(()),
        }
    }
}

/// One ascii element as read: the coordinates and the index list; every other property is
/// checked and dropped.
#[derive(Default)]
struct PlyRecord {
    xyz: [f64; 3],
    indices: Vec<i64>,
}

impl PlyRecord {
    fn scalar(&mut self, name: &str, value: f64) {
        let axis = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return,
        };
        self.xyz[axis] = value;
    }
}

fn header_error(path: &Path, error: ParseError) -> LoadError {
    let text = error.to_string();
    // `ParseError` displays as "Line N: message"; the location already says the line.
    let raw = match error.line() {
        Some(line) => text.strip_prefix(&format!("Line {line}: ")).unwrap_or(&text),
        None => &text,
    };
    let (column, message) = describe_header_error(raw);
    let location = match (error.line(), column) {
        (Some(line), Some(column)) => Location::LineColumn {
            line: line as u64,
            column,
        },
        (Some(line), None) => Location::Line(line as u64),
        (None, _) => Location::File,
    };
    if error.kind() == std::io::ErrorKind::UnexpectedEof {
        LoadError::Truncated {
            path: path.to_path_buf(),
            location,
            message,
        }
    } else {
        LoadError::Parse {
            path: path.to_path_buf(),
            location,
            message: format!("bad header: {message}"),
        }
    }
}

/// One line from the text of a header `ParseError` of `ply-rs`, which reads
/// `"<message>\n\tString: '<line>'\n\tError: <Debug of the grammar's error>"`: the message,
/// the offending line quoted, and what the grammar expected at which column (returned apart,
/// 1-based). Messages that embed Debug dumps get words instead.
fn describe_header_error(raw: &str) -> (Option<u64>, String) {
    let mut parts = raw.split("\n\t");
    let head = parts.next().unwrap_or("").trim();
    let mut line = None;
    let mut grammar = None;
    for part in parts {
        if let Some(l) = part.strip_prefix("String: ") {
            line = Some(l.trim().trim_matches('\'').trim_end());
        } else if let Some(e) = part.strip_prefix("Error: ") {
            grammar = Some(e);
        }
    }
    let quoted = line.map_or(String::new(), |l| format!("'{l}'"));
    let magic = head.starts_with("Expected magic number");
    let mut message = if magic {
        format!("the first line must be 'ply', not {quoted}")
    } else if head.starts_with("Property") && head.contains("without preceding element") {
        format!("a property line before any element line: {quoted}")
    } else if head.starts_with("Found contradicting format") {
        format!("a second format line contradicts the first: {quoted}")
    } else if head.starts_with("Couldn't parse line") {
        format!("cannot parse line {quoted}")
    } else {
        let head = head.trim_end_matches('.').replace(['\n', '\t'], " ");
        match line {
            Some(_) => format!("{head}: {quoted}"),
            None => head,
        }
    };
    let column = grammar
        .and_then(|g| debug_field(g, "column: "))
        .and_then(|c| c.parse().ok());
    // The grammar's set for the first line lists every header keyword: no help there.
    if let Some(expected) = grammar.filter(|_| !magic).and_then(expected_tokens) {
        message.push_str(&format!(": expected {expected}"));
    }
    (column, message)
}

/// The digits after `key` in a Debug dump.
fn debug_field<'a>(dump: &'a str, key: &str) -> Option<&'a str> {
    let rest = &dump[dump.find(key)? + key.len()..];
    let end = rest.find(|c: char| !c.is_ascii_digit()).unwrap_or(rest.len());
    (end > 0).then(|| &rest[..end])
}

/// The tokens of the `ExpectedSet { expected: {...} }` of a Debug dump of a `peg` error, as
/// words: `"element"` → element, `[' '|'\t']` → a space, `['0'..='9']` → a digit.
fn expected_tokens(dump: &str) -> Option<String> {
    let key = "expected: {";
    let body = &dump[dump.rfind(key)? + key.len()..];
    // The set holds Debug forms of strings: quoted, with backslash escapes.
    let mut tokens: Vec<String> = Vec::new();
    let mut chars = body.chars();
    while let Some(c) = chars.next() {
        match c {
            '}' => break,
            '"' => {
                let mut token = String::new();
                while let Some(c) = chars.next() {
                    match c {
                        '\\' => token.extend(chars.next()),
                        '"' => break,
                        c => token.push(c),
                    }
                }
                tokens.push(match token.as_str() {
                    r"[' '|'\t']" => "a space".to_string(),
                    "['0'..='9']" => "a digit".to_string(),
                    r#""\n""# | r#""\r\n""# | r"['\n'|'\r']" => "the end of the line".to_string(),
                    t => t.trim_matches('"').to_string(),
                });
            }
            _ => {}
        }
    }
    tokens.retain(|t| !t.is_empty());
    tokens.dedup();
    match tokens.len() {
        0 => None,
        1 => Some(tokens.remove(0)),
        n => Some(format!("one of {} or {}", tokens[..n - 1].join(", "), tokens[n - 1])),
    }
}

fn read_ascii(
    path: &Path,
    header: &Header,
    layout: &Layout,
    payload: &[u8],
    header_line_count: u64,
    sink: &mut MeshSink<'_>,
) -> Result<(), LoadError> {
    let mut lines = payload.split(|&b| b == b'\n');
    let mut line_number = header_line_count;
    let mut record = PlyRecord::default();
    for (name, element) in &header.elements {
        let role = layout.role(name);
        for index in 0..element.count {
            let line = loop {
                let Some(line) = lines.next() else {
                    return Err(LoadError::Truncated {
                        path: path.to_path_buf(),
                        location: Location::element(name.as_str(), index as u64),
                        message: format!("the header declares {} '{name}' elements", element.count),
                    });
                };
                line_number += 1;
                if !line.trim_ascii().is_empty() {
                    break line;
                }
            };
            let location = || Location::ElementAtLine {
                kind: name.to_string(),
                index: index as u64,
                line: line_number,
            };
            parse_ascii_element(path, element, role, line, &mut record, &location)?;
            sink.record(role, &record, location)?;
        }
    }
    for line in lines {
        line_number += 1;
        if !line.trim_ascii().is_empty() {
            return Err(LoadError::CountMismatch {
                path: path.to_path_buf(),
                location: Location::Line(line_number),
                message: "data follows the last element the header declares".into(),
            });
        }
    }
    Ok(())
}

/// Parses one ascii element line into `record` (coordinates and index list; other values are
/// checked to be numbers and dropped).
fn parse_ascii_element(
    path: &Path,
    element: &ElementDef,
    role: Role,
    line: &[u8],
    record: &mut PlyRecord,
    location: &impl Fn() -> Location,
) -> Result<(), LoadError> {
    let parse_error = |message: String| LoadError::Parse {
        path: path.to_path_buf(),
        location: location(),
        message,
    };
    let mismatch = |message: String| LoadError::CountMismatch {
        path: path.to_path_buf(),
        location: location(),
        message,
    };
    let mut tokens = line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty());
    let mut next_value = |property: &str| {
        tokens
            .next()
            .ok_or_else(|| mismatch(format!("the line ends before property '{property}'")))
    };
    record.indices.clear();
    for (property, def) in &element.properties {
        match &def.data_type {
            PropertyType::Scalar(_) => {
                let token = next_value(property)?;
                let value = parse_f64(token).ok_or_else(|| {
                    parse_error(format!(
                        "bad value '{}' for property '{property}'",
                        String::from_utf8_lossy(token)
                    ))
                })?;
                if role == Role::Vertex {
                    record.scalar(property, value);
                }
            }
            PropertyType::List(..) => {
                let token = next_value(property)?;
                let count = std::str::from_utf8(token)
                    .ok()
                    .and_then(|s| s.parse::<u32>().ok())
                    .ok_or_else(|| {
                        parse_error(format!(
                            "bad list length '{}' for property '{property}'",
                            String::from_utf8_lossy(token)
                        ))
                    })?;
                let is_index_list =
                    matches!(role, Role::Faces | Role::Strips) && INDEX_LIST_NAMES.contains(&property.as_str());
                for item in 0..count {
                    let token = next_value(property).map_err(|_| {
                        mismatch(format!(
                            "list '{property}' declares {count} values, the line has {item}"
                        ))
                    })?;
                    if is_index_list {
                        let index = std::str::from_utf8(token)
                            .ok()
                            .and_then(|s| s.parse::<i64>().ok())
                            .ok_or_else(|| {
                                parse_error(format!("bad vertex index '{}'", String::from_utf8_lossy(token)))
                            })?;
                        record.indices.push(index);
                    } else if parse_f64(token).is_none() {
                        return Err(parse_error(format!(
                            "bad value '{}' in list '{property}'",
                            String::from_utf8_lossy(token)
                        )));
                    }
                }
            }
        }
    }
    if tokens.next().is_some() {
        return Err(mismatch(format!(
            "the line has more values than the {} properties the header declares",
            element.properties.len()
        )));
    }
    Ok(())
}

fn parse_f64(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token).ok()?.parse::<f64>().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_errors_are_one_line_with_line_column_and_what_was_expected() {
        let dir = std::env::temp_dir().join(format!("occult-ply-header-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("the temporary directory is writable");
        let error = |name: &str, text: &str| {
            let path = dir.join(name);
            std::fs::write(&path, text).expect("the temporary directory is writable");
            load_ply(&path).unwrap_err().to_string()
        };
        let e = error("typo.ply", "ply\nformat ascii 1.0\nelment vertex 3\nend_header\n");
        assert_eq!(
            e,
            format!(
                "{} line 3, column 1: bad header: cannot parse line 'elment vertex 3': expected one of comment, element, end_header, format, obj_info, ply or property",
                dir.join("typo.ply").display()
            )
        );
        let e = error("count.ply", "ply\nformat ascii 1.0\nelement vertex x\nend_header\n");
        assert!(
            e.ends_with("line 3, column 16: bad header: cannot parse line 'element vertex x': expected one of a space or a digit"),
            "{e}"
        );
        let e = error(
            "type.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty flot x\nend_header\n",
        );
        assert!(e.contains("line 4, column 10:") && e.contains("float, float32"), "{e}");
        let e = error("magic.ply", "plx\nformat ascii 1.0\n");
        assert!(
            e.ends_with("line 1, column 1: bad header: the first line must be 'ply', not 'plx'"),
            "{e}"
        );
        let e = error("orphan.ply", "ply\nproperty float x\nend_header\n");
        assert!(
            e.ends_with("line 2: bad header: a property line before any element line: 'property float x'"),
            "{e}"
        );
        for e in [e, error("noformat.ply", "ply\nelement vertex 3\nend_header\n")] {
            assert!(
                !e.contains('{') && !e.contains('\n') && !e.contains("ParseError"),
                "{e}"
            );
        }
        std::fs::remove_dir_all(&dir).ok();
    }
    use ply_rs_bw::ply::{Addable, PropertyDef};

    fn header(encoding: Encoding, vertex_count: usize) -> Header {
        let mut vertex = ElementDef::new("vertex".into());
        vertex.count = vertex_count;
        for axis in ["x", "y", "z"] {
            vertex
                .properties
                .add(PropertyDef::new(axis.into(), PropertyType::Scalar(ScalarType::Float)));
        }
        let mut header = Header::new();
        header.encoding = encoding;
        header.elements.add(vertex);
        header
    }

    #[test]
    fn declared_counts_are_checked_against_the_bytes() {
        let path = Path::new("t.ply");
        assert!(check_declared_counts(path, &header(Encoding::BinaryLittleEndian, 10), 120).is_ok());
        assert!(matches!(
            check_declared_counts(path, &header(Encoding::BinaryLittleEndian, 10), 100),
            Err(LoadError::Truncated { .. })
        ));
        assert!(matches!(
            check_declared_counts(path, &header(Encoding::BinaryBigEndian, 1 << 40), 1000),
            Err(LoadError::AbsurdCount { count, min_bytes: 12, .. }) if count == 1 << 40
        ));
        // Ascii: at least two characters per value ("0 0 0\n"); the last newline may be missing.
        assert!(check_declared_counts(path, &header(Encoding::Ascii, 2), 11).is_ok());
        assert!(check_declared_counts(path, &header(Encoding::Ascii, 0), 0).is_ok());
        assert!(matches!(
            check_declared_counts(path, &header(Encoding::Ascii, usize::MAX), 10),
            Err(LoadError::AbsurdCount { .. })
        ));
    }

    /// A sink for `t.ply` with `vertex_count` vertices and no face element.
    fn sink_of(vertex_count: usize) -> MeshSink<'static> {
        let layout = Layout {
            vertex_count,
            polygons: None,
        };
        MeshSink::new(Path::new("t.ply"), &layout)
    }

    #[test]
    fn bare_header_lines_become_comments_and_typos_stay_lines() {
        let text = b"ply\r\nformat ascii 1.0\r\nCreated by Scanner 3000\r\n\r\nelment vertex 3\nend_header\n1 2 3\n";
        let scan = HeaderScan::of(text);
        assert_eq!(scan.bare_lines, [3, 4]);
        assert_eq!(scan.first_bare_line, Some((3, "Created by Scanner 3000".to_string())));
        assert_eq!(&text[scan.end..], b"1 2 3\n");
        assert_eq!(
            scan.rewritten(text),
            b"ply\r\nformat ascii 1.0\r\ncomment\r\ncomment\r\nelment vertex 3\nend_header\n"
        );
        // Without `end_header` the whole file is header, its last line without a line end.
        let cut = b"ply\nhello\nworld";
        let scan = HeaderScan::of(cut);
        assert_eq!((scan.end, scan.bare_lines.as_slice()), (cut.len(), &[2, 3][..]));
        assert_eq!(scan.rewritten(cut), b"ply\ncomment\ncomment");
        assert_eq!(edit_distance(b"elment", b"element"), 1);
        assert_eq!(edit_distance(b"", b"ply"), 3);
        for typo in [&b"Property"[..], b"fromat", b"END_HEADER", b"elements"] {
            assert!(is_keyword_typo(typo), "{}", String::from_utf8_lossy(typo));
        }
        for text in [&b"Created"[..], b"VCGLIB", b"author", b"element_count_is_long"] {
            assert!(!is_keyword_typo(text), "{}", String::from_utf8_lossy(text));
        }
    }

    #[test]
    fn strips_restart_flip_and_drop_degenerates() {
        let mut sink = sink_of(5);
        sink.strips(&[0, 1, 2, 3, -1, 4, 4, 1, 2], || Location::File)
            .expect("strip indices within the 5 vertices");
        // The second strip starts with a swap (4 4 1, dropped), so 4 1 2 is odd: flipped.
        assert_eq!(sink.triangles, vec![[0, 1, 2], [2, 1, 3], [1, 4, 2]]);
        assert!(matches!(
            sink.strips(&[0, 1, 5], || Location::File),
            Err(LoadError::IndexOutOfRange { index: 5, .. })
        ));
        assert!(matches!(
            sink.face(&[0, -1, 2], || Location::File),
            Err(LoadError::IndexOutOfRange { index: -1, .. })
        ));
    }

    #[test]
    fn faces_of_fewer_than_three_corners_are_counted_not_drawn() {
        let mut sink = sink_of(3);
        sink.face(&[0, 1], || Location::File)
            .expect("a short face is skipped, not an error");
        sink.face(&[], || Location::File)
            .expect("an empty face is skipped, not an error");
        assert!(sink.triangles.is_empty());
        assert_eq!(sink.short_face_count, 2);
    }

    #[test]
    fn non_finite_and_overflowing_coordinates_are_errors() {
        let mut sink = sink_of(1);
        let at = || Location::element("vertex", 0);
        assert!(matches!(
            sink.vertex([0.0, f64::NAN, 0.0], at),
            Err(LoadError::NonFinite { .. })
        ));
        assert!(
            matches!(sink.vertex([1e300, 0.0, 0.0], at), Err(LoadError::NonFinite { value, .. }) if value == f32::INFINITY)
        );
        assert!(sink.vertex([1.0, 2.0, 3.0], at).is_ok());
    }
}

//! Typed errors of the core. Each variant carries structured fields (which element, which rule, where in the
//! input); the engine gives each variant its stable code (`kac_engine::code`), the CLI prints the message. Nothing
//! here knows about the service.

use serde::Serialize;
use std::fmt;

/// Where in the input a problem was found, in the units the format has.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Location {
    /// 1-based line number of a text format.
    Line { line: usize },
    /// 0-based byte offset of a binary format.
    Byte { offset: usize },
    /// JSON pointer (RFC 6901) into a JSON document (glTF, kac JSON).
    Pointer { pointer: String },
    /// The format has no finer location for this problem.
    Unknown,
}

impl Location {
    pub fn line(line: usize) -> Self {
        Location::Line { line }
    }
    pub fn byte(offset: usize) -> Self {
        Location::Byte { offset }
    }
    pub fn pointer(pointer: impl Into<String>) -> Self {
        Location::Pointer { pointer: pointer.into() }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line { line } => write!(f, "line {line}"),
            Location::Byte { offset } => write!(f, "byte offset {offset}"),
            Location::Pointer { pointer } => write!(f, "{pointer}"),
            Location::Unknown => write!(f, "an unknown position"),
        }
    }
}

/// The kind of element a problem refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Element {
    Vertex,
    Face,
    Tetrahedron,
    Edge,
    Segment,
    Point,
}

impl fmt::Display for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Element::Vertex => "vertex",
            Element::Face => "face",
            Element::Tetrahedron => "tetrahedron",
            Element::Edge => "edge",
            Element::Segment => "segment",
            Element::Point => "point",
        })
    }
}

/// A shape could not be read or cannot be used: the fatal findings of reading and validation.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize)]
#[serde(tag = "error", rename_all = "snake_case")]
pub enum ShapeError {
    /// The bytes do not follow the format's grammar.
    #[error("{format}: malformed input at {location}: {message}")]
    Syntax { format: &'static str, location: Location, message: String },
    /// The input ends before the format says it should.
    #[error("{format}: input ends early at {location}: {message}")]
    Truncated { format: &'static str, location: Location, message: String },
    /// A coordinate (or weight) is NaN or infinite.
    #[error("{element} {index} has a non-finite value ({value}) at {location}")]
    NonFinite { element: Element, index: usize, value: String, location: Location },
    /// An element refers to a vertex that does not exist.
    #[error("{element} {index} refers to vertex {value}, but the shape has {vertex_count} vertices (at {location})")]
    IndexOutOfRange { element: Element, index: usize, value: i64, vertex_count: usize, location: Location },
    /// A value breaks a rule of the model (a negative edge weight, a face with fewer than three corners, ...).
    #[error("{element} {index} breaks a rule: {rule} (at {location})")]
    InvalidElement { element: Element, index: usize, rule: String, location: Location },
    /// Nothing usable is left.
    #[error("the shape is empty: {what}")]
    Empty { what: String },
    /// Valid input of the format that kac does not take (a glTF primitive of points, a Gmsh version, ...).
    #[error("{format}: unsupported at {location}: {message}")]
    Unsupported { format: &'static str, location: Location, message: String },
    /// No reader could be chosen.
    #[error("unknown format: {message}")]
    UnknownFormat { message: String },
    /// A configured limit was exceeded.
    #[error("{what} is {value}, above the limit of {limit}")]
    LimitExceeded { what: String, value: u64, limit: u64 },
    /// The bytes could not be read as the format given (by name, media type or extension), and they look like
    /// another format: what was tried, what the bytes look like, and how they begin.
    #[error("the bytes are not {tried} (read as {tried}: {reason}); they look like {looks_like}, beginning {head}")]
    FormatMismatch { tried: &'static str, looks_like: &'static str, head: String, reason: String },
    /// The file could not be read from disk.
    #[error("cannot read {path}: {message}")]
    Io { path: String, message: String },
}

impl ShapeError {}

pub type Result<T, E = ShapeError> = std::result::Result<T, E>;

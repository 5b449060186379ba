//! Finite results: no analysis succeeds with a number that is not one. Every result's numbers are checked once,
//! where the runner and the correspondence builder turn their typed results into an [`Output`] (the one place both
//! the CLI and the service get results from), before anything is printed or stored: a NaN or an infinity fails the
//! analysis with `non-finite-result`, naming the field or array and the first element that holds it.
//!
//! The typed result is walked by a serde serializer of its own rather than read back from JSON, where serde_json
//! writes a non-finite number as `null`, the same as a field that has no value. What is allowed stays explicit: rows
//! of vertices validation dropped (NaN in every per-vertex array by construction), and the arrays and fields whose
//! non-finite values are documented markers (a boundary vertex's curvature, an unreachable vertex's distance).
//! Depends on the result types only.

use super::*;
use serde::ser::{self, Serialize};

/// Non-finite values that mean "no value here" in a result's own fields, by the end of their path (a field's
/// name, or the names of its last fields), with where the core sets them. Any other field holds a number.
const FIELD_MARKERS: &[(&str, &str)] = &[
    ("lambda_first_nonzero", "NaN where the k pairs hold no non-zero eigenvalue (descriptors::signatures)"),
    ("weyl.dimension_estimate", "NaN where Weyl's fit has too few eigenvalues (descriptors::weyl)"),
    ("weyl.measure_estimate_leading", "NaN where Weyl's fit has too few eigenvalues (descriptors::weyl)"),
    ("null_space.value", "NaN where the null space was not counted (operators::properties)"),
    ("error_estimate", "NaN for an eigenvalue seen on one level only (spectrum::extrapolate)"),
];

/// An array whose non-finite values are documented markers, and which values those are.
struct ArrayMarker {
    array: &'static str,
    allowed: fn(f64) -> bool,
}

/// The arrays with markers; in every other array, a row of a vertex validation kept (and every row of an array that
/// is not per vertex) holds finite numbers only.
const ARRAY_MARKERS: &[ArrayMarker] = &[
    // NaN on the boundary and at vertices of no area (descriptors::curvature).
    ArrayMarker { array: "mean_curvature", allowed: f64::is_nan },
    ArrayMarker { array: "gaussian_curvature", allowed: f64::is_nan },
    // NaN at a vertex whose faces' normals cancel (descriptors::curvature).
    ArrayMarker { array: "normals", allowed: f64::is_nan },
    // NaN on the boundary, where the expansion has a boundary term (analysis::tools).
    ArrayMarker { array: "heat_curvature", allowed: f64::is_nan },
    // +∞ where no source is reachable; NaN where Varadhan's estimate is undefined (pde::geodesic).
    ArrayMarker { array: "distance", allowed: |x| x.is_nan() || x == f64::INFINITY },
    // NaN on a degenerate element (pde::calculus).
    ArrayMarker { array: "gradient", allowed: f64::is_nan },
];

/// Why a result is refused: the first non-finite number, where it is.
fn non_finite(place: String, x: f64) -> AnalysisError {
    AnalysisError::NonFinite { place, value: x }
}

/// The first number of `value` that is NaN or ±∞ and not a documented marker: its path (`poisson.removed_mean[0]`)
/// and the number.
pub fn first_non_finite<T: Serialize + ?Sized>(value: &T) -> Option<(String, f64)> {
    let mut walk = Walk { path: vec![] };
    match value.serialize(&mut walk) {
        Err(Stop::Found(place, x)) => Some((place, x)),
        Err(Stop::Other(_)) | Ok(()) => None,
    }
}

/// A typed result as JSON once every number of it is checked: the first NaN or infinity (not a documented
/// marker) fails it with `non-finite-result`, naming where it is. For results without per-vertex arrays (a
/// comparison); [`checked_output`] checks the arrays too.
pub fn finite_json<T: Serialize + ?Sized>(value: &T) -> Result<Value, AnalysisError> {
    if let Some((place, x)) = first_non_finite(value) {
        return Err(non_finite(place, x));
    }
    serde_json::to_value(value)
        .map_err(|e| AnalysisError::invalid_parameter(format!("the result could not be written as JSON: {e}")))
}

/// The first value of an array that is not finite, skipping rows that `dropped` names and the documented markers of
/// the array: (row, column, value).
pub(crate) fn first_non_finite_in(a: &VertexArray, dropped: impl Fn(usize) -> bool) -> Option<(usize, usize, f64)> {
    let marker = ARRAY_MARKERS.iter().find(|m| m.array == a.name).map(|m| m.allowed);
    let cols = a.cols.max(1);
    a.data.iter().enumerate().find_map(|(i, &x)| {
        let (row, col) = (i / cols, i % cols);
        let fine = x.is_finite() || dropped(row) || marker.is_some_and(|m| m(x));
        (!fine).then_some((row, col, x))
    })
}

/// A result as the JSON it is served as, once every number of it has been checked: the typed result (head and
/// body) and each array. `shape_of` gives an array's shape when its rows are that shape's vertices in the upload's
/// numbering (None: every row is checked); there the rows of vertices validation dropped are skipped, and so are
/// up to `left_out` more rows with no value in any column: the points the operator left out (a cloud's outliers,
/// counted in its parameters), which it does not say one by one.
pub(crate) fn checked_output<'v>(
    typed: &Typed,
    arrays: Vec<VertexArray>,
    fingerprints: Vec<Fingerprint>,
    shape_of: impl Fn(&VertexArray) -> Option<&'v Validated>,
    left_out: usize,
) -> Result<Output, AnalysisError> {
    let summary = finite_json(typed)?;
    for a in &arrays {
        let map = shape_of(a).map(|v| &v.vertex_map);
        let dropped_by_validation = |row: usize| map.is_some_and(|m| m.get(row) == Some(&u32::MAX));
        let cols = a.cols.max(1);
        let no_value = |row: usize| a.data[row * cols..(row + 1) * cols].iter().all(|x| x.is_nan());
        let rows = a.data.len() / cols;
        let left: Vec<usize> = match (map, left_out) {
            (Some(_), 1..) => (0..rows).filter(|&r| !dropped_by_validation(r) && no_value(r)).collect(),
            _ => vec![],
        };
        let left = if left.len() <= left_out { left } else { vec![] };
        let dropped = |row: usize| dropped_by_validation(row) || left.binary_search(&row).is_ok();
        if let Some((row, col, x)) = first_non_finite_in(a, dropped) {
            return Err(non_finite(format!("arrays.{}[{row}][{col}]", a.name), x));
        }
    }
    Ok(Output { summary, arrays, fingerprints })
}

/// A serializer that writes nothing: it walks a value's numbers, keeping the path to the current one, and stops at
/// the first that is not finite.
struct Walk {
    path: Vec<Segment>,
}

enum Segment {
    Key(String),
    Index(usize),
}

impl Walk {
    fn place(&self) -> String {
        let mut s = String::new();
        for seg in &self.path {
            match seg {
                Segment::Key(k) if s.is_empty() => s.push_str(k),
                Segment::Key(k) => {
                    s.push('.');
                    s.push_str(k);
                }
                Segment::Index(i) => s.push_str(&format!("[{i}]")),
            }
        }
        s
    }
    fn number(&mut self, x: f64) -> Result<(), Stop> {
        if x.is_finite() {
            return Ok(());
        }
        // The path's keys without the indices (`error_estimate[3]` is a value of `error_estimate`).
        let keys = self
            .path
            .iter()
            .filter_map(|s| match s {
                Segment::Key(k) => Some(k.as_str()),
                Segment::Index(_) => None,
            })
            .collect::<Vec<_>>()
            .join(".");
        let marker = |m: &str| keys == m || keys.ends_with(&format!(".{m}"));
        if FIELD_MARKERS.iter().any(|(m, _)| marker(m)) {
            return Ok(());
        }
        Err(Stop::Found(self.place(), x))
    }
    fn inside(&mut self, seg: Segment, value: &(impl Serialize + ?Sized)) -> Result<(), Stop> {
        self.path.push(seg);
        let r = value.serialize(&mut *self);
        self.path.pop();
        r
    }
}

/// How a walk ends early: at a non-finite number, or at an error of the value's own serialization.
#[derive(Debug)]
enum Stop {
    Found(String, f64),
    Other(String),
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stop::Found(place, x) => write!(f, "{place} is {x}"),
            Stop::Other(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Stop {}

impl ser::Error for Stop {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        Stop::Other(msg.to_string())
    }
}

/// A compound value being walked: a sequence's next index, or a map's last key.
struct Compound<'a> {
    walk: &'a mut Walk,
    index: usize,
    key: Option<String>,
}

impl<'a> Compound<'a> {
    fn new(walk: &'a mut Walk) -> Self {
        Compound { walk, index: 0, key: None }
    }
    fn element(&mut self, value: &(impl Serialize + ?Sized)) -> Result<(), Stop> {
        let i = self.index;
        self.index += 1;
        self.walk.inside(Segment::Index(i), value)
    }
}

/// A map key as text (strings, numbers, chars, unit variants); other keys as `?`.
fn key_text(key: &(impl Serialize + ?Sized)) -> String {
    match serde_json::to_value(key) {
        Ok(Value::String(s)) => s,
        Ok(other @ (Value::Number(_) | Value::Bool(_))) => other.to_string(),
        _ => "?".into(),
    }
}

impl<'a> ser::Serializer for &'a mut Walk {
    type Ok = ();
    type Error = Stop;
    type SerializeSeq = Compound<'a>;
    type SerializeTuple = Compound<'a>;
    type SerializeTupleStruct = Compound<'a>;
    type SerializeTupleVariant = Compound<'a>;
    type SerializeMap = Compound<'a>;
    type SerializeStruct = Compound<'a>;
    type SerializeStructVariant = Compound<'a>;

    fn serialize_f64(self, v: f64) -> Result<(), Stop> {
        self.number(v)
    }
    fn serialize_f32(self, v: f32) -> Result<(), Stop> {
        self.number(f64::from(v))
    }
    fn serialize_bool(self, _: bool) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_i8(self, _: i8) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_i16(self, _: i16) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_i32(self, _: i32) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_i64(self, _: i64) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_i128(self, _: i128) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_u8(self, _: u8) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_u16(self, _: u16) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_u32(self, _: u32) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_u64(self, _: u64) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_u128(self, _: u128) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_char(self, _: char) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_str(self, _: &str) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_none(self) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), Stop> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_unit_variant(self, _: &'static str, _: u32, _: &'static str) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(self, _: &'static str, value: &T) -> Result<(), Stop> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<(), Stop> {
        self.inside(Segment::Key(variant.into()), value)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self))
    }
    fn serialize_tuple(self, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, Stop> {
        self.path.push(Segment::Key(variant.into()));
        Ok(Compound::new(self))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self))
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, Stop> {
        self.path.push(Segment::Key(variant.into()));
        Ok(Compound::new(self))
    }
}

impl ser::SerializeSeq for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.element(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl ser::SerializeTuple for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.element(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl ser::SerializeTupleStruct for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.element(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

/// A variant's compound (tuple or struct): its name was pushed on the path when it began, and is popped at its end.
impl ser::SerializeTupleVariant for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.element(value)
    }
    fn end(self) -> Result<(), Stop> {
        self.walk.path.pop();
        Ok(())
    }
}

impl ser::SerializeMap for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), Stop> {
        self.key = Some(key_text(key));
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        let key = self.key.take().unwrap_or_else(|| "?".into());
        self.walk.inside(Segment::Key(key), value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl ser::SerializeStruct for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, key: &'static str, value: &T) -> Result<(), Stop> {
        self.walk.inside(Segment::Key(key.into()), value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl ser::SerializeStructVariant for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, key: &'static str, value: &T) -> Result<(), Stop> {
        self.walk.inside(Segment::Key(key.into()), value)
    }
    fn end(self) -> Result<(), Stop> {
        self.walk.path.pop();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn energy(x: f64) -> Typed {
        Typed {
            head: ResultHead { shape_id: "s".into(), algorithm_version: 1, eigenpairs_reused: false, warnings: vec![] },
            body: Summary::DirichletEnergy(DirichletEnergySummary {
                dirichlet_energy: vec![
                    Energy { of: "x".into(), energy: 1.0, u_m_u: 2.0, rayleigh_quotient: None },
                    Energy { of: "y".into(), energy: x, u_m_u: 2.0, rayleigh_quotient: Some(0.5) },
                ],
                definition: "E(u) = ½ uᵀLu",
                operator: OperatorUsed {
                    operator: "cotan",
                    mass: "consistent",
                    boundary: "neumann",
                    size: 3,
                    parameters: Default::default(),
                },
            }),
        }
    }

    fn column(name: &'static str, data: Vec<f64>) -> VertexArray {
        VertexArray { name, rows: data.len(), cols: 1, data, columns: None }
    }

    /// serde_json writes NaN and ±∞ as null, so a result of overflowed numbers would be served as a result of
    /// nulls: the walk over the typed result finds each one before it is written, with its path, and a finite
    /// result passes unchanged.
    #[test]
    fn a_non_finite_number_is_found_with_its_path() {
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let found = first_non_finite(&energy(x)).map(|(place, _)| place);
            assert_eq!(found.as_deref(), Some("dirichlet_energy[1].energy"), "{x}");
        }
        assert_eq!(first_non_finite(&energy(f64::MAX)), None);
        // Maps (by key), tuples, options, nested sequences.
        let nested: (Vec<Vec<f64>>, std::collections::BTreeMap<&str, Option<f32>>) =
            (vec![vec![0.0], vec![1.0, 2.0]], [("a", Some(1.0)), ("b", Some(f32::NAN))].into_iter().collect());
        assert_eq!(first_non_finite(&nested).map(|p| p.0).as_deref(), Some("[1].b"));
        let nested = (vec![vec![0.0], vec![1.0, f64::NAN]], ());
        assert_eq!(first_non_finite(&nested).map(|p| p.0).as_deref(), Some("[0][1][1]"));
        // The documented markers pass, by the end of their path only.
        #[derive(Serialize)]
        struct Weyl {
            dimension_estimate: f64,
        }
        #[derive(Serialize)]
        struct Markers {
            lambda_first_nonzero: f64,
            weyl: Weyl,
            error_estimate: Vec<f64>,
        }
        let m = Markers {
            lambda_first_nonzero: f64::NAN,
            weyl: Weyl { dimension_estimate: f64::NAN },
            error_estimate: vec![0.1, f64::NAN],
        };
        assert_eq!(first_non_finite(&m), None);
        let elsewhere = [("dimension_estimate", f64::NAN)].into_iter().collect::<std::collections::BTreeMap<_, _>>();
        assert_eq!(first_non_finite(&elsewhere).map(|p| p.0).as_deref(), Some("dimension_estimate"));
    }

    /// The one check every result passes before it is returned: a non-finite number of the summary or of an
    /// array fails the analysis with `non-finite-result` naming where it is; rows of dropped vertices and the
    /// documented markers (an unreachable vertex's distance) pass.
    #[test]
    fn the_result_check_refuses_a_non_finite_number() {
        let v = {
            let mesh = kac_core::geometry::generate::icosphere(0);
            let bytes = serde_json::to_vec(&kac_core::io::write::json(&Shape::TriangleMesh(mesh))).unwrap();
            kac_core::load_bytes(&bytes, kac_core::Format::Json, &Default::default(), &Default::default()).unwrap()
        };
        let n = v.vertex_map.len();
        let ok = checked_output(&energy(1.0), vec![column("solution", vec![1.0; n])], vec![], |_| Some(&v), 0).unwrap();
        assert_eq!(ok.summary["dirichlet_energy"][1]["energy"], 1.0);
        let e = checked_output(&energy(f64::NAN), vec![], vec![], |_| Some(&v), 0).unwrap_err();
        assert_eq!(e.code().as_str(), "non-finite-result");
        assert!(!e.caller_fault());
        assert!(e.to_string().contains("dirichlet_energy[1].energy is NaN"), "{e}");
        let mut data = vec![1.0; n];
        data[3] = f64::INFINITY;
        let e = checked_output(&energy(1.0), vec![column("solution", data)], vec![], |_| Some(&v), 0).unwrap_err();
        assert_eq!(e, AnalysisError::NonFinite { place: "arrays.solution[3][0]".into(), value: f64::INFINITY });
        // A marker: +∞ for a vertex no source reaches; NaN in the solution of a row whose vertex was dropped.
        let mut distance = vec![0.5; n];
        distance[2] = f64::INFINITY;
        assert!(checked_output(&energy(1.0), vec![column("distance", distance)], vec![], |_| Some(&v), 0).is_ok());
        let mut dropped = v.clone();
        dropped.vertex_map[4] = u32::MAX;
        let mut data = vec![1.0; n];
        data[4] = f64::NAN;
        let solution = |data: &[f64]| vec![column("solution", data.to_vec())];
        assert!(checked_output(&energy(1.0), solution(&data), vec![], |_| Some(&dropped), 0).is_ok());
        // A row the operator left out (a cloud's outlier) has no value in any column: as many such rows as the
        // operator says it left out pass, one more does not.
        assert!(checked_output(&energy(1.0), solution(&data), vec![], |_| Some(&v), 0).is_err());
        assert!(checked_output(&energy(1.0), solution(&data), vec![], |_| Some(&v), 1).is_ok());
        data[7] = f64::NAN;
        assert!(checked_output(&energy(1.0), solution(&data), vec![], |_| Some(&v), 2).is_ok());
        let e = checked_output(&energy(1.0), solution(&data), vec![], |_| Some(&v), 1).unwrap_err();
        assert!(
            matches!(&e, AnalysisError::NonFinite { place, value } if place == "arrays.solution[4][0]" && value.is_nan())
        );
        // Not per vertex: every row is checked.
        assert!(checked_output(&energy(1.0), vec![column("mass", data)], vec![], |_| None, 5).is_err());
    }
}

//! Strict requests: every field of a request body, at every level, and every query parameter must be one that the
//! OpenAPI document declares at that place. Anything else is a 422 `invalid-request` problem that names the
//! field's JSON pointer, the closest valid name ("did you mean `normalization`?") and, for a field that belongs
//! one level down, where it goes ("`boundary` belongs in `operator`"). The check walks the document served at
//! `/openapi.json`, so what the server enforces and what it documents are one thing.
//!
//! Walking a schema: `$ref` is followed; `allOf` members add their properties (a flattened struct); of a `oneOf`
//! whose branches are objects tagged by a one-value `enum` property (an internally tagged enum such as
//! `Analysis`), the branch named by the value's tag is taken; a `oneOf` that wraps one object schema (`Option<T>`,
//! a documented default) is that schema. An object schema without declared properties (free-form JSON, maps) is
//! not checked.
//!
//! No object may name a key twice ([`duplicate_key`]): a JSON parser keeps one of them (serde_json's `Value` the
//! last) and the other would be dropped without a word, so every JSON the service reads (bodies, multipart parts,
//! `?analysis=`) is walked for repeats before it is parsed. Depends on the OpenAPI document and serde only; no
//! HTTP types.

use serde::de::{DeserializeSeed, Deserializer, Error as _, MapAccess, SeqAccess, Visitor};
use serde_json::{Map, Value};
use std::cell::RefCell;
use std::collections::{BTreeSet, HashSet};

/// A field or parameter the document does not declare where it was sent.
#[derive(Debug, Clone, PartialEq)]
pub struct Unknown {
    /// JSON pointer of the field (RFC 6901), or `?name` for a query parameter.
    pub pointer: String,
    pub name: String,
    /// The closest declared name at that place, when one is close.
    pub suggestion: Option<Box<str>>,
    /// The object field (one level down) that declares this name, when one does.
    pub belongs_in: Option<Box<str>>,
    /// Every name declared at that place.
    pub allowed: Vec<String>,
    /// Set when the field is declared but its value is not a name it takes: the tag of a tagged union sent as
    /// something other than one of its names (`"analysis": 5`, which a deserializer would read as a variant index).
    pub not_a_name: Option<Box<str>>,
}

impl Unknown {
    pub fn detail(&self) -> String {
        if let Some(v) = &self.not_a_name {
            return format!(
                "`{}` at {} is {v}: give one of its names as a string (accepted: {})",
                self.name,
                self.pointer,
                self.allowed.join(", ")
            );
        }
        let what = if self.pointer.starts_with('?') { "query parameter" } else { "field" };
        let mut d = format!("unknown {what} `{}` at {}", self.name, self.pointer);
        if let Some(parent) = &self.belongs_in {
            d.push_str(&format!(": `{}` belongs in `{parent}`", self.name));
        } else if let Some(s) = &self.suggestion {
            d.push_str(&format!(": did you mean `{s}`?"));
        }
        if self.allowed.is_empty() {
            d.push_str(" (none are accepted here)");
        } else {
            d.push_str(&format!(" (accepted: {})", self.allowed.join(", ")));
        }
        d
    }
}

/// A key that appears twice in one JSON object.
#[derive(Debug, Clone, PartialEq)]
pub struct DuplicateKey {
    /// JSON pointer (RFC 6901) of the repeated member: its object's pointer and the key.
    pub pointer: String,
    pub key: String,
}

impl DuplicateKey {
    pub fn detail(&self) -> String {
        format!("the key `{}` appears more than once at {}: give each key once in an object", self.key, self.pointer)
    }
}

/// Where the walker is: a path of object keys and array indices, rendered as a JSON pointer only when a repeat is
/// found (a fingerprint of a million numbers builds no million strings).
enum Step<'p> {
    Root,
    Key(&'p Step<'p>, &'p str),
    Index(&'p Step<'p>, usize),
}

impl Step<'_> {
    fn pointer(&self) -> String {
        match self {
            Step::Root => String::new(),
            Step::Key(up, k) => format!("{}/{}", up.pointer(), escape(k)),
            Step::Index(up, i) => format!("{}/{i}", up.pointer()),
        }
    }
}

/// Walks one JSON value, remembering the first repeated key it meets (and stopping there).
struct NoRepeats<'p> {
    at: &'p Step<'p>,
    found: &'p RefCell<Option<DuplicateKey>>,
}

impl<'de> DeserializeSeed<'de> for NoRepeats<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for NoRepeats<'_> {
    type Value = ();
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0;
        while seq.next_element_seed(NoRepeats { at: &Step::Index(self.at, i), found: self.found })?.is_some() {
            i += 1;
        }
        Ok(())
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut seen: HashSet<String> = HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            if seen.contains(&key) {
                let pointer = Step::Key(self.at, &key).pointer();
                *self.found.borrow_mut() = Some(DuplicateKey { pointer, key });
                return Err(A::Error::custom("a repeated key"));
            }
            map.next_value_seed(NoRepeats { at: &Step::Key(self.at, &key), found: self.found })?;
            seen.insert(key);
        }
        Ok(())
    }
}

/// The first key repeated within one object of the JSON text, if any. Text that is not JSON has none (the parser
/// that reads it next names its error); nesting is bounded by serde_json's recursion limit.
pub fn duplicate_key(json: &[u8]) -> Option<DuplicateKey> {
    let found = RefCell::new(None);
    let mut de = serde_json::Deserializer::from_slice(json);
    let _ = NoRepeats { at: &Step::Root, found: &found }.deserialize(&mut de);
    found.into_inner()
}

fn resolve<'a>(doc: &'a Value, schema: &'a Value) -> &'a Value {
    let mut s = schema;
    for _ in 0..16 {
        match s.get("$ref").and_then(Value::as_str).and_then(|r| r.strip_prefix("#/components/schemas/")) {
            Some(name) => match doc.pointer(&format!("/components/schemas/{name}")) {
                Some(next) => s = next,
                None => break,
            },
            None => break,
        }
    }
    s
}

/// The one-value `enum` of a tag property of an object schema: `Some((property, value))`.
/// A branch made of flattened parts (`allOf`) has its tag in one of them.
fn tag_of<'a>(doc: &'a Value, branch: &'a Value) -> Option<(&'a str, &'a str)> {
    let b = resolve(doc, branch);
    let own = b.get("properties").and_then(Value::as_object).and_then(|props| {
        props.iter().find_map(|(name, p)| {
            let e = resolve(doc, p).get("enum")?.as_array()?;
            (e.len() == 1).then(|| e[0].as_str().map(|v| (name.as_str(), v))).flatten()
        })
    });
    own.or_else(|| b.get("allOf")?.as_array()?.iter().find_map(|m| tag_of(doc, m)))
}

/// The object schemas that together describe `value` at this place (several for `allOf`), or `None` when the place
/// is not checked (free-form, or a tagged union whose tag matches no branch: the deserializer names that error).
fn object_parts<'a>(doc: &'a Value, schema: &'a Value, value: &Map<String, Value>, out: &mut Vec<&'a Value>) -> bool {
    let s = resolve(doc, schema);
    let mut any = false;
    if s.get("properties").is_some_and(Value::is_object) {
        out.push(s);
        any = true;
    }
    if let Some(all) = s.get("allOf").and_then(Value::as_array) {
        for member in all {
            if !object_parts(doc, member, value, out) {
                return false;
            }
            any = true;
        }
    }
    for key in ["oneOf", "anyOf"] {
        let Some(branches) = s.get(key).and_then(Value::as_array) else { continue };
        let objects: Vec<&Value> = branches
            .iter()
            .filter(|b| {
                let r = resolve(doc, b);
                r.get("properties").is_some() || r.get("allOf").is_some() || r.get("oneOf").is_some()
            })
            .collect();
        let tagged: Vec<(&Value, (&str, &str))> =
            objects.iter().filter_map(|b| tag_of(doc, b).map(|t| (*b, t))).collect();
        let chosen = if objects.len() == 1 {
            objects[0]
        } else if !tagged.is_empty() && tagged.len() == objects.len() {
            let (prop, _) = tagged[0].1;
            match tagged.iter().find(|(_, (p, v))| *p == prop && value.get(prop).and_then(Value::as_str) == Some(*v)) {
                Some((b, _)) => b,
                None => return false,
            }
        } else {
            return false;
        };
        if !object_parts(doc, chosen, value, out) {
            return false;
        }
        any = true;
    }
    any
}

/// The schema of the items of an array schema (through `$ref` and one-object `oneOf` wrappers).
fn items_of<'a>(doc: &'a Value, schema: &'a Value) -> Option<&'a Value> {
    let s = resolve(doc, schema);
    if let Some(items) = s.get("items") {
        return Some(items);
    }
    let branches = s.get("oneOf").or_else(|| s.get("anyOf"))?.as_array()?;
    branches.iter().find_map(|b| items_of(doc, b))
}

fn escape(name: &str) -> String {
    name.replace('~', "~0").replace('/', "~1")
}

/// Levenshtein distance (names are short).
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for j in 0..b.len() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != b[j])).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// The closest of `allowed` to `name`: within a third of the name's length (at least 2 edits), or the same with
/// `-`/`_` and case ignored.
fn closest(name: &str, allowed: &[String]) -> Option<String> {
    let norm = |s: &str| s.to_ascii_lowercase().replace('-', "_");
    if let Some(a) = allowed.iter().find(|a| norm(a) == norm(name)) {
        return Some(a.clone());
    }
    let limit = (name.chars().count() / 3).max(2);
    allowed
        .iter()
        .map(|a| (distance(&norm(name), &norm(a)), a))
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, a)| a.clone())
}

/// The tag property of a tagged union (a `oneOf` whose object branches each carry a one-value `enum`) and its
/// names.
fn tag_union<'a>(doc: &'a Value, schema: &'a Value) -> Option<(&'a str, Vec<&'a str>)> {
    let s = resolve(doc, schema);
    if let Some(all) = s.get("allOf").and_then(Value::as_array) {
        return all.iter().find_map(|m| tag_union(doc, m));
    }
    let branches = s.get("oneOf")?.as_array()?;
    let tags: Vec<(&str, &str)> = branches.iter().filter_map(|b| tag_of(doc, b)).collect();
    if tags.len() < 2 || tags.len() != branches.len() || tags.iter().any(|(p, _)| *p != tags[0].0) {
        return None;
    }
    Some((tags[0].0, tags.iter().map(|(_, v)| *v).collect()))
}

fn check_object(doc: &Value, schema: &Value, value: &Map<String, Value>, pointer: &str) -> Result<(), Unknown> {
    // A tag that is not a string would be read as a variant's index and pick a branch no name was given for.
    if let Some((prop, names)) = tag_union(doc, schema) {
        if let Some(v) = value.get(prop).filter(|v| !v.is_string()) {
            return Err(Unknown {
                pointer: format!("{pointer}/{}", escape(prop)),
                name: prop.to_string(),
                suggestion: None,
                belongs_in: None,
                allowed: names.iter().map(|n| n.to_string()).collect(),
                not_a_name: Some(v.to_string().into()),
            });
        }
    }
    let mut parts = Vec::new();
    if !object_parts(doc, schema, value, &mut parts) {
        return Ok(());
    }
    let mut properties: Vec<(&String, &Value)> = Vec::new();
    for p in &parts {
        if let Some(props) = p.get("properties").and_then(Value::as_object) {
            properties.extend(props.iter());
        }
    }
    let allowed: Vec<String> =
        properties.iter().map(|(n, _)| (*n).clone()).collect::<BTreeSet<_>>().into_iter().collect();
    for (key, v) in value {
        let here = format!("{pointer}/{}", escape(key));
        match properties.iter().find(|(n, _)| *n == key) {
            Some((_, sub)) => check_value(doc, sub, v, &here)?,
            None => {
                // A name declared one level down (in an object-valued field) is a misplaced field.
                let belongs_in = properties.iter().find_map(|(n, sub)| {
                    let mut inner = Vec::new();
                    object_parts(doc, sub, &Map::new(), &mut inner);
                    inner
                        .iter()
                        .any(|p| p.get("properties").and_then(|x| x.get(key)).is_some())
                        .then(|| (*n).as_str().into())
                });
                return Err(Unknown {
                    pointer: here,
                    name: key.clone(),
                    suggestion: closest(key, &allowed).map(Into::into),
                    belongs_in,
                    allowed,
                    not_a_name: None,
                });
            }
        }
    }
    Ok(())
}

fn check_value(doc: &Value, schema: &Value, value: &Value, pointer: &str) -> Result<(), Unknown> {
    match value {
        Value::Object(map) => check_object(doc, schema, map, pointer),
        Value::Array(items) => match items_of(doc, schema) {
            Some(item_schema) => {
                for (i, v) in items.iter().enumerate() {
                    check_value(doc, item_schema, v, &format!("{pointer}/{i}"))?;
                }
                Ok(())
            }
            None => Ok(()),
        },
        _ => Ok(()),
    }
}

/// Checks a request body against the named component schema of the served document.
pub fn check_body(doc: &Value, value: &Value, schema: &str) -> Result<(), Unknown> {
    let schema = serde_json::json!({ "$ref": format!("#/components/schemas/{schema}") });
    check_value(doc, &schema, value, "")
}

/// Checks query parameter names against those the document declares for the operation (`path` as routed, e.g.
/// `/v1/jobs/{id}`).
pub fn check_query(doc: &Value, path: &str, method: &str, query: &str) -> Result<(), Unknown> {
    let Some(op) = doc.get("paths").and_then(|p| p.get(path)).and_then(|p| p.get(method.to_ascii_lowercase())) else {
        return Ok(());
    };
    let allowed: Vec<String> = op
        .get("parameters")
        .and_then(Value::as_array)
        .map(|ps| {
            ps.iter()
                .filter(|p| p.get("in").and_then(Value::as_str) == Some("query"))
                .filter_map(|p| p.get("name").and_then(Value::as_str).map(String::from))
                .collect()
        })
        .unwrap_or_default();
    for (name, _) in form_urlencoded::parse(query.as_bytes()) {
        if !allowed.iter().any(|a| *a == name) {
            return Err(Unknown {
                pointer: format!("?{name}"),
                name: name.to_string(),
                suggestion: closest(&name, &allowed).map(Into::into),
                belongs_in: None,
                allowed: allowed.clone(),
                not_a_name: None,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc() -> &'static Value {
        crate::service::openapi::served()
    }
    use serde_json::json;

    #[test]
    fn misspelt_fields_get_the_closest_name() {
        let e = check_body(
            doc(),
            &json!({"shape_id": "x", "analysis": "shape-dna", "options": {"normalisation": "area"}}),
            "JobRequest",
        )
        .unwrap_err();
        assert_eq!(e.pointer, "/options/normalisation");
        assert_eq!(e.suggestion.as_deref(), Some("normalization"));
    }

    #[test]
    fn a_tag_that_is_not_a_name_is_refused_not_read_as_an_index() {
        for tag in [json!(5), json!(6), json!(null), json!(true), json!(["gps"]), json!({"x": 1})] {
            let e = check_body(
                doc(),
                &json!({"shape_id": "x", "analysis": tag, "options": {"normalisation": "area"}}),
                "JobRequest",
            )
            .unwrap_err();
            assert_eq!((e.pointer.as_str(), e.not_a_name.is_some()), ("/analysis", true), "{tag}");
            assert!(e.allowed.iter().any(|a| a == "gps") && e.detail().contains("as a string"), "{}", e.detail());
        }
    }

    #[test]
    fn misplaced_fields_say_where_they_belong() {
        let e =
            check_body(doc(), &json!({"shape_id": "x", "analysis": "spectrum", "boundary": "dirichlet"}), "JobRequest")
                .unwrap_err();
        assert_eq!((e.pointer.as_str(), e.belongs_in.as_deref()), ("/boundary", Some("operator")));
        assert!(e.detail().contains("`boundary` belongs in `operator`"), "{}", e.detail());
    }

    #[test]
    fn a_field_of_another_analysis_is_unknown_here() {
        // `scale_invariant` is no field of `hks` (the scale-invariant form is the `si-hks` analysis).
        let e = check_body(doc(), &json!({"shape_id": "x", "analysis": "hks", "scale_invariant": true}), "JobRequest")
            .unwrap_err();
        assert_eq!(e.pointer, "/scale_invariant");
    }

    #[test]
    fn valid_requests_pass_at_every_level() {
        for body in [
            json!({"shape_id": "x", "analysis": "spectrum", "k": 5, "operator": {"boundary": "dirichlet"},
                   "solver": {"tol": 1e-9, "verify": false}}),
            json!({"shape_id": "x", "analysis": "hks", "options": {"count": 10, "scale": true}}),
            json!({"shape_id": "x", "analysis": "interpolate", "values": [[0, 1.0], [3, 2.0]]}),
            json!({"shape_id": "x", "analysis": "no-such-analysis"}),
        ] {
            check_body(doc(), &body, "JobRequest").unwrap_or_else(|e| panic!("{body}: {}", e.detail()));
        }
    }

    #[test]
    fn query_parameters_are_checked_against_the_operation() {
        assert!(check_query(doc(), "/v1/analyze", "POST", "wait=1&format=off").is_ok());
        let e = check_query(doc(), "/v1/analyze", "POST", "wiat=1").unwrap_err();
        assert_eq!((e.pointer.as_str(), e.suggestion.as_deref()), ("?wiat", Some("wait")));
    }

    #[test]
    fn flattened_parts_of_a_tagged_branch_are_checked() {
        let ok = json!({ "shape_id": "x", "analysis": "wave", "times": [0.1], "source": 3, "width": 0.2 });
        assert!(check_body(doc(), &ok, "JobRequest").is_ok());
        let bad = json!({ "shape_id": "x", "analysis": "wave", "times": [0.1], "sourse": 3 });
        let e = check_body(doc(), &bad, "JobRequest").unwrap_err();
        assert_eq!(e.suggestion.as_deref(), Some("source"));
    }

    #[test]
    fn repeated_keys_are_found_at_any_depth() {
        assert_eq!(duplicate_key(br#"{"a": 1, "b": [1, {"c": 2}], "d": {"e": {}}}"#), None);
        assert_eq!(duplicate_key(br#"{"k": 1, "k": 2}"#).map(|d| d.pointer), Some("/k".into()));
        let d = duplicate_key(br#"{"options": [0, {"x/y": 1, "n": 2, "x/y": 3}]}"#).unwrap();
        assert_eq!((d.pointer.as_str(), d.key.as_str()), ("/options/1/x~1y", "x/y"));
        // The same key in sibling objects is no repeat; text that is not JSON is left to its parser.
        assert_eq!(duplicate_key(br#"[{"a": 1}, {"a": 2}]"#), None);
        assert_eq!(duplicate_key(br#"{"a": "#), None);
        // Keys are compared decoded: "\u0061" is "a".
        assert_eq!(duplicate_key(br#"{"a": 1, "\u0061": 2}"#).map(|d| d.key), Some("a".into()));
    }

    #[test]
    fn edit_distance() {
        assert_eq!(distance("normalisation", "normalization"), 1);
        assert_eq!(distance("", "abc"), 3);
        assert_eq!(closest("K", &["k".into(), "operator".into()]).as_deref(), Some("k"));
        assert_eq!(closest("zzzzzz", &["k".into()]), None);
    }
}

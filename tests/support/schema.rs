//! Results held to their schemas: the committed OpenAPI document's `{Name}Result` for an analysis' result, as a
//! JSON Schema 2020-12 validator (OpenAPI 3.1 schemas are JSON Schema), closed for the check at every level: a
//! field a schema does not name fails, so a result can only say what its types say.

use serde_json::{json, Value};
use std::collections::HashMap;
use std::sync::Mutex;

pub struct ResultSchemas {
    components: Value,
    validators: Mutex<HashMap<String, std::sync::Arc<jsonschema::Validator>>>,
}

/// `additionalProperties: false` on every object schema with declared properties, at any depth.
fn close(schema: &mut Value) {
    match schema {
        Value::Object(o) => {
            if o.contains_key("properties") && !o.contains_key("additionalProperties") {
                o.insert("additionalProperties".into(), false.into());
            }
            for v in o.values_mut() {
                close(v);
            }
        }
        Value::Array(a) => a.iter_mut().for_each(close),
        _ => {}
    }
}

impl ResultSchemas {
    /// The committed document (`openapi/openapi.json`, the one the clients are generated from).
    pub fn committed() -> Self {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json");
        let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let mut components = doc["components"].clone();
        let mapping = components["schemas"]["AnalysisResult"]["discriminator"]["mapping"].clone();
        let mapping = mapping.as_object().expect("AnalysisResult maps each analysis to its result");
        assert!(!mapping.is_empty());
        // Closed at every level: each object schema with declared properties (the results, and every type they
        // hold) takes no other field; free-form objects (an operator's `parameters`) declare none and stay open.
        for schema in components["schemas"].as_object_mut().unwrap().values_mut() {
            close(schema);
        }
        Self { components, validators: Mutex::new(HashMap::new()) }
    }

    /// Checks a result against the schema its `analysis` names; the errors, each with where it is.
    pub fn check(&self, result: &Value) -> Result<(), String> {
        let name = result["analysis"].as_str().ok_or("the result names no analysis")?;
        // The schema the document's discriminator maps this analysis to.
        let mapping = &self.components["schemas"]["AnalysisResult"]["discriminator"]["mapping"];
        let component = mapping[name]
            .as_str()
            .ok_or_else(|| format!("the document maps no result schema to `{name}`"))?
            .trim_start_matches("#/components/schemas/")
            .to_string();
        let validator = {
            let mut cache = self.validators.lock().unwrap();
            cache
                .entry(component.clone())
                .or_insert_with(|| {
                    let root = json!({
                        "$schema": "https://json-schema.org/draft/2020-12/schema",
                        "$ref": format!("#/components/schemas/{component}"),
                        "components": self.components,
                    });
                    std::sync::Arc::new(jsonschema::validator_for(&root).expect("the document is a valid schema"))
                })
                .clone()
        };
        let errors: Vec<String> =
            validator.iter_errors(result).map(|e| format!("{}: {e}", e.instance_path())).take(10).collect();
        match errors.is_empty() {
            true => Ok(()),
            false => Err(format!("{component}: {}", errors.join("; "))),
        }
    }
}

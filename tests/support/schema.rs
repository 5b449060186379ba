//! Results held to their schemas: the committed OpenAPI document's `{Name}Result` for an analysis' result, as a
//! JSON Schema 2020-12 validator (OpenAPI 3.1 schemas are JSON Schema), closed for the check: a field the schema
//! does not name fails, so a result can only say what its type says.

use serde_json::{json, Value};
use std::collections::HashMap;
use std::sync::Mutex;

pub struct ResultSchemas {
    components: Value,
    validators: Mutex<HashMap<String, std::sync::Arc<jsonschema::Validator>>>,
}

/// `si-hks` → `SiHks`.
fn pascal(name: &str) -> String {
    name.split('-')
        .map(|w| {
            let mut c = w.chars();
            c.next().map(|f| f.to_ascii_uppercase().to_string() + c.as_str()).unwrap_or_default()
        })
        .collect()
}

impl ResultSchemas {
    /// The committed document (`openapi/openapi.json`, the one the clients are generated from).
    pub fn committed() -> Self {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json");
        let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let mut components = doc["components"].clone();
        let mapping = components["schemas"]["AnalysisResult"]["discriminator"]["mapping"].clone();
        let mapping = mapping.as_object().expect("AnalysisResult maps each analysis to its result");
        for target in mapping.values() {
            let name = target.as_str().unwrap().trim_start_matches("#/components/schemas/");
            components["schemas"][name]["additionalProperties"] = false.into();
        }
        Self { components, validators: Mutex::new(HashMap::new()) }
    }

    /// Checks a result against the schema its `analysis` names; the errors, each with where it is.
    pub fn check(&self, result: &Value) -> Result<(), String> {
        let name = result["analysis"].as_str().ok_or("the result names no analysis")?;
        let component = format!("{}Result", pascal(name));
        if self.components["schemas"].get(&component).is_none() {
            return Err(format!("the document has no {component}"));
        }
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

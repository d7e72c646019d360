//! The JSON Schema of a message, derived from its JSON form.
//!
//! Every protocol message is a `#[repr(C)]` struct of fixed-size fields (numbers, fixed
//! arrays, nested structs of the same), so each message of a type serialises to the same
//! shape; the schema derived from one message describes them all. Foxglove only needs the
//! field names and types to offer them for plotting.

use serde_json::{json, Map, Value};

/// The JSON Schema (draft 2020-12) of values shaped like `value`, titled `title`.
pub fn json_schema(title: &str, value: &Value) -> Value {
    let mut schema = shape(value);
    if let Value::Object(map) = &mut schema {
        map.insert(
            "$schema".into(),
            json!("https://json-schema.org/draft/2020-12/schema"),
        );
        map.insert("title".into(), json!(title));
    }
    schema
}

fn shape(value: &Value) -> Value {
    match value {
        // Every field of a protocol message is a number, string or array: a null is a NaN
        // float ("not known", e.g. a supply voltage no driver measures yet), and a later
        // message of the same type may carry a number there.
        Value::Null => json!({"type": ["number", "null"]}),
        Value::Bool(_) => json!({"type": "boolean"}),
        Value::Number(n) if n.is_f64() => json!({"type": "number"}),
        Value::Number(_) => json!({"type": "integer"}),
        Value::String(_) => json!({"type": "string"}),
        Value::Array(items) => {
            let item = items.first().map_or_else(|| json!({}), shape);
            json!({"type": "array", "items": item, "minItems": items.len(), "maxItems": items.len()})
        }
        Value::Object(fields) => {
            let properties: Map<String, Value> =
                fields.iter().map(|(k, v)| (k.clone(), shape(v))).collect();
            let required: Vec<&String> = fields.keys().collect();
            json!({"type": "object", "properties": properties, "required": required})
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::ImuSample;

    #[test]
    fn an_imu_sample_has_every_field_typed() {
        let value = serde_json::to_value(ImuSample::default()).unwrap();
        let schema = json_schema("thrusterd.ImuSample", &value);
        assert_eq!(schema["title"], "thrusterd.ImuSample");
        assert_eq!(schema["type"], "object");
        assert_eq!(schema["properties"]["seq"]["type"], "integer");
        assert_eq!(schema["properties"]["gyro"]["type"], "array");
        assert_eq!(schema["properties"]["gyro"]["items"]["type"], "number");
        assert_eq!(schema["properties"]["gyro"]["maxItems"], 3);
        assert_eq!(schema["properties"]["depth"]["type"], "number");
        assert_eq!(
            schema["required"].as_array().unwrap().len(),
            value.as_object().unwrap().len()
        );
    }
}

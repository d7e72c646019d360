//! The JSON Schema of each message type, declared from the type, and the recorded JSON form.
//!
//! The schema comes from the protocol's types (`schemars`, feature `schema` of
//! `thruster-protocol`), not from a sample: a field that is NaN in the first message (serde
//! writes `null`) is still `"type": "number"`, and a field added to a message is in its schema
//! without another edit. Foxglove's and Lichtblick's JSON Schema parser (`parseJsonSchema` of
//! their `mcap-support` package) takes objects, numbers, strings and arrays of those, but no
//! arrays of arrays and no `"type": "null"`. So a matrix (`[[f64; C]; R]`) is recorded as an
//! array of row objects, `[{"row": [...]}, ...]` (`/model.effectiveness[1].row[0]` in a Plot
//! panel: DOF 1, thruster 0), by [`to_recorded`]; [`from_recorded`] turns it back for serde.
//! A NaN is still written as `null` (JSON has no NaN): the app shows no value there.

use schemars::generate::SchemaSettings;
use schemars::JsonSchema;
use serde_json::{json, Map, Value};

/// The key of a matrix row's object in the recorded form.
pub const ROW_KEY: &str = "row";

/// The JSON Schema (draft 2020-12, no `$ref`: every nested type inline) of `T`'s recorded
/// form, titled `title`.
pub fn schema_of<T: JsonSchema>(title: &str) -> Value {
    let generator = SchemaSettings::draft2020_12()
        .with(|s| s.inline_subschemas = true)
        .into_generator();
    let mut schema = generator.into_root_schema_for::<T>().to_value();
    rows_as_objects(&mut schema);
    if let Value::Object(map) = &mut schema {
        map.insert("title".into(), json!(title));
    }
    schema
}

/// Every `array of arrays` in a schema as an array of `{"row": inner array}` objects.
fn rows_as_objects(schema: &mut Value) {
    let Value::Object(map) = schema else { return };
    if let Some(Value::Object(props)) = map.get_mut("properties") {
        props.values_mut().for_each(rows_as_objects);
    }
    if let Some(items) = map.get_mut("items") {
        rows_as_objects(items);
        if items.get("type") == Some(&json!("array")) {
            let row = items.take();
            *items = json!({
                "type": "object",
                "description": "one row of the matrix",
                "properties": {ROW_KEY: row},
                "required": [ROW_KEY],
            });
        }
    }
}

/// `value` (a message as serde writes it) in the recorded form: every array of arrays as an
/// array of `{"row": [...]}` objects.
pub fn to_recorded(value: &mut Value) {
    match value {
        Value::Array(items) => {
            items.iter_mut().for_each(to_recorded);
            if !items.is_empty() && items.iter().all(Value::is_array) {
                for item in items.iter_mut() {
                    let mut row = Map::new();
                    row.insert(ROW_KEY.into(), item.take());
                    *item = Value::Object(row);
                }
            }
        }
        Value::Object(fields) => fields.values_mut().for_each(to_recorded),
        _ => {}
    }
}

/// The inverse of [`to_recorded`]: arrays of `{"row": [...]}` objects back to arrays of arrays.
/// A recording written before the recorded form (arrays of arrays) passes unchanged.
pub fn from_recorded(value: &mut Value) {
    match value {
        Value::Array(items) => {
            let rows = !items.is_empty()
                && items.iter().all(|i| {
                    i.as_object().is_some_and(|o| {
                        o.len() == 1 && o.get(ROW_KEY).is_some_and(Value::is_array)
                    })
                });
            if rows {
                for item in items.iter_mut() {
                    *item = item[ROW_KEY].take();
                }
            }
            items.iter_mut().for_each(from_recorded);
        }
        Value::Object(fields) => fields.values_mut().for_each(from_recorded),
        _ => {}
    }
}

/// Where `value` does not match `schema` (a field without a schema entry, a schema property the
/// value lacks, a type or length that differs), as `path: what`; empty when it matches. Used by
/// the tests on every topic's type, so a message whose JSON form drifts from its declared
/// schema fails there.
pub fn mismatches(schema: &Value, value: &Value, path: &str, out: &mut Vec<String>) {
    let ty = schema.get("type").and_then(Value::as_str).unwrap_or("");
    match value {
        Value::Object(fields) => {
            if ty != "object" {
                return out.push(format!("{path}: an object, schema type {ty:?}"));
            }
            let props = schema.get("properties").and_then(Value::as_object);
            for (k, v) in fields {
                match props.and_then(|p| p.get(k)) {
                    Some(s) => mismatches(s, v, &format!("{path}.{k}"), out),
                    None => out.push(format!("{path}.{k}: no schema entry")),
                }
            }
            for k in props.into_iter().flat_map(|p| p.keys()) {
                if !fields.contains_key(k) {
                    out.push(format!("{path}.{k}: in the schema, not in the message"));
                }
            }
        }
        Value::Array(items) => {
            if ty != "array" {
                return out.push(format!("{path}: an array, schema type {ty:?}"));
            }
            let n = items.len() as u64;
            let min = schema.get("minItems").and_then(Value::as_u64).unwrap_or(0);
            let max = schema
                .get("maxItems")
                .and_then(Value::as_u64)
                .unwrap_or(u64::MAX);
            if !(min..=max).contains(&n) {
                out.push(format!("{path}: {n} items, schema {min}..={max}"));
            }
            let item = schema.get("items").cloned().unwrap_or(Value::Null);
            for (i, v) in items.iter().enumerate() {
                mismatches(&item, v, &format!("{path}[{i}]"), out);
            }
        }
        // A NaN float: serde_json writes null.
        Value::Null if ty == "number" => {}
        Value::Number(n) if ty == "number" || (ty == "integer" && !n.is_f64()) => {}
        Value::String(_) if ty == "string" => {}
        Value::Bool(_) if ty == "boolean" => {}
        other => out.push(format!("{path}: {other}, schema type {ty:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thruster_protocol::{ImuSample, ModelMsg};

    #[test]
    fn an_imu_sample_has_every_field_typed() {
        let schema = schema_of::<ImuSample>("thrusterd.ImuSample");
        assert_eq!(schema["title"], "thrusterd.ImuSample");
        assert_eq!(schema["type"], "object");
        assert_eq!(schema["properties"]["seq"]["type"], "integer");
        assert_eq!(schema["properties"]["gyro"]["type"], "array");
        assert_eq!(schema["properties"]["gyro"]["items"]["type"], "number");
        assert_eq!(schema["properties"]["gyro"]["maxItems"], 3);
        assert_eq!(schema["properties"]["depth"]["type"], "number");
    }

    #[test]
    fn a_matrix_is_recorded_as_row_objects_and_read_back() {
        let mut m = ModelMsg {
            count: 2,
            ..ModelMsg::default()
        };
        m.effectiveness[1][0] = 2.5;
        m.std_err[0][0] = f64::NAN;
        let mut value = serde_json::to_value(m).unwrap();
        to_recorded(&mut value);
        assert_eq!(value["effectiveness"][1][ROW_KEY][0], 2.5);
        assert_eq!(value["effectiveness"].as_array().unwrap().len(), 6);
        assert!(value["std_err"][0][ROW_KEY][0].is_null());
        let schema = schema_of::<ModelMsg>("thrusterd.ModelMsg");
        let eff = &schema["properties"]["effectiveness"];
        assert_eq!(eff["items"]["type"], "object");
        assert_eq!(eff["items"]["properties"][ROW_KEY]["maxItems"], 16);
        let mut out = Vec::new();
        mismatches(&schema, &value, "", &mut out);
        assert!(out.is_empty(), "{out:?}");
        from_recorded(&mut value);
        assert_eq!(value["effectiveness"][1][0], 2.5);
        assert_eq!(value["allocation"].as_array().unwrap().len(), 16);
    }

    #[test]
    fn a_field_without_a_schema_entry_is_named() {
        let schema = schema_of::<ImuSample>("thrusterd.ImuSample");
        let mut value = serde_json::to_value(ImuSample::default()).unwrap();
        value["added_later"] = json!(1.0);
        value.as_object_mut().unwrap().remove("depth");
        let mut out = Vec::new();
        mismatches(&schema, &value, "", &mut out);
        out.sort();
        assert_eq!(
            out,
            [
                ".added_later: no schema entry",
                ".depth: in the schema, not in the message"
            ]
        );
    }
}

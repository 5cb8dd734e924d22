//! Shared by the Mie integration tests that read JSON reference files.

use serde_json::Value;

/// A JSON array of numbers as f64s (panics on anything else: the reference files are ours).
pub fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

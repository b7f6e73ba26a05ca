//! The JSON Schemas shipped in `docs/schema/` are the ones the types generate, and they
//! describe the files the types write and read (the validation of real run folders, the
//! simulator's and the ICD writer's, against these files runs in `.ci/run` with Python
//! `jsonschema`: `tests/icd/validate_schema.py`).

use gro_reference::run_folder::{schemas, Metadata};

fn shipped(name: &str) -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs/schema")
        .join(name);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn shipped_schemas_are_fresh() {
    for (name, text) in schemas() {
        assert!(
            shipped(name) == text,
            "docs/schema/{name} is stale: regenerate with `cargo run -p gro-reference --example write_schemas`"
        );
    }
}

/// The metadata schema names every key the type writes, with the type's descriptions, and
/// lets unknown keys through (the ICD: unknown keys are ignored).
#[test]
fn metadata_schema_has_every_key_and_allows_unknown_ones() {
    let (_, text) = schemas()
        .into_iter()
        .find(|(n, _)| *n == "metadata.schema.json")
        .unwrap_or_else(|| panic!("no metadata schema"));
    let schema: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
    let props = schema["properties"]
        .as_object()
        .cloned()
        .unwrap_or_default();
    let full = Metadata {
        description: Some("d".into()),
        seed: Some(1),
        epoch_utc: Some("1991-04-09T00:00:00Z".into()),
        cycle_period_s: Some(1.0),
        duration_s: Some(2.0),
        telemetry_every_n_cycles: Some(1),
        ephemeris_period_s: Some(60.0),
        declared_effects: Some(vec!["aberration".into()]),
        fss_transfer_function_sigma: Some(Default::default()),
        boot_tables: Some(Default::default()),
        ..Metadata::default()
    };
    let written = full.to_json_value().unwrap_or_default();
    for key in written.as_object().into_iter().flat_map(|o| o.keys()) {
        assert!(props.contains_key(key), "schema lacks {key}");
    }
    assert_ne!(schema["additionalProperties"], serde_json::json!(false));
    assert!(props["sensors"].to_string().len() > 10);
}

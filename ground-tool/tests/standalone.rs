//! The ground tool stands on its own (issue 18): nothing it is built from, tests included,
//! is the simulator. Read from `Cargo.lock` (every dependency kind, dev-dependencies too);
//! `.ci/run` checks the same with `cargo tree -p ground-tool -e normal,build`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::{BTreeMap, BTreeSet};

/// Every package `name` needs, transitively, by `Cargo.lock`'s dependency lists.
fn closure(lock: &toml::Table, name: &str) -> BTreeSet<String> {
    let mut deps: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for p in lock["package"].as_array().into_iter().flatten() {
        let n = p["name"].as_str().unwrap_or_default().to_owned();
        let d: Vec<String> = p
            .get("dependencies")
            .and_then(|d| d.as_array())
            .into_iter()
            .flatten()
            // "name" or "name version" when two versions are locked.
            .filter_map(|x| x.as_str()?.split(' ').next().map(str::to_owned))
            .collect();
        deps.entry(n).or_default().extend(d);
    }
    let mut seen = BTreeSet::new();
    let mut stack = vec![name.to_owned()];
    while let Some(n) = stack.pop() {
        if seen.insert(n.clone()) {
            stack.extend(deps.get(&n).cloned().unwrap_or_default());
        }
    }
    seen
}

#[test]
fn ground_tool_does_not_depend_on_the_simulator() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.lock");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let lock: toml::Table = text
        .parse()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let ground = closure(&lock, "ground-tool");
    assert!(
        ground.contains("gro-reference") && ground.contains("fsw-core"),
        "the closure is not read right: {ground:?}"
    );
    assert!(
        !ground.contains("sim-harness"),
        "ground-tool depends on sim-harness (Cargo.lock): the ground must not carry the simulator (docs/architecture.md)"
    );
    // The check can fail: the tests crate does carry it.
    assert!(closure(&lock, "tests").contains("sim-harness"));
}

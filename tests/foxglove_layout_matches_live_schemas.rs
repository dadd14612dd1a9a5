//! The Foxglove layout shipped for the live view (`rig-config/foxglove/rigtwin-live.json`)
//! cannot rot: every panel's topic and every message path (`/live/daq.vibrometer.max`,
//! `/control/state.error`, ...) exists in the schemas the live view advertises for a session of
//! the default rig ([`rigtwin::session::live::topic_schemas`]); the layout holds the panels
//! the issue asks for (measured and twin tip velocities, control error, contact activity, twin
//! status and lag, the per-step comparison table); a path the schemas do not have is caught.

use std::collections::BTreeMap;
use std::path::Path;

use rigtwin::config::RigConfig;
use rigtwin::rig::channels::layout;
use rigtwin::session::live::{topic_schemas, LiveOptions, FOXGLOVE_LAYOUT};
use serde_json::Value;

/// The live view's topics and their schemas for the default rig.
fn schemas() -> BTreeMap<String, Value> {
    let daq = layout(&RigConfig::default_rig().daq);
    topic_schemas(&daq, &LiveOptions::default())
        .into_iter()
        .map(|t| {
            let schema: Value = serde_json::from_slice(&t.schema)
                .unwrap_or_else(|e| panic!("{}: schema is not JSON: {e}", t.topic));
            (t.topic.to_string(), schema)
        })
        .collect()
}

/// Every (panel id, message path or topic) of a layout: `paths[].value` of Plot and
/// StateTransitions panels, `topicPath` of Table and RawMessages panels.
fn references(layout: &Value) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (id, config) in layout["configById"].as_object().expect("configById") {
        if let Some(paths) = config["paths"].as_array() {
            for p in paths {
                let v = p["value"]
                    .as_str()
                    .unwrap_or_else(|| panic!("{id}: path {p}"));
                out.push((id.clone(), v.to_string()));
            }
        }
        if let Some(t) = config["topicPath"].as_str() {
            out.push((id.clone(), t.to_string()));
        }
    }
    out
}

/// Follows `$ref` (`#/$defs/NAME`) within `root`.
fn deref<'a>(root: &'a Value, mut node: &'a Value) -> &'a Value {
    while let Some(r) = node["$ref"].as_str() {
        let name = r
            .strip_prefix("#/$defs/")
            .unwrap_or_else(|| panic!("unexpected $ref {r}"));
        node = &root["$defs"][name];
    }
    node
}

/// The schema of `field` in `node` (an object schema, possibly through `$ref`, `allOf`,
/// `anyOf`, `oneOf`), if it has one.
fn field<'a>(root: &'a Value, node: &'a Value, name: &str) -> Option<&'a Value> {
    let node = deref(root, node);
    if let Some(p) = node["properties"].get(name) {
        return Some(p);
    }
    for key in ["allOf", "anyOf", "oneOf"] {
        if let Some(alts) = node[key].as_array() {
            if let Some(found) = alts.iter().find_map(|a| field(root, a, name)) {
                return Some(found);
            }
        }
    }
    None
}

/// Checks a message path against the schemas: `Err` says what is missing.
fn resolve(schemas: &BTreeMap<String, Value>, path: &str) -> Result<(), String> {
    // The topic is the longest served topic the path starts with, followed by the end or '.'.
    let (topic, schema) = schemas
        .iter()
        .filter(|(t, _)| {
            path.strip_prefix(t.as_str())
                .is_some_and(|rest| rest.is_empty() || rest.starts_with('.'))
        })
        .max_by_key(|(t, _)| t.len())
        .ok_or_else(|| format!("no served topic in {path:?} (topics: {:?})", schemas.keys()))?;
    let rest = &path[topic.len()..];
    let mut node = schema;
    for part in rest.split('.').skip(1) {
        // `[0]`, `[:]` slices select array items.
        let (name, indexed) = match part.find('[') {
            Some(i) => (&part[..i], true),
            None => (part, false),
        };
        node = field(schema, node, name)
            .ok_or_else(|| format!("{path}: {topic} has no field {name:?} here"))?;
        if indexed {
            node = &deref(schema, node)["items"];
        }
    }
    Ok(())
}

fn load_layout() -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(FOXGLOVE_LAYOUT);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"))
}

#[test]
fn every_topic_and_field_of_the_shipped_layout_is_served() {
    let schemas = schemas();
    let layout = load_layout();
    let refs = references(&layout);
    assert!(refs.len() >= 20, "{} references", refs.len());
    let bad: Vec<String> = refs
        .iter()
        .filter_map(|(id, p)| resolve(&schemas, p).err().map(|e| format!("{id}: {e}")))
        .collect();
    assert!(
        bad.is_empty(),
        "layout paths the live view does not serve:\n{}",
        bad.join("\n")
    );

    // The panels a test engineer expects (issue 18): tips measured and twin, control error,
    // contact activity, twin status and lag, the per-step comparison table.
    let paths: Vec<&str> = refs.iter().map(|(_, p)| p.as_str()).collect();
    for wanted in [
        "/live/daq.vibrometer.max",
        "/live/daq.vibrometer.min",
        "/live/twin.upper_tip.max",
        "/live/twin.upper_tip.min",
        "/control/state.error",
        "/live/daq.contact_voltage.min",
        "/live/twin.contact.mean",
        "/twin/status.lag_s",
        "/twin/status.behind",
        "/twin/steps",
    ] {
        assert!(paths.contains(&wanted), "the layout lacks {wanted}");
    }
    // Every panel of the tree is configured and every configured panel is in the tree.
    let mut in_tree = Vec::new();
    fn walk(node: &Value, out: &mut Vec<String>) {
        match node {
            Value::String(id) => out.push(id.clone()),
            Value::Object(o) => {
                walk(&o["first"], out);
                walk(&o["second"], out);
            }
            other => panic!("layout tree node {other}"),
        }
    }
    walk(&layout["layout"], &mut in_tree);
    in_tree.sort();
    let mut configured: Vec<String> = layout["configById"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    configured.sort();
    assert_eq!(in_tree, configured);
}

#[test]
fn a_path_the_live_view_does_not_serve_is_caught() {
    let schemas = schemas();
    assert!(resolve(&schemas, "/live/daq.vibrometer.max").is_ok());
    assert!(resolve(&schemas, "/twin/steps.twin.rms_error_upper").is_ok());
    assert!(resolve(&schemas, "/session/steps.summary.rms_upper").is_ok());
    for bad in [
        "/live/daq.vibrometer.peak",
        "/live/daq.upper_tip_max",
        "/live/twin.vibrometer.max",
        "/control/state.errors",
        "/twin/statuses.lag_s",
    ] {
        let e = resolve(&schemas, bad).unwrap_err();
        assert!(
            e.contains("no field") || e.contains("no served topic"),
            "{bad}: {e}"
        );
    }
}

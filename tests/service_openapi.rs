//! Keeps `openapi.yaml` and the code in sync: every route of the router is in the spec and vice
//! versa (same methods), the submit request's properties are exactly the accepted fields, and
//! every request enum lists exactly the values the code accepts.
//!
//! The crate has no YAML parser; `openapi.yaml` is written in a plain block style and this test
//! reads it with a small indentation-based reader (mappings by indentation, `- ` items folded
//! into their mapping, `[a, b]` flow lists as values).

use std::collections::BTreeSet;
use vectorfusion::pipeline::{JobKind, Method, Preset, Style};
use vectorfusion::server::types::SUBMIT_FIELDS;
use vectorfusion::store::JobStatus;

#[derive(Debug, Default)]
struct Node {
    value: Option<String>,
    children: Vec<(String, Node)>,
}

impl Node {
    fn get(&self, key: &str) -> Option<&Node> {
        self.children.iter().find(|(k, _)| k == key).map(|(_, n)| n)
    }
    fn path(&self, keys: &[&str]) -> &Node {
        let mut n = self;
        for k in keys {
            n = n
                .get(k)
                .unwrap_or_else(|| panic!("openapi.yaml has no {keys:?} (missing {k:?})"));
        }
        n
    }
    fn keys(&self) -> Vec<String> {
        self.children.iter().map(|(k, _)| k.clone()).collect()
    }
    fn flow_list(&self) -> Vec<String> {
        let v = self.value.as_deref().unwrap_or("");
        v.trim()
            .trim_start_matches('[')
            .trim_end_matches(']')
            .split(',')
            .map(|s| s.trim().trim_matches('\'').trim_matches('"').to_string())
            .filter(|s| !s.is_empty())
            .collect()
    }
}

fn parse(text: &str) -> Node {
    // (indent, key, value)
    let mut lines = Vec::new();
    for raw in text.lines() {
        let trimmed = raw.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let mut indent = raw.len() - trimmed.len();
        let mut body = trimmed;
        while let Some(rest) = body.strip_prefix("- ") {
            indent += 2;
            body = rest;
        }
        let Some((k, v)) = split_key(body) else {
            continue;
        };
        lines.push((indent, k, v));
    }
    fn build(lines: &[(usize, String, Option<String>)], i: &mut usize, indent: usize) -> Node {
        let mut node = Node::default();
        while *i < lines.len() {
            let (ind, k, v) = &lines[*i];
            if *ind < indent {
                break;
            }
            if *ind > indent {
                // deeper than expected without a parent key (block text); skip
                *i += 1;
                continue;
            }
            *i += 1;
            let child_indent = lines.get(*i).map_or(0, |l| l.0);
            let mut child = if child_indent > *ind {
                build(lines, i, child_indent)
            } else {
                Node::default()
            };
            child.value = v.clone();
            node.children.push((k.clone(), child));
        }
        node
    }
    let mut i = 0;
    build(&lines, &mut i, 0)
}

/// `key: value` or `key:`; keys may be quoted or contain `/`, `{`, `}`.
fn split_key(s: &str) -> Option<(String, Option<String>)> {
    let (k, v) = if let Some(rest) = s.strip_prefix('\'') {
        let end = rest.find('\'')?;
        let after = rest[end + 1..].strip_prefix(':')?;
        (rest[..end].to_string(), after)
    } else {
        let p = s
            .find(": ")
            .or_else(|| s.strip_suffix(':').map(|x| x.len()))?;
        (s[..p].to_string(), &s[(p + 1).min(s.len())..])
    };
    let v = v.trim();
    Some((k, (!v.is_empty()).then(|| v.to_string())))
}

fn spec() -> Node {
    parse(include_str!("../openapi.yaml"))
}

fn serde_names<T: serde::Serialize>(all: &[T]) -> BTreeSet<String> {
    all.iter()
        .map(|v| {
            serde_json::to_value(v)
                .unwrap()
                .as_str()
                .unwrap()
                .to_string()
        })
        .collect()
}

#[test]
fn every_route_is_documented_and_every_documented_route_exists() {
    let spec = spec();
    assert_eq!(spec.path(&["openapi"]).value.as_deref(), Some("3.1.0"));
    let mut documented = BTreeSet::new();
    for (path, item) in &spec.path(&["paths"]).children {
        for method in item.keys() {
            if ["get", "post", "put", "patch", "delete", "head", "options"]
                .contains(&method.as_str())
            {
                documented.insert((method, path.clone()));
            }
        }
    }
    let routed: BTreeSet<(String, String)> = vectorfusion::server::routes().into_iter().collect();
    let missing: Vec<_> = routed.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&routed).collect();
    assert!(
        missing.is_empty(),
        "routes missing from openapi.yaml: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "openapi.yaml documents routes the server lacks: {extra:?}"
    );
}

#[test]
fn submit_request_fields_and_enums_match_the_code() {
    let spec = spec();
    let schemas = spec.path(&["components", "schemas"]);
    // SubmitRequest is one of the two kinds' requests, told apart by `kind`.
    let mapping = schemas.path(&["SubmitRequest", "discriminator", "mapping"]);
    assert_eq!(
        mapping.keys().into_iter().collect::<BTreeSet<_>>(),
        serde_names(JobKind::ALL)
    );
    let text = schemas.path(&["TextJobRequest", "properties"]);
    let vectorize = schemas.path(&["VectorizeJobRequest", "properties"]);
    let documented: BTreeSet<String> = text.keys().into_iter().chain(vectorize.keys()).collect();
    let accepted: BTreeSet<String> = SUBMIT_FIELDS.iter().map(|s| s.to_string()).collect();
    assert_eq!(documented, accepted);
    // What each kind requires, and the fields only the other kind takes (null or absent).
    let required = |name: &str| schemas.path(&[name, "required"]).flow_list();
    assert_eq!(required("TextJobRequest"), ["kind", "caption"]);
    assert_eq!(required("VectorizeJobRequest"), ["kind", "image"]);
    assert_eq!(
        text.path(&["image", "type"]).value.as_deref(),
        Some("'null'")
    );
    assert_eq!(
        vectorize.path(&["method", "type"]).value.as_deref(),
        Some("'null'")
    );
    let enum_of = |props: &Node, field: &str| -> BTreeSet<String> {
        props
            .path(&[field, "enum"])
            .flow_list()
            .into_iter()
            .filter(|v| v != "null")
            .collect()
    };
    let kinds: BTreeSet<String> = enum_of(text, "kind")
        .into_iter()
        .chain(enum_of(vectorize, "kind"))
        .collect();
    assert_eq!(kinds, serde_names(JobKind::ALL));
    assert_eq!(enum_of(text, "method"), serde_names(Method::ALL));
    for props in [text, vectorize] {
        assert_eq!(enum_of(props, "style"), serde_names(&Style::ALL));
        assert_eq!(enum_of(props, "preset"), serde_names(Preset::ALL));
    }
    let statuses: BTreeSet<String> = spec
        .path(&["components", "schemas", "JobStatus", "enum"])
        .flow_list()
        .into_iter()
        .collect();
    assert_eq!(statuses, serde_names(&JobStatus::ALL));
    let stages: BTreeSet<String> = spec
        .path(&["components", "schemas", "Stage", "enum"])
        .flow_list()
        .into_iter()
        .collect();
    assert_eq!(stages, serde_names(&vectorfusion::progress::Stage::ALL));
    let limits = vectorfusion::pipeline::Limits::default();
    for props in [text, vectorize] {
        // documented defaults and bounds are the code's
        let num = |field: &str, key: &str| -> i64 {
            props
                .path(&[field, key])
                .value
                .as_deref()
                .unwrap()
                .parse()
                .unwrap()
        };
        // Omitted paths/steps/samples are the preset's: no fixed default may be documented.
        for f in vectorfusion::server::types::PRESET_FIELDS {
            assert!(
                props.path(&[f]).get("default").is_none(),
                "{f} has a documented default, but the preset decides"
            );
            let d = props.path(&[f, "description"]).value.clone().unwrap();
            assert!(d.contains("preset"), "{f}: {d}");
        }
        assert_eq!(
            props.path(&["preset", "default"]).value.as_deref(),
            Some(
                serde_names(&[Preset::default()])
                    .pop_first()
                    .unwrap()
                    .as_str()
            )
        );
        assert_eq!(num("paths", "maximum"), limits.max_paths as i64);
        assert_eq!(num("steps", "maximum"), limits.max_steps as i64);
        assert_eq!(num("samples", "maximum"), limits.max_samples as i64);
        assert_eq!(num("caption", "maxLength"), limits.max_caption_chars as i64);
        assert_eq!(
            num("priority", "minimum"),
            *vectorfusion::pipeline::PRIORITY_RANGE.start() as i64
        );
        assert_eq!(
            num("priority", "maximum"),
            *vectorfusion::pipeline::PRIORITY_RANGE.end() as i64
        );
    }
}

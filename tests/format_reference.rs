//! `scenes/FORMAT.md` against the serde types: its example loads (unknown fields are refused)
//! and runs, every field and variant the types write back out is documented, and every name
//! the reference's tables document is one the types write.

use std::collections::BTreeSet;
use std::path::Path;

use harmonic::prelude::*;

fn reference() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/FORMAT.md");
    std::fs::read_to_string(path).expect("scenes/FORMAT.md")
}

fn example(doc: &str) -> &str {
    let after = doc
        .split("## The example")
        .nth(1)
        .expect("an example section");
    let start = after.find("```ron").expect("a ron block") + "```ron".len();
    let end = after[start..].find("```").expect("a closed block");
    &after[start..start + end]
}

/// Lower-case identifiers followed by `:` (fields) and capitalised ones (variants) in RON text.
fn names(ron_text: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let (mut fields, mut variants) = (BTreeSet::new(), BTreeSet::new());
    let bytes = ron_text.as_bytes();
    let mut i = 0;
    let mut in_string = false;
    while i < bytes.len() {
        let c = bytes[i];
        if c == b'"' {
            in_string = !in_string;
            i += 1;
            continue;
        }
        if in_string || !(c.is_ascii_alphabetic() || c == b'_') {
            i += 1;
            continue;
        }
        let start = i;
        while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
            i += 1;
        }
        let word = &ron_text[start..i];
        let next = ron_text[i..].trim_start().chars().next();
        if word.chars().next().is_some_and(|c| c.is_ascii_uppercase()) {
            if !matches!(word, "Some" | "None") {
                variants.insert(word.to_string());
            }
        } else if next == Some(':') {
            fields.insert(word.to_string());
        }
    }
    (fields, variants)
}

#[test]
fn the_reference_example_loads_and_runs() {
    let doc = reference();
    let scene = Scene::parse(example(&doc), "scenes/FORMAT.md").unwrap_or_else(|e| panic!("{e}"));
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..10 {
        sim.step().unwrap();
    }
    assert!(sim.positions().iter().all(|x| x.is_finite()));
}

#[test]
fn every_field_the_types_write_is_documented_and_no_other() {
    let doc = reference();
    let scene = Scene::parse(example(&doc), "scenes/FORMAT.md").unwrap();
    // Written back out: every field of every type the example uses, defaults included.
    let written = ron::ser::to_string_pretty(&scene, ron::ser::PrettyConfig::new()).unwrap();
    let (fields, variants) = names(&written);
    assert!(fields.len() > 50, "only {} fields written", fields.len());
    let undocumented: Vec<_> = fields
        .iter()
        .chain(&variants)
        .filter(|n| !doc.contains(&format!("`{n}")))
        .collect();
    assert!(
        undocumented.is_empty(),
        "written by the serde types but not in scenes/FORMAT.md: {undocumented:?}"
    );
    // The names in the first column of the reference's tables are real.
    let mut documented = BTreeSet::new();
    for line in doc.lines().filter(|l| l.starts_with("| `")) {
        let first = line.split('|').nth(1).unwrap_or("");
        for part in first.split(',') {
            let name = part.trim().trim_matches('`');
            if !name.is_empty() {
                documented.insert(name.to_string());
            }
        }
    }
    let stale: Vec<_> = documented
        .iter()
        .filter(|n| !fields.contains(*n) && !variants.contains(*n))
        .collect();
    assert!(
        stale.is_empty(),
        "documented but not a field or variant: {stale:?}"
    );
}

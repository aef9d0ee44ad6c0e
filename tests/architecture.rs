//! ARCHITECTURE.md's crate table must list exactly the workspace members, with their names.

use std::collections::BTreeSet;

fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn architecture_crate_table_matches_the_workspace() {
    let arch = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let start = arch
        .find("<!-- crate-table:start -->")
        .expect("table start marker");
    let end = arch
        .find("<!-- crate-table:end -->")
        .expect("table end marker");
    let mut documented = BTreeSet::new();
    for line in arch[start..end].lines().filter(|l| l.starts_with("| `")) {
        let cols: Vec<&str> = line.split('|').map(str::trim).collect();
        let name = cols[1].trim_matches('`').to_string();
        let path = cols[2].trim_matches('`').trim_end_matches('/').to_string();
        documented.insert((name, path));
    }
    let cargo = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let members_start = cargo.find("members = [").expect("workspace members");
    let members_end = members_start + cargo[members_start..].find(']').unwrap();
    let mut actual = BTreeSet::new();
    for m in cargo[members_start..members_end]
        .split('"')
        .skip(1)
        .step_by(2)
    {
        let manifest = std::fs::read_to_string(root().join(m).join("Cargo.toml")).unwrap();
        let name = manifest
            .lines()
            .find_map(|l| l.strip_prefix("name = "))
            .unwrap()
            .trim_matches('"')
            .to_string();
        actual.insert((name, m.to_string()));
    }
    println!("documented {documented:?}\nworkspace  {actual:?}");
    assert_eq!(documented, actual);
}

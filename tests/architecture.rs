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

/// Issue 28: the renderer and the tasks reach deformables through the engine's solver-neutral
/// interface, so neither crate depends on a solver crate.
#[test]
fn render_and_tasks_depend_on_no_solver_crate() {
    for krate in ["plugins/render", "plugins/tasks"] {
        let toml = std::fs::read_to_string(root().join(krate).join("Cargo.toml")).unwrap();
        let solvers: Vec<&str> = toml
            .lines()
            .filter(|l| {
                l.trim_start().starts_with("modesuite-fem")
                    || l.trim_start().starts_with("modesuite-pbd")
            })
            .collect();
        println!("{krate}: solver dependencies {solvers:?} (want none)");
        assert!(solvers.is_empty(), "{krate} depends on {solvers:?}");
    }
}

struct Dupes;

impl modesuite::engine::Plugin for Dupes {
    fn name(&self) -> &str {
        "test.dupes"
    }
    fn build(&self, app: &mut modesuite::engine::SimApp) {
        // the tasks plugin already registered both
        app.register_section(modesuite::tasks::TaskSection);
        let place = app
            .world
            .resource::<modesuite::tasks::Experts>()
            .0
            .get("place")
            .cloned()
            .unwrap();
        modesuite::tasks::register_expert(app, place);
    }
}

/// A name registered twice (a scene section, an expert) is refused, the plugin is named, the
/// first registration stays, and the app compiles no scene until the clash is fixed.
#[test]
fn a_name_registered_twice_is_refused_and_named() {
    let mut app = modesuite::make::default_app();
    assert_eq!(app.setup_errors(), &[] as &[String]);
    let sections = app.registry().sections.len();
    app.add_plugins(Dupes);
    let errors = app.setup_errors().to_vec();
    println!("{errors:#?}");
    assert_eq!(errors.len(), 2, "{errors:?}");
    assert!(
        errors[0]
            .starts_with("plugin \"test.dupes\": scene section \"task\" is already registered"),
        "{}",
        errors[0]
    );
    assert!(
        errors[1].starts_with("plugin \"test.dupes\": expert \"place\" is already registered"),
        "{}",
        errors[1]
    );
    assert_eq!(app.registry().sections.len(), sections);
    let (desc, source) = modesuite::make::load_target("MoDe-Franka-Place-v0").unwrap();
    let e = app.compile_scene(&desc, &source).err().expect("refused");
    println!("compile: {e}");
    assert!(e.to_string().contains("already registered"), "{e}");
}

//! The states a killed writer can leave (files of an uncommitted episode: its data file, an
//! episodes file with one row too many, a partial temporary file), built deterministically:
//! readers see exactly the committed episodes, and the next writer removes the leftovers and
//! appends as if the kill had not happened.

use std::path::PathBuf;

use modesuite_dataset::{Column, Dataset, DatasetWriter, EpisodeInput, Feature, Features, Info};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("modesuite-ds-crash-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn info() -> Info {
    let names: Vec<String> = ["a", "b"].iter().map(|s| s.to_string()).collect();
    Info::new(
        10,
        None,
        Features::with_defaults(vec![
            ("observation.state".into(), Feature::f32(&names)),
            ("next.done".into(), Feature::scalar("bool")),
        ]),
    )
}

fn episode(len: usize, seed: u64) -> EpisodeInput {
    EpisodeInput {
        task: "test".into(),
        columns: vec![
            (
                "observation.state".into(),
                Column::F32 {
                    dim: 2,
                    values: (0..2 * len).map(|i| (i as u64 + seed) as f32).collect(),
                },
            ),
            (
                "next.done".into(),
                Column::Bool((0..len).map(|i| i + 1 == len).collect()),
            ),
        ],
        videos: Vec::new(),
        seed,
        success: Some(seed.is_multiple_of(2)),
    }
}

#[test]
fn leftovers_of_a_killed_append_are_ignored_then_removed() {
    let dir = scratch("left");
    let extra = serde_json::json!({"target": "test"});
    let mut w = DatasetWriter::open_or_create(&dir, info(), &extra).unwrap();
    w.append(episode(5, 1)).unwrap();
    w.append(episode(7, 2)).unwrap();
    // a kill just before the commit of episode 2: every file of it written but info.json
    let committed = std::fs::read(dir.join("meta/info.json")).unwrap();
    w.append(episode(4, 3)).unwrap();
    std::fs::write(dir.join("meta/info.json"), &committed).unwrap();
    // and a temporary file of an atomic write cut short
    let partial = dir.join("meta/episodes/chunk-000/.file-000.parquet.999.partial");
    std::fs::write(&partial, b"half").unwrap();
    drop(w);
    let ds = Dataset::open(&dir).unwrap();
    assert_eq!(
        (
            ds.info.total_episodes,
            ds.episodes.len(),
            ds.info.total_frames
        ),
        (2, 2, 12)
    );
    let mut orphans: Vec<String> = ds
        .orphans
        .iter()
        .map(|p| p.strip_prefix(&dir).unwrap().display().to_string())
        .collect();
    orphans.sort();
    println!("orphans: {orphans:?}");
    assert_eq!(
        orphans,
        [
            "data/chunk-000/file-002.parquet",
            "meta/episodes/chunk-000/.file-000.parquet.999.partial"
        ]
    );
    let cols = ds.read_episode(1).unwrap();
    assert_eq!(cols[0].1.rows(), 7);
    // the next writer deletes them and appends episode 2 anew
    let mut w = DatasetWriter::open_or_create(&dir, info(), &extra).unwrap();
    assert_eq!(w.append(episode(3, 9)).unwrap(), 2);
    let ds = Dataset::open(&dir).unwrap();
    assert!(ds.orphans.is_empty(), "{:?}", ds.orphans);
    assert_eq!((ds.info.total_episodes, ds.info.total_frames), (3, 15));
    assert_eq!(
        (
            ds.episodes[2].seed,
            ds.episodes[2].from_index,
            ds.episodes[2].to_index
        ),
        (9, 12, 15)
    );
    let Column::I64(index) = &ds.read_episode(2).unwrap()[5].1 else {
        panic!("index")
    };
    assert_eq!(index, &[12, 13, 14]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_episodes_and_foreign_folders_are_refused_and_change_nothing() {
    let dir = scratch("bad");
    let mut w = DatasetWriter::open_or_create(&dir, info(), &serde_json::Value::Null).unwrap();
    w.append(episode(5, 1)).unwrap();
    let before = std::fs::read(dir.join("meta/info.json")).unwrap();
    let mut wrong = episode(5, 2);
    wrong.columns[0].1 = Column::F32 {
        dim: 3,
        values: vec![0.0; 15],
    };
    let e = w.append(wrong).unwrap_err();
    println!("{e}");
    assert!(e.to_string().contains("observation.state"), "{e}");
    let mut empty = episode(1, 2);
    for (_, c) in &mut empty.columns {
        *c = match c {
            Column::F32 { dim, .. } => Column::F32 {
                dim: *dim,
                values: vec![],
            },
            _ => Column::Bool(vec![]),
        };
    }
    assert!(w
        .append(empty)
        .unwrap_err()
        .to_string()
        .contains("at least one frame"));
    assert_eq!(std::fs::read(dir.join("meta/info.json")).unwrap(), before);
    assert!(Dataset::open(&dir).unwrap().orphans.is_empty());
    let mut other = info();
    other.fps = 20;
    let e = DatasetWriter::open_or_create(&dir, other, &serde_json::Value::Null)
        .err()
        .unwrap();
    assert!(e.to_string().contains("other features or fps"), "{e}");
    std::fs::write(
        dir.join("meta/info.json"),
        b"{\"codebase_version\": \"v2.1\"",
    )
    .unwrap();
    let e = Dataset::open(&dir).unwrap_err();
    println!("{e}");
    assert!(e.to_string().contains("info.json:1:"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

"""Datasets recorded by `modesuite record` read with pyarrow and pandas as LeRobot v3.0 reads
them (issue 31, point 1): required features, contiguous indices, totals, timestamps, the tasks
table's pandas index, and one video frame per data row."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

TASK = "MoDe-Franka-Place-v0"
DEFAULTS = [
    ("timestamp", "float32"),
    ("frame_index", "int64"),
    ("episode_index", "int64"),
    ("index", "int64"),
    ("task_index", "int64"),
]


@pytest.fixture(scope="module")
def dataset(modesuite_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ds") / "place"
    cmd = [str(modesuite_bin), "record", TASK, "--episodes", "3", "--seed", "5", "--noise",
           "0.05", "--steps", "60", "--cameras", "robot", "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out


def test_info_and_features(dataset: Path) -> None:
    info = json.loads((dataset / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0"
    assert info["total_episodes"] == 3 and info["splits"] == {"train": "0:3"}
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    names = list(info["features"])
    assert names[-5:] == [n for n, _ in DEFAULTS], names
    for n, dtype in DEFAULTS:
        assert info["features"][n] == {"dtype": dtype, "shape": [1], "names": None}
    video = info["features"]["observation.images.robot"]
    assert video["dtype"] == "video" and video["names"] == ["height", "width", "channels"]
    assert video["info"]["video.codec"] == "h264" and video["info"]["video.fps"] == info["fps"]
    for n in ("observation.state", "action", "next.reward", "next.done", "next.success"):
        assert n in info["features"]


def test_data_files_follow_lerobot_rules(dataset: Path) -> None:
    info = json.loads((dataset / "meta/info.json").read_text())
    files = sorted(dataset.glob("data/*/*.parquet"))  # every file, as LeRobot's loader reads
    table = pa.concat_tables([pq.read_table(f) for f in files])
    data_features = [n for n, f in info["features"].items() if f["dtype"] != "video"]
    assert table.column_names == data_features
    assert table.num_rows == info["total_frames"]
    state = table.schema.field("observation.state").type
    assert pa.types.is_fixed_size_list(state) and state.value_type == pa.float32()
    assert state.list_size == info["features"]["observation.state"]["shape"][0]
    for n, dtype in DEFAULTS:
        assert str(table.schema.field(n).type) == {"float32": "float", "int64": "int64"}[dtype]
    index = table["index"].to_numpy()
    assert np.array_equal(index, np.arange(info["total_frames"]))
    fi = table["frame_index"].to_numpy()
    ts = table["timestamp"].to_numpy()
    assert np.array_equal(ts, (fi / info["fps"]).astype(np.float32))
    episodes = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert [e["episode_index"] for e in episodes] == [0, 1, 2]
    ep = table["episode_index"].to_numpy()
    for e in episodes:
        rows = np.flatnonzero(ep == e["episode_index"])
        assert rows[0] == e["dataset_from_index"] and rows[-1] + 1 == e["dataset_to_index"]
        assert len(rows) == e["length"] and np.array_equal(fi[rows], np.arange(e["length"]))
        assert e["tasks"] == ["Place the free end of the foam rod on the table."]
        assert e["videos/observation.images.robot/from_timestamp"] == 0.0
        assert e["stats/action/count"] == [e["length"]]
    print(f"{len(files)} data files, {table.num_rows} rows, episode lengths "
          f"{[e['length'] for e in episodes]}, seeds {[e['modesuite/seed'] for e in episodes]}")


def test_tasks_table_reads_as_lerobot_does(dataset: Path) -> None:
    tasks = pd.read_parquet(dataset / "meta/tasks.parquet")
    task = "Place the free end of the foam rod on the table."
    assert tasks.index.name == "task" and list(tasks.columns) == ["task_index"]
    assert task in tasks.index and int(tasks.loc[task].task_index) == 0
    assert tasks.iloc[0].name == task


def test_stats_cover_every_feature(dataset: Path) -> None:
    info = json.loads((dataset / "meta/info.json").read_text())
    stats = json.loads((dataset / "meta/stats.json").read_text())
    assert set(stats) == set(info["features"])
    keys = {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}
    for name, s in stats.items():
        assert set(s) == keys, name
        assert s["count"][0] > 0
    assert np.asarray(stats["observation.images.robot"]["mean"]).shape == (3, 1, 1)
    table = pq.read_table(sorted(dataset.glob("data/*/*.parquet")))
    action = np.stack(table["action"].to_numpy(zero_copy_only=False))
    assert np.allclose(stats["action"]["min"], action.min(axis=0))
    assert np.allclose(stats["action"]["mean"], action.mean(axis=0))
    assert np.allclose(stats["action"]["q50"], np.quantile(action, 0.5, axis=0), atol=0.05)


def test_one_video_frame_per_row(dataset: Path) -> None:
    episodes = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    for e in episodes:
        c = e["videos/observation.images.robot/chunk_index"]
        f = e["videos/observation.images.robot/file_index"]
        mp4 = dataset / f"videos/observation.images.robot/chunk-{c:03d}/file-{f:03d}.mp4"
        out = subprocess.run(
            ["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
             "stream=nb_read_frames,width,height", "-of", "json", str(mp4)],
            check=True, capture_output=True, text=True,
        )
        stream = json.loads(out.stdout)["streams"][0]
        assert int(stream["nb_read_frames"]) == e["length"], (mp4, stream)
        assert (stream["width"], stream["height"]) == (128, 128)


def test_a_policy_of_action_chunks_from_the_dataset_in_python(
    dataset: Path, modesuite_bin: Path, tmp_path: Path
) -> None:
    """`train --algo bc --set chunk=3` on the recording, loaded with `modesuite.Policy`: its
    `chunk`, `act_chunk` (3 actions per observation, in bounds) and `act` (each chunk's first)."""
    import modesuite

    out = tmp_path / "bc3"
    cmd = [str(modesuite_bin), "train", TASK, "--algo", "bc", "--dataset", str(dataset),
           "--out", str(out), "--set", "epochs=20", "--set", "chunk=3"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    policy = modesuite.Policy(out)
    assert (policy.algo, policy.chunk) == ("bc", 3)
    obs = np.random.default_rng(0).normal(size=(4, policy.obs_dim))
    chunks = policy.act_chunk(obs)
    assert chunks.shape == (4, 3, policy.act_dim) and chunks.dtype == np.float32
    assert np.all(np.abs(chunks) <= 1.0 + 1e-6)  # Franka Place's EE-delta bounds are +-1
    assert np.array_equal(policy.act(obs), chunks[:, 0, :])
    assert policy.act_chunk(obs[2]).shape == (3, policy.act_dim)
    assert not np.array_equal(chunks[:, 0, :], chunks[:, 2, :])
    assert policy.ensemble is None
    # with ACT's temporal ensembling: the exponent is the policy's; act stays the raw first action
    out = tmp_path / "bc3e"
    cmd = [str(modesuite_bin), "train", TASK, "--algo", "bc", "--dataset", str(dataset),
           "--out", str(out), "--set", "epochs=20", "--set", "chunk=3", "--set", "ensemble=0.01"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    ens = modesuite.Policy(out)
    assert (ens.chunk, ens.ensemble) == (3, 0.01)
    assert np.array_equal(ens.act(obs), chunks[:, 0, :])  # same data, seed and network
    # played one step at a time as `modesuite eval` plays them: open-loop chunks ignore the
    # observations between looks; ensembled ones average every chunk's prediction for the step
    player = modesuite.PolicyPlayer(policy)
    played = [player.act(obs[t]) for t in range(4)]
    assert np.array_equal(np.stack(played[:3]), chunks[0]) and np.array_equal(played[3], chunks[3, 0])
    player.reset()
    assert np.array_equal(player.act(obs[1]), chunks[1, 0])
    eplayer = modesuite.PolicyPlayer(ens)
    first, second = eplayer.act(obs[0]), eplayer.act(obs[1])
    assert np.array_equal(first, chunks[0, 0])
    w = np.exp(0.01)  # the prediction made one step earlier weighs exp(M * 1)
    want = (w * chunks[0, 1].astype(np.float64) + chunks[1, 0]) / (w + 1.0)
    assert np.allclose(second, want, rtol=1e-6, atol=1e-7), (second, want)
    with pytest.raises(ValueError, match="one observation"):
        eplayer.act(obs)

"""Hostile model files: every one is refused in one line, before anything large is inflated or
built (issue: hardening)."""

import io
import json
import resource
import zipfile
from pathlib import Path

import numpy as np
import pytest

from planner.learned import load_agent
from planner.model_file import FORMAT, ModelFileError, load_model, save_model


def npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def metadata_bytes(metadata: object) -> bytes:
    return npy(np.frombuffer(json.dumps(metadata).encode(), dtype=np.uint8))


PLAIN_MLP = Path(__file__).parents[1] / "configs" / "train" / "ddqn-stage4.npz"
"""A Double DQN on a plain MLP (arrays `0.weight`, ...): the former shipped model, now a teacher."""


def plain_mlp() -> tuple[dict[str, np.ndarray], dict]:
    return load_model(PLAIN_MLP)


def write(path, members: dict[str, bytes], compression=zipfile.ZIP_DEFLATED) -> None:
    with zipfile.ZipFile(path, "w", compression) as archive:
        for name, data in members.items():
            archive.writestr(name, data)


def with_metadata(path, **changes) -> None:
    arrays, metadata = plain_mlp()
    save_model(path, arrays, {**metadata, **changes})


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def test_a_member_that_inflates_beyond_the_limit_is_refused_before_inflating(tmp_path):
    bomb = tmp_path / "bomb.npz"
    write(
        bomb, {"metadata.npy": metadata_bytes({"format": FORMAT}), "array/q.npy": npy(np.zeros(12_000_000))}
    )
    assert bomb.stat().st_size < 1_000_000
    before = peak_rss_mb()
    with pytest.raises(ModelFileError, match="MB when unpacked; at most 64 MB"):
        load_agent(bomb)
    assert peak_rss_mb() - before < 50


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"hidden": [4_000_000]}, "hidden: expected at most 8 layer widths in 1..4096"),
        ({"actions": 5}, r"actions: the loop commands LEFT, STAY, RIGHT \(3\), not 5"),
        ({"encoding": "telepathy"}, "encoding: expected one of"),
        ({"kind": "forest"}, "kind: expected 'mlp', 'lane-mlp' or 'qtable'"),
        ({"observation_size": 10**9}, "observation_size: expected an integer"),
        ({"observation_size": True}, "observation_size: expected an integer"),
        ({"hidden": [True]}, "hidden: expected at most 8 layer widths"),
        ({"kind": "lane-mlp"}, "model arrays do not match its metadata"),
        ({"grid": {"cells_ahead": 10**8}}, "grid.cells_ahead: Input should be less than or equal to 200"),
        ({"observation_size": 50}, "model arrays do not match its metadata"),
        ({"mobil_prior": "lots"}, "mobil_prior: expected a number"),
        ({"mobil_prior": -0.5}, r"mobil_prior: expected a bonus in 0..10 reward units, got -0.5"),
        ({"mobil_prior": 1e308 * 10}, "mobil_prior: expected a number"),
        ({"mobil_prior": 0.4, "encoding": "paper"}, "mobil_prior: MOBIL needs the observation encoding"),
    ],
)
def test_metadata_the_loop_cannot_use_is_refused_before_building(tmp_path, changes, message):
    path = tmp_path / "crafted.npz"
    with_metadata(path, **changes)
    with pytest.raises(ModelFileError, match=message) as error:
        load_agent(path)
    assert "\n" not in str(error.value) and len(str(error.value)) <= 300


@pytest.mark.parametrize("metadata", [[1, 2], None, "text", 3.5])
def test_metadata_that_is_not_an_object_is_refused(tmp_path, metadata):
    path = tmp_path / "odd.npz"
    write(path, {"metadata.npy": metadata_bytes(metadata)})
    with pytest.raises(ModelFileError, match="metadata must be a JSON object|unsupported model format"):
        load_agent(path)


def test_deeply_nested_metadata_and_corrupt_members_end_in_one_line(tmp_path):
    nested = tmp_path / "nested.npz"
    deep = b"[" * 100_000 + b"]" * 100_000
    write(nested, {"metadata.npy": npy(np.frombuffer(deep, dtype=np.uint8))})
    with pytest.raises(ModelFileError, match="not valid JSON"):
        load_agent(nested)
    corrupt = tmp_path / "corrupt.npz"
    write(corrupt, {"metadata.npy": metadata_bytes({"format": FORMAT}) * 50})
    raw = bytearray(corrupt.read_bytes())
    raw[60:90] = b"\x00" * 30
    corrupt.write_bytes(bytes(raw))
    with pytest.raises(ModelFileError, match="not a drivestack model file"):
        load_agent(corrupt)
    bare = tmp_path / "bare.npz"
    bare.write_bytes(npy(np.zeros(3)))
    with pytest.raises(ModelFileError, match="not a drivestack model file"):
        load_agent(bare)


def test_a_header_claiming_more_than_the_member_holds_is_refused(tmp_path):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
    path = tmp_path / "liar.npz"
    write(
        path,
        {"metadata.npy": metadata_bytes({"format": FORMAT}), "array/q.npy": header.getvalue() + b"\0" * 64},
    )
    with pytest.raises(ModelFileError, match="declares"):
        load_agent(path)


def test_nan_weights_are_refused(tmp_path):
    arrays, metadata = plain_mlp()
    arrays["0.weight"] = arrays["0.weight"].copy()
    arrays["0.weight"][0, 0] = np.nan
    path = save_model(tmp_path / "nan.npz", arrays, metadata)
    with pytest.raises(ModelFileError, match="array '0.weight' holds NaN or infinite values"):
        load_agent(path)


def test_encrypted_or_oddly_compressed_members_are_refused(tmp_path):
    path = tmp_path / "encrypted.npz"
    with_metadata(path)
    raw = bytearray(path.read_bytes())
    local = raw.find(b"PK\x03\x04")
    central = raw.find(b"PK\x01\x02")
    raw[local + 6] |= 0x1
    raw[central + 8] |= 0x1
    path.write_bytes(bytes(raw))
    with pytest.raises(ModelFileError, match="encrypted or compressed in an unknown way"):
        load_agent(path)


def test_a_model_that_does_not_fit_the_road_is_refused_alike_everywhere(tmp_path):
    """A model on the paper's state (every road lane, binary lane code) sized for 4 lanes, on a
    2-lane road: `run` (from the metadata, before torch), the agent as built, `train.init_model`
    and `export` (the file says 2 lanes) refuse it with the one message of `check_road_fit`."""
    from typer.testing import CliRunner

    from perception.grid import OccupancyGridBuilder
    from records import GridConfig
    from stack.apps.cli import app
    from stack.apps.export import export_sb3
    from stack.runs.kept import build_agent
    from stack.settings.run import build_config
    from stack.training.model import initial_model
    from tests.test_cli import tiny_config_file

    arrays, metadata = plain_mlp()
    grid = {**metadata["grid"], "lanes": "absolute", "lane_code": "binary", "features": []}
    builder = OccupancyGridBuilder(GridConfig(**grid))
    size, given = (int(builder.space("observation", lanes).shape[0]) for lanes in (4, 2))
    arrays["0.weight"] = np.zeros((arrays["0.weight"].shape[0], size), dtype=arrays["0.weight"].dtype)
    model = tmp_path / "paper-4-lanes.npz"
    metadata.pop("mobil_prior", None)  # MOBIL cannot read the paper's state
    save_model(model, arrays, {**metadata, "grid": grid, "observation_size": size, "lanes_count": 2})
    expected = (
        f"{model}: expects observations of {size} values; its observation grid gives {given} "
        "on this 2-lane road"
    )

    options = ["--agent", "ddqn", "--model", str(model), "--set", "highway.lanes_count=2"]
    config = str(tiny_config_file(tmp_path))
    result = CliRunner().invoke(app, ["run", "-c", config, *options, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and result.output.strip().endswith(expected), result.output
    road = {"highway": {"lanes_count": 2}, "perception": grid}
    with pytest.raises(ModelFileError) as built:
        build_agent(build_config({**road, "planner": {"agent": "ddqn", "model": str(model)}}), 0)
    train = {"init_model": str(model), "network": metadata["network"], "encoding": "observation"}
    with pytest.raises(ModelFileError) as started:
        initial_model(build_config({**road, "train": train}))
    with pytest.raises(ModelFileError) as exported:
        export_sb3(model, tmp_path / "sb3.zip")
    refusals = [str(built.value), str(started.value), str(exported.value)]
    assert refusals == [expected, f"train.init_model: {expected}", expected]

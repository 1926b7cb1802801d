"""`method=onnx`: an ONNX policy scored by the harness. The exported DGNN reproduces `method=dgnn`'s results; a model
of the PettingZoo form's flat observation drives robots; bad models are refused naming `method.model`."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import job_dirs
from stafpipe.launch import launch

onnx = pytest.importorskip("onnx")  # the `onnx` extra (installed with `test`)
pytest.importorskip("onnxruntime")

OPEN_MAP = "world: {xmin: 0, ymin: -4, xmax: 12, ymax: 4}\nteam: {n: 4, formation: line, start: [2, 0], goal: [9, 0]}\n"


def _results(workdir, overrides: list[str]) -> pd.DataFrame:
    before = set(job_dirs(workdir / "outputs" / "eval")) if (workdir / "outputs" / "eval").exists() else set()
    assert launch("eval", overrides) == 0
    [run] = set(job_dirs(workdir / "outputs" / "eval")) - before
    return pd.read_parquet(run / "results.parquet")


def _go_to_goal_model(path) -> None:
    """A policy of the flat observation (n, F + n (E + 1)): twice the robot-frame goal vector (own[:, 0:2]), clipped."""
    from onnx import TensorProto, helper

    const = lambda name, values, kind=TensorProto.INT64: helper.make_tensor(name, kind, [len(values)], values)  # noqa: E731
    graph = helper.make_graph(
        [
            helper.make_node("Slice", ["obs", "starts", "ends", "axes"], ["goal"]),
            helper.make_node("Mul", ["goal", "gain"], ["scaled"]),
            helper.make_node("Clip", ["scaled", "lo", "hi"], ["action"]),
        ],
        "go_to_goal",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["robots", "width"])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["robots", 2])],
        [
            const("starts", [0]),
            const("ends", [2]),
            const("axes", [1]),
            helper.make_tensor("gain", TensorProto.FLOAT, [], [2.0]),
            helper.make_tensor("lo", TensorProto.FLOAT, [], [-1.0]),
            helper.make_tensor("hi", TensorProto.FLOAT, [], [1.0]),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


@pytest.mark.slow  # an export and two evals: about 15 s
def test_the_exported_dgnn_reproduces_method_dgnn(workdir) -> None:
    from stafpipe.export_onnx import export

    model = export("dgnn", "", workdir / "dgnn.onnx")
    common = ["scenario=corridor", "formation=wedge", "eval.episodes=2", "scenario.time_limit=12"]
    torch_run = _results(workdir, ["method=dgnn", *common])
    onnx_run = _results(workdir, ["method=onnx", f"method.model={model}", *common])
    assert list(onnx_run["method"].unique()) == ["onnx"]
    for column in ("seed", "sr", "tt", "collisions"):
        assert onnx_run[column].equals(torch_run[column]), column
    for column in ("cfi_0.5", "cfi_0.1"):
        np.testing.assert_allclose(onnx_run[column], torch_run[column], atol=1e-6)
    assert torch_run["cfi_0.5"].gt(0).all()  # the episodes did something to compare


@pytest.mark.slow  # one 7-m episode through onnxruntime: about 6 s
def test_a_flat_observation_model_drives_the_robots_to_their_goals(workdir) -> None:
    from stafpipe.episode_log import read_episode

    _go_to_goal_model(workdir / "go.onnx")
    (workdir / "open.yaml").write_text(OPEN_MAP)
    model, scenario = f"method.model={workdir / 'go.onnx'}", f"scenario.path={workdir / 'open.yaml'}"
    assert launch("eval", ["method=onnx", model, scenario, "eval.episodes=1"]) == 0
    [log] = (workdir / "outputs" / "eval").glob("*/*/episodes/episode_0000.mcap")
    rec = read_episode(log)
    start, end = (np.linalg.norm(rec.positions[k] - rec.goal, axis=1) for k in (0, -1))
    assert start.min() > 6.5 and end.max() < 0.3  # every robot went the 7 m to its goal slot (it ignores the others)


def test_bad_models_are_refused_naming_the_key(workdir, capsys) -> None:
    (workdir / "junk.onnx").write_bytes(b"not a model")
    from onnx import TensorProto, helper

    two = helper.make_graph(
        [helper.make_node("Add", ["a", "b"], ["action"])],
        "two_inputs",
        [helper.make_tensor_value_info(x, TensorProto.FLOAT, ["robots", 2]) for x in "ab"],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["robots", 2])],
    )
    onnx.save(helper.make_model(two, opset_imports=[helper.make_opsetid("", 18)]), str(workdir / "two.onnx"))
    for model, says in (
        ("", "method.model is required"),
        (str(workdir / "none.onnx"), "method.model must name an existing file"),
        (str(workdir / "junk.onnx"), "is not an ONNX model onnxruntime can load"),
        (str(workdir / "two.onnx"), "takes inputs ['a', 'b']; expected own, edge, mask"),
    ):
        code = launch("eval", ["method=onnx", f"method.model='{model}'", "scenario=corridor", "eval.episodes=1"])
        assert code == 2 and says in capsys.readouterr().err, model
    assert not (workdir / "outputs" / "eval").exists() or not job_dirs(workdir / "outputs" / "eval")

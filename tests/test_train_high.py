"""`stafpipe train-high`: deterministic per seed, resumable after a kill, clear errors for bad data."""

from __future__ import annotations

import pandas as pd
import pytest
import torch

import stafpipe.highlevel.training as training
from conftest import job_dirs, tensorboard_scalars
from stafpipe.config.schema import DataConfig, FormationConfig
from stafpipe.highlevel.checkpoint import load_checkpoint
from stafpipe.highlevel.config import HighLevelConfig, TrainHighConfig
from stafpipe.highlevel.graphs import team_graph, teams_from_frame
from stafpipe.highlevel.instances import generate_instances
from stafpipe.launch import launch

TINY = ["data.instances=48", "train_high.epochs=2", "train_high.batch_size=16"]


def _graphs():
    df = generate_instances(DataConfig(instances=40, n_min=4, n_max=8), FormationConfig(), 0)
    return [team_graph(t, HighLevelConfig().features, 2.0) for t in teams_from_frame(df, 2)]


def _weights(model):
    return [p.detach().clone() for p in model.parameters()]


@pytest.mark.slow  # over 10 s on 2 cores
def test_training_is_deterministic_and_resumes_to_the_same_weights(tmp_path, monkeypatch) -> None:
    tc = TrainHighConfig(epochs=3, batch_size=8)
    graphs = _graphs()
    full, hist = training.train(graphs, HighLevelConfig(), tc, 5, tmp_path / "a", "h", {})
    again, _ = training.train(graphs, HighLevelConfig(), tc, 5, tmp_path / "b", "h", {})
    assert all(torch.equal(x, y) for x, y in zip(_weights(full), _weights(again), strict=True))
    assert len(hist) == 3 and hist[-1]["train_total"] < hist[0]["train_total"]

    def killed(epoch: int) -> None:
        if epoch == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(training, "after_epoch", killed)
    with pytest.raises(KeyboardInterrupt):
        training.train(graphs, HighLevelConfig(), tc, 5, tmp_path / "c", "h", {})
    assert not (tmp_path / "c" / "high_level.pt").exists() and (tmp_path / "c" / "last.pt").exists()
    monkeypatch.setattr(training, "after_epoch", lambda epoch: None)
    resumed, rhist = training.train(graphs, HighLevelConfig(), tc, 5, tmp_path / "c", "h", {})
    assert [r["epoch"] for r in rhist] == [1, 2, 3] and rhist == hist
    assert all(torch.equal(x, y) for x, y in zip(_weights(full), _weights(resumed), strict=True))


def test_train_high_stage_writes_checkpoint_losses_and_curves(workdir) -> None:
    assert launch("train-high", [*TINY, "seed=2"]) == 0
    [run] = job_dirs(workdir)
    losses = pd.read_parquet(run / "losses.parquet")
    assert list(losses.epoch) == [1, 2] and {"train_adjacency", "val_balance", "val_goal"} <= set(losses.columns)
    _model, made_by = load_checkpoint(run / "high_level.pt")
    assert made_by["seed"] == 2 and made_by["train_high"]["epochs"] == 2 and made_by["teams"] == 48
    assert (run / "loss_curves.png").stat().st_size > 0
    board = tensorboard_scalars(run)
    assert {"train/total", "train/adjacency", "val/balance", "val/goal"} <= set(board)
    want = [(1, pytest.approx(losses.train_total[0])), (2, pytest.approx(losses.train_total[1]))]
    assert board["train/total"] == want


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_train_high_on_a_generated_file_and_bad_inputs(workdir) -> None:
    assert launch("generate", ["data.instances=32", "hydra.run.dir=gen"]) == 0
    assert launch("train-high", [*TINY, "train_high.data=gen"]) == 0
    (workdir / "bad.csv").write_text("instance,robot,x\n0,0,1.0\n")
    assert launch("train-high", [*TINY, "train_high.data=bad.csv"]) == 2
    assert launch("train-high", [*TINY, "train_high.data=nowhere.parquet"]) == 2
    assert launch("train-high", [*TINY, "train_high.m_choices=[2,7]"]) == 2
    assert len(job_dirs(workdir / "outputs")) == 1


def test_a_resumed_run_keeps_one_event_file_with_each_step_once(tmp_path) -> None:
    """A killed training leaves its event file; the resumed session replaces it by one file holding the whole
    history (the rows it took over and its own), so TensorBoard shows each step once."""
    from stafpipe.tensorboard_log import TB_DIR, ScalarLog

    rows = [{"epoch": k, "train_total": 1.0 / k} for k in (1, 2, 3)]
    first = ScalarLog(tmp_path, "epoch")
    first.sync(rows[:1])
    first.sync(rows[:2])
    first.close()  # killed after epoch 2: its file stays behind
    resumed = ScalarLog(tmp_path, "epoch")
    resumed.sync(rows)
    resumed.close()
    assert len(list((tmp_path / TB_DIR).glob("events.out.tfevents.*"))) == 1
    assert tensorboard_scalars(tmp_path)["train/total"] == [(k, pytest.approx(1.0 / k)) for k in (1, 2, 3)]

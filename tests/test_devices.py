"""train-high and train-ppo on a device: CPU by default, CUDA when asked and present, a clear error when absent."""

import pytest
import torch

from conftest import job_dirs
from stafpipe.highlevel.checkpoint import load_checkpoint
from stafpipe.launch import launch
from stafpipe.learning.checkpoint import load_policy

HIGH = ["train_high.epochs=2", "data.instances=40", "data.n_max=6"]
PPO = ["train_ppo.iterations=2", "train_ppo.worlds=2", "train_ppo.episode_steps=8", "train_ppo.policy.hidden=16"]
no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


@no_cuda
@pytest.mark.parametrize(
    ("stage", "overrides", "key"), [("train-high", HIGH, "train_high"), ("train-ppo", PPO, "train_ppo")]
)
def test_asking_for_cuda_without_one_is_a_clear_error(workdir, capsys, stage, overrides, key) -> None:
    assert launch(stage, [*overrides, f"{key}.device=cuda"]) == 2
    err = capsys.readouterr().err
    assert f"{key}.device" in err and "no usable CUDA device" in err and "Traceback" not in err
    assert job_dirs(workdir) == [] and list(workdir.rglob(".hydra")) == []  # refused before any work


@pytest.mark.parametrize(("stage", "key"), [("train-high", "train_high"), ("train-ppo", "train_ppo")])
def test_a_malformed_device_is_refused_before_any_work(workdir, capsys, stage, key) -> None:
    assert launch(stage, [f"{key}.device=gpu"]) == 2
    assert f"{key}.device must be cpu, cuda or cuda:N" in capsys.readouterr().err


@needs_cuda
def test_training_on_cuda_writes_checkpoints_for_the_cpu(workdir) -> None:
    assert launch("train-high", [*HIGH, "train_high.device=cuda"]) == 0
    assert launch("train-ppo", [*PPO, "train_ppo.device=cuda"]) == 0
    high, ppo = sorted(job_dirs(workdir), key=lambda d: (d / "high_level.pt").is_file(), reverse=True)
    model, made_by = load_checkpoint(high / "high_level.pt")
    assert made_by["train_high"]["device"] == "cuda"
    assert all(p.device.type == "cpu" for p in model.parameters())
    policy, _made_by = load_policy(str(ppo / "policy.pt"), "dgnn")
    assert all(p.device.type == "cpu" for p in policy.parameters())


@needs_cuda
def test_staf_training_on_cuda_matches_the_cpu_within_float_rounding(workdir) -> None:
    """STAF's network (the pair map, the warm start on the CPU, then PPO's update on the GPU) trains there and comes
    back to the CPU, and its weights are the CPU run's to float rounding: the same samples, the same steps."""
    planned = [*PPO, "train_ppo.method=staf_planned", "train_ppo.imitation.epochs=1", "train_ppo.imitation.rollouts=1"]
    assert launch("train-ppo", [*planned, "train_ppo.device=cpu"]) == 0
    assert launch("train-ppo", [*planned, "train_ppo.device=cuda"]) == 0
    runs = {load_policy(str(d / "policy.pt"), "staf_planned")[1]["train_ppo"]["device"]: d for d in job_dirs(workdir)}
    on_cpu, _ = load_policy(str(runs["cpu"] / "policy.pt"), "staf_planned")
    on_gpu, _ = load_policy(str(runs["cuda"] / "policy.pt"), "staf_planned")
    for (name, a), b in zip(on_cpu.state_dict().items(), on_gpu.state_dict().values(), strict=True):
        assert b.device.type == "cpu"
        assert torch.allclose(a, b, rtol=1e-3, atol=1e-4), name

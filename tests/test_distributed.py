"""Distributed PPO (`train_ppo.workers`, learning/distributed.py): two local workers through torch.distributed's
elastic launcher train, survive a SIGKILL by resuming, and repeat their result exactly."""

from __future__ import annotations

import subprocess
import sys
import time

import pandas as pd
import pytest
import torch

from stafpipe.launch import launch
from stafpipe.learning.ppo import STATE_FILE

WORDS = [
    "train_ppo.workers=2",
    "train_ppo.threads=1",
    "train_ppo.worlds=4",
    "train_ppo.episode_steps=30",
    "train_ppo.iterations=4",
    "train_ppo.checkpoint_every=1",
    "train_ppo.eval_every=2",
    "train_ppo.policy.hidden=16",
    "train_ppo.formations=[line]",  # one map to find the way through, in every worker
    # the warm start on worker 0 and validation dealt out between the two
    "train_ppo.imitation.epochs=1",
    "train_ppo.imitation.rollouts=1",
    "train_ppo.validation=[bridge,doorway]",
    "train_ppo.validation_episodes=2",
]
TIMING = ("charts/fps", "charts/rollout_fps", "charts/update_seconds", "charts/exchange_seconds")


def _saved_iteration(run) -> int:
    path = run / STATE_FILE
    return int(torch.load(path, weights_only=True)["iteration"]) if path.is_file() else -1


@pytest.mark.slow  # three runs of two worker processes each: about 45 s on 2 cores
def test_two_workers_resume_after_a_kill_to_the_uninterrupted_result(workdir) -> None:
    assert launch("train-ppo", [*WORDS, "hydra.run.dir=full"]) == 0
    assert "imitation round 0" in (workdir / "full" / "train-ppo.log").read_text()  # worker 0 logs to the run's file
    killed = workdir / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "stafpipe", "train-ppo", *WORDS, "train_ppo.resume=true", f"hydra.run.dir={killed}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 120
    while _saved_iteration(killed) < 1 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.kill()  # the workers die with the process that launched them
    proc.wait(timeout=60)
    assert 1 <= _saved_iteration(killed) < 4, "the kill did not land inside the training"
    assert launch("train-ppo", [*WORDS, "train_ppo.resume=true", f"hydra.run.dir={killed}"]) == 0

    a = torch.load(workdir / "full" / "policy.pt", weights_only=True)["state_dict"]
    b = torch.load(killed / "policy.pt", weights_only=True)["state_dict"]
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    curves = [pd.read_csv(run / "learning_curves.csv").drop(columns=list(TIMING)) for run in (workdir / "full", killed)]
    assert list(curves[0].iteration) == [1, 2, 3, 4]
    pd.testing.assert_frame_equal(*curves)
    state = torch.load(killed / STATE_FILE, weights_only=True)
    assert len(state["worker_rngs"]) == 2  # each worker's random state, so each resumes its own draws
    assert "imitation/val_success_rate" in curves[0] and curves[0]["val/success_rate"].notna().sum() == 2


@pytest.mark.slow  # two worker processes start: about 10 s
def test_a_bad_input_found_by_a_worker_is_a_clear_error_and_leaves_nothing(workdir, capsys) -> None:
    words = [*WORDS[:5], "train_ppo.validation=[corridor]", "hydra.run.dir=bad"]  # corridor is a training map
    assert launch("train-ppo", words) == 2
    assert "train_ppo.validation: ['corridor'] are also training scenarios" in capsys.readouterr().err
    assert not (workdir / "bad").exists()

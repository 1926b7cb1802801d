"""`stafpipe ablate` studies on tiny settings, the classical partitions, and `stafpipe plot partitions`."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from conftest import job_dirs
from stafpipe.cli import app
from stafpipe.highlevel.graphs import radius_edges
from stafpipe.highlevel.partition import balanced_kmeans, spectral_partition
from stafpipe.launch import launch

SMALL = ["ablate.teams=12", "ablate.formations=[circle,line]", "ablate.m_values=[2,3]"]


def _run(workdir, *overrides) -> pd.DataFrame:
    assert launch("ablate", list(overrides)) == 0
    run = job_dirs(workdir / "outputs")[-1]
    assert (run / "partitions.png").is_file() and (run / "summary.md").is_file()
    return pd.read_parquet(run / "results.parquet")


def test_classical_partitions_find_two_obvious_clusters() -> None:
    square = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    pos = np.concatenate([square, square + [10, 0]])
    goal = pos + [0, 20]
    truth = np.array([0] * 4 + [1] * 4)
    for labels in (spectral_partition(pos, goal, radius_edges(pos, 2.0), 2, 2.0, 0), balanced_kmeans(pos, goal, 2, 0)):
        assert (labels == truth).all() or (labels == 1 - truth).all()


def test_noise_study_agrees_with_itself_without_noise(workdir) -> None:
    df = _run(workdir, "ablate.study=noise", "ablate.teams=12", "ablate.noise_sigmas=[0.0,0.5]")
    assert (df[df.sigma == 0.0].ari == 1.0).all()  # the cut is a deterministic function of the positions
    assert df[df.sigma == 0.5].ari.mean() < 1.0


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_subteam_count_and_classical_studies_give_m_nonempty_subteams(workdir) -> None:
    counts = _run(workdir, "ablate.study=subteam_count", *SMALL)
    assert len(counts) == 2 * 2 * 12 and (counts.subteams_used == counts.m).all()
    classical = _run(workdir, "ablate.study=classical", *SMALL)
    assert set(classical.method) == {"learned", "spectral", "balanced_kmeans"}
    assert (classical[classical.method == "balanced_kmeans"].imbalance <= 1).all()


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_loss_terms_study_trains_each_variant_and_checks_findings(workdir) -> None:
    df = _run(
        workdir,
        "ablate.variants=[a_balance_only,full]",
        "ablate.train_instances=32",
        "ablate.epochs=2",
        "ablate.teams=8",
        "train_high.batch_size=16",
    )
    assert len(df) == 2 * 2 * 8 and set(df.labels) == {"raw", "repaired"}
    run = job_dirs(workdir / "outputs")[-1]
    assert "| a_balance_only | splits evenly |" in (run / "findings.md").read_text()
    assert (run / "variants" / "full" / "high_level.pt").is_file()
    result = CliRunner().invoke(app, ["plot", "partitions", str(run)])
    assert result.exit_code == 0 and "partitions.png" in result.output


def test_bad_ablate_settings_are_refused(workdir) -> None:
    assert launch("ablate", ["ablate.study=everything"]) == 2
    assert launch("ablate", ["ablate.m=12"]) == 2  # m must be below n = 12
    assert launch("ablate", ["ablate.study=noise", "high.checkpoint=missing.pt"]) == 2
    assert not job_dirs(workdir)

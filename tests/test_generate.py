import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from stafpipe.config.schema import DataConfig, FormationConfig
from stafpipe.formations import formation_slots
from stafpipe.highlevel.instances import COLUMNS, generate_instances
from stafpipe.launch import launch


def _generate(seed: int, *extra: str) -> bytes:
    assert launch("generate", ["experiment=smoke", f"seed={seed}", *extra]) == 0
    newest = max(p for p in __import__("pathlib").Path("outputs/generate").glob("*/*/formations.parquet"))
    return newest.read_bytes()


def test_same_seed_same_bytes_other_seed_other_bytes(workdir) -> None:
    a, b, c = _generate(3), _generate(3), _generate(4)
    assert a == b
    assert a != c


def test_schema_and_ranges(workdir) -> None:
    _generate(0, "data.mix=[circle,wedge,line]")
    [path] = list(workdir.glob("outputs/generate/*/*/formations.parquet"))
    df = pd.read_parquet(path)
    assert list(df.columns) == list(COLUMNS)
    assert pq.read_schema(path).metadata[b"stafpipe.schema_version"] == b"1"
    assert df.instance.nunique() == 200
    sizes = df.groupby("instance").n.first()
    assert sizes.between(4, 8).all() and (df.groupby("instance").size() == sizes).all()
    assert set(df.formation) == {"circle", "wedge", "line"}
    assert df.corridor_width.between(0.6, 4.0).all()
    assert pd.read_csv(path.with_suffix(".csv")).shape == df.shape


def test_noise_free_instance_is_the_formation_moved_to_start_and_goal() -> None:
    data = DataConfig(instances=30, position_noise=0.0, spacing_jitter=0.0)
    df = generate_instances(data, FormationConfig(type="wedge", spacing=1.5), seed=1)
    for _, team in df.groupby("instance"):
        n = len(team)
        start, goal = team[["x", "y"]].to_numpy(), team[["goal_x", "goal_y"]].to_numpy()
        # Same shape at start and goal: the goal is a pure translation of the start formation.
        shift = goal - start
        assert np.allclose(shift, shift[0])
        # Pairwise distances equal those of the template (a rigid motion of the slots).
        template = formation_slots("wedge", n, 1.5)
        d = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
        assert np.allclose(d(start), d(template))


def test_position_noise_has_the_configured_spread() -> None:
    data = DataConfig(instances=400, position_noise=0.2, spacing_jitter=0.0)
    df = generate_instances(data, FormationConfig(type="line"), seed=2)
    # Goal slots are noise-free: start minus (goal minus the team's common shift) is pure noise.
    resid = []
    for _, team in df.groupby("instance"):
        s, g = team[["x", "y"]].to_numpy(), team[["goal_x", "goal_y"]].to_numpy()
        delta = s - g
        resid.append(delta - delta.mean(axis=0))
    resid = np.concatenate(resid)
    n_mean = df.groupby("instance").n.first().mean()
    expected = 0.2 * np.sqrt(1 - 1 / n_mean)  # residual after removing the team mean
    assert abs(resid.std() - expected) < 0.01

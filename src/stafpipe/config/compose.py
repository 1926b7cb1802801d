"""A stage's job config composed the way Hydra composes it for a run (its compose API), for the checks that run
before any job (`launch`), for pipelines (config hashes) and for the messages of `compose_errors`."""

from __future__ import annotations

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

from stafpipe.config import register_configs
from stafpipe.paths import conf_dir


def config_name(stage: str) -> str:
    """The primary config file (without .yaml) of `stage`: `train-high` -> `train_high`."""
    return stage.replace("-", "_")


def compose_config(stage: str, overrides: list[str]) -> DictConfig:
    """The job config `stage` would run with these overrides."""
    register_configs()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(conf_dir()), version_base="1.3"):
        return compose(config_name=config_name(stage), overrides=overrides)

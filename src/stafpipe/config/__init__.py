"""Structured configs: dataclasses registered in Hydra's ConfigStore so that every YAML is type-checked."""

from hydra.core.config_store import ConfigStore

from stafpipe.config.schema import DataConfig, FormationConfig, StafConfig

__all__ = ["DataConfig", "FormationConfig", "StafConfig", "register_configs"]


def register_configs() -> None:
    """Register the schemas: `stafpipe_schema` is the root every primary config starts from."""
    from stafpipe.registry import load_plugins, method_config_class

    cs = ConfigStore.instance()
    cs.store(name="stafpipe_schema", node=StafConfig)
    for name in load_plugins():
        cs.store(group="method", name=f"base_{name}", node=method_config_class(name))

"""The device option of the training stages (`train_high.device`, `train_ppo.device`): checked with the config, before
any work (torch is imported only when a CUDA device is asked for), and resolved by `torch_io.training_device`."""

from __future__ import annotations

import re

from stafpipe.errors import ConfigError, require

DEVICE_FORMAT = r"cpu|cuda(:\d+)?"


def check_device(name: str, key: str) -> None:
    """A ConfigError naming `key` for a malformed device, or a CUDA device this machine does not have."""
    require(re.fullmatch(DEVICE_FORMAT, name) is not None, key, "must be cpu, cuda or cuda:N", name)
    if name == "cpu":
        return
    import torch

    if not torch.cuda.is_available():
        build = f"built with CUDA {torch.version.cuda}" if torch.version.cuda else "a CPU-only build"
        raise ConfigError(
            f"{key}: {name!r} was asked for, but this machine has no usable CUDA device (torch {torch.__version__}, "
            f"{build}); use {key}=cpu"
        )
    index = int(name.split(":")[1]) if ":" in name else 0
    if index >= torch.cuda.device_count():
        raise ConfigError(f"{key}: {name!r} was asked for, but only {torch.cuda.device_count()} CUDA device(s) exist")

"""Policy checkpoints: weights, the policy config, and how they were made (plain data, `weights_only` loading)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from stafpipe.errors import StafpipeError
from stafpipe.learning.config import PolicyConfig
from stafpipe.learning.policy_net import PolicyNet
from stafpipe.paths import package_dir
from stafpipe.torch_io import load_payload, save_payload

FORMAT = "stafpipe.policy/1"


def build_policy(method: str, cfg: PolicyConfig) -> PolicyNet:
    """A fresh policy network of the learned method `method` (its adapter names the network)."""
    from stafpipe.registry import adapter_class

    return adapter_class(method).network(cfg)


class PolicyCheckpointError(StafpipeError):
    """A policy checkpoint that is missing, damaged or of another kind."""


SHIPPED = "shipped:"
"""`shipped:NAME` names the checkpoint NAME.pt shipped with the package (e.g. `shipped:staf_planned_seed1`)."""


def ensemble_paths(checkpoint: str, ensemble: list[str] | None, method: str) -> list[str]:
    """The runs averaged with the checkpoint: `method.ensemble` as given; unset, the shipped partners when the
    checkpoint is the shipped one (empty) and none with any other (a user's own checkpoint is never mixed with ours).
    The shipped partners are the registry's (`Method.partners`; STAF-planned's two runs, how much better than one:
    the STAF-planned journal (docs/staf_planned.md), "The pair as the default")."""
    from stafpipe.registry import load_plugins

    if ensemble is not None:
        return list(ensemble)
    methods = load_plugins()
    return list(methods[method].partners) if not checkpoint and method in methods else []


def shipped_policy(method: str) -> Path:
    return package_dir() / "checkpoints" / f"{method}.pt"


def shipped_policies() -> list[str]:
    """Names of the shipped policy checkpoints: those whose recorded config (NAME.yaml beside NAME.pt) is a
    `train-ppo` run's (the deep graph cut ships too, but is not a policy)."""
    import yaml

    def stage(pt: Path) -> object:
        try:
            return (yaml.safe_load(pt.with_suffix(".yaml").read_text()) or {}).get("stage")
        except (OSError, yaml.YAMLError, AttributeError):
            return None

    return sorted(p.stem for p in (package_dir() / "checkpoints").glob("*.pt") if stage(p) == "train-ppo")


def policy_path(path: str | Path, method: str) -> Path:
    """The file a checkpoint setting names: empty, the one shipped for `method`; `shipped:NAME`, NAME.pt of the
    package's checkpoints; else the path as given."""
    text = str(path)
    if not text:
        return shipped_policy(method)
    if not text.startswith(SHIPPED):
        return Path(path)
    name = text[len(SHIPPED) :]
    found = shipped_policy(name)
    if not name or "/" in name or not found.is_file():
        raise PolicyCheckpointError(
            f"{text}: no checkpoint of that name ships with stafpipe (shipped policies: {shipped_policies()})"
        )
    return found


def save_policy(path: Path, method: str, policy: PolicyNet, made_by: dict[str, Any]) -> Path:
    payload = {
        "format": FORMAT,
        "method": method,
        "policy": dataclasses.asdict(policy.cfg),
        "state_dict": policy.state_dict(),
        "made_by": made_by,
    }
    return save_payload(Path(path), payload)


def load_policy(path: str | Path, method: str) -> tuple[PolicyNet, dict[str, Any]]:
    """The policy of a checkpoint (`path` as `policy_path` reads it), in eval mode, and its record."""
    path = policy_path(path, method)
    payload = load_payload(path, PolicyCheckpointError, "policy checkpoint", "train one with `stafpipe train-ppo`")
    if not isinstance(payload, dict) or payload.get("format") != FORMAT or payload.get("method") != method:
        found = (payload.get("format"), payload.get("method")) if isinstance(payload, dict) else type(payload).__name__
        raise PolicyCheckpointError(f"{path}: not a stafpipe {method} policy checkpoint (found {found})")
    try:
        policy = build_policy(method, PolicyConfig(**payload["policy"]))
        policy.load_state_dict(payload["state_dict"])
    except (TypeError, RuntimeError, KeyError) as exc:
        raise PolicyCheckpointError(f"{path}: weights do not fit the policy its config describes ({exc})") from None
    policy.eval()
    return policy, payload.get("made_by", {})


def load_members(
    paths: list[str], policy: PolicyNet, method: str, key: str
) -> list[tuple[str, PolicyNet, dict[str, Any]]]:
    """(path, policy, record) of each run in `paths`, every one the same network as `policy` (the same policy config:
    one set of features serves them all); an error names `key[k]`."""
    members = []
    for k, path in enumerate(paths):
        where = f"{key}[{k}]"
        if not path:
            raise PolicyCheckpointError(f"{where}: empty; give the path of a policy.pt of `stafpipe train-ppo`")
        try:
            member, made_by = load_policy(path, method)
        except StafpipeError as exc:
            raise PolicyCheckpointError(f"{where}: {exc}") from None
        if member.cfg != policy.cfg:
            raise PolicyCheckpointError(
                f"{where} ({path}): another network than the checkpoint's (its policy config {member.cfg} against "
                f"{policy.cfg}); an ensemble averages runs of one network"
            )
        members.append((path, member, made_by))
    return members

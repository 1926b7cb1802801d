"""Config errors of the command line, said in the user's terms: which override is wrong, the options or keys that
exist (did you mean ...?), never the schema's internal `base_*` names or Hydra's search path. Every such error exits
with 2, as every other user error (docs/decisions.md)."""

from __future__ import annotations

import difflib
import re
import unicodedata
from collections.abc import Sequence

from hydra.errors import HydraException, MissingConfigException, OverrideParseException
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from stafpipe.config.compose import compose_config


def jobs_to_check(overrides: Sequence[str]) -> list[list[str]] | None:
    """Overrides of jobs that together try every value a command line gives: the first job (a sweep's first value
    of each swept key) and, per swept key, one job for each of its other values. None where flags other than -m make
    the command something other than jobs of the config (--help, --info, --cfg ...)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    plain = [o for o in overrides if o not in ("-m", "--multirun")]
    if any(o.startswith("-") for o in plain):
        return None
    parsed = OverridesParser.create().parse_overrides(plain)  # a syntax error raises: reported by `explain`
    values = [
        [f"{ov.get_key_element()}={v}" for v in ov.sweep_string_iterator()]
        if ov.is_sweep_override()
        else [ov.input_line]
        for ov in parsed
    ]
    first = [v[0] for v in values]
    jobs = [first]
    for k, options in enumerate(values):
        jobs += [first[:k] + [v] + first[k + 1 :] for v in options[1:]]
    return [[str(part) for part in job] for job in jobs]


def explain(exc: BaseException, stage: str, overrides: Sequence[str]) -> str:
    """One message for a config that does not compose."""
    if isinstance(exc, MissingConfigException) and exc.missing_cfg_file and "/" in exc.missing_cfg_file:
        group, _, option = exc.missing_cfg_file.rpartition("/")
        choices = sorted(o for o in (exc.options or []) if not o.startswith("base_"))
        close = difflib.get_close_matches(option, choices, n=1)
        hint = f" (did you mean {group}={close[0]}?)" if close else ""
        return f"{group}={option}: no such {group}{hint}; choose one of: {', '.join(choices)}"
    text = str(exc)
    if isinstance(exc, OverrideParseException):
        return _unparsable(overrides, text)
    missing = re.search(r"Could not (?:override|append to|delete) '([^']+)'", text) or re.search(
        r"Key '([^']+)' (?:is not in struct|not in)", text
    )  # Hydra's wording (1.3)
    if missing:
        key = missing.group(1)
        others = [o for o in overrides if o.lstrip("+~").split("=", 1)[0] != key]
        try:
            base = compose_config(stage, others)
        except (HydraException, OmegaConfBaseException):
            base = None
        return f"{key} is not a setting of `stafpipe {stage}`{_did_you_mean(base, key)}"
    cause = exc.__cause__ or exc
    full_key = getattr(cause, "full_key", None)
    first = str(cause).strip().splitlines()[0] if str(cause).strip() else type(cause).__name__
    if full_key and "." not in str(full_key):  # OmegaConf names a field inside a list by its own name alone
        holders = [
            o.lstrip("+~").split("=", 1)[0]
            for o in overrides
            if "=" in o and re.search(rf"\b{re.escape(str(full_key))}\s*:", o.split("=", 1)[1])
        ]
        if len(holders) == 1:
            return f"{holders[0]}, field {full_key}: {first}"
    return f"{full_key}: {first}" if full_key else first


def _did_you_mean(cfg: DictConfig | None, key: str) -> str:
    """` (did you mean a.b.c?)` for the closest existing key of `cfg` to the dotted `key`, or ''."""
    if cfg is None:
        return ""
    parts = key.split(".")
    node, path = cfg, list[str]()
    for part in parts[:-1]:
        child = node.get(part) if isinstance(node, DictConfig) else None
        if not isinstance(child, DictConfig):
            names = list(node.keys()) if isinstance(node, DictConfig) else []
            close = difflib.get_close_matches(part, [str(n) for n in names], n=1)
            return f" (did you mean {'.'.join([*path, close[0]])}?)" if close else ""
        node, path = child, [*path, part]
    close = difflib.get_close_matches(parts[-1], [str(k) for k in node], n=1)
    return f" (did you mean {'.'.join([*path, close[0]])}?)" if close else ""


def _unparsable(overrides: Sequence[str], text: str) -> str:
    """Which override Hydra's grammar cannot read, and why, instead of the parser's exception name: a character
    outside the grammar's (a letter with an accent, a full-width digit) is allowed only inside a quoted value."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    for override in overrides:
        if override in ("-m", "--multirun") or override.startswith("-"):
            continue
        try:
            parser.parse_overrides([override])
        except OverrideParseException:
            key, _, value = override.partition("=")
            odd = next((c for c in override if not c.isascii()), None)
            if odd is not None and odd in key:
                return f"{override}: a key is a dotted name of ASCII letters, digits and _ (found {odd!r})"
            plain = unicodedata.normalize("NFKC", value)  # full-width digits and letters to ASCII
            if odd is not None and plain.isascii():
                return f"{override}: {odd!r} is not an ASCII character (did you mean {key}={plain}?)"
            if odd is not None:
                return f"{override}: {odd!r} may appear only in a quoted value: {key}='{value}'"
            reason = text.strip().splitlines()[0].split(": ", 1)[0]
            return f"{override}: not an override Hydra's grammar can read ({reason}); quote the value: {key}='{value}'"
    return text.strip().splitlines()[0]

"""Errors that stafpipe reports to the user as a one-line message and a non-zero exit, without a traceback."""


class StafpipeError(Exception):
    """Base class of the errors a user can fix: bad configs, scenario files, checkpoints, logs."""


class ConfigError(StafpipeError):
    """A configuration value is out of its valid range; the message names the key."""


def require(ok: bool, key: str, message: str, value: object) -> None:
    """Raise a ConfigError naming `key` unless `ok`."""
    if not ok:
        raise ConfigError(f"{key} {message}, got {value!r}")


def yaml_problem(exc: Exception) -> str:
    """What is wrong in a YAML file and where ("found duplicate key time_limit at line 11, column 1"): PyYAML's
    first line ("while constructing a mapping") names neither the key nor the line."""
    problem, mark = getattr(exc, "problem", None), getattr(exc, "problem_mark", None)
    if not problem:
        return str(exc).splitlines()[0]
    return f"{problem} at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else str(problem)

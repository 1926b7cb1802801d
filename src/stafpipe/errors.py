"""Errors that stafpipe reports to the user as a one-line message and a non-zero exit, without a traceback."""


class StafpipeError(Exception):
    """Base class of the errors a user can fix: bad configs, scenario files, checkpoints, logs."""


class ConfigError(StafpipeError):
    """A configuration value is out of its valid range; the message names the key."""


def require(ok: bool, key: str, message: str, value: object) -> None:
    """Raise a ConfigError naming `key` unless `ok`."""
    if not ok:
        raise ConfigError(f"{key} {message}, got {value!r}")

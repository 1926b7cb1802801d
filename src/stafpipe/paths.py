"""Where the shipped configs and pipelines live, for editable and non-editable installs alike."""

from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parent


def _shipped_dir(name: str) -> Path:
    # A wheel carries conf/ and pipelines/ inside the package (pyproject force-include);
    # an editable install or a source checkout has them at the repository root.
    for candidate in (_PACKAGE_DIR / name, _PACKAGE_DIR.parents[1] / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"stafpipe cannot find its '{name}' directory next to {_PACKAGE_DIR}")


def conf_dir() -> Path:
    """The directory of the primary Hydra configs (conf/)."""
    return _shipped_dir("conf")


def pipelines_dir() -> Path:
    """The directory of the shipped pipeline files (pipelines/)."""
    return _shipped_dir("pipelines")


def package_dir() -> Path:
    """The installed package's own directory (src/stafpipe in a checkout)."""
    return _PACKAGE_DIR

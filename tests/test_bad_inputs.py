"""Every bad input of tests/data/bad_inputs.yaml that no other test runs is refused: exit 2, a message naming the
fault, no traceback, and nothing of the run left behind (docs/bad_inputs.md)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from bad_inputs import FILE_FAULTS, Case, load_cases, run_case

CASES = [c for c in load_cases() if c.tested_in == "tests/test_bad_inputs.py"]


def run_file_fault(case: Case, tmp: Path) -> tuple[int, str]:
    """Run a file-system fault case with the fault made by patching: mkdir under the read-only place fails with
    EROFS; on a full disk every atomic rename (each output's last step) fails with ENOSPC."""
    real_mkdir = Path.mkdir
    read_only = tmp / ("ro" if case.kind == "read-only run directory" else "outputs")

    def mkdir(self: Path, *args: object, **kwargs: object) -> None:
        if Path(self) == read_only or Path(self).is_relative_to(read_only):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        real_mkdir(self, *args, **kwargs)  # type: ignore[arg-type]

    def replace(src: object, dst: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.MonkeyPatch.context() as mp:
        if case.kind == "disk full while writing":
            mp.setattr(os, "replace", replace)
        else:
            mp.setattr(Path, "mkdir", mkdir)
        return run_case(case, tmp)


def _refused_and_clean(case: Case, code: int, out: str, root: Path) -> None:
    assert code == 2, out
    assert case.said in out, out
    assert "Traceback" not in out, out
    assert not list(root.rglob("stage.json")), "a refused run counts as done"
    assert not list(root.rglob(".hydra")), "a refused run left its directory behind"
    leftovers = [*root.rglob("*.part"), *root.rglob(".*.tmp-*")]
    assert not leftovers, f"unfinished files left: {leftovers}"


@pytest.mark.slow
@pytest.mark.parametrize("case", [c for c in CASES if c.kind not in FILE_FAULTS], ids=lambda c: c.kind)
def test_a_bad_input_is_refused_before_any_work(case: Case, workdir: Path) -> None:
    code, out = run_case(case, workdir)
    _refused_and_clean(case, code, out, workdir)


@pytest.mark.parametrize("case", [c for c in CASES if c.kind in FILE_FAULTS], ids=lambda c: c.kind)
def test_a_file_system_fault_is_one_line_and_leaves_nothing_unfinished(case: Case, workdir: Path) -> None:
    code, out = run_file_fault(case, workdir)
    _refused_and_clean(case, code, out, workdir)
    assert len([line for line in out.splitlines() if line.startswith("error:")]) == 1, out


def test_the_table_has_every_kind_once_and_names_a_test_for_each() -> None:
    cases = load_cases()
    assert len(cases) >= 140 and len({c.kind for c in cases}) == len(cases)
    for c in cases:
        path, _, name = c.tested_in.partition("::")
        test = Path(__file__).parents[1] / path
        assert test.is_file() and (not name or f"def {name}(" in test.read_text()), c.tested_in
    doc = (Path(__file__).parents[1] / "docs" / "bad_inputs.md").read_text()
    assert all(f"| {c.kind} |" in doc for c in cases), "docs/bad_inputs.md lacks a case: rerun tests/bad_inputs.py"

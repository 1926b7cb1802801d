"""REPRODUCTION.md and reproduction.csv: one row per claim, verdicts computed by `report.verdicts`."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pandas as pd

from stafpipe.report.claims import Claim, Row, judge
from stafpipe.report.claims_others import cezayirli_claims, zhu_claims
from stafpipe.report.claims_staf import staf_claims
from stafpipe.report.claims_staf_paper import paper_staf_claims
from stafpipe.report.evidence import Evidence
from stafpipe.report.verdicts import FAILS, HOLDS, MISSING, PARTLY


def all_claims() -> list[Claim]:
    return [*staf_claims(), *paper_staf_claims(), *zhu_claims(), *cezayirli_claims()]


def judge_all(evidence: Evidence, claims: list[Claim] | None = None) -> list[Row]:
    return [judge(c, evidence) for c in (all_claims() if claims is None else claims)]


def rows_frame(rows: list[Row]) -> pd.DataFrame:
    return pd.DataFrame(
        [
            {
                "paper": r.claim.paper,
                "artifact": r.claim.artifact,
                "claim": r.claim.statement,
                "printed": r.claim.printed,
                "ours": r.measured.ours.value,
                "ours_ci95": r.measured.ours.ci,
                "ours_low95": r.measured.ours.lower,
                "ours_high95": r.measured.ours.upper,
                "ours_n": r.measured.ours.n,
                "criterion": r.measured.criterion.text(),
                "verdict": r.verdict,
                "note": r.measured.note,
                "pipeline": r.claim.pipeline,
            }
            for r in rows
        ]
    )


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(rows: list[Row], figures: list[str]) -> str:
    """The report; `figures`: the figures' paths relative to the report (the plot stage copies them there)."""
    counts = Counter(r.verdict for r in rows)
    lines = [
        "# Reproduction report",
        "",
        "Written by `stafpipe run reproduce` (`stafpipe plot report` over the run directories of its steps). Each row",
        "is a table, figure or claim of STAF, Zhu et al. (ICRA 2019) or Cezayirli & Kerestecioglu: the paper's number",
        "or words, ours with its 95 % interval over episodes (or over test teams for the graph-cut studies), the",
        "criterion, and the verdict the criterion computes from the numbers (`src/stafpipe/report/`; nothing here is",
        "typed by hand). CFI is ours (docs/metrics.md), with the printed gap term in the note where the runs carry it.",
        "",
        "The verdicts lean against us: a claim holds only if its whole interval lies on the claim's side (a wider",
        "interval can only weaken a verdict), a comparison only if the two intervals are apart, a tie never; a",
        "number with no interval (one sample) never holds. Success rates carry Wilson's interval over episodes, so",
        "50 perfect episodes (lower end 92.9 %) do not show SR >= 95 %; other means the wider of Student's t and a",
        "BCa bootstrap interval. Thresholds are compared within 1e-6. docs/reproduction.md has the rules.",
        "",
        f"**{len(rows)} rows: {counts[HOLDS]} hold, {counts[PARTLY]} partly, {counts[FAILS]} do not hold, "
        f"{counts[MISSING]} not measured.**",
        "",
        "| # | paper | artifact | claim | paper's | ours | criterion | verdict | note | pipeline |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(rows, start=1):
        ours = r.measured.ours.text(3 if abs(r.measured.ours.value) < 2 else 1)
        verdict = f"**{r.verdict}**" if r.verdict == FAILS else r.verdict
        cells = [
            str(i),
            r.claim.paper,
            r.claim.artifact,
            r.claim.statement,
            r.claim.printed,
            ours,
            r.measured.criterion.text(),
            verdict,
            r.measured.note,
            f"`{r.claim.pipeline}`",
        ]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    if figures:
        lines += ["", "## Figures", ""]
        lines += [f"- [{Path(f).name}]({f})" for f in figures]
    return "\n".join(lines) + "\n"

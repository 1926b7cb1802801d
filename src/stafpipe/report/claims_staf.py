"""STAF's tables, figures and claims (STAF Sec. 4-5, App. F) as report rows, answered by the runs of STAF-planned
(ours, `method=staf_planned`: our plan + the learned low level). Paper numbers: Table 1 from
`plots.staf_tables.PAPER_TABLE1` (STAF-planned's cells beside the paper's STAF: `paper_key`); the others quoted
from the paper's text, cited in each row."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pandas as pd

from stafpipe.metrics import CFI_SIGMAS
from stafpipe.plots.staf_tables import LABELS, PAPER_TABLE1, paper_key
from stafpipe.report.claims import PLANNED, Claim, Measured, fraction
from stafpipe.report.claims_learning import learning_claims
from stafpipe.report.evidence import Evidence, column_number, lowest
from stafpipe.report.verdicts import HOLDS, Criterion, Number

FORMATIONS = ("circle", "wedge", "line")
STAF = "staf"
"""The paper's STAF as we implement it (`method=staf`, docs/staf_paper.md): its own Table 1 rows and Fig. 4."""
NAMES = {STAF: "STAF", PLANNED: LABELS[PLANNED], "dgnn": "DGNN", "lf": "L&F"}
OURS = NAMES[PLANNED]


def cell(method: str, formation: str) -> dict[str, Any]:
    """Table 1's cell: the corridor, ten holonomic robots (STAF Sec. 4)."""
    return {"method": method, "scenario": "corridor", "formation": formation, "n": 10, "drive": "holonomic"}


def _cfi_note(ev: Evidence, method: str, formation: str, shown: str = "cfi_0.5") -> str:
    """The other readings of the same episodes (docs/metrics.md) than the one `shown`: the whole episode, the printed
    gap term, in the passage only."""
    notes = []
    readings = (("cfi_0.5", "whole episode"), ("cfi_printed_0.5", "with the printed gap term"))
    for column, name in (*readings, ("cfi_passage_0.5", "in the passage")):
        if column == shown:
            continue
        number = ev.number(column, 100, " %", **cell(method, formation))
        if not math.isnan(number.value):
            notes.append(f"{name}: {number.text()}")
    return "; ".join(notes)


def mean_of(column: str, where: dict[str, Any], criterion: Criterion, note: str = "") -> Callable[[Evidence], Measured]:
    """A measurement: the mean of `column` (in per cent) over the matching episodes, judged by `criterion`."""
    return lambda ev: Measured(ev.number(column, 100, " %", **where), criterion, note)


def _absolute(column: str, where: dict[str, Any], criterion: Criterion) -> Callable[[Evidence], Measured]:
    """A measurement: the mean of `column` in its own unit over the matching episodes, judged by `criterion`."""
    return lambda ev: Measured(ev.number(column, **where), criterion)


def _table1_claims() -> list[Claim]:
    claims = []
    for f in FORMATIONS:
        for method in (STAF, PLANNED, "dgnn"):
            sr = PAPER_TABLE1[paper_key(method, f)][0]
            claims.append(
                Claim(
                    "STAF",
                    "Table 1",
                    f"{NAMES[method]} success rate, {f}",
                    f"{sr:.0f} %",
                    "staf_table1",
                    mean_of("sr", cell(method, f), Criterion("at_least", sr - 5)),
                )
            )
        lf_sr = PAPER_TABLE1[("lf", f)][0]
        claims.append(
            Claim(
                "STAF",
                "Table 1",
                f"L&F success rate, {f}",
                f"{lf_sr:.0f} %",
                "staf_table1",
                mean_of("sr", cell("lf", f), Criterion("near", lf_sr, 15)),
            )
        )
        cfi = PAPER_TABLE1[paper_key(PLANNED, f)][2]
        claims += [
            Claim(
                "STAF",
                "Table 1",
                f"STAF collisions per episode, {f}",
                "none reported",
                "staf_table1",
                _absolute("collisions", cell(STAF, f), Criterion("at_most", 0.1)),
            ),
            Claim(
                "STAF",
                "Table 1",
                f"STAF CFI (sigma 0.5) in the passage, {f}",
                f"{cfi:.2f} %",
                "staf_table1",
                _cfi(STAF, f, cfi, "cfi_passage_0.5"),
            ),
            Claim(
                "STAF", "Table 1", f"{OURS} CFI (sigma 0.5), {f}", f"{cfi:.2f} %", "staf_table1", _cfi(PLANNED, f, cfi)
            ),
        ]
        lf_cfi, dgnn_cfi = PAPER_TABLE1[("lf", f)][2], PAPER_TABLE1[("dgnn", f)][2]
        claims.append(
            Claim(
                "STAF",
                "Table 1",
                f"L&F keeps formation better than DGNN (CFI 0.5), {f}",
                f"L&F {lf_cfi:.1f} % > DGNN {dgnn_cfi:.1f} %",
                "staf_table1",
                _compare("cfi_0.5", cell("lf", f), cell("dgnn", f), "DGNN"),
            )
        )
    claims += [
        Claim(
            "STAF",
            "Table 1",
            f"the CFI of {OURS} is above DGNN's and L&F's at every sigma and formation",
            "9 of 9 cells",
            "staf_table1",
            _staf_cfi_above_both,
        ),
        Claim(
            "STAF",
            "Table 1",
            f"L&F is the fastest method (its TT below those of {OURS} and DGNN)",
            "3 of 3 formations (27.4 / 26.5 / 30.1 s)",
            "staf_table1",
            _lf_fastest,
        ),
        Claim(
            "STAF",
            "Table 1",
            "L&F gets stuck: its whole team does not pass the corridor (SR below 100 % in every formation)",
            "40 / 70 / 60 %",
            "staf_table1",
            _lf_stuck,
        ),
    ]
    return claims


def _cfi(method: str, formation: str, paper: float, column: str = "cfi_0.5") -> Callable[[Evidence], Measured]:
    """CFI(0.5) of `method`'s Table 1 cell against the paper's less 5 points, the other readings in the note."""
    return lambda ev: Measured(
        ev.number(column, 100, " %", **cell(method, formation)),
        Criterion("at_least", paper - 5),
        _cfi_note(ev, method, formation, column),
    )


def _compare(column: str, ours: dict[str, Any], other: dict[str, Any], name: str) -> Callable[[Evidence], Measured]:
    return lambda ev: _above(ev, column, ours, other, name)


def _lf_stuck(ev: Evidence) -> Measured:
    srs = [x for f in FORMATIONS if not math.isnan((x := ev.number("sr", 100, " %", **cell("lf", f))).value)]
    worst = max(srs, key=lambda x: x.value, default=Number(math.nan))
    return Measured(worst, Criterion("at_most", 90), "the largest of L&F's three SRs")


def _above(ev: Evidence, column: str, ours: dict[str, Any], other: dict[str, Any], name: str) -> Measured:
    a, b = ev.number(column, 100, " %", **ours), ev.number(column, 100, " %", **other)
    return Measured(a, Criterion.than("above", b), f"{name}: {b.text()}")


def _staf_cfi_above_both(ev: Evidence) -> Measured:
    hits, total = 0, 0
    for f in FORMATIONS:
        for s in CFI_SIGMAS:
            col = f"cfi_{s:g}"
            ours = ev.number(col, **cell(PLANNED, f))
            others = [ev.number(col, **cell(m, f)) for m in ("dgnn", "lf")]
            if any(math.isnan(x.value) for x in (ours, *others)):
                continue
            total += 1
            hits += all(Criterion.than("above", o).verdict(ours) == HOLDS for o in others)
    return Measured(
        Number(hits if total else math.nan, 0, total), Criterion("at_least", 9), "cells above both outside the CIs"
    )


def _lf_fastest(ev: Evidence) -> Measured:
    hits, total = 0, 0
    for f in FORMATIONS:
        lf = ev.number("tt_arrived", **cell("lf", f))
        rivals = [ev.number("tt_arrived", **cell(m, f)) for m in (PLANNED, "dgnn")]
        if math.isnan(lf.value) or all(math.isnan(r.value) for r in rivals):
            continue
        total += 1
        hits += all(math.isnan(r.value) or Criterion.than("below", r).verdict(lf) == HOLDS for r in rivals)
    return Measured(
        Number(hits if total else math.nan, 0, total),
        Criterion("at_least", 3),
        "formations where L&F's TT of arrivals is below both others' outside both CIs (the same measure on every "
        "side: L&F's whole team never arrives)",
    )


def _table2_and_fig4() -> list[Claim]:
    claims = []
    for f in FORMATIONS:

        def both(ev: Evidence, f: str = f) -> Measured:
            rows = ev.select(**cell(PLANNED, f))
            if rows.empty or "sub2_sr" not in rows:
                return Measured(Number(math.nan), Criterion("at_least", 95))
            subs = [column_number(rows, c, 100, " %") for c in ("sub1_sr", "sub2_sr")]
            return Measured(
                lowest(subs), Criterion("at_least", 95), f"subteams {subs[0].value:.1f} / {subs[1].value:.1f} %"
            )

        claims.append(Claim("STAF", "Table 2", f"both subteams succeed, {f}", "100 % each", "staf_table1", both))

    def two_subteams(ev: Evidence) -> Measured:
        rows = pd.concat([ev.select(**cell(STAF, f)) for f in FORMATIONS])
        hits = int((rows["subteams_max"] == 2).sum()) if not rows.empty else 0
        return Measured(
            fraction(hits, len(rows)),
            Criterion("at_least", 95),
            "STAF's episodes (circle, wedge, line) with exactly two subteams, m chosen by its rule (Sec. 7); "
            "STAF-planned fixes m = 2, so its rows could not fail this",
        )

    claims.append(
        Claim("STAF", "Fig. 4", "the team divides into two subteams (red, blue)", "2", "staf_table1", two_subteams)
    )
    return claims


def _loss_terms(ev: Evidence, variant: str, column: str) -> tuple[Number, Number]:
    df = ev.study("loss_terms")
    if df.empty:
        return Number(math.nan), Number(math.nan)
    raw = df[df["labels"] == "raw"]
    return column_number(raw[raw["variant"] == variant], column), column_number(raw[raw["variant"] == "full"], column)


def _fig7_claims() -> list[Claim]:
    def vs_full(variant: str, column: str, kind: str, effect: float) -> Callable[[Evidence], Measured]:
        def measure(ev: Evidence) -> Measured:
            ours, full = _loss_terms(ev, variant, column)
            return Measured(ours, Criterion.than(kind, full, min_effect=effect), f"full loss: {full.text(3)}")

        return measure

    def absolute(variant: str, column: str, criterion: Criterion) -> Callable[[Evidence], Measured]:
        return lambda ev: Measured(_loss_terms(ev, variant, column)[0], criterion)

    rows = [
        (
            "Fig. 7(a)",
            "balance alone splits 12 robots evenly into 3 (imbalance, robots)",
            "even",
            absolute("a_balance_only", "imbalance", Criterion("at_most", 1)),
        ),
        (
            "Fig. 7(b)",
            "adjacency alone puts every robot in one subteam (subteams used)",
            "1",
            absolute("b_adjacency_only", "subteams_used", Criterion("at_most", 1.1)),
        ),
        (
            "Fig. 7(c)",
            "goal distance alone aligns subteams with their goals (goal distance, below the full loss')",
            "aligned",
            vs_full("c_goal_only", "goal_distance", "below", 0.01),
        ),
        (
            "Fig. 7(d)",
            "without balance the division is unbalanced (imbalance, above the full loss')",
            "unbalanced",
            vs_full("d_without_balance", "imbalance", "above", 0.5),
        ),
        (
            "Fig. 7(e)",
            "without adjacency the subteams are not compact (cut fraction, above the full loss')",
            "uncompact",
            vs_full("e_without_adjacency", "cut_fraction", "above", 0.01),
        ),
        (
            "Fig. 7(f)",
            "without the goal term subteams are misaligned with goals (goal distance, above the full loss')",
            "misaligned",
            vs_full("f_without_goal", "goal_distance", "above", 0.01),
        ),
    ]
    return [Claim("STAF", a, s, p, "staf_ablation", m) for a, s, p, m in rows]


def _team_size_claims() -> list[Claim]:
    def circle(n: int) -> dict[str, Any]:
        return {**cell(PLANNED, "circle"), "n": n}

    def all_sizes(ev: Evidence) -> Measured:
        worst = lowest([ev.number("sr", 100, " %", **circle(n)) for n in (4, 6, 7, 8)])
        return Measured(worst, Criterion("at_least", 95), "the lowest SR over teams of 4, 6, 7, 8")

    return [
        Claim(
            "STAF",
            "Fig. 8(e)",
            "CFI of 4 robots at sigma < 0.03",
            "87 %",
            "staf_team_size",
            mean_of("cfi_0.01", circle(4), Criterion("at_least", 87), "sigma 0.01"),
        ),
        Claim(
            "STAF",
            "Fig. 8(e)",
            "CFI of 8 robots at sigma < 0.03",
            "at least 80 %",
            "staf_team_size",
            mean_of("cfi_0.01", circle(8), Criterion("at_least", 80), "sigma 0.01"),
        ),
        Claim(
            "STAF", "Fig. 8(a-d)", "teams of 4, 6, 7 and 8 robots pass the corridor", "all", "staf_team_size", all_sizes
        ),
    ]


def _study_mean(ev: Evidence, study: str, column: str, **where: Any) -> Number:
    df = ev.study(study)
    for key, value in where.items():
        if df.empty or key not in df:
            return Number(math.nan)
        df = df[df[key] == value]
    return column_number(df, column)


def _study(name: str, column: str, criterion: Criterion, **where: Any) -> Callable[[Evidence], Measured]:
    return lambda ev: Measured(_study_mean(ev, name, column, **where), criterion)


def _graph_cut_claims() -> list[Claim]:
    claims = [
        Claim(
            "STAF",
            "Fig. 9",
            f"a team of 10 divides into {m} balanced subteams (imbalance, robots; circle, wedge, line together)",
            "handled",
            "staf_subteam_count",
            _study("subteam_count", "imbalance", Criterion("at_most", 1), m=m),
        )
        for m in (2, 3, 4)
    ]
    for sigma, why in ((0.1, "0.1 m, a realistic position error"), (1.0, "1 m, standard normal noise")):
        claims.append(
            Claim(
                "STAF",
                "Fig. 14",
                f"the division stays consistent under Gaussian position noise of {why} "
                "(adjusted Rand index to the noise-free cut)",
                "consistent",
                "staf_noise",
                _study("noise", "ari", Criterion("at_least", 0.9), sigma=sigma),
            )
        )
    return claims


def _platform_claims() -> list[Claim]:
    def diff(ev: Evidence) -> Measured:
        worst = lowest([ev.number("sr", 100, " %", **{**cell(PLANNED, f), "drive": "diff_drive"}) for f in FORMATIONS])
        return Measured(worst, Criterion("at_least", 95), "the lowest SR of circle, wedge, line")

    def builtin(ev: Evidence) -> Measured:
        rows = ev.episodes
        if rows.empty:
            return Measured(Number(math.nan), Criterion("at_least", 95))
        rows = rows[(rows["method"] == PLANNED) & (rows["faults"] == "") & (rows["drive"] == "holonomic")]
        plain = rows["label"].isin(["", "gap-2m", "gap-3m", "long-10m"]) | rows["label"].str.startswith("b-")
        rows = rows[plain & ~rows["scenario"].str.startswith("gen")]
        rows = rows[(rows["scenario"] != "corridor") | rows["label"].isin(["gap-2m", "gap-3m", "long-10m"])]
        srs = {
            " ".join(map(str, key)).strip(): column_number(g, "sr", 100, " %")
            for key, g in rows.groupby(["scenario", "label"])
        }
        worst = lowest(list(srs.values()))
        name = next((k for k, v in srs.items() if v is worst), "")
        return Measured(
            worst, Criterion("at_least", 95), f"the lowest of {len(srs)} built-in maps and variants ({name})"
        )

    return [
        Claim(
            "STAF",
            "App. F, platforms",
            f"{OURS} on differential-drive robots (Warthog, Limo) passes the corridor",
            "qualitative (Fig. 5, 11-13)",
            "staf_platforms",
            diff,
        ),
        Claim(
            "STAF",
            "Generalisation (ours)",
            f"{OURS} passes every built-in map (doorway, bridge, narrowing, several "
            "passages, bollards, forest, corridor 2 m / 3 m / 10 m long)",
            "-",
            "staf_generalisation",
            builtin,
        ),
        Claim(
            "STAF",
            "App. F, platforms",
            f"DGNN on differential-drive robots is below {OURS} (line formation SR)",
            "-",
            "staf_platforms",
            lambda ev: _above(
                ev,
                "sr",
                {**cell(PLANNED, "line"), "drive": "diff_drive"},
                {**cell("dgnn", "line"), "drive": "diff_drive"},
                "DGNN",
            ),
        ),
    ]


def staf_claims() -> list[Claim]:
    return [
        *_table1_claims(),
        *_table2_and_fig4(),
        *_fig7_claims(),
        *_team_size_claims(),
        *_graph_cut_claims(),
        *_platform_claims(),
        *learning_claims(),
    ]

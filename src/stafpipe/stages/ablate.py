"""`stafpipe ablate`: the graph-cut studies (ablate.study = loss_terms | subteam_count | noise | classical).

Writes `results.parquet/.csv` (one row per test team and setting), `summary.parquet/.csv/.md` (mean and 95 % CI per
setting), `partitions.parquet/.csv` (an example team per setting, redrawn by `stafpipe plot partitions RUN_DIR`) and the
study's figures as PNG + PDF; loss_terms also writes `findings.md` (the paper's Fig. 7 claims checked) and trains one
network per variant under `variants/<name>/` (resumable like train-high).
"""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig

from stafpipe.highlevel.config import AblateConfig, HighLevelConfig, TrainHighConfig
from stafpipe.io import atomic_write, markdown_table, save_figure, write_table
from stafpipe.sections import section

log = logging.getLogger(__name__)
GROUPS = {
    "loss_terms": ["variant", "labels"],
    "subteam_count": ["formation", "m"],
    "noise": ["sigma"],
    "classical": ["formation", "m", "method"],
}
TITLES = {
    "loss_terms": "Loss ablation (STAF Fig. 7): raw argmax of each variant's network",
    "subteam_count": "Subteam count (STAF Fig. 9)",
    "noise": "Position noise (STAF Fig. 14)",
    "classical": "Learned cut vs classical partitions",
}


def run_ablate(cfg: DictConfig, out_dir: Path) -> list[Path]:
    from stafpipe.highlevel import studies
    from stafpipe.highlevel.checkpoint import load_checkpoint
    from stafpipe.launch import config_hash
    from stafpipe.plots.partitions import ari_figure, partition_figure

    ab = section(cfg.ablate, AblateConfig)
    high = section(cfg.high, HighLevelConfig)
    tc = section(cfg.train_high, TrainHighConfig)
    ab.check()
    high.check()
    tc.check()
    seed = int(cfg.seed)
    if ab.study == "loss_terms":
        results, parts = studies.loss_terms_study(ab, high, tc, seed, out_dir, config_hash(cfg))
    else:
        model, made_by = load_checkpoint(high.checkpoint, overrides=high)
        log.info(
            "graph cut from %s (made by commit %s)",
            high.checkpoint or "the shipped checkpoint",
            made_by.get("commit", "?"),
        )
        study = {
            "subteam_count": studies.subteam_count_study,
            "noise": studies.noise_study,
            "classical": studies.classical_study,
        }[ab.study]
        results, parts = study(model, ab, seed)
    summary = studies.summarise(results, GROUPS[ab.study])
    outputs = write_table(results, out_dir / "results") + write_table(summary, out_dir / "summary")
    outputs += write_table(parts, out_dir / "partitions")
    shown = [c for c in summary.columns if not c.endswith("_ci95")]
    outputs.append(atomic_write(out_dir / "summary.md", lambda tmp: tmp.write_text(markdown_table(summary[shown]))))
    ncols = 4 if ab.study in ("loss_terms", "noise") else len(ab.m_values) if ab.study == "subteam_count" else 3
    outputs += save_figure(partition_figure(parts, high.radius, ncols, TITLES[ab.study]), out_dir / "partitions")
    if ab.study == "noise":
        outputs += save_figure(ari_figure(summary), out_dir / "ari_vs_noise")
    if ab.study == "loss_terms":
        text = studies.findings_markdown(summary)
        outputs.append(atomic_write(out_dir / "findings.md", lambda tmp: tmp.write_text(text)))
        outputs += sorted((out_dir / "variants").rglob("*.pt"))
        print(text)
    print(markdown_table(summary[shown]))
    return outputs

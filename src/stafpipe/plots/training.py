"""Loss curves of a training run."""

from __future__ import annotations

from matplotlib.figure import Figure

from stafpipe.highlevel.loss import TERMS


def loss_curve_figure(history: list[dict[str, float]]) -> Figure:
    """One panel per loss term (and the weighted total): training and validation per epoch."""
    names = [*TERMS, "total"]
    fig = Figure(figsize=(3.2 * len(names), 2.8))
    epochs = [row["epoch"] for row in history]
    for k, name in enumerate(names):
        ax = fig.add_subplot(1, len(names), k + 1)
        for split, style in (("train", "-"), ("val", "--")):
            key = f"{split}_{name}"
            if history and key in history[0]:
                ax.plot(epochs, [row[key] for row in history], style, label=split)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("epoch")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig

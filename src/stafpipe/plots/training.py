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


PPO_PANELS = [
    ("charts/success_rate", "success rate"),
    ("charts/episode_return", "episode return"),
    ("charts/collisions_per_episode", "collisions / episode"),
    ("losses/value", "value loss"),
    ("losses/approx_kl", "approx. KL"),
    ("charts/fps", "robot-steps / s"),
]


def ppo_figure(history: list[dict[str, float]]) -> Figure:
    """PPO learning curves against environment robot-steps."""
    fig = Figure(figsize=(12, 5.6))
    x = [row["robot_steps"] / 1e6 for row in history]
    for k, (key, title) in enumerate(PPO_PANELS):
        ax = fig.add_subplot(2, 3, k + 1)
        ax.plot(x, [row.get(key, float("nan")) for row in history], label="sampled actions")
        eval_key = key.replace("charts/", "eval/")
        if eval_key != key and any(eval_key in row for row in history):
            pts = [(xv, row[eval_key]) for xv, row in zip(x, history, strict=True) if eval_key in row]
            ax.plot(*zip(*pts, strict=True), "o-", ms=3, label="mean action (eval)")
            ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("robot-steps (millions)", fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig

"""Render the pictures of docs/guide.md into docs/img/ (run from the repository root):

    JAX_PLATFORMS=cpu python docs/make_figures.py            # everything (~1-2 min on a CPU)
    JAX_PLATFORMS=cpu python docs/make_figures.py --skip-training

Writes craft_reference.png (the reference get_gem map), football_kickoff.png,
hierarchy_get_gem.png (the paper hierarchy of craft/get_gem as boxes by level) and, unless
``--skip-training``, curves_make_stick.png (a tiny top-down vs flat run on craft/make_stick).
"""
from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

import smjax

IMG = Path(__file__).resolve().parent / "img"


def save_rgb(image, path: Path, scale: float = 1.0) -> Path:
    picture = Image.fromarray(np.asarray(image, np.uint8))
    if scale != 1.0:
        picture = picture.resize((int(picture.width * scale), int(picture.height * scale)), Image.NEAREST)
    picture.save(path, optimize=True)
    return path


def craft_frame() -> Path:
    from smjax.envs.craft import REFERENCE_GEM_MAP, from_ascii

    env, _ = smjax.make("craft/get_gem", observation="none")
    state, params = from_ascii(REFERENCE_GEM_MAP, task="get_gem")
    return save_rgb(env.render(state, params), IMG / "craft_reference.png")


def football_frame() -> Path:
    env, params = smjax.make("football/11v11_easy")
    _, state = env.reset(jax.random.PRNGKey(0), params)
    return save_rgb(env.render(state, params), IMG / "football_kickoff.png")


def hierarchy_diagram(task: str = "craft/get_gem", name: str = "paper") -> Path:
    """Options as boxes, one row per level, arrows from each option to the templates it calls."""
    env, _ = smjax.make(task)
    h = env.hierarchies()[name]
    rows: dict[int, list[str]] = {}
    for option in h.option_names:
        rows.setdefault(h.level(option), []).append(option)
    width = max(len(r) for r in rows.values())
    fig, ax = plt.subplots(figsize=(max(6.0, 1.9 * width), 0.9 * (len(rows) + 1)))
    where = {}
    for level, names in rows.items():
        for i, option in enumerate(names):
            x = (i + 0.5) * width / len(names)
            y = -level
            where[option] = (x, y)
            prims = [k for k in h.children.get(option, ()) if k in h.primitive_names]
            label = option + (f"\n+ {len(prims)} primitives" if prims else "")
            leaf = not h.children.get(option)
            ax.text(x, y, label, ha="center", va="center", fontsize=9,
                    bbox=dict(boxstyle="round,pad=0.4", fc="#f3e2b3" if leaf else "#cfe0f5", ec="#555"))
    for option, kids in h.children.items():
        for kid in kids:
            if kid in where:
                (x0, y0), (x1, y1) = where[option], where[kid]
                ax.annotate("", xy=(x1, y1 + 0.22), xytext=(x0, y0 - 0.22),
                            arrowprops=dict(arrowstyle="->", color="#444", lw=0.8))
    for level in rows:
        ax.text(-0.1, -level, f"level {level}", ha="right", va="center", fontsize=9, color="#333")
    ax.margins(x=0.05)
    ax.set_xlim(-0.9, width + 0.1)
    ax.set_ylim(-len(rows) - 0.6, -0.4)
    ax.axis("off")
    ax.set_title(f"{task}, hierarchy '{name}'\nblue: learned options; yellow: leaves (always "
                 f"teleported or scripted)", fontsize=9)
    fig.tight_layout()
    out = IMG / "hierarchy_get_gem.png"
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def learning_curves() -> Path:
    from smjax.train import TrainConfig, run
    from smjax.viz.plots import plot_curves

    cfg = TrainConfig(num_envs=32, rollout_ticks=16, updates_per_chunk=4, success_window=64,
                      max_episodes_per_level=1500, eval_envs=32, eval_max_ticks=200)
    with tempfile.TemporaryDirectory() as tmp:
        dirs = []
        for method in ("top-down", "flat"):
            out = Path(tmp) / method
            run("craft/make_stick", cfg.replace(method=method), [0], out,
                env_overrides={"observation": "compact"}, progress=False)
            dirs.append(out)
        return plot_curves(dirs, IMG / "curves_make_stick.png",
                           title="craft/make_stick, 1 seed, tiny budget (illustration only)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-training", action="store_true", help="skip the learning-curve run")
    args = parser.parse_args()
    IMG.mkdir(parents=True, exist_ok=True)
    made = [craft_frame(), football_frame(), hierarchy_diagram()]
    if not args.skip_training:
        made.append(learning_curves())
    for path in made:
        print(f"{path} ({path.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    main()

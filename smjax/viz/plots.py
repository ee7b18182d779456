"""Learning-curve plots in the paper's style: running success vs episodes, one panel per
level, and one for fine-tuning (the task's teleport-free success, with the evaluated
final_success before and after it); ``PlotHook`` draws a run's own as it finishes."""
from __future__ import annotations

import csv
import json
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

from smjax.train import distributed as dist
from smjax.train.hooks import Hook, ResultsReport


def _load(run_dir: Path):
    from smjax.train.results import read_curves

    return read_curves(run_dir / "curves.csv"), read_meta(run_dir)


def read_meta(run_dir: Path) -> dict:
    """The fields of a run's results.json the plot reads ({} without the file), checked:
    a damaged file is refused naming it and the field, not plotted from wrong types."""
    path = Path(run_dir) / "results.json"
    if not path.exists():
        return {}
    try:
        meta = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise ValueError(f"{path} cannot be read ({str(err)[:100]})") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path} is not a smjax results file (a {type(meta).__name__}, not an "
                         f"object)")
    for name in ("method", "algo"):
        _need(path, name, isinstance(meta.get(name, ""), str), "a string")
    finetune = meta.get("finetune") or {}
    _need(path, "finetune", isinstance(finetune, dict), "an object")
    for name, where in (("final_success", meta), ("finetune.final_success_before", finetune)):
        values = where.get(name.rsplit(".", 1)[-1]) or []
        _need(path, name, isinstance(values, list) and all(
            x is None or (isinstance(x, (int, float)) and not isinstance(x, bool)) for x in values),
              "a list of numbers")
    return meta


def _need(path: Path, field: str, ok: bool, what: str) -> None:
    if not ok:
        raise ValueError(f"{path}: field {field!r} must be {what}")


def check_curves(run_dir: Path) -> None:
    """Refuse, naming the file, a run without a readable curves.csv holding at least one row,
    or with a damaged results.json."""
    from smjax.train.results import CURVE_COLUMNS, read_curves

    path = Path(run_dir) / "curves.csv"
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} has no curves.csv (is it a run directory?)")
    try:
        rows = read_curves(path)
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise ValueError(f"{path} cannot be read ({err})") from None
    if not rows:
        raise ValueError(f"{path} has no rows: the run recorded no progress yet")
    missing = [c for c in CURVE_COLUMNS if c not in rows[0]]
    if missing:
        raise ValueError(f"{path} is not a smjax curves file (missing columns {missing})")
    for i, r in enumerate(rows, start=2):
        try:
            int(r["level"]), int(r["seed"]), int(r["episodes"])
            if r["running_success"] not in ("", None):
                float(r["running_success"])
        except (TypeError, ValueError):
            raise ValueError(f"{path} line {i} is malformed: {r}") from None
    read_meta(run_dir)


FINETUNE = "finetune"  # the template column of fine-tuning's rows


def _before_after(ax, meta: dict, color) -> None:
    """Fine-tuning's panel: the evaluated final_success before it (dotted) and after it
    (dashed), means over seeds."""
    ft = meta.get("finetune") or {}
    before = [x for x in ft.get("final_success_before") or [] if x is not None]
    after = [x for x in meta.get("final_success") or [] if x is not None]
    if before:
        ax.axhline(np.mean(before), color=color, ls=":", lw=1,
                   label=f"before: {np.mean(before):.2f}")
    if after:
        ax.axhline(np.mean(after), color=color, ls="--", lw=1, label=f"after: {np.mean(after):.2f}")


def run_labels(dirs: list[Path], metas: list[dict]) -> list[str]:
    """Legend labels: "method (algo)", with the run's directory where two would coincide
    (two seeds' or two configs' runs of one method)."""
    labels = [f"{m.get('method', d.name)} ({m.get('algo', '?')})" for d, m in zip(dirs, metas)]
    if len(set(labels)) == len(labels):
        return labels
    names = [d.name for d in dirs]
    if len(set(names)) < len(names):  # runs/a/x and runs/b/x: the fuller path
        names = [str(d) for d in dirs]
    return [f"{label}: {name}" for label, name in zip(labels, names)]


def plot_curves(run_dirs, out_path, title: str | None = None) -> Path:
    """Overlay runs (e.g. top-down vs flat): one panel per level, mean +- std over seeds.

    Episodes on the x axis count from the start of each level (the run's total is the
    sum over its panels, as the paper counts it).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [(Path(d), *_load(Path(d))) for d in run_dirs]
    # fine-tuning's panel last (runs with and without it can be overlaid)
    levels = sorted({(int(r["level"]), r["template"]) for _, rows, _ in runs for r in rows},
                    key=lambda k: (k[1] == FINETUNE, k))
    n = max(1, len(levels))
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4), squeeze=False)
    labels = run_labels([d for d, _, _ in runs], [meta for _, _, meta in runs])
    for (d, rows, meta), label in zip(runs, labels):
        by_level = success_points(rows)
        for ax, key in zip(axes[0], levels):
            seeds = by_level.get(key)
            if not seeds:
                continue
            grid, mean, std = mean_over_seeds(seeds)
            line, = ax.plot(grid, mean, label=label)
            ax.fill_between(grid, mean - std, mean + std, alpha=0.2, color=line.get_color())
            if key[1] == FINETUNE:
                _before_after(ax, meta, line.get_color())
    _label_panels(axes[0], levels)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out_path = Path(out_path)
    if not out_path.suffix:  # matplotlib would append .png silently: say the real name
        out_path = out_path.with_name(out_path.name + ".png")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_path, dpi=110)
    plt.close(fig)
    return out_path


def success_points(rows: list[dict]) -> dict:
    """(level, template) -> seed -> [(episodes, running success)] of a run's curve rows
    (rows without a complete success window left out)."""
    by_level = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r["running_success"] == "":
            continue
        by_level[(int(r["level"]), r["template"])][int(r["seed"])].append(
            (int(r["episodes"]), float(r["running_success"])))
    return by_level


def mean_over_seeds(seeds: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(episodes grid, mean, std) of the seeds' curves, each interpolated on a common grid
    of 100 points up to the longest (NaN before a seed's first point, its last value after
    its end)."""
    grid_max = max(pts[-1][0] for pts in seeds.values())
    grid = np.linspace(0, grid_max, 100)
    ys = []
    for pts in seeds.values():
        x, y = np.array(pts).T
        ys.append(np.interp(grid, x, y, left=np.nan, right=y[-1]))
    ys = np.array(ys)
    with warnings.catch_warnings():  # columns before any seed's first point are all-NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        mean, std = np.nanmean(ys, 0), np.nanstd(ys, 0)
    return grid, mean, std


def _label_panels(axes, levels) -> None:
    """Titles, axis labels and legends of the panels, one per (level, template)."""
    for ax, (level, template) in zip(axes, levels):
        finetune = template == FINETUNE
        ax.set_title("fine-tuning, no teleports" if finetune else f"level {level}: {template}")
        ax.set_xlabel("episodes")
        ax.set_ylabel("task success" if finetune else "running success")
        ax.grid(alpha=0.3)
        if not ax.lines:
            ax.text(0.5, 0.5, "no complete success window yet", ha="center", va="center",
                    transform=ax.transAxes, fontsize=8, color="gray")
    # a legend on the first panel that has curves (a level can have none, e.g. a run cut
    # before its first full success window)
    for ax in axes:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
            break
    for ax, (_, template) in zip(axes, levels):  # fine-tuning's before/after lines
        if template == FINETUNE and ax.get_legend() is None and ax.lines:
            ax.legend(fontsize=7)


def plot_run(run_dir) -> Path:
    """A run's own curves.png, drawn from its curves.csv and results.json."""
    run_dir = Path(run_dir)
    return plot_curves([run_dir], run_dir / "curves.png")


class PlotHook(Hook):
    """curves.png beside each results.json a run writes (a sweep: in every ``point-<k>/``),
    as ``smjax train`` draws it: ``run(..., hooks=[PlotHook()])``. It reads the files the
    built-in results hook wrote before it; process 0 draws."""

    # most of matplotlib's import, without choosing a backend (``plot_curves`` picks Agg)
    modules = ("matplotlib.figure", "matplotlib.backends.backend_agg")

    def results(self, trainer, report: ResultsReport) -> None:
        if report.out_dir is not None and dist.is_writer():
            plot_run(report.out_dir)

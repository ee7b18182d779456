"""Learning-curve overlays: every run gets its own legend label; the plot hook draws a
run's curves.png from the files its results hook wrote."""
from pathlib import Path

from smjax.train.hooks import ResultsReport
from smjax.viz.plots import PlotHook, run_labels


def test_runs_of_one_method_are_labelled_apart():
    meta = {"method": "top-down", "algo": "ppo"}
    assert run_labels([Path("runs/a"), Path("runs/b")], [meta, meta]) == [
        "top-down (ppo): a", "top-down (ppo): b"]
    assert run_labels([Path("x/run"), Path("y/run")], [meta, meta]) == [
        "top-down (ppo): x/run", "top-down (ppo): y/run"]
    flat = {"method": "flat", "algo": "ppo"}
    assert run_labels([Path("a"), Path("b")], [meta, flat]) == ["top-down (ppo)", "flat (ppo)"]


def test_the_plot_hook_draws_curves_png_beside_the_results(tmp_path):
    from smjax.train.results import write_results

    results = {"method": "top-down", "algo": "ppo", "final_success": [0.9],
               "finetune": {"final_success_before": [0.5]}}
    curves = [(0, 1, "open_door", e, 10 * e, e / 100) for e in (10, 50, 100)]
    curves += [(0, 2, "finetune", e, 10 * e, 0.5 + e / 400) for e in (20, 80)]
    write_results(tmp_path, results, curves)
    hook = PlotHook()
    hook.results(None, ResultsReport(tmp_path, results, {}))
    assert (tmp_path / "curves.png").stat().st_size > 5000
    hook.results(None, ResultsReport(None, results, {}))  # no directory: nothing to draw

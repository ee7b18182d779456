"""Learning-curve overlays: every run gets its own legend label."""
from pathlib import Path

from smjax.viz.plots import run_labels


def test_runs_of_one_method_are_labelled_apart():
    meta = {"method": "top-down", "algo": "ppo"}
    assert run_labels([Path("runs/a"), Path("runs/b")], [meta, meta]) == [
        "top-down (ppo): a", "top-down (ppo): b"]
    assert run_labels([Path("x/run"), Path("y/run")], [meta, meta]) == [
        "top-down (ppo): x/run", "top-down (ppo): y/run"]
    flat = {"method": "flat", "algo": "ppo"}
    assert run_labels([Path("a"), Path("b")], [meta, flat]) == ["top-down (ppo)", "flat (ppo)"]

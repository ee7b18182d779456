"""The progress bar: one bar counting (seed, stage) pairs, described as the guide says."""
from pathlib import Path
from types import SimpleNamespace

import pytest

pytest.importorskip("tqdm")

from smjax.train.progress import Progress  # noqa: E402


class _Trainer:
    """Two seeds, three levels and fine-tuning: seed 0 at level 2, seed 1 fine-tuning."""

    def __init__(self):
        self.seeds = [0, 1]
        self.plans = [SimpleNamespace(level=i) for i in (1, 2, 3)]
        self.num_stages = 4
        self.cfg = SimpleNamespace(updates_per_chunk=1, num_envs=4, rollout_ticks=8)
        counters = SimpleNamespace(running=0.5, gate_success=None, episodes=10, env_steps=80)
        ft = SimpleNamespace(task_running=0.7)
        self.state = SimpleNamespace(stage=[1, 3], level=[counters, counters], finetune=[ft, ft])

    def _training(self):
        return [0, 1]

    def _finetuning(self, s):
        return s == 1

    def _plan(self, s):
        return self.plans[self.state.stage[s]]

    def _level_cfg(self, s):
        return SimpleNamespace(max_steps_per_level=0)


def test_the_bar_says_it_counts_stages_and_where_the_seeds_are():
    bar = Progress(_Trainer())
    try:
        bar.draw(1.0)
        assert bar.bar.desc == "2 seeds x (3 levels + fine-tune)"
        assert bar.bar.unit == "stage" and bar.bar.total == 8 and bar.bar.n == 4
        assert "seeds_at=L2:1 FT:1" in bar.bar.postfix
    finally:
        bar.bar.close()


def test_the_guide_describes_the_bar_it_shows():
    guide = (Path(__file__).parent.parent / "docs" / "guide.md").read_text()
    text = " ".join(guide.split())
    assert "one progress bar per level" not in text
    assert "`2 seeds x (3 levels + fine-tune): 3/8`" in text and "`seeds_at`" in text

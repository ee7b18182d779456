"""The progress bar: one bar counting (seed, stage) pairs, described as the guide says."""
from pathlib import Path
from types import SimpleNamespace

import pytest

pytest.importorskip("tqdm")

from smjax.train.hooks import ChunkReport  # noqa: E402
from smjax.train.progress import ProgressBar  # noqa: E402
from smjax.train.stages import SeedStatus  # noqa: E402


def test_the_bar_says_it_counts_stages_and_where_the_seeds_are():
    # two seeds, three levels and fine-tuning: seed 0 at level 2, seed 1 fine-tuning
    trainer = SimpleNamespace(seeds=[0, 1], plans=[None] * 3, num_stages=4,
                              state=SimpleNamespace(stage=[1, 3]))
    seeds = [SeedStatus(where="L2", running=0.5, gate=None, task=None, episodes=10,
                        env_steps=80, by_steps=False),
             SeedStatus(where="FT", running=None, gate=None, task=0.7, episodes=10,
                        env_steps=80, by_steps=False)]
    hook = ProgressBar()
    hook.start(trainer)
    try:
        hook.chunk(trainer, ChunkReport(chunk=1, seconds=1.0, steps=64, scalars=[], seeds=seeds,
                                        stages_done=4, stage_ended=False))
        assert hook.bar.desc == "2 seeds x (3 levels + fine-tune)"
        assert hook.bar.unit == "stage" and hook.bar.total == 8 and hook.bar.n == 4
        assert "seeds_at=L2:1 FT:1" in hook.bar.postfix
        assert "task=0.70" in hook.bar.postfix and "success=0.50" in hook.bar.postfix
    finally:
        hook.bar.close()


def test_the_guide_describes_the_bar_it_shows():
    guide = (Path(__file__).parent.parent / "docs" / "guide.md").read_text()
    text = " ".join(guide.split())
    assert "one progress bar per level" not in text
    assert "`2 seeds x (3 levels + fine-tune): 3/8`" in text and "`seeds_at`" in text


def test_the_bar_shows_from_the_start_what_the_seconds_before_training_go_to(capsys):
    from smjax.train.progress import PREPARING

    trainer = SimpleNamespace(seeds=[0, 1], plans=[None] * 2, num_stages=3,
                              state=SimpleNamespace(stage=[0, 0]))
    hook = ProgressBar()
    hook.prepare(trainer)
    assert hook.bar.postfix == PREPARING and hook.bar.total == 6
    hook.start(trainer)  # still compiling or loading until the first chunk reports
    assert hook.bar.postfix == PREPARING
    hook.close()  # a run refused before its first chunk leaves no bar behind its message
    assert hook.bar.disable and not hook.bar.leave
    trained = ProgressBar()
    trained.prepare(trainer)
    seeds = [SeedStatus(where="L1", running=0.5, gate=None, task=None, episodes=10,
                        env_steps=80, by_steps=False)] * 2
    trained.chunk(trainer, ChunkReport(chunk=1, seconds=1.0, steps=64, scalars=[], seeds=seeds,
                                       stages_done=0, stage_ended=False))
    assert PREPARING not in trained.bar.postfix and "seeds_at=L1:2" in trained.bar.postfix
    trained.close()
    assert trained.bar.leave

"""Helpers shared by the resume tests (test_resume, test_sweep, test_finetune)."""
from smjax.train.loop import HierarchyTrainer


class MachineLost(Exception):
    """The machine went away right after a checkpoint (raised by ``lose_machine_after_save``)."""


def lose_machine_after_save(monkeypatch, when) -> None:
    """Make every checkpoint save raise ``MachineLost`` once written, if ``when(trainer)``."""
    save = HierarchyTrainer.save

    def save_then_lose_the_machine(trainer):
        save(trainer)
        if when(trainer):
            raise MachineLost

    monkeypatch.setattr(HierarchyTrainer, "save", save_then_lose_the_machine)

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


def without_levels_bank(out) -> None:
    """Drop the keep-the-better counters from the checkpoint in ``out`` (its arrays stay):
    its seeds resume as from format 3 or older, a seed already fine-tuning without its
    levels' bank."""
    import orbax.checkpoint as ocp

    from smjax.train import checkpoint as ckpt

    info = ckpt.load_meta(out)
    leaves = ocp.StandardCheckpointer().restore(ckpt.checkpoint_dir(out) / info["path"])
    arrays = [leaves[str(i)] for i in range(max(int(k) for k in leaves) + 1)]
    for key in ("check_success", "kept", "baseline"):
        info["meta"]["host"]["finetune"].pop(key)
    ckpt.save_checkpoint(out, info["step"], arrays, info["meta"])


def as_format_3(out, bank_leaves: int) -> None:
    """Rewrite the checkpoint in ``out`` as smjax wrote it before it kept the levels' bank
    for fine-tuning (checkpoint format 3): that bank's ``bank_leaves`` leaves, the last
    ones, dropped."""
    import orbax.checkpoint as ocp

    from smjax.train import checkpoint as ckpt

    info = ckpt.load_meta(out)
    leaves = ocp.StandardCheckpointer().restore(ckpt.checkpoint_dir(out) / info["path"])
    n = max(int(k) for k in leaves) + 1
    arrays = [leaves[str(i)] for i in range(n - bank_leaves)]
    host = info["meta"]["host"]
    for key in ("check_success", "kept", "baseline"):
        host["finetune"].pop(key)
    ckpt.save_checkpoint(out, info["step"], arrays, info["meta"] | {"format": 3})


def as_format_2(out, window: int) -> None:
    """Rewrite the format-3 checkpoint in ``out`` (``as_format_3``) as smjax wrote it before
    the running-success windows were arrays (format 2): the window arrays (the last leaves) dropped,
    each window as the host list of ``[total, count]`` batches that format kept (oldest
    first, trimmed to the most recent batches holding ``window`` episodes)."""
    import numpy as np
    import orbax.checkpoint as ocp

    from smjax.train import checkpoint as ckpt

    info = ckpt.load_meta(out)
    leaves = ocp.StandardCheckpointer().restore(ckpt.checkpoint_dir(out) / info["path"])
    n = max(int(k) for k in leaves) + 1
    # TrainArrays' last fields: window (total, count, next), task_window (total, count, next)
    windows = [np.asarray(leaves[str(i)]) for i in range(n - 6, n)]

    def lists(total, count, nxt):
        out = []
        for t, c, k in zip(total, count, nxt):
            batches, seen = [], 0
            for j in range(len(c)):  # newest first, until the window is covered
                i = (k - 1 - j) % len(c)
                if c[i] == 0 or seen >= window:
                    break
                batches.insert(0, [float(t[i]), int(c[i])])
                seen += int(c[i])
            out.append(batches)
        return out

    host = info["meta"]["host"]
    host["history"] = lists(*windows[:3])
    host["finetune"]["task_history"] = lists(*windows[3:])
    arrays = [leaves[str(i)] if str(i) in leaves else np.zeros((0,)) for i in range(n - 6)]
    ckpt.save_checkpoint(out, info["step"], arrays, info["meta"] | {"format": 2})

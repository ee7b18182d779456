"""A run's saved programs are keyed by the config fields its programs depend on: a run that
changes only a budget, a threshold, a stopping rule or a logging setting
(``OUTSIDE_PROGRAMS``), or a learner's traced hyper-parameter (only the learners' init
depends on those), compiles the very same programs, so it may load an earlier run's
untraced (tests/test_startup.py runs it from the command line)."""
import hashlib
import json

from smjax.train import TrainConfig
from smjax.train import engine as engine_module
from smjax.train import program_cache
from smjax.train.config import OUTSIDE_PROGRAMS, program_config
from smjax.train.run import run

TINY = dict(num_envs=8, rollout_ticks=4, max_episodes_per_level=16, success_window=8,
            eval_envs=8, gate_envs=8, finetune_max_episodes=16, checkpoint_every=1e9)
# every field of OUTSIDE_PROGRAMS, changed from TINY's value (or the default)
CHANGED = dict(threshold=0.5, ceiling_fraction=0.8, max_episodes_per_level=24,
               max_steps_per_level=100_000, gate_interval=3, gate_max_ticks=500,
               eval_max_ticks=500, eval_policies="all", continue_episodes=True,
               level_side_cost_weight=0.5, finetune_threshold=0.5,
               finetune_option_threshold=0.6, finetune_turn_episodes=12, finetune_max_rest=2,
               finetune_continue_episodes=False, finetune_max_episodes=24,
               finetune_plateau_episodes=100, finetune_plateau_gain=0.1,
               finetune_side_cost_weight=0.5, tensorboard=True, checkpoint_every=5.0)


def test_every_field_outside_the_programs_is_checked_here():
    assert sorted(CHANGED) == sorted(OUTSIDE_PROGRAMS)


def test_the_program_config_leaves_out_those_fields_also_per_level():
    base = TrainConfig(**TINY)
    changed = TrainConfig(**(TINY | CHANGED))
    assert program_config(changed) == program_config(base)
    per_level = TrainConfig(levels={"get_wood": {"threshold": 0.6, "success_window": 32}})
    assert program_config(per_level)["levels"] == {"get_wood": {"success_window": 32}}
    assert program_config(TrainConfig(levels={"get_wood": {"threshold": 0.6}}))["levels"] == {}
    for field, value in (("success_window", 16), ("gamma", 0.95), ("num_envs", 16)):
        assert program_config(base.replace(**{field: value})) != program_config(base), field


def _program_texts(cfg: TrainConfig, monkeypatch, tmp_path) -> dict:
    """sha256 of the StableHLO of every program the run keys by its identity, and the
    identities (each program compiled from that lowering, not saved)."""
    texts = {}

    def compile_and_keep_text(jitted, args, name, identity, static=(), donate=()):
        lowered = jitted.lower(*args, *static)
        text = hashlib.sha256(lowered.as_text().encode()).hexdigest()
        texts[name] = (text, json.dumps(identity))
        return lowered.compile()

    with monkeypatch.context() as patched:
        for module in (engine_module, program_cache):
            patched.setattr(module, "compile_program", compile_and_keep_text)
        run("craft/get_wood", cfg, [0], tmp_path, progress=False, overwrite=True)
    return texts


def test_changing_every_field_outside_the_programs_leaves_every_program_as_it_was(
        monkeypatch, tmp_path):
    # (joint fine-tuning, the default, compiles every large program)
    base = TrainConfig(**TINY)
    before = _program_texts(base, monkeypatch, tmp_path)
    # the level chunk, joint fine-tuning's, the episodes program, the learners' init and the
    # environments' reset: the same texts under the same keys
    assert {"chunk", "joint_chunk", "episodes-8", "init"} <= set(before), sorted(before)
    assert len(before) >= 5, sorted(before)
    # and a learner's traced hyper-parameters, which only the init's state holds (the init
    # reads nothing else of the config but the learner's settings)
    hyper = {"agent": {"learning_rate": 2e-3, "ent_coef": 0.02, "clip_eps": 0.3},
             "finetune_agent": {"learning_rate": 2e-4}}
    after = _program_texts(base.replace(**CHANGED, **hyper), monkeypatch, tmp_path)
    assert after.pop("init") != before.pop("init")
    assert after == before
    config = json.loads((tmp_path / "results.json").read_text())["config"]
    assert config["threshold"] == 0.5 and config["agent"]["learning_rate"] == 2e-3

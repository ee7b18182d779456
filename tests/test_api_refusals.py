"""The Python API refuses what cannot be meant: a hierarchy with an option or template the
task never reaches, a task named like a primitive action, a Craft map whose task can never
succeed, and TrainConfig values of the wrong type (numpy scalars of the right kind are
accepted)."""
from __future__ import annotations

import math
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np
import pytest

from hier_env import make_keydoor
from smjax.envs.craft import from_ascii
from smjax.options.hierarchy import HierarchyError, declare
from smjax.train import TrainConfig
from smjax.train.config import ConfigError

STICK_MAP = "\n".join(["############", "#@.........#"] + ["#..........#"] * 8 + ["#.1......g.#",
                                                                                   "############"])


def _keydoor_parts():
    env, _ = make_keydoor()
    names = sorted(env.templates())
    return env, names, list(env.primitive_action_names)


def test_declare_refuses_an_option_the_task_never_reaches():
    env, names, prims = _keydoor_parts()
    first, second = names[0], names[1]
    with pytest.raises(HierarchyError, match=f"never reachable from the task 'root'.*{second}|"
                                             f"{second}.*never reachable from the task 'root'"):
        declare(env, "root", {"root": [first], first: prims, second: prims})


def test_declare_refuses_an_own_template_the_task_never_reaches():
    env, names, prims = _keydoor_parts()
    spare = env.templates()[names[0]]
    with pytest.raises(HierarchyError, match="declared but never reachable"):
        declare(env, "root", {"root": prims}, templates=[spare])
    assert declare(env, "root", {"root": [names[0]]}, templates=[spare]).num_options == 2


def test_declare_refuses_a_task_named_like_a_primitive():
    env, _, prims = _keydoor_parts()
    with pytest.raises(HierarchyError, match="primitive action"):
        declare(env, prims[0], {prims[0]: prims})


def test_from_ascii_refuses_a_make_task_without_its_raw_material():
    with pytest.raises(ValueError, match="no wood .* 'make_stick'"):
        from_ascii(STICK_MAP, task="make_stick")
    state, _ = from_ascii(STICK_MAP.replace("g", "w"), task="make_stick")
    assert state.grid.shape == (12, 12)


@pytest.mark.parametrize("field, value", [
    ("threshold", True), ("gamma", True), ("checkpoint_every", math.inf),
    ("checkpoint_every", math.nan), ("num_envs", True), ("num_envs", np.float32(16))])
def test_train_config_refuses_wrong_types(field, value):
    with pytest.raises(ConfigError, match=field):
        TrainConfig(**{field: value})


def test_train_config_refuses_an_unknown_agent_key():
    with pytest.raises(ConfigError, match="no_such_key"):
        TrainConfig(agent={"no_such_key": 1})


def test_train_config_accepts_numpy_scalars_of_the_right_kind():
    cfg = TrainConfig(num_envs=np.int64(16), threshold=np.float32(0.5), gamma=np.float64(0.9))
    assert cfg.num_envs == 16 and type(cfg.num_envs) is int
    assert cfg.threshold == 0.5 and type(cfg.threshold) is float

"""A saved policy's files: ``RUN/policy/policy.json`` (what it is: task, hierarchy, learner,
how it acts and was evaluated, the config that trained it, versions) and
``RUN/policy/arrays.msgpack`` (every seed's bank of option parameters, which options are
learned, the final evaluation's keys), written with flax's msgpack serialization.

The arrays are written first, then the JSON naming their SHA-256: a crash between the
two leaves a JSON that does not match, refused as damaged, never a policy that loads
half of another run. Every problem reading them is a ``PolicyError`` in one line.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import jax
import numpy as np
from flax import serialization

from smjax.core.files import atomic_write_bytes, atomic_write_text, json_safe
from smjax.core.version import smjax_version

POLICY_DIR = "policy"
META_FILE = "policy.json"
ARRAYS_FILE = "arrays.msgpack"
# the layout of both files; a loader refuses every other (a new layout gets a new number)
POLICY_FORMAT = 1
KIND = "smjax policy"
# what a loader reads of policy.json (the rest documents the run)
REQUIRED = ("task", "seeds", "hierarchy", "learner", "runner", "evaluation", "observation",
            "arrays")


class PolicyError(ValueError):
    """A saved policy cannot be loaded or does not fit what it is loaded for; the message
    names the path and what to do."""


def host_arrays(tree):
    """Every leaf as numpy (PRNG keys as their raw uint32 data)."""
    def one(x):
        if jax.dtypes.issubdtype(getattr(x, "dtype", None), jax.dtypes.prng_key):
            x = jax.random.key_data(x)
        return np.asarray(x)

    return jax.tree.map(one, tree)


def write_policy(run_dir, meta: dict, arrays: dict) -> Path:
    """Write ``arrays`` (``bank``, ``learned``, ``eval_keys``: leading axis one per seed)
    and ``meta`` into ``run_dir/policy``; returns that folder."""
    folder = Path(run_dir) / POLICY_DIR
    data = serialization.msgpack_serialize(serialization.to_state_dict(host_arrays(arrays)))
    atomic_write_bytes(folder / ARRAYS_FILE, data)
    record = {"kind": KIND, "format": POLICY_FORMAT, **meta,
              "arrays": {"file": ARRAYS_FILE, "sha256": hashlib.sha256(data).hexdigest()}}
    atomic_write_text(folder / META_FILE,
                      json.dumps(json_safe(record), indent=2, allow_nan=False) + "\n")
    return folder


def policy_folder(path) -> Path:
    """The policy folder of a run directory (or the folder itself)."""
    path = Path(path)
    return path if (path / META_FILE).is_file() else path / POLICY_DIR


def read_meta(path) -> dict:
    """policy.json of a run directory, checked to be a smjax policy of this format."""
    folder = policy_folder(path)
    meta_path = folder / META_FILE
    if not meta_path.is_file():
        raise PolicyError(f"{path} holds no saved policy (no {meta_path}); train with --out "
                          f"{path}, or resume the run to write it")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise PolicyError(f"{meta_path} is damaged ({str(err)[:100]}); resume the run "
                          f"(smjax train ... --resume) to write it again") from None
    if not isinstance(meta, dict) or meta.get("kind") != KIND:
        raise PolicyError(f"{meta_path} is not a smjax policy file")
    if meta.get("format") != POLICY_FORMAT:
        raise PolicyError(
            f"{meta_path} is a policy of format {meta.get('format')!r}, written by smjax "
            f"{meta.get('smjax_version')}; this smjax reads format {POLICY_FORMAT}: load it "
            f"with that version, or resume the run with this one to write it again")
    missing = [k for k in REQUIRED if k not in meta]
    if missing:
        raise PolicyError(f"{meta_path} is damaged (no {', '.join(missing)}); resume the run "
                          f"to write it again")
    return meta


def read_arrays(path, meta: dict) -> dict:
    """The arrays file named by ``meta``, checked against its SHA-256, as nested dicts of
    numpy arrays (``restore_tree`` gives them their pytree structure)."""
    arrays_path = policy_folder(path) / ARRAYS_FILE
    try:
        data = arrays_path.read_bytes()
    except OSError as err:
        raise PolicyError(f"{arrays_path} cannot be read ({err.strerror or err}); resume the "
                          f"run to write the policy again") from None
    if hashlib.sha256(data).hexdigest() != meta["arrays"]["sha256"]:
        raise PolicyError(f"{arrays_path} is damaged (its checksum does not match "
                          f"{META_FILE}); resume the run to write the policy again")
    return serialization.msgpack_restore(data)


def restore_tree(like, stored, where: str):
    """``stored`` (nested dicts) in the structure of ``like`` (a tree of arrays or shapes),
    every leaf's shape and dtype checked: a policy for another learner or observation is
    refused naming the first leaf that differs."""
    try:
        tree = serialization.from_state_dict(like, stored)
    except (KeyError, ValueError, TypeError) as err:
        raise PolicyError(f"{where}: the saved parameters do not fit this learner ({err})") from None
    expected = jax.tree_util.tree_flatten_with_path(like)[0]
    got = jax.tree.leaves(tree)
    if len(got) != len(expected):
        raise PolicyError(f"{where}: the saved parameters do not fit this learner "
                          f"({len(got)} arrays, {len(expected)} expected)")
    for (key_path, want), have in zip(expected, got):
        if tuple(have.shape) != tuple(want.shape) or have.dtype != want.dtype:
            name = jax.tree_util.keystr(key_path)
            raise PolicyError(f"{where}: saved parameter {name} is {have.dtype}{list(have.shape)}, "
                              f"this learner's is {want.dtype}{list(want.shape)}")
    return tree


def observation_spec(runner) -> dict:
    """What the policies of ``runner`` see (a memory appended where the run had one)."""
    env, params = runner.env, runner.env_params
    obs = jax.eval_shape(lambda k: runner.policy_obs(env.reset_env(k, params)[0][None])[0],
                         jax.random.PRNGKey(0))
    return {"shape": list(obs.shape), "dtype": str(obs.dtype)}


def policy_meta(runner, runner_settings: dict, *, task: str, registered: bool,
                env_overrides: dict, hierarchy: str, declared: dict | None, learner: dict,
                evaluation: dict) -> dict:
    """policy.json's description of a run's policy, but its seeds and config (each point
    of a sweep has its own). ``runner_settings``: the keyword arguments ``runner`` was
    built with; ``learner``: ``{"algo", "agent"}``; ``evaluation``: ``{"policy",
    "option_temperature", "gamma", "episodes", "max_ticks"}`` of the final evaluation."""
    env_name, _, task_name = task.rpartition(":")[2].partition("/")
    return {"task": task, "env": env_name, "task_name": task_name, "registered": registered,
            "env_overrides": env_overrides, "hierarchy": hierarchy,
            "hierarchy_declared": declared, "options": list(runner.h.option_names),
            "learner": learner, "runner": runner_settings, "evaluation": evaluation,
            "observation": observation_spec(runner), "smjax_version": smjax_version(),
            "jax_version": jax.__version__}

"""``smjax.make("ENV/TASK", **overrides)`` and ``smjax.registry()``.

Environment packages register their tasks when imported; the registry imports them
lazily on first use so that ``import smjax`` stays cheap (MuJoCo is only loaded when a
``fetch/...`` task is made).

A user's own tasks live in a module that calls ``register`` when imported. Naming the
task ``MODULE:ENV/TASK`` (``mypkg.envs:keydoor/find_treasure``) imports MODULE first, so
the name alone is enough wherever smjax makes a task again (the CLI, ``--resume``,
``smjax render --policy``).
"""
from __future__ import annotations

import difflib
import importlib
import inspect
import os
import sys
from dataclasses import dataclass
from typing import Any, Callable

from smjax.core.overrides import coerce_annotated

# Modules whose import registers tasks. Order is the listing order.
ENV_MODULES = ("smjax.envs.craft", "smjax.envs.fetch", "smjax.envs.football")


@dataclass(frozen=True)
class RegistryEntry:
    name: str
    factory: Callable[..., tuple[Any, Any]]
    description: str

    @property
    def override_names(self) -> tuple[str, ...]:
        params = inspect.signature(self.factory).parameters.values()
        return tuple(p.name for p in params if p.kind == p.KEYWORD_ONLY)


_REGISTRY: dict[str, RegistryEntry] = {}
_LOADED: set[str] = set()
_LOAD_ERRORS: dict[str, str] = {}


def register(name: str, factory: Callable[..., tuple[Any, Any]], description: str = "") -> None:
    """Register ``factory(**overrides) -> (env, params)`` under ``ENV/TASK``.

    Overrides a task accepts are the factory's keyword-only parameters.
    """
    if name.count("/") != 1 or not all(name.split("/")) or ":" in name:
        raise ValueError(f"task names look like 'ENV/TASK' (no ':'), got {name!r}")
    _REGISTRY[name] = RegistryEntry(name, factory, description)


def _load(env_prefix: str | None = None) -> None:
    for module in ENV_MODULES:
        short = module.rsplit(".", 1)[-1]
        if module in _LOADED or (env_prefix is not None and short != env_prefix):
            continue
        _LOADED.add(module)
        try:
            importlib.import_module(module)
        except ImportError as err:  # keep the others usable; say why on lookup
            _LOAD_ERRORS[short] = f"{type(err).__name__}: {err}"


def import_env_module(module: str) -> None:
    """Import a user's module whose import registers tasks (``register(...)``).

    The working directory is searched last, as ``python -m`` would (the ``smjax`` console
    script's path holds only its own folder), so installed packages are never shadowed.
    """
    if not module or not all(part.isidentifier() for part in module.split(".")):
        raise ValueError(f"{module!r} is not a module name (e.g. mypkg.envs)")
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.append(cwd)
    try:
        importlib.import_module(module)
    except ModuleNotFoundError as err:
        if err.name is None or not module.startswith(err.name):
            raise  # the module was found; something it imports is missing
        # a user's mistake in a name (ValueError), not a missing dependency of smjax
        raise ValueError(f"cannot import {module!r} (looked in the installed packages and "
                         f"{cwd}): {err}") from None


def split_task(name: str) -> tuple[str | None, str]:
    """``MODULE:ENV/TASK`` -> (MODULE, ENV/TASK); a plain ``ENV/TASK`` -> (None, ENV/TASK)."""
    if isinstance(name, str) and ":" in name:
        module, task = name.split(":", 1)
        return module, task
    return None, name


def registry() -> dict[str, str]:
    """All registered task names -> one-line descriptions."""
    _load()
    return {name: entry.description for name, entry in sorted(_REGISTRY.items())}


def unavailable() -> dict[str, str]:
    """Environment packages whose import failed (a dependency not installed): their name
    -> why, which says what to install."""
    _load()
    return dict(sorted(_LOAD_ERRORS.items()))


def get_entry(name: str) -> RegistryEntry:
    module, name = split_task(name)
    if module is not None:
        import_env_module(module)
    if not isinstance(name, str) or "/" not in name:
        _load()
        raise ValueError(
            f"task names look like 'ENV/TASK' or 'MODULE:ENV/TASK' (e.g. 'craft/get_gem', "
            f"'mypkg.envs:keydoor/find_treasure'), got {name!r}. "
            f"Valid names: {', '.join(sorted(_REGISTRY))}"
        )
    _load(name.split("/", 1)[0])
    if name not in _REGISTRY:
        prefix = name.split("/", 1)[0]
        if prefix in _LOAD_ERRORS:  # e.g. an optional dependency not installed
            raise KeyError(f"task {name!r} is not available: environment package {prefix!r} "
                           f"failed to import: {_LOAD_ERRORS[prefix]}")
        _load()
        close = difflib.get_close_matches(name, list(_REGISTRY), n=3)
        maybe = f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        mine = "" if module else (" Your own task: name it MODULE:ENV/TASK, or pass --import "
                                  "MODULE, where MODULE calls smjax.core.register.")
        raise KeyError(f"unknown task {name!r}.{maybe} Valid names: "
                       f"{', '.join(sorted(_REGISTRY))}.{mine}")
    return _REGISTRY[name]


def coerce_overrides(entry: RegistryEntry, overrides: dict[str, Any]) -> dict[str, Any]:
    """Parse text and booleans by the factory parameter's type, strictly and alike for every
    environment (``checkpoint_reward="no"`` is False, never ``bool("no")``). Numbers go to
    the factory as they are: it checks them with the same parsers and knows their range."""
    params = inspect.signature(entry.factory).parameters
    out = {}
    for k, v in overrides.items():
        p = params[k]
        if isinstance(v, str) or str(p.annotation).replace(" ", "") in ("bool", "bool|None"):
            v = coerce_annotated(f"{entry.name} override {k!r}", v, p.annotation, p.default)
        out[k] = v
    return out


def make(name: str, **overrides: Any) -> tuple[Any, Any]:
    """Make an environment and its default params: ``env, params = make("craft/get_gem")``.

    Unknown names and unknown override keys raise errors that list the valid choices.
    """
    entry = get_entry(name)
    valid = entry.override_names
    unknown = sorted(set(overrides) - set(valid))
    if unknown:
        raise TypeError(
            f"unknown override(s) {unknown} for {name!r}; valid overrides: "
            f"{', '.join(valid) if valid else '(none)'}"
        )
    env, params = entry.factory(**coerce_overrides(entry, overrides))
    env.name = name
    return env, params

"""The code's two structural rules, read with ``ast`` from every module of smjax/ (and, for
the second, benchmarks/).

1. Imports run one way: a module imports only its own layer and the layers below it.

    core                      the environment protocol, spaces, registry, files
    options, agents           hierarchies and the tick; learners (each over core alone)
    envs                      environments and their templates (core, options)
    testing                   the contract harness (core, options)
    policy                    saved policies: load, act, evaluate (core, options, agents)
    train                     the engine, trainer, results (core, options, agents, policy);
                              environments come in through core's registry or as objects
    viz                       plots and frames, drawn from train's files and policies
    cli                       the command line (cli*.py, bench, __main__), on top
    root                      ``smjax/__init__.py``: core's make/registry, and
                              ``load_policy`` on first use

   Every import counts, lazy ones inside functions too (they still make the lower layer
   depend on the upper one). The registry loads environment packages by name
   (``importlib.import_module`` of a string), which is not an import statement.

2. Private names stay in their module: no ``from M import _x`` of another module, and no
   ``obj._x`` (nor ``getattr(obj, "_x")``) of a name the reading module does not define
   itself. A name others need gets a public name. Third-party modules' privates, bound by
   an import, and the NamedTuple API (``_replace``, ``_fields``, ...) are outside the rule.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ROOT = REPO / "smjax"

# layer -> the layers below it, which it may import (itself always allowed)
BELOW = {
    "core": set(),
    "options": {"core"},
    "agents": {"core"},
    "envs": {"core", "options"},
    "testing": {"core", "options"},
    "policy": {"core", "options", "agents"},
    "train": {"core", "options", "agents", "policy"},
    "viz": {"core", "options", "agents", "policy", "train"},
    "cli": {"core", "options", "agents", "envs", "testing", "policy", "train", "viz", "root"},
    "root": {"core", "policy"},
}
# Top-level modules of the command-line layer.
CLI_MODULES = {"cli", "cli_train", "cli_errors", "cli_policy", "bench", "__main__"}


def layer_of(module: str) -> str:
    """The layer of a dotted smjax module name (``smjax`` itself is "root")."""
    parts = module.split(".")
    assert parts[0] == "smjax", module
    if len(parts) == 1 or parts[1] == "__init__":
        return "root"
    top = parts[1]
    if top in CLI_MODULES:
        return "cli"
    if top in BELOW:
        return top
    raise AssertionError(f"{module}: no layer assigned; add its package to BELOW")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imported_modules(path: Path) -> list[tuple[int, str]]:
    """(line, dotted smjax module) of every import statement in the file, lazy ones too."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    return imports_in(path.read_text(), package, str(path))


def _resolved(node: ast.ImportFrom, package: str) -> str:
    """The module an ``ImportFrom`` reads, relative imports resolved against ``package``."""
    if not node.level:
        return node.module or ""
    base = package.split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_in(text: str, package: str, filename: str = "<string>") -> list[tuple[int, str]]:
    """(line, dotted smjax module) of every import in ``text``, a module of ``package``."""
    out = []
    for node in ast.walk(ast.parse(text, filename)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            # ``from smjax.envs.craft import dynamics`` imports a submodule: count it at
            # the package's layer (the same layer), so the package name suffices
            out.append((node.lineno, _resolved(node, package)))
    return [(line, m) for line, m in out if m == "smjax" or m.startswith("smjax.")]


MODULES = sorted(ROOT.rglob("*.py"))
SCANNED = MODULES + sorted((REPO / "benchmarks").rglob("*.py"))


def _short(path: Path) -> str:
    return str(path.relative_to(REPO))


def test_every_module_has_a_layer():
    assert MODULES, f"no modules found under {ROOT}"
    for path in MODULES:
        layer_of(module_name(path))


def test_the_layers_are_an_order():
    """No layer reaches itself through the layers below it: the rules allow no circle."""
    for layer in BELOW:
        seen, todo = set(), list(BELOW[layer])
        while todo:
            lower = todo.pop()
            assert lower != layer, f"{layer} reaches itself through {sorted(seen)}"
            if lower not in seen:
                seen.add(lower)
                todo += BELOW[lower]


@pytest.mark.parametrize("path", MODULES, ids=_short)
def test_imports_respect_the_layers(path):
    source = module_name(path)
    src_layer = layer_of(source)
    bad = []
    for line, target in imported_modules(path):
        dst_layer = layer_of(target)
        if dst_layer == src_layer or dst_layer in BELOW[src_layer]:
            continue
        bad.append(f"line {line}: imports {target} ({dst_layer} layer)")
    assert not bad, (f"{source} ({src_layer} layer, may import "
                     f"{sorted(BELOW[src_layer]) or 'nothing else'}): " + "; ".join(bad))


def test_the_rules_named_in_the_design():
    """Named on their own: train imports neither an environment nor plotting, options never
    imports agents, agents never train, and nothing but the entry point imports the command
    line (cli_* are its parts)."""
    for path in MODULES:
        source = module_name(path)
        for line, target in imported_modules(path):
            where = f"{source} line {line} imports {target}"
            if source.startswith("smjax.train"):
                assert not target.startswith(("smjax.envs", "smjax.viz")), where
            if source.startswith("smjax.options"):
                assert not target.startswith("smjax.agents"), where
            if source.startswith("smjax.agents"):
                assert not target.startswith("smjax.train"), where
            if source.startswith(("smjax.options", "smjax.agents", "smjax.policy")):
                assert not target.startswith("smjax.envs"), where
            if target == "smjax.cli" or target.startswith("smjax.cli."):
                assert source == "smjax.__main__", where


# ---- rule 2: private names ---------------------------------------------------------------
NAMEDTUPLE_API = {"_replace", "_fields", "_asdict", "_make", "_field_defaults"}
ATTRIBUTE_CALLS = {"getattr", "setattr", "hasattr", "delattr"}


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__") and name not in NAMEDTUPLE_API


def _defined_here(tree: ast.AST) -> set[str]:
    """The private names a module defines: functions, classes, and names or attributes it
    assigns (``_x = ...``, ``self._x = ...``, ``obj._x = ...``)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            out.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            out.add(node.attr)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out.add(node.target.id)
    return {n for n in out if _private(n)}


def _third_party_names(tree: ast.AST, package: str) -> set[str]:
    """Names bound by importing a module that is not smjax's (``os``, ``jax._src...``)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names
                    if not a.name.startswith("smjax")}
        elif isinstance(node, ast.ImportFrom) and not node.level and \
                not (node.module or "").startswith("smjax"):
            out |= {a.asname or a.name for a in node.names}
    return out


def private_uses(text: str, package: str, filename: str = "<string>") -> list[str]:
    """Where ``text`` (a module of ``package``) uses another module's private name."""
    tree = ast.parse(text, filename)
    mine, foreign = _defined_here(tree), _third_party_names(tree, package)
    bad = []

    def check(line: int, owner: ast.AST, name: str) -> None:
        if not _private(name) or name in mine:
            return
        if isinstance(owner, ast.Name) and owner.id in ({"self", "cls"} | foreign):
            return
        bad.append(f"line {line}: {ast.unparse(owner)}.{name}")

    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = _resolved(node, package)
            if node.level or module.startswith("smjax"):
                bad += [f"line {node.lineno}: from {module} import {a.name}"
                        for a in node.names if _private(a.name)]
        elif isinstance(node, ast.Attribute):
            check(node.lineno, node.value, node.attr)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
                node.func.id in ATTRIBUTE_CALLS and len(node.args) >= 2 and \
                isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str):
            check(node.lineno, node.args[0], node.args[1].value)
    return bad


def _package(path: Path) -> str:
    if path.is_relative_to(ROOT):
        name = module_name(path)
        return name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    return "benchmarks"


@pytest.mark.parametrize("path", SCANNED, ids=_short)
def test_no_private_names_across_modules(path):
    bad = private_uses(path.read_text(), _package(path), str(path))
    assert not bad, f"{_short(path)} uses private names of other modules: " + "; ".join(bad)


def test_the_checkers_see_what_they_look_for():
    """The parsers find plain, from-, lazy and relative imports, and private names used
    across modules but not a module's own (guards the tests themselves)."""
    text = (
        "import smjax\n"
        "import numpy as np\n"
        "from smjax.core.env import Environment\n"
        "def later():\n"
        "    from smjax.viz.plots import plot_curves\n"
        "from . import dynamics\n"
        "from ..fetch import types\n"
    )
    found = sorted(m for _, m in imports_in(text, "smjax.envs.craft"))
    assert found == ["smjax", "smjax.core.env", "smjax.envs.craft", "smjax.envs.fetch",
                     "smjax.viz.plots"], found
    assert layer_of("smjax.envs.craft.reset") == "envs"
    assert layer_of("smjax.cli_policy") == "cli" and layer_of("smjax") == "root"
    uses = (
        "import os\n"
        "from smjax.train.results import _clean\n"
        "from .engine import _decide\n"
        "class A:\n"
        "    def __init__(self):\n"
        "        self._mine = 1\n"
        "def f(engine, args, a, t):\n"
        "    engine._chunk(a._mine, t._replace(x=1), os._exit)\n"
        "    return getattr(args, '_batch', None), hasattr(a, '_mine')\n"
    )
    assert private_uses(uses, "smjax.train") == [
        "line 2: from smjax.train.results import _clean",
        "line 3: from smjax.train.engine import _decide",
        "line 8: engine._chunk", "line 9: args._batch"], private_uses(uses, "smjax.train")

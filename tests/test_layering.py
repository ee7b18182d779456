"""Imports run one way: every module's imports, read with ``ast``, respect the layers.

    core                      imports nothing of smjax above it
    envs, options, agents     import core and their own package (envs may also import
                              options, for their templates and hierarchies)
    testing                   the harness: core, options and itself
    train, viz                anything below; train writes plots with viz and viz reads
                              train's results files, so they form one layer
    cli, cli_train, cli_errors, bench, __main__: the command line, on top; nothing below
                              imports it

Every import counts, including those inside functions (lazy imports still make the lower
layer depend on the upper one). The registry loads environment packages by name
(``importlib.import_module`` of a string), which is not an import statement: core stays
free of environment code.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "smjax"

# layer -> the smjax layers it may import (itself always allowed)
ALLOWED = {
    "core": set(),
    "envs": {"core", "options"},
    "options": {"core"},
    "agents": {"core"},
    "testing": {"core", "options"},
    "train": {"core", "envs", "options", "agents", "testing", "viz", "root"},
    "viz": {"core", "envs", "options", "agents", "testing", "train", "root"},
    "cli": {"core", "envs", "options", "agents", "testing", "train", "viz", "root"},
    "root": {"core"},  # smjax/__init__.py: make and registry
}
# Top-level modules of the command-line layer.
CLI_MODULES = {"cli", "cli_train", "cli_errors", "bench", "__main__"}


def layer_of(module: str) -> str:
    """The layer of a dotted smjax module name (``smjax`` itself is "root")."""
    parts = module.split(".")
    assert parts[0] == "smjax", module
    if len(parts) == 1 or parts[1] == "__init__":
        return "root"
    top = parts[1]
    if top in CLI_MODULES:
        return "cli"
    if top in ALLOWED:
        return top
    raise AssertionError(f"{module}: no layer assigned; add its package to ALLOWED")


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


def imports_in(text: str, package: str, filename: str = "<string>") -> list[tuple[int, str]]:
    """(line, dotted smjax module) of every import in ``text``, a module of ``package``."""
    out = []
    for node in ast.walk(ast.parse(text, filename)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the importing package
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # ``from smjax.envs.craft import dynamics`` imports a submodule: count it
            # at the package's layer (the same layer), so the package name suffices.
            out.append((node.lineno, target))
    return [(line, m) for line, m in out if m == "smjax" or m.startswith("smjax.")]


MODULES = sorted(ROOT.rglob("*.py"))


def test_every_module_has_a_layer():
    assert MODULES, f"no modules found under {ROOT}"
    for path in MODULES:
        layer_of(module_name(path))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT.parent)))
def test_imports_respect_the_layers(path):
    source = module_name(path)
    src_layer = layer_of(source)
    bad = []
    for line, target in imported_modules(path):
        dst_layer = layer_of(target)
        if dst_layer == src_layer or dst_layer in ALLOWED[src_layer]:
            continue
        bad.append(f"line {line}: imports {target} ({dst_layer} layer)")
    assert not bad, (f"{source} ({src_layer} layer, may import "
                     f"{sorted(ALLOWED[src_layer]) or 'nothing else'}): " + "; ".join(bad))


def test_the_specific_one_way_rules():
    """The rules named on their own: options never imports agents, agents never train,
    neither imports an environment module, and nothing but the entry point imports the
    command line."""
    for path in MODULES:
        source = module_name(path)
        for line, target in imported_modules(path):
            where = f"{source} line {line} imports {target}"
            if source.startswith("smjax.options"):
                assert not target.startswith("smjax.agents"), where
            if source.startswith("smjax.agents"):
                assert not target.startswith("smjax.train"), where
            if source.startswith(("smjax.options", "smjax.agents")):
                assert not target.startswith("smjax.envs"), where
            if target == "smjax.cli" or target.startswith("smjax.cli."):
                assert source == "smjax.__main__", where


def test_the_checker_sees_imports():
    """The parser finds plain, from-, lazy and relative imports (guards the test itself)."""
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
    assert layer_of("smjax.cli_train") == "cli"
    assert layer_of("smjax") == "root"

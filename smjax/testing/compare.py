"""Pytree comparisons whose failures name a contract property (used by the checkers)."""
from __future__ import annotations

import contextlib
from contextvars import ContextVar
from typing import Any, Iterator

import jax
import jax.numpy as jnp
import numpy as np

# Tolerances for floats computed by two different programs (jit vs eager, vmap vs loop):
# XLA fuses a vmapped or unjitted computation differently, which changes float32
# rounding by a few ulps; discrete leaves (ints, bools) must still agree exactly.
RTOL, ATOL = 1e-5, 1e-6
_TOLERANCES: ContextVar[tuple[float, float]] = ContextVar("tolerances", default=(RTOL, ATOL))


@contextlib.contextmanager
def tolerances(rtol: float = RTOL, atol: float = ATOL) -> Iterator[None]:
    """Within the block, floats of two programs agree within ``rtol``/``atol``.

    A physics engine's solver (MJX) leaves residuals of ~1e-6 in absolute terms on
    quantities near zero (accelerations at rest), so Fetch is checked with a larger atol.
    """
    token = _TOLERANCES.set((float(rtol), float(atol)))
    try:
        yield
    finally:
        _TOLERANCES.reset(token)


def fail(prop: str, who: str, detail: str) -> None:
    """Raise the harness's AssertionError: the property first, then who, then why."""
    raise AssertionError(f"{prop} failed for {who}: {detail}")


def _first_diff(a: np.ndarray, b: np.ndarray) -> str:
    same = a == b
    if np.issubdtype(a.dtype, np.inexact):
        rtol, atol = _TOLERANCES.get()
        same = same | (np.isnan(a) & np.isnan(b)) | np.isclose(a, b, rtol=rtol, atol=atol)
    diff = np.argwhere(~np.asarray(same).reshape(a.shape))
    if a.ndim == 0 or diff.size == 0:
        return f"{a!r} vs {b!r}"
    idx = tuple(int(i) for i in diff[0])
    return f"first at index {idx}: {a[idx]!r} vs {b[idx]!r} ({len(diff)} elements differ)"


def _leaf_mismatch(a: np.ndarray, b: np.ndarray, exact: bool) -> str | None:
    if a.shape != b.shape or a.dtype != b.dtype:
        return f"shape/dtype {a.shape} {a.dtype} vs {b.shape} {b.dtype}"
    if exact or not np.issubdtype(a.dtype, np.inexact):
        same = np.array_equal(a, b, equal_nan=np.issubdtype(a.dtype, np.inexact))
        return None if same else f"values differ, {_first_diff(a, b)}"
    rtol, atol = _TOLERANCES.get()
    if np.allclose(a, b, rtol=rtol, atol=atol, equal_nan=True):
        return None
    return f"values differ beyond rtol={rtol}, atol={atol}, {_first_diff(a, b)}"


def trees_mismatch(got: Any, want: Any, exact: bool = False) -> str | None:
    """None if two pytrees agree (floats within the tolerances unless ``exact``), else why not."""
    got_leaves, got_def = jax.tree_util.tree_flatten_with_path(got)
    want_leaves, want_def = jax.tree_util.tree_flatten_with_path(want)
    if got_def != want_def:
        return f"tree structures differ: {got_def} vs {want_def}"
    for (path, a), (_, b) in zip(got_leaves, want_leaves):
        # jnp first: a Python scalar leaf (gymnax states start with time=0) is compared as
        # the int32/float32 JAX makes of it, not as NumPy's int64/float64.
        why = _leaf_mismatch(np.asarray(jnp.asarray(a)), np.asarray(jnp.asarray(b)), exact)
        if why is not None:
            return f"leaf {jax.tree_util.keystr(path) or '(value)'}: {why}"
    return None


def assert_trees_close(got: Any, want: Any, *, prop: str, who: str, exact: bool = False,
                       where: str = "") -> None:
    """Raise ``AssertionError`` naming ``prop`` and ``who`` unless the trees agree."""
    why = trees_mismatch(got, want, exact)
    if why is not None:
        fail(prop, who, f"{where}: {why}" if where else why)


def index(tree: Any, *idx: int) -> Any:
    """The element ``idx`` of every leaf of a batched pytree."""
    return jax.tree.map(lambda x: x[idx], tree)


def all_equal(a: Any, b: Any) -> jax.Array:
    """Traceable: True if every leaf of two pytrees of equal structure is equal."""
    eq = [jnp.all(x == y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b))]
    return jnp.all(jnp.stack(eq)) if eq else jnp.asarray(True)

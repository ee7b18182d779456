"""Execution-stack invariants under random push/pop sequences (vs a Python list model)."""
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings, strategies as st

from smjax.options.stack import (
    EMPTY, stack_contains, stack_init, stack_pop, stack_push, stack_tick, stack_top, stack_truncate,
)

D = 4
ops = st.lists(st.tuples(st.sampled_from(["push", "pop", "tick", "truncate"]),
                         st.integers(0, 9), st.booleans()), max_size=30)


def _apply(stack, op, arg, when):
    if op == "push":
        return stack_push(stack, arg, when)
    if op == "pop":
        return stack_pop(stack, when)
    if op == "tick":
        return stack_tick(stack)
    return stack_truncate(stack, jnp.asarray(arg % (D + 2)))


_apply_jit = jax.jit(_apply, static_argnums=(1,))


def _model(model, op, arg, when):
    items = list(model)
    if op == "push" and when and len(items) < D:
        items.append([arg, 0])
    elif op == "pop" and when and items:
        items.pop()
    elif op == "tick":
        for it in items:
            it[1] += 1
    elif op == "truncate":
        items = items[: arg % (D + 2)]
    return items


@settings(max_examples=60, deadline=None)
@given(ops)
def test_stack_matches_list_model(seq):
    stack = stack_init(D, 7)
    model = [[7, 0]]
    for op, arg, when in seq:
        stack = _apply_jit(stack, op, arg, when)
        model = _model(model, op, arg, when)
        depth = int(stack.depth)
        assert depth == len(model)
        assert 0 <= depth <= D
        np.testing.assert_array_equal(np.asarray(stack.option[:depth]), [m[0] for m in model])
        np.testing.assert_array_equal(np.asarray(stack.steps[:depth]), [m[1] for m in model])
        # entries above the top are empty and carry no steps
        assert (np.asarray(stack.option[depth:]) == EMPTY).all()
        assert (np.asarray(stack.steps[depth:]) == 0).all()
        assert int(stack_top(stack)) == (model[-1][0] if model else EMPTY)


def test_push_onto_full_stack_is_ignored_and_pop_empty_is_ignored():
    stack = stack_init(2, 0)
    stack = stack_push(stack, 3)
    full = stack_push(stack, 5)
    assert int(full.depth) == 2 and int(stack_top(full)) == 3
    empty = stack_pop(stack_pop(stack_pop(full)))
    assert int(empty.depth) == 0 and int(stack_top(empty)) == EMPTY


def test_stack_ops_vmap_per_environment():
    stacks = jax.vmap(lambda _: stack_init(3, 0))(jnp.arange(5))
    when = jnp.array([True, False, True, False, True])
    pushed = jax.vmap(stack_push)(stacks, jnp.arange(5) + 1, when)
    np.testing.assert_array_equal(np.asarray(pushed.depth), [2, 1, 2, 1, 2])
    np.testing.assert_array_equal(np.asarray(jax.vmap(stack_top)(pushed)), [1, 0, 3, 0, 5])
    has = jax.vmap(stack_contains, (0, None))(pushed, 3)
    np.testing.assert_array_equal(np.asarray(has), [False, False, True, False, False])

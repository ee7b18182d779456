"""choose_uniform picks only True entries, each about equally often."""
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings, strategies as st

from smjax.core.sampling import choose_uniform


@settings(max_examples=40, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=80), st.integers(0, 2**31 - 1))
def test_choice_is_a_true_entry(bits, seed):
    mask = jnp.asarray(bits)
    index, count = jax.jit(choose_uniform)(jax.random.PRNGKey(seed), mask)
    assert int(count) == sum(bits)
    if sum(bits):
        assert bits[int(index)]
    else:
        assert int(index) == 0


def test_choice_is_uniform():
    mask = jnp.zeros(576, bool).at[jnp.array([3, 50, 51, 300, 575])].set(True)
    keys = jax.random.split(jax.random.PRNGKey(0), 20000)
    idx, _ = jax.jit(jax.vmap(choose_uniform, (0, None)))(keys, mask)
    values, counts = np.unique(np.asarray(idx), return_counts=True)
    assert values.tolist() == [3, 50, 51, 300, 575]
    assert np.allclose(counts / 20000, 0.2, atol=0.02)

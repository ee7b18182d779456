"""Per-tick random draws: every random number of a tick from one key (``Noise``)."""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.core.sampling import key_words
from smjax.envs.football import constants as C
from smjax.envs.football.types import Noise


def _mix32(x: jax.Array) -> jax.Array:
    """A strong 32-bit integer mixer (the "lowbias32" finaliser)."""
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)


def draw_noise(key: jax.Array) -> Noise:
    """All of a tick's random numbers from one key.

    The key's words seed a counter-based generator (an integer hash of key and counter),
    which is far cheaper than drawing 300 numbers with threefry and matters because the
    whole step is only a few thousand operations. Keys given to ``step`` are already
    threefry outputs, so the hash only has to decorrelate the counters; each 32-bit hash
    gives two 16-bit uniforms (resolution 1/65536 is plenty for game events). Normal draws are
    triangular (sum of two uniforms, scaled to unit variance): the game only needs
    symmetric, bell-shaped noise.
    """
    words = key_words(key)
    seed_a = words[0]
    seed_b = words[-1] ^ jnp.uint32(0x9E3779B9) * jnp.uint32(words.shape[0])
    width = C.NUM_UNIFORM + 2 * C.NUM_NORMAL          # even: two 16-bit draws per hash
    counter = jnp.arange(C.NUM_TOTAL * width // 2, dtype=jnp.uint32)
    bits = _mix32((counter * jnp.uint32(0x9E3779B9) + seed_a) ^ seed_b)
    halves = jnp.stack([bits >> 16, bits & jnp.uint32(0xFFFF)], axis=-1)
    u = (halves.astype(jnp.float32) + 0.5) * jnp.float32(2.0**-16)
    u = u.reshape(C.NUM_TOTAL, width)
    pair = u[:, C.NUM_UNIFORM:].reshape(C.NUM_TOTAL, C.NUM_NORMAL, 2)
    normal = (pair[..., 0] + pair[..., 1] - 1.0) * jnp.float32(6.0**0.5)
    # Materialise the draws once: otherwise XLA re-computes the hash inside every
    # fusion that reads it (it counts integer ops as cheap), several times per tick.
    return jax.lax.optimization_barrier(Noise(uniform=u[:, : C.NUM_UNIFORM], normal=normal))

"""Craft's transition with the recipes as tables (craft_recipes_vectorized.py) against smjax's
scalar one: the same states (checked on 20,000 random states and actions, and every workshop),
then a jitted, environment-vmapped 200-step scan of each, 256 environments: its compile seconds,
optimized HLO instructions and median run time. From the repository root:
JAX_PLATFORMS=cpu PYTHONPATH=. python benchmarks/results/program_sources/craft_recipes_bench.py"""
import os
import sys, time
import numpy as np, jax, jax.numpy as jnp
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import craft_recipes_vectorized as vec_dyn
from smjax.envs.craft import dynamics as old
from smjax.envs.craft import constants as C
from smjax.envs.craft.types import CraftState
B = 256
rng = np.random.default_rng(0)
def states(n):
    grid = rng.integers(0, 13, (n, 12, 12)).astype(np.uint8)
    pos = rng.integers(1, 11, (n, 2)).astype(np.int32)
    inv = (rng.random((n, 31)) < 0.4).astype(np.int32) * rng.integers(0, 3, (n, 31)).astype(np.int32)
    return CraftState(grid=jnp.asarray(grid), pos=jnp.asarray(pos), direction=jnp.asarray(rng.integers(0,4,n).astype(np.int32)),
                      inventory=jnp.asarray(inv), step=jnp.zeros(n, jnp.int32))
s = states(20000); a = jnp.asarray(rng.integers(0, 6, 20000).astype(np.int32))
# make workshops be faced often
fo = jax.jit(jax.vmap(old.transition)); fn = jax.jit(jax.vmap(vec_dyn.transition))
o = fo(s, a); n = fn(s, a)
for f in ("grid","pos","direction","inventory","step"):
    assert np.array_equal(np.asarray(getattr(o,f)), np.asarray(getattr(n,f))), f
# exhaustively: every workshop with random inventories
for w in C.WORKSHOPS:
    inv = jnp.asarray((rng.random((20000, 31)) < 0.5).astype(np.int32) * rng.integers(0, 3, (20000, 31)).astype(np.int32))
    ws = jnp.full((20000,), w, jnp.int32)
    x = jax.vmap(lambda i, k: jnp.stack(old.fire_recipes([i[j] for j in range(31)], k)))(inv, ws)
    y = jax.vmap(vec_dyn.fire_recipes)(inv, ws)
    assert np.array_equal(np.asarray(x), np.asarray(y)), w
print("equal")
def scan_steps(tr):
    def f(s, a):
        def body(s, a): 
            s = tr(s, a); return s, s.inventory.sum()
        return jax.lax.scan(body, s, a)
    return jax.jit(jax.vmap(f, (0, 1)))
sb = states(B); acts = jnp.asarray(rng.integers(0, 6, (200, B)).astype(np.int32))
for name, tr in (("old", old.transition), ("new", vec_dyn.transition), ("old", old.transition), ("new", vec_dyn.transition)):
    f = scan_steps(tr)
    t0 = time.perf_counter(); lo = f.lower(sb, acts); c = lo.compile(); tc = time.perf_counter() - t0
    import re
    ninst = len(re.findall(r"^\s+(?:ROOT )?%\S+ = ", c.as_text(), re.M))
    jax.block_until_ready(c(sb, acts)); ts = []
    for _ in range(7):
        t0 = time.perf_counter(); jax.block_until_ready(c(sb, acts)); ts.append(time.perf_counter() - t0)
    print(name, "compile %.2f s" % tc, "hlo", ninst, "run median %.2f ms" % (1e3*np.median(ts)))

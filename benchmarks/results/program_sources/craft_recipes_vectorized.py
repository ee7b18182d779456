"""Craft's transition with the inventory as one vector and the recipes as tables: one
workshop's recipes (in file order) picked by selects, each fired by a reduction over the kinds.
Measured, not adopted (craft_recipes_bench.py): fewer instructions, a slower step on a CPU."""
import numpy as np, jax.numpy as jnp
from smjax.envs.craft import constants as C
from smjax.envs.craft.types import CraftState
N = C.GRID_SIZE

def _tables():
    per = {w: [r for r in C.RECIPE_IDS if r[2] == w] for w in C.WORKSHOPS}
    K = max(len(v) for v in per.values())
    need = np.zeros((len(C.WORKSHOPS), K, C.NUM_KINDS), bool)
    delta = np.zeros((len(C.WORKSHOPS), K, C.NUM_KINDS), np.int32)
    for wi, w in enumerate(C.WORKSHOPS):
        for j, (out, ins, _) in enumerate(per[w]):
            need[wi, j, list(ins)] = True
            delta[wi, j, list(ins)] = -1
            delta[wi, j, out] += 1
    return need, delta
NEED, DELTA = _tables()

def fire_recipes(inv, workshop):
    # one workshop's recipes in file order; a table picked by selects, not a gather
    need = jnp.zeros(NEED.shape[1:], bool); delta = jnp.zeros(DELTA.shape[1:], inv.dtype)
    for wi, w in enumerate(C.WORKSHOPS):
        at = workshop == w
        need = jnp.where(at, NEED[wi], need); delta = jnp.where(at, DELTA[wi], delta)
    active = jnp.any(need, axis=1)
    for j in range(NEED.shape[1]):
        fire = active[j] & jnp.all((inv > 0) | ~need[j])
        inv = inv + jnp.where(fire, delta[j], 0)
    return inv

KINDS = np.arange(C.NUM_KINDS)
def transition(state, action):
    action = jnp.asarray(action, jnp.int32)
    is_move = (action >= 0) & (action < 4)
    is_use = action == C.USE
    direction = jnp.where(is_move, action, state.direction)
    dx = jnp.where(direction == C.LEFT, -1, jnp.where(direction == C.RIGHT, 1, 0))
    dy = jnp.where(direction == C.DOWN, -1, jnp.where(direction == C.UP, 1, 0))
    ahead_x = state.pos[0] + dx; ahead_y = state.pos[1] + dy
    flat = state.grid.reshape(-1)
    ahead_idx = ahead_x * N + ahead_y
    ahead_kind = flat[ahead_idx].astype(jnp.int32)
    moved = is_move & (ahead_kind == C.EMPTY)
    pos = jnp.stack([jnp.where(moved, ahead_x, state.pos[0]), jnp.where(moved, ahead_y, state.pos[1])])
    inv = state.inventory
    grab = is_use & (ahead_kind >= C.PRIMITIVE_IDS[0]) & (ahead_kind <= C.PRIMITIVE_IDS[-1])
    cross = is_use & (ahead_kind == C.WATER) & (inv[C.BRIDGE] > 0)
    mine = is_use & (ahead_kind == C.STONE) & (inv[C.AXE] > 0)
    inv = fire_recipes(inv, jnp.where(is_use, ahead_kind, C.EMPTY))
    inv = inv + ((KINDS == ahead_kind) & grab).astype(inv.dtype) - ((KINDS == C.BRIDGE) & cross).astype(inv.dtype)
    clear = grab | cross | mine
    cell_ids = jnp.arange(N * N, dtype=jnp.int32)
    flat = jnp.where((cell_ids == ahead_idx) & clear, jnp.uint8(C.EMPTY), flat)
    return CraftState(grid=flat.reshape(N, N), pos=pos, direction=direction, inventory=inv, step=state.step + 1)

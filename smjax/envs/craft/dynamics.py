"""Craft's transition and reward: pure, branch-free functions of one (unbatched) state.

Rules (docs/environments.md, Craft):

* A move (DOWN/UP/LEFT/RIGHT) always sets the facing direction and moves one cell if the
  target cell is empty; any occupied cell blocks (the boundary ring keeps the agent inside).
* USE acts on the faced cell: a primitive is picked up (+1, cell cleared); at a workshop every
  recipe of that workshop fires, in file order, whose inputs the *running* inventory holds
  (each consumes one of each input and yields 1, so a later recipe sees earlier outputs);
  water with a bridge held is removed and one bridge consumed; stone with an axe held is
  removed and the axe kept. Anything else: nothing happens.
* NOOP (5), and any other id outside 0..4, changes nothing but the step counter.
* Reward for goal G: ``max(0, [inv[G] > 0] - 0.1 * (sum(inv) - inv[G]))``, i.e. every held
  unit of every other item costs 0.1 (multiplicity counts; extra units of G itself are free).
  ``terminated`` = G held; ``truncated`` = the step cap reached without G.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from smjax.envs.craft import constants as C
from smjax.envs.craft.types import CraftParams, CraftState

N = C.GRID_SIZE


def fire_recipes(counts: list[jax.Array], workshop: jax.Array) -> list[jax.Array]:
    """Apply one USE at ``workshop`` (a kind id; anything else: none) to per-kind counts.

    Works on a list of 31 scalars rather than the inventory vector: under vmap each
    ``.at[i].add`` on a [B, 31] array is its own pass over memory, while scalar arithmetic
    fuses into one loop.
    """
    counts = list(counts)
    for out, ins, at in C.RECIPE_IDS:
        fire = workshop == at
        for i in ins:
            fire = fire & (counts[i] > 0)
        delta = fire.astype(counts[out].dtype)
        for i in ins:
            counts[i] = counts[i] - delta
        counts[out] = counts[out] + delta
    return counts


def transition(state: CraftState, action: jax.Array) -> CraftState:
    """The next state (step counter included) after one primitive action (0..5)."""
    action = jnp.asarray(action, jnp.int32)
    is_move = (action >= 0) & (action < 4)
    is_use = action == C.USE
    direction = jnp.where(is_move, action, state.direction)
    # Arithmetic instead of a table lookup (a gather under vmap); DOWN/UP/LEFT/RIGHT.
    dx = jnp.where(direction == C.LEFT, -1, jnp.where(direction == C.RIGHT, 1, 0))
    dy = jnp.where(direction == C.DOWN, -1, jnp.where(direction == C.UP, 1, 0))
    ahead_x = state.pos[0] + dx  # target of a move / faced cell of a USE
    ahead_y = state.pos[1] + dy
    flat = state.grid.reshape(-1)
    ahead_idx = ahead_x * N + ahead_y
    ahead_kind = flat[ahead_idx].astype(jnp.int32)

    moved = is_move & (ahead_kind == C.EMPTY)
    pos = jnp.stack([jnp.where(moved, ahead_x, state.pos[0]),
                     jnp.where(moved, ahead_y, state.pos[1])])

    counts = [state.inventory[k] for k in range(C.NUM_KINDS)]
    grab = is_use & (ahead_kind >= C.PRIMITIVE_IDS[0]) & (ahead_kind <= C.PRIMITIVE_IDS[-1])
    cross = is_use & (ahead_kind == C.WATER) & (counts[C.BRIDGE] > 0)
    mine = is_use & (ahead_kind == C.STONE) & (counts[C.AXE] > 0)
    counts = fire_recipes(counts, jnp.where(is_use, ahead_kind, C.EMPTY))
    for k in C.PRIMITIVE_IDS:
        counts[k] = counts[k] + (grab & (ahead_kind == k)).astype(counts[k].dtype)
    counts[C.BRIDGE] = counts[C.BRIDGE] - cross.astype(counts[C.BRIDGE].dtype)
    clear = grab | cross | mine
    # Compare-and-select over the 144 cells instead of a scatter: under vmap it fuses into
    # one elementwise loop, where a batched scatter is a slow per-row loop on CPU.
    cell_ids = jnp.arange(N * N, dtype=jnp.int32)
    flat = jnp.where((cell_ids == ahead_idx) & clear, jnp.uint8(C.EMPTY), flat)
    return CraftState(
        grid=flat.reshape(N, N),
        pos=pos,
        direction=direction,
        inventory=jnp.stack(counts),
        step=state.step + 1,
    )


def reward_and_done(state: CraftState, params: CraftParams):
    """(reward float32, terminated bool, truncated bool) of the state after a step."""
    inv = state.inventory
    goal_count = inv[params.goal]
    have = goal_count > 0
    others = jnp.sum(inv) - goal_count
    reward = jnp.maximum(0.0, have.astype(jnp.float32) - 0.1 * others.astype(jnp.float32))
    terminated = have
    truncated = (state.step >= params.max_steps) & ~terminated
    return reward, terminated, truncated

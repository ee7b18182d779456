"""Craft's transition and reward: pure, branch-free functions of one (unbatched) state.

Rules (ENVIRONMENTS.md section 3):

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
import numpy as np

from smjax.envs.craft import constants as C
from smjax.envs.craft.structs import CraftParams, CraftState

N = C.GRID_SIZE
_DELTAS = jnp.asarray(C.DIRECTION_DELTAS)
_GRABBABLE = np.zeros(C.NUM_KINDS, bool)
_GRABBABLE[list(C.PRIMITIVE_IDS)] = True


def fire_recipes(inventory: jax.Array, workshop: jax.Array) -> jax.Array:
    """Apply one USE at ``workshop`` (a kind id, or anything else for none) to an inventory."""
    for out, ins, at in C.RECIPE_IDS:
        held = jnp.asarray(True)
        for i in ins:
            held = held & (inventory[i] > 0)
        fire = (workshop == at) & held
        delta = fire.astype(inventory.dtype)
        for i in ins:
            inventory = inventory.at[i].add(-delta)
        inventory = inventory.at[out].add(delta)
    return inventory


def transition(state: CraftState, action: jax.Array) -> CraftState:
    """The next state (step counter included) after one primitive action (0..5)."""
    action = jnp.asarray(action, jnp.int32)
    is_move = (action >= 0) & (action < 4)
    is_use = action == C.USE
    direction = jnp.where(is_move, action, state.direction)
    delta = _DELTAS[direction]
    ahead = state.pos + delta  # the target of a move, or the faced cell of a USE
    flat = state.grid.reshape(-1)
    ahead_idx = ahead[0] * N + ahead[1]
    ahead_kind = flat[ahead_idx].astype(jnp.int32)

    moved = is_move & (ahead_kind == C.EMPTY)
    pos = jnp.where(moved, ahead, state.pos)

    inv = state.inventory
    grab = is_use & jnp.asarray(_GRABBABLE)[ahead_kind]
    cross = is_use & (ahead_kind == C.WATER) & (inv[C.BRIDGE] > 0)
    mine = is_use & (ahead_kind == C.STONE) & (inv[C.AXE] > 0)
    workshop = jnp.where(is_use, ahead_kind, C.EMPTY)
    inv = fire_recipes(inv, workshop)
    inv = inv.at[ahead_kind].add(grab.astype(inv.dtype))
    inv = inv.at[C.BRIDGE].add(-cross.astype(inv.dtype))
    clear = grab | cross | mine
    # Compare-and-select over the 144 cells instead of a scatter: under vmap it fuses into
    # one elementwise loop, where a batched scatter would be a slow per-row loop on CPU.
    cell_ids = jnp.arange(N * N, dtype=jnp.int32)
    flat = jnp.where((cell_ids == ahead_idx) & clear, jnp.uint8(C.EMPTY), flat)
    return CraftState(
        grid=flat.reshape(N, N),
        pos=pos,
        direction=direction,
        inventory=inv,
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

"""Where a trained hierarchy's teleport-free episodes end: per seed, the share with a
positive return, the return's distribution, episode lengths, episodes still running
at the tick cap, the ticks each option spends on top of the stack, which option
was on top when an episode ended short of full success, and what each deciding option
chose (any environment: where a hierarchy loses its episodes, and which choice loops).

    python benchmarks/diagnose_hierarchy.py RUN_DIR [--episodes 1024] [--policy sample]
        [--max-ticks 2000] [--json OUT.json] [--trace N]

RUN_DIR is a finished ``smjax train ... --out RUN_DIR``: its saved policy
(``smjax.load_policy``) is what runs. Every seed's hierarchy runs alone
(root on the stack, no teleports, nobody learning), as the final evaluation does, and
each environment's first episode counts.

Reading it on Craft: an episode's return is ``max(0, [goal held] - 0.1 x other items
held)`` at its end, so a positive return means the goal was reached, and ``(1 - return)
/ 0.1`` is the number of other items still held (get_gem keeps its axe: 1 at best).
Episodes with return 0 either ran into the step cap or ended holding ten items or more.

``--trace N`` also prints N episodes of the first seed that ended short of the task's best
(after the report, on standard error; the seed's environments are played again from its reset
key, at most 256 of them, so with up to 256 --episodes from the report's start states): the
start state where the environment has a text form (``Environment.describe``; Craft: the map),
then the episode as runs of ticks with the same option on top and the same inventory, with
the agent's position where the state has one.
"""
from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from smjax.envs.craft import constants as C
from smjax.options.runner import NO_OPTION, Controls
from smjax.options.stack import stack_top
from smjax.options.episodes import EVAL_TEMPERATURES, eval_temperatures
from smjax.policy import load_policy


def _frozen_controls(learned, temperature, gamma: float) -> Controls:
    """The final evaluation's controls: root on the stack, no teleports, nobody learns,
    episodes reset where the task ends (``gamma``: the run's discount; nothing reads it)."""
    return Controls(jnp.asarray(NO_OPTION), jnp.asarray(0), learned, gamma=gamma,
                    teleport=jnp.asarray(False), temperature=temperature, acts_frozen=True)


def _item_name(kinds, k: int) -> str:
    """Item ``k``'s name where the environment's items are named (Craft), else its index."""
    return kinds[k] if kinds else str(k)


def _inventory(state):
    """Item counts [B, K] where the state has an inventory (Craft), else None."""
    inv = getattr(state, "inventory", None)
    return None if inv is None else inv.astype(jnp.float32)


def episodes_program(runner, gamma: float, num_envs: int, max_ticks: int):
    """jit(vmap over seeds) of: run ``num_envs`` environments until each has finished one
    episode; per environment (return, success, length in ticks, finished), and, where the
    state has an inventory, the units of each item gained per option [O, K] (summed over
    first episodes; a gain counts for the option on top of the stack when the tick starts,
    so a call's first step counts for its caller; an episode's last step is not seen), and
    each environment's inventory before its first episode's last tick [B, K];
    the ticks of each first episode with each option on top [B, O]; the option on top
    in each first episode's last tick [B]; and how often the option on top chose each
    action where it decided [B, O, A] (the tick's own pick: the same keys as ``tick``)."""
    O, A = runner.h.num_options, runner.h.num_actions

    def one_seed(key, bank, learned, temperature):
        controls = _frozen_controls(learned, temperature, gamma)
        k_reset, key = jax.random.split(key)
        carry = runner.reset(k_reset, controls, num_envs)
        deciding = runner.deciding(learned, False)  # fixed for the whole run (top_choice)
        callable_ = runner.callable_options(deciding, controls.learner, False)
        zeros = jnp.zeros((num_envs,), jnp.float32)

        def cond(c):
            return ~c[2].all() & (c[6] < max_ticks)

        def body(c):
            carry, key, done, ret, success, length, t, gains, on_top, last_top, chosen, held = c
            key, k = jax.random.split(key)
            before = _inventory(carry.env_state)
            if before is not None:
                held = jnp.where(done[:, None], held, before)
            top = jnp.maximum(jax.vmap(stack_top)(carry.stack), 0)
            chosen = chosen + jnp.where(done[:, None, None], 0, top_choice(carry, k, top))
            carry, _, ends = runner.tick(carry, k, None, bank, controls)  # nobody learns
            if before is not None:
                counted = (~ends.reset & ~done)[:, None]
                gain = jnp.where(counted, jnp.maximum(_inventory(carry.env_state) - before, 0), 0)
                gains = gains + jax.nn.one_hot(top, O).T @ gain
            first = ends.finished & ~done
            on_top = on_top + jnp.where(done[:, None], 0, jax.nn.one_hot(top, O, dtype=jnp.int32))
            return (carry, key, done | ends.finished, jnp.where(first, ends.ret, ret),
                    jnp.where(first, ends.success, success), jnp.where(first, t + 1, length),
                    t + 1, gains, on_top, jnp.where(done, last_top, top), chosen, held)

        def top_choice(carry, k, top):
            """int32 [B, O, A]: one-hot of the top option's pick where it decides now,
            computed as ``tick`` does (its split of ``k``; teleports are off)."""
            k_act, k_frozen = jax.random.split(k, 6)[:2]
            _, _, frozen, _ = runner.policy_choices(carry, None, bank, controls, callable_,
                                                   k_act, k_frozen)
            pick = jnp.take_along_axis(frozen, top[:, None], 1)[:, 0]
            decides = deciding[top]
            return (jax.nn.one_hot(top, O, dtype=jnp.int32)[:, :, None]
                    * (jax.nn.one_hot(pick, A, dtype=jnp.int32) * decides[:, None])[:, None, :])

        inv = _inventory(carry.env_state)
        K = 0 if inv is None else inv.shape[-1]
        gains = jnp.zeros((O, K), jnp.float32)
        init = (carry, key, jnp.zeros((num_envs,), bool), zeros, zeros,
                jnp.zeros((num_envs,), jnp.int32), jnp.asarray(0), gains,
                jnp.zeros((num_envs, O), jnp.int32), jnp.zeros((num_envs,), jnp.int32),
                jnp.zeros((num_envs, O, A), jnp.int32), jnp.zeros((num_envs, K), jnp.float32))
        _, _, done, ret, success, length, _, gains, on_top, last_top, chosen, held = \
            jax.lax.while_loop(cond, body, init)
        return ret, success, length, done, gains / num_envs, on_top, last_top, chosen, held

    return jax.jit(jax.vmap(one_seed, in_axes=(0, 0, 0, None)))


TRACE_ENVS = 256  # environments a trace plays (its per-tick record is [ticks, envs, items])


def trace_program(runner, gamma: float, num_envs: int, ticks: int):
    """jit of: one seed's ``num_envs`` environments for ``ticks`` ticks from reset, as the
    evaluation plays them (nobody learns); the start states, and per tick [T, B] the option
    on top, the inventory [T, B, K] and position [T, B, 2] (zero-width where the state has
    none), whether an episode ended, and its success."""
    def play(key, bank, learned, temperature):
        controls = _frozen_controls(learned, temperature, gamma)
        k_reset, key = jax.random.split(key)
        carry = runner.reset(k_reset, controls, num_envs)

        def tick(carry, k):
            state, empty = carry.env_state, jnp.zeros((num_envs, 0), jnp.int32)
            inventory = getattr(state, "inventory", empty)
            pos = getattr(state, "pos", empty)
            top = jax.vmap(stack_top)(carry.stack)
            carry, _, ends = runner.tick(carry, k, None, bank, controls)
            return carry, (top, inventory, pos, ends.finished, ends.success)

        _, per_tick = jax.lax.scan(tick, carry, jax.random.split(key, ticks))
        return carry.env_state, per_tick

    return jax.jit(play)


def trace_lost(runner, start, per_tick, count: int, kinds) -> str:
    """Text of up to ``count`` first episodes that ended short of the task's best (or were
    still running): the start state, then runs of ticks with the same option on top and
    inventory (``ticks A-B option held={...} pos P..Q``)."""
    top, inventory, pos, finished, success = (np.asarray(x) for x in per_tick)
    T, B = top.shape
    end = np.where(finished.any(0), finished.argmax(0), T - 1)
    short = [b for b in range(B) if not finished[end[b], b]
             or success[end[b], b] < runner.h.success_ceiling - 1e-6]
    names, lines = runner.h.option_names, []
    for b in short[:count]:
        ran = "ran into the trace's end" if not finished[end[b], b] else \
            f"ended with success {success[end[b], b]:.2f}"
        lines.append(f"== episode {b}: {end[b] + 1} ticks, {ran}")
        text = runner.env.describe(jax.tree.map(lambda x: x[b], start))
        if text:
            lines.append(text)
        runs = []  # [first tick, last tick, (option, held), position at first, at last]
        for t in range(end[b] + 1):
            held = {_item_name(kinds, k): int(v)
                    for k, v in enumerate(inventory[t, b]) if v}
            what = (names[top[t, b]] if top[t, b] >= 0 else "-", held)
            where = tuple(pos[t, b].tolist())
            if runs and runs[-1][2] == what:
                runs[-1][1], runs[-1][4] = t, where
            else:
                runs.append([t, t, what, where, where])
        for first, last, (option, held), start_at, end_at in runs:
            at = f" pos {start_at}..{end_at}" if start_at else ""
            lines.append(f"  ticks {first}-{last} {option} held={held}{at}")
    return "\n".join(lines) if lines else "(no episode ended short of the best)"


def where_time_goes(on_top, last_top, chosen, success, done, names, action_names,
                    best: float = 1.0) -> dict:
    """Mean ticks per episode with each option on top, in fully successful episodes (at the
    task's ``best`` success) and in the others; the share of the others that ended (or hit
    the cap) with each option on top; and the mean number of times per episode each deciding
    option chose each of its children, in both kinds of episode (where a loop is: which
    choice repeats)."""
    on_top, last_top, chosen, success, done = (np.asarray(x) for x in
                                               (on_top, last_top, chosen, success, done))
    full = done & (success >= best - 1e-6)  # the task's best (Hierarchy.success_ceiling)

    def ticks(mask):
        if not mask.any():
            return None
        means = on_top[mask].mean(0)
        return {n: round(float(m), 1) for n, m in zip(names, means) if m >= 0.05}

    def choices(mask):
        if not mask.any():
            return None
        means = chosen[mask].mean(0)  # [O, A]
        return {names[o]: {action_names[a]: round(float(means[o, a]), 1)
                           for a in np.flatnonzero(means[o] >= 0.05)}
                for o in range(means.shape[0]) if means[o].sum() >= 0.05}

    short = ~full
    ended = collections.Counter(names[o] for o in last_top[short].tolist())
    return {"ticks_on_top_full_success": ticks(full), "ticks_on_top_others": ticks(short),
            "top_at_end_of_others": {k: round(v / max(short.sum(), 1), 3)
                                     for k, v in ended.most_common()},
            "choices_full_success": choices(full), "choices_others": choices(short)}


def held_at_end(held, ret, success, done, kinds, best: float = 1.0) -> dict:
    """Mean units of each item held before the last tick of the episodes that returned
    nothing (ran into the cap) and of those that ended with a positive return below the
    task's ``best`` success (what the task charged for), where the state has an inventory."""
    held, ret, success, done = (np.asarray(x) for x in (held, ret, success, done))
    out = {}
    for name, mask in (("held_before_end_of_zero_return", done & (ret <= 0)),
                       ("held_before_end_of_short_return",
                        done & (ret > 0) & (success < best - 1e-6))):
        means = held[mask].mean(0) if mask.any() else np.zeros(held.shape[-1])
        out[name] = {_item_name(kinds, k): round(float(v), 2)
                     for k, v in enumerate(means) if v >= 0.05}
    return out


def summarize(ret, success, length, done) -> dict:
    """One seed's episodes as numbers a reader can act on."""
    ret, success, length, done = (np.asarray(x) for x in (ret, success, length, done))
    positive = done & (ret > 0)
    rounded = collections.Counter(np.round(ret[done], 2).tolist())
    return {
        "success": float(success.mean()),
        "return": float(ret.mean()),
        "positive_return": float(positive.mean()),
        "unfinished": float((~done).mean()),
        "return_histogram": {f"{k:.2f}": v for k, v in sorted(rounded.items())},
        "length_positive_median": float(np.median(length[positive])) if positive.any() else None,
        "length_positive_p90": float(np.percentile(length[positive], 90)) if positive.any() else None,
        "length_zero_median": (float(np.median(length[done & (ret <= 0)]))
                               if (done & (ret <= 0)).any() else None),
        "success_histogram": {f"{k:.2f}": v for k, v in sorted(collections.Counter(
            np.round(success[done], 2).tolist()).items())},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=1024, help="episodes per seed")
    parser.add_argument("--policy", default="sample", choices=sorted(EVAL_TEMPERATURES))
    parser.add_argument("--max-ticks", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", help="also write the report here")
    parser.add_argument("--trace", type=int, default=0, metavar="N",
                        help="also print N of the first seed's episodes that ended short of "
                             "the best, tick by tick (on standard error)")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.max_ticks < 1 or args.trace < 0:
        parser.error("--episodes and --max-ticks must be >= 1, --trace >= 0")
    policy = load_policy(args.run_dir)
    runner, (bank, learned), seeds = policy.runner, policy.params(), policy.seeds
    program = episodes_program(runner, policy.gamma, args.episodes, args.max_ticks)
    keys = jax.random.split(jax.random.key(args.seed), len(seeds))
    temperature = eval_temperatures(args.policy, runner.h.num_options,
                                    policy.meta["evaluation"]["option_temperature"])
    out = program(keys, bank, learned, temperature)
    names = list(runner.h.option_names)
    action_names = list(runner.h.primitive_names[:runner.h.num_primitives]) + names[1:]
    per_seed = [summarize(*(x[i] for x in out[:4]))
                | where_time_goes(out[5][i], out[6][i], out[7][i], out[1][i], out[3][i], names,
                                  action_names, runner.h.success_ceiling)
                for i in range(len(seeds))]
    gains = np.asarray(out[4]).mean(0)  # [O, K], mean over seeds, per episode
    kinds = C.KIND_NAMES if gains.shape[1] == C.NUM_KINDS else None  # Craft's item names
    if gains.shape[1]:
        for i, p in enumerate(per_seed):
            p |= held_at_end(out[8][i], out[0][i], out[1][i], out[3][i], kinds,
                             runner.h.success_ceiling)
    picked = {runner.h.option_names[o]: {_item_name(kinds, k): round(float(v), 3)
                                         for k, v in enumerate(gains[o]) if v >= 0.005}
              for o in range(gains.shape[0]) if gains[o].sum() >= 0.005}
    report = {"run_dir": str(args.run_dir), "policy": args.policy, "episodes": args.episodes,
              "seeds": seeds, "per_seed": per_seed,
              "gained_per_episode_by_option": picked,
              "mean": {k: float(np.mean([p[k] for p in per_seed]))
                       for k in ("success", "return", "positive_return", "unfinished")}}
    text = json.dumps(report, indent=1)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    if args.trace:  # the first seed's start states again (its reset key), fresh tick keys
        first = jax.tree.map(lambda x: x[0], (bank, learned))
        program = trace_program(runner, policy.gamma, min(args.episodes, TRACE_ENVS),
                                args.max_ticks)
        start, per_tick = program(keys[0], *first, temperature)
        print(trace_lost(runner, start, per_tick, args.trace, kinds), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""AI-vs-AI ladder for smjax football: does a harder built-in AI beat an easier one?

Plays every ordered pair of difficulties (row = team A, column = team B) for
``--games`` matches of ``--steps`` ticks, vmapped in one compiled program. Half the
matches of a pair have A on the left (kicking off), half on the right, so the kick-off
advantage cancels. Prints a markdown table of A's mean goal difference (with its
standard error) and A's goals per match.

    JAX_PLATFORMS=cpu python benchmarks/football_ai_ladder.py --games 32 --steps 3000

``--gif PATH`` also records one episode of ``football/11v11_easy`` (the agent's team
on the built-in AI at 0.95, action 19 for all 11) as an animated GIF, every
``--gif-every``-th tick for ``--gif-steps`` ticks.
"""
from __future__ import annotations

import argparse
import itertools
import time

import jax
import jax.numpy as jnp
import numpy as np

from smjax.envs.football.match import play_match


def ladder(difficulties: list[float], games: int, steps: int, seed: int = 0) -> dict:
    if games < 2 or games % 2:
        raise ValueError(f"--games must be an even number >= 2 (half on each side), got {games}")
    pairs = list(itertools.product(range(len(difficulties)), repeat=2))
    diff = jnp.asarray(difficulties, jnp.float32)
    a_idx = np.repeat([p[0] for p in pairs], games)
    b_idx = np.repeat([p[1] for p in pairs], games)
    a_left = np.tile(np.arange(games) < games // 2, len(pairs))
    left = np.where(a_left, a_idx, b_idx)
    right = np.where(a_left, b_idx, a_idx)
    match_diffs = jnp.stack([diff[left], diff[right]], axis=1)
    keys = jax.random.split(jax.random.PRNGKey(seed), len(a_idx))
    play = jax.jit(jax.vmap(play_match, in_axes=(0, 0, None)), static_argnums=2)
    t0 = time.perf_counter()
    scores = np.asarray(play(keys, match_diffs, steps))
    seconds = time.perf_counter() - t0
    goals_a = np.where(a_left, scores[:, 0], scores[:, 1])
    goals_b = np.where(a_left, scores[:, 1], scores[:, 0])
    n = len(difficulties)
    gd = (goals_a - goals_b).reshape(n, n, games)
    return {
        "mean_goal_difference": gd.mean(-1),
        "stderr": gd.std(-1, ddof=1) / np.sqrt(games),
        "goals_for": goals_a.reshape(n, n, games).mean(-1),
        "seconds": seconds,
        "ticks": len(a_idx) * steps,
    }


def record_gif(path: str, steps: int, every: int, seed: int = 0) -> str:
    """Play ``football/11v11_easy`` with every left player on action 19; write a GIF."""
    import smjax
    from smjax.viz.gif import write_gif

    env, params = smjax.make("football/11v11_easy", game_length=steps)
    _, state = env.reset(jax.random.PRNGKey(seed), params)
    builtin = jnp.full((11,), 19, jnp.int32)

    def body(s, k):
        _, s, _, _, _, _ = env.step_env(k, s, builtin, params)
        return s, s

    _, states = jax.jit(lambda s, k: jax.lax.scan(body, s, jax.random.split(k, steps)))(
        state, jax.random.PRNGKey(seed + 1))
    frames = [env.render(jax.tree.map(lambda x: x[t], states), params)
              for t in range(0, steps, every)]
    return write_gif(frames, path, fps=10)


def to_markdown(difficulties: list[float], result: dict) -> str:
    head = "| A \\ B | " + " | ".join(f"{d:g}" for d in difficulties) + " |"
    rule = "|---|" + "---|" * len(difficulties)
    rows = []
    for i, d in enumerate(difficulties):
        cells = [f"{result['mean_goal_difference'][i, j]:+.2f} ± {result['stderr'][i, j]:.2f} "
                 f"({result['goals_for'][i, j]:.2f})" for j in range(len(difficulties))]
        rows.append(f"| {d:g} | " + " | ".join(cells) + " |")
    return "\n".join([head, rule, *rows])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--difficulties", type=float, nargs="+", default=[0.05, 0.6, 0.95])
    parser.add_argument("--games", type=int, default=32, help="matches per pair (even)")
    parser.add_argument("--steps", type=int, default=3000, help="ticks per match")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--gif", default=None, help="also write a GIF of one episode here")
    parser.add_argument("--gif-steps", type=int, default=600)
    parser.add_argument("--gif-every", type=int, default=2)
    parser.add_argument("--skip-ladder", action="store_true", help="only write the GIF")
    args = parser.parse_args(argv)
    if args.gif:
        print(f"GIF written to {record_gif(args.gif, args.gif_steps, args.gif_every, args.seed)}")
    if args.skip_ladder:
        return
    for d in args.difficulties:
        if not 0.0 <= d <= 1.0:
            parser.error(f"difficulties lie in [0, 1], got {d}")
    result = ladder(args.difficulties, args.games, args.steps, args.seed)
    print(f"Mean goal difference of A (row) against B (column), ± standard error, "
          f"(A's goals per match); {args.games} matches of {args.steps} ticks per pair, "
          f"sides swapped for half of them.")
    print(to_markdown(args.difficulties, result))
    print(f"{result['ticks']} ticks in {result['seconds']:.1f} s (compile included) on "
          f"{jax.devices()[0].platform}")


if __name__ == "__main__":
    main()

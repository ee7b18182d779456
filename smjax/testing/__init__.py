"""A contract every smjax environment meets, and a harness that checks it.

``check_env(env, params)`` plays a small batch of environments with random actions and
checks these properties (each failure is an ``AssertionError`` whose message starts
with the property's name and names the environment):

* ``spaces``: ``action_space``/``observation_space`` are ``smjax.core.spaces`` spaces;
* ``jit == eager``: ``reset`` and ``step`` give the same values jitted and unjitted;
* ``step outputs``: per env, obs has the space's shape and dtype, reward is a float
  scalar, terminated/truncated are bool scalars, ``info["final_observation"]`` exists;
* ``determinism``: the same key gives the same rollout, bit for bit;
* ``observation finite`` / ``observation in space``: every observation (reset, step and
  ``info["final_observation"]``) is finite and inside ``observation_space(params)``;
* ``reward finite``: every reward of the rollout is finite (no NaN or inf);
* ``vmap == loop``: vmapped ``reset``/``step`` equal the single environment's, env by env;
* ``auto-reset``: when an episode ends, ``step`` returns the observation and state that
  ``reset_env`` gives for the second half of ``jax.random.split(key)`` (what
  ``Environment.step`` does);
* ``final_observation``: it is the observation ``step_env`` ended on when an episode
  ends, and the returned observation otherwise;
* ``render``: ``render`` returns a uint8 (H, W, 3) image (skipped if not implemented);
* ``describe``: ``describe`` returns a non-empty str, or None (no text form).

``check_hierarchy(env, params, hierarchy)`` checks every template of a hierarchy on
states reached by random play and by the hierarchy's own teleports: ``template output`` (predicates are bool scalars),
``vmap == loop`` (initiation, satisfied, failed, teleport and controller agree jitted and
vmapped vs one state at a time), ``teleport outcome`` (where initiable, the teleport's
outcome satisfies the template; a teleport initiable in none of the states fails, as
unchecked), ``teleport action``/``controller action`` (inside the
action space).

Floats computed by two different programs (jit vs eager, vmap vs loop) are compared with
``RTOL``/``ATOL`` (or the ``rtol``/``atol`` a check is given, else the environment's
``contract_tolerances``): XLA fuses them differently,
which changes float32 rounding; integer and bool leaves must be equal. Of a state, those
comparisons see what ``env.contract_state`` returns (all of it by default; Fetch leaves
out MJX's forces and accelerations, which amplify rounding in the positions they follow).
"""
from smjax.testing.compare import ATOL, RTOL, assert_trees_close, tolerances, trees_mismatch
from smjax.testing.env_contract import check_env
from smjax.testing.hierarchy_contract import check_hierarchy, check_template

__all__ = ["check_env", "check_hierarchy", "check_template", "assert_trees_close",
           "trees_mismatch", "tolerances", "RTOL", "ATOL"]

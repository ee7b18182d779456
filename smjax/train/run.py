"""One entry point for every method: make the env, resolve the hierarchy, train, and hand
the results to the hooks, which write them."""
from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any, NamedTuple, Sequence

from smjax.core.compile_cache import enable_compilation_cache
from smjax.core.registry import make
from smjax.core.timeline import TIMELINE
from smjax.train import checkpoint as ckpt
from smjax.train import distributed as dist
from smjax.train.config import (RUN_SETTINGS, ConfigError, TrainConfig, config_differences,
                                program_config)
from smjax.train.engine import Engine
from smjax.train.learner import agent_fields_in_programs, make_joint_learner, make_learner
from smjax.options.hierarchy import Hierarchy
from smjax.train.hooks import Hook, ResultsReport
from smjax.train.loop import HierarchyTrainer, NonFiniteError, default_hooks
from smjax.train.program_cache import cacheable_identity
from smjax.policy.artifact import policy_meta
from smjax.policy.hierarchies import declared_identity
from smjax.train.plans import resolve_run
from smjax.train.ahead import CompileAhead
from smjax.train.memory import check_fits
from smjax.train.outdir import DirLock, OutDirError, prepare_out_dir
from smjax.train.restorable import check_restorable
from smjax.train.reward_probe import nonfinite_reward
from smjax.train.results import ResultsError, ResultsHook, build_results, write_sweep
from smjax.train.sweep import normalize_sweep, point_config, point_raw, slot_layout, sweep_points


def validate_seeds(seeds) -> list[int]:
    seeds = list(seeds)
    if not seeds:
        raise ValueError("need at least one seed")
    for s in seeds:
        if not isinstance(s, int) or isinstance(s, bool) or s < 0 or s >= 2**32:
            raise ValueError(f"seeds must be integers in [0, 2**32), got {s!r}")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct, got {seeds}")
    return seeds


def run_identity(task_name: str, cfg: TrainConfig, seeds: list[int], env_overrides: dict) -> dict:
    """What must match for a checkpoint to be resumed (as JSON stores it: tuples are lists,
    so a resumed run compares equal to what its checkpoint saved): the task, seeds,
    environment overrides and every config field but ``RUN_SETTINGS``."""
    config = {k: v for k, v in cfg.to_dict().items() if k not in RUN_SETTINGS}
    identity = {"task": task_name, "seeds": seeds, "env_overrides": env_overrides} | config
    return json.loads(json.dumps(identity))


# evaluation-only settings: a resume of a trained run (every stage done) may change them,
# e.g. fewer ticks, where an evaluation with the saved ones cannot finish, or every mode
EVAL_SETTINGS = ("eval_envs", "eval_max_ticks", "eval_policies")


def check_resumable(out_dir, identity: dict, step: str | None = None) -> bool:
    """True if ``out_dir`` holds a checkpoint of this very run; refuse a different one."""
    info = ckpt.shared_meta(out_dir, step)
    if info is None:
        return False
    _refuse_another_run(out_dir, info, identity)
    return True


def _refuse_another_run(out_dir, info: dict, identity: dict) -> None:
    """Refuse the checkpoint ``info`` (``ckpt.shared_meta``: of this smjax's format) where
    it is not of this run; every config field is compared, one the checkpoint's identity
    lacks as its default."""
    saved = TrainConfig().to_dict() | info["meta"]["run"]
    # (the defaults hold RUN_SETTINGS, which no identity holds: they never count as a difference)
    free = RUN_SETTINGS + (EVAL_SETTINGS if info["meta"].get("trained") else ())
    diff = [k for k in config_differences(saved, identity) if k not in free]
    if diff:
        details = ", ".join(f"{k}: checkpoint {saved.get(k)!r} vs now {identity.get(k)!r}" for k in diff)
        raise ConfigError(f"cannot resume {out_dir}: the run differs in {details}")


def _claim_out_dir(out_dir, resume: bool, overwrite: bool) -> DirLock | None:
    """Validate and lock ``out_dir`` on process 0; every process raises alike."""
    lock, error = None, None
    if dist.is_writer():
        try:
            lock = prepare_out_dir(out_dir, resume=resume, overwrite=overwrite)
        except OutDirError as err:
            if not dist.is_multiprocess():
                raise
            error = str(err)
    if dist.is_multiprocess():
        error = dist.broadcast_json(error)
    if error:
        raise OutDirError(error)
    return lock


def run(task: str | tuple, cfg: TrainConfig, seeds, out_dir: str | Path | None = None, *,
        env_overrides: dict | None = None, progress: bool = True, resume: bool = False,
        overwrite: bool = False, sweep: dict | None = None,
        hierarchy: Hierarchy | str | None = None, resume_from: str | None = None,
        hooks: Sequence[Hook] = ()) -> dict:
    """Train ``task`` with ``cfg`` for all ``seeds`` in one compiled program; returns the
    results dict (docs/guide.md, "Results format").

    ``task``: a registered name (``"craft/get_gem"``) or an ``(env, env_params)`` pair.
    ``out_dir``: where checkpoints, results.json, curves.csv and the saved policy
    (``policy/``) go; validated and locked before anything compiles (a directory in use, or
    holding a run's files without ``resume`` or ``overwrite``, is refused). ``resume``
    continues from its last checkpoint (``resume_from``: an older step, ``"step-30"``); a
    checkpoint of another configuration is refused naming the fields. ``hierarchy``: a
    catalogue name (as ``cfg.hierarchy``) or a declared :class:`~smjax.options.Hierarchy`
    (pass it again to resume). ``sweep`` (``{"agent.learning_rate": [1e-4, 3e-4]}``):
    every point of the lists' product for every seed in the same program (docs/guide.md,
    "Sweeps"); returns ``{"points": [{"overrides", "results"}, ...], "compile_seconds"}``.
    ``hooks``: the caller's side jobs (:class:`smjax.train.hooks.Hook`), after the built-in
    ones (progress bar, TensorBoard, checkpoints, the files above), e.g.
    ``smjax.viz.plots.PlotHook()`` for curves.png as ``smjax train`` draws it. With several
    processes every one makes this same call, and process 0 alone touches ``out_dir``.
    """
    enable_compilation_cache()  # a second run of the same programs skips compiling
    TIMELINE.listen_to_jax()
    seeds = validate_seeds(seeds)
    if isinstance(hierarchy, str):  # a catalogue name: the config's field says it
        if cfg.hierarchy not in (None, hierarchy):
            raise ConfigError(f"hierarchy {hierarchy!r} contradicts the config's hierarchy "
                              f"{cfg.hierarchy!r}; give one of them")
        cfg, hierarchy = cfg.replace(hierarchy=hierarchy), None
    if sweep is not None:  # a bad sweep is refused before anything is locked or compiled
        sweep = normalize_sweep(cfg, sweep)
    if resume and out_dir is None:
        raise ValueError("resume needs the run's output directory")
    if resume_from is not None and not resume:
        raise ValueError("resume_from (--resume-from) needs resume (--resume DIR)")
    with TIMELINE.span("output directory check and lock"):
        lock = _claim_out_dir(out_dir, resume, overwrite) if out_dir is not None else None
    try:
        return _run_locked(task, cfg, seeds, Outputs(out_dir, tuple(hooks), progress),
                           dict(env_overrides or {}), resume, sweep, hierarchy, resume_from)
    finally:
        if lock is not None:
            lock.release()


class Outputs(NamedTuple):
    """Where a run writes (None: nowhere) and who hears of it."""

    out_dir: str | Path | None
    hooks: tuple[Hook, ...] = ()  # the caller's, after the built-in ones
    progress: bool = True         # the progress bar (process 0)


def _program_identity(task, cfg: TrainConfig, identity: dict) -> dict:
    """The run's identity as its programs see it: the config fields they depend on
    (``program_config``; of the learner's settings, no traced hyper-parameter), with the
    task, environment overrides, declared hierarchy and sweep. A run that changes only a
    budget, a threshold or a learning rate loads the same programs."""
    kept = {k: v for k, v in identity.items() if k not in cfg.to_dict()}
    config = program_config(cfg) | agent_fields_in_programs(cfg)
    return kept | {"task_name": task, "config": config}


def _run_locked(task, cfg: TrainConfig, seeds: list[int], outputs: Outputs,
                env_overrides: dict, resume: bool, sweep: dict | None,
                given: Hierarchy | None = None, resume_from: str | None = None) -> dict:
    out_dir = outputs.out_dir
    points = sweep_points(sweep) if sweep is not None else None
    with TIMELINE.span("environment, learner and hierarchy"):
        env, env_params = make(task, **env_overrides) if isinstance(task, str) else task
        resolved = resolve_run(env, cfg, given)
        cfg = resolved.cfg
        agent = make_learner(env, env_params, cfg)
        joint_agent = make_joint_learner(env, env_params, cfg, agent)
    identity = run_identity(env.name, cfg, seeds, env_overrides)
    if given is not None:  # its shape must match on resume
        identity["hierarchy_declared"] = declared_identity(given)
    if sweep is not None:  # a checkpoint of a sweep resumes only that sweep
        identity["sweep"] = sweep
    _check_checkpoint(out_dir, identity, resume, resume_from)
    slot_seeds, hp, configs = (slot_layout(cfg, points, seeds) if points is not None
                               else (seeds, None, None))
    # the checkpoint's files and host state, checked before the trainer compiles anything
    checked = (check_restorable(out_dir, resume_from, len(slot_seeds), resolved.num_stages)
               if resume else None)
    # programs may compile ahead from the trainer's construction on; closed by the run, or
    # here where it never starts (nothing left queued to compile)
    ahead, trainer = CompileAhead.for_backend(), None
    try:
        with TIMELINE.span("memory check, engine and trainer"):
            check_fits(env, env_params, cfg, len(slot_seeds))
            engine = Engine(env, env_params, resolved.hierarchy, agent, cfg, joint_agent)
            programs = cacheable_identity(task, given, _program_identity(task, cfg, identity))
            engine.program_identity = programs
            # the learners' init writes the traced hyper-parameters into their state
            engine.init_identity = (None if programs is None
                                    else programs | {"init_agent": cfg.agent})
            hooks = default_hooks(cfg, out_dir, outputs.progress, identity)
            if out_dir is not None:  # the run's files, before the caller's hooks read them
                hooks.append(ResultsHook(
                    _policy_meta(task, engine, resolved.hierarchy_name, given, env_overrides)))
            trainer = HierarchyTrainer(engine, list(resolved.plans), slot_seeds, hp=hp,
                                       configs=configs, hooks=hooks + list(outputs.hooks),
                                       ahead=ahead)
            trainer.results_due = len(points) if points is not None else 1
        if not engine.root_has_threshold and dist.is_writer():
            root = resolved.hierarchy.task
            warnings.warn(_UNBOUNDED.format(env.name, cfg.for_level(root).threshold), stacklevel=3)
        if resume:
            with TIMELINE.span("checkpoint restore"):
                trainer.restore(resume_from, checked)
    except BaseException:
        ahead.close()
        if trainer is not None:  # a restore that failed: the progress bar goes
            trainer.close_hooks()
        raise
    raw = _train(trainer, env, env_params, out_dir)
    extra = {"hierarchy_used": resolved.hierarchy_name, "env_overrides": env_overrides,
             "success_unbounded": not engine.root_has_threshold}
    return _results(trainer, env.name, cfg, seeds, raw, extra, out_dir, points)


def _check_checkpoint(out_dir, identity: dict, resume: bool, resume_from: str | None) -> None:
    """A resume needs a checkpoint of this very run in ``out_dir``; a fresh run none."""
    # with several processes process 0's view of out_dir decides, so all raise alike
    existing = ckpt.shared_meta(out_dir, resume_from) if out_dir is not None else None
    if resume:
        if existing is None:
            raise FileNotFoundError(f"nothing to resume: no checkpoint in {ckpt.checkpoint_dir(out_dir)}")
        _refuse_another_run(out_dir, existing, identity)
    elif existing is not None:  # (prepare_out_dir refuses this first; kept for safety)
        raise FileExistsError(
            f"{out_dir} already holds a checkpointed run; pass resume (--resume) to continue it "
            f"or choose another output directory")


def _train(trainer: HierarchyTrainer, env, env_params, out_dir) -> dict:
    """``trainer.run()``; a non-finite update says its likely cause and what is kept."""
    try:
        return trainer.run()
    except NonFiniteError as err:
        cause = nonfinite_reward(env, env_params)
        remedy = "fix the reward" if cause else "lower the learning rate"
        why = f"{cause}; " if cause else ""
        raise NonFiniteError(f"{err}; {why}{_kept(out_dir, remedy)}") from None


def _results(trainer: HierarchyTrainer, env_name: str, cfg: TrainConfig, seeds: list[int],
             raw: dict, extra: dict, out_dir, points: list | None) -> dict:
    """The run's results, or each sweep point's and sweep.json, handed to the hooks (which
    write the files). The final checkpoint (``trained``) was written before: a failure
    here loses nothing, and the error says how to write them from that checkpoint."""
    try:
        if points is None:
            return _report(trainer, env_name, cfg, seeds, raw, extra, out_dir)
        out = {"points": [], "compile_seconds": raw["compile_seconds"]}
        for p, point in enumerate(points):
            part = point_raw(raw, p, len(seeds), len(trainer.seeds))
            where = None if out_dir is None else Path(out_dir) / f"point-{p}"
            results = _report(trainer, env_name, point_config(cfg, point), seeds, part, extra,
                              where, point)
            out["points"].append({"overrides": point, "results": results})
        if out_dir is not None and dist.is_writer():
            write_sweep(out_dir, out)  # the sweep's index of its points, as run returns it
        return out
    except Exception as err:  # noqa: BLE001 - any failure here must not lose the training
        if out_dir is None:
            raise
        raise ResultsError(
            f"training finished and is checkpointed in {ckpt.checkpoint_dir(out_dir)}; "
            f"resume it (smjax train ... --resume {out_dir}, or run(..., resume=True)) to "
            f"write its results without training again. Writing them failed: "
            f"{type(err).__name__}: {err}") from err


_UNBOUNDED = ("{}: the task's success is the episode return, not known to lie in [0, 1] "
              "(success unbounded), so the threshold {:g} cannot tell when the task is "
              "learned: the root level (and fine-tuning) spend their whole budget. Declare a "
              "success in [0, 1] (declare(env, task, children, success=...)) to end them at "
              "the threshold")


def _report(trainer: HierarchyTrainer, env_name: str, cfg: TrainConfig, seeds: list[int],
            raw: dict, extra: dict, out_dir, overrides: dict | None = None) -> dict:
    """The results of a run, or of one point of a sweep, handed to every hook (results.json,
    curves.csv and the saved policy are the built-in ``ResultsHook``'s); with ``_raw``."""
    config = cfg.to_dict() | extra
    unbounded = config.pop("success_unbounded", False)
    results = build_results(env_name, cfg.method, cfg.algo, seeds, cfg.threshold, raw, config,
                            success_unbounded=unbounded)
    report = ResultsReport(None if out_dir is None else Path(out_dir), results, raw, overrides)
    with TIMELINE.span("results.json, curves.csv, curves.png"):
        for hook in trainer.hooks:
            hook.results(trainer, report)
    results_with_raw: dict[str, Any] = dict(results)
    results_with_raw["_raw"] = raw
    return results_with_raw


def _kept(out_dir, remedy: str) -> str:
    """What a user can fall back on after a non-finite update."""
    if out_dir is None:
        return f"no checkpoint (no output directory); {remedy} and train again"
    info = ckpt.load_meta(out_dir) if dist.is_writer() else None
    if info is None:
        return (f"no checkpoint had been written to {out_dir}; {remedy} and train again "
                f"(--overwrite)")
    return (f"the last good checkpoint ({info['path']}, chunk {info['step']}) is kept in "
            f"{ckpt.checkpoint_dir(out_dir)}")


def _policy_meta(task, engine: Engine, hierarchy_name: str, given: Hierarchy | None,
                 env_overrides: dict) -> dict:
    """The saved policy's description of this run (``smjax.policy.artifact.policy_meta``)."""
    cfg = engine.cfg
    return policy_meta(
        engine.runner, engine.runner_settings,
        task=task if isinstance(task, str) else engine.env.name,
        registered=isinstance(task, str), env_overrides=env_overrides, hierarchy=hierarchy_name,
        declared=None if given is None else declared_identity(given),
        learner={"algo": cfg.algo, "agent": dict(cfg.agent)},
        evaluation={"policy": engine.frozen_policy, "option_temperature": cfg.option_temperature,
                    "gamma": engine.gamma, "episodes": cfg.evaluation.eval_envs,
                    "max_ticks": cfg.evaluation.eval_max_ticks})

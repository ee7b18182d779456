"""Every large program a run compiles: its size and its compile seconds, and where XLA
spends a compile.

Trains a task in-process (``smjax.train.run``, the compilation cache and compiling ahead
off, so each program compiles alone, where the run first needs it) and records, for each
program the engine compiles (``Engine.compile``: the level chunk, joint fine-tuning's
chunk, the episodes programs), its StableHLO size (operations), the optimized HLO's size
(instructions and fusions) and the seconds to lower and to compile it; and the count and
seconds of all the run's XLA compiles (``jax.monitoring``'s backend-compile events).
``--phases PROGRAM`` traces that program's compile with the profiler and sums XLA:CPU's own
phases (HLO passes, then its back end: the fused kernels emitted, LLVM's machine code, the
thunks), each over the threads it ran on.

    JAX_PLATFORMS=cpu python benchmarks/program_sizes.py --task craft/make_stick --seeds 2 \
        --env observation=compact --phases chunk --json sizes.json
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import re
import sys
import tempfile
import time

os.environ["SMJAX_COMPILATION_CACHE"] = "0"
os.environ["SMJAX_COMPILE_AHEAD"] = "0"

import jax  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _kernels import fused_computations  # noqa: E402

# XLA:CPU's trace events of a compile: the whole, its HLO passes and its back end, and inside
# the back end the kernels' emission (one event a kernel), LLVM's code generation and the thunks
PHASES = ("PjRtCpuClient::Compile", "HLO passes through layout assignment",
          "HLO passes after layout assignment", "CpuCompiler::RunBackend",
          "FusionCompiler::Compile", "Codegen", "ThunkEmitter::EmitEntryComputation")


def hlo_sizes(lowered, compiled) -> dict:
    """Operations of the StableHLO; instructions and fused computations of the optimized
    HLO."""
    hlo = compiled.as_text()
    return {"stablehlo_ops": len(re.findall(r"\bstablehlo\.[a-z_]+", lowered.as_text())),
            "hlo_instructions": len(re.findall(r"^\s+(?:ROOT )?%\S+ = ", hlo, re.M)),
            "fusions": fused_computations(hlo)}


def traced(fn):
    """``fn()``'s result and XLA's compile phases while it ran (seconds, summed over its
    threads)."""
    with tempfile.TemporaryDirectory(prefix="program-sizes-trace-") as folder:
        jax.profiler.start_trace(folder)
        try:
            result = fn()
        finally:
            jax.profiler.stop_trace()
        paths = [os.path.join(d, f) for d, _, files in os.walk(folder) for f in files
                 if f.endswith(".xplane.pb")]
        data = jax.profiler.ProfileData.from_file(paths[-1])
    seconds, counts = collections.Counter(), collections.Counter()
    for plane in data.planes:
        for line in plane.lines:
            for event in line.events:
                name = next((p for p in PHASES if event.name.startswith(p)), None)
                if name:
                    seconds[name] += event.duration_ns / 1e9
                    counts[name] += 1
    return result, {name: {"seconds": round(seconds[name], 3), "events": counts[name]}
                    for name in PHASES if counts[name]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="craft/make_stick")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a training config field, as smjax train --set")
    ap.add_argument("--phases", nargs="*", default=[], metavar="PROGRAM",
                    help="programs (chunk, joint_chunk, episodes-256, ...) whose compile is "
                         "traced, for XLA's phases")
    ap.add_argument("--json", help="also write the records here")
    args = ap.parse_args(argv)

    from smjax.cli_train import key_values
    from smjax.train import engine as engine_module
    from smjax.train.config import resolve_config
    from smjax.train.run import run

    programs: list[dict] = []
    compiles: list[float] = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, seconds, **_: compiles.append(seconds)
        if event == "/jax/core/compile/backend_compile_duration" else None)

    def measured(jitted, fn_args, name, identity, static=(), donate=()):
        """What ``compile_program`` does with the cache off, timed and measured."""
        def lower_and_compile():
            t0 = time.perf_counter()
            lowered = jitted.lower(*fn_args, *static)
            t1 = time.perf_counter()
            return lowered, lowered.compile(), t1 - t0, time.perf_counter() - t1

        phases = None
        if name in args.phases:
            (lowered, compiled, lower_s, compile_s), phases = traced(lower_and_compile)
        else:
            lowered, compiled, lower_s, compile_s = lower_and_compile()
        record = {"program": name, "lower_seconds": round(lower_s, 2),
                  "compile_seconds": round(compile_s, 2)} | hlo_sizes(lowered, compiled)
        if phases is not None:
            record["phases"] = phases
        programs.append(record)
        print(json.dumps(record), flush=True)
        return compiled

    engine_module.compile_program = measured
    overrides = dict(kv.split("=", 1) for kv in args.env)
    cfg = resolve_config(sets=key_values(args.set, "--set"))
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        results = run(args.task, cfg, list(range(args.seeds)), out, env_overrides=overrides,
                      progress=False)
    summary = {"task": args.task, "seeds": args.seeds, "env": args.env,
               "jax": jax.__version__, "device": jax.devices()[0].device_kind,
               "run_seconds": round(time.perf_counter() - t0, 1),
               "final_success": results["final_success"],
               "xla_compiles": len(compiles), "xla_compile_seconds": round(sum(compiles), 1),
               "programs": programs}
    big = sum(p["compile_seconds"] for p in programs)
    print(f"{len(compiles)} XLA compiles, {sum(compiles):.1f} s; the {len(programs)} programs "
          f"above {big:.1f} s of it", file=sys.stderr)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()

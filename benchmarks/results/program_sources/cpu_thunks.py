"""profile_training.py's parts on a CPU, each part's XLA:CPU thunks from a profiler trace: the
time summed per thunk name (fusions, dots, loops) over a call, the ones that took longest first.
From the repository root: JAX_PLATFORMS=cpu SMJAX_COMPILATION_CACHE=0 PYTHONPATH=. python
benchmarks/results/program_sources/cpu_thunks.py --task craft/get_gem --env observation=compact
--seeds 2 --repeats 3 --parts rollout update --kernels"""
import sys, os, glob, gzip, json, tempfile, collections, time, shutil
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
import jax
import profile_training as pt
SKIP = ("PjitFunction", "Threadpool", "CommonPjRt", "$", "Python", "ParseArguments", "Handle", "Allocate",
        "Wait for", "ThunkExecutor", "end: ")
def cpu_profile(call, repeats=3, top=30):
    d = tempfile.mkdtemp()
    jax.block_until_ready(call())
    jax.profiler.start_trace(d, create_perfetto_trace=True)
    t0 = time.perf_counter()
    for _ in range(repeats): jax.block_until_ready(call())
    wall = (time.perf_counter() - t0) / repeats
    jax.profiler.stop_trace()
    ev = json.load(gzip.open(glob.glob(f"{d}/**/perfetto_trace.json.gz", recursive=True)[0]))
    shutil.rmtree(d, ignore_errors=True)
    ev = ev["traceEvents"] if isinstance(ev, dict) else ev
    dur = collections.Counter(); n = collections.Counter()
    for e in ev:
        if e.get("ph") != "X" or any(e["name"].startswith(s) for s in SKIP): continue
        dur[e["name"]] += e["dur"] / 1e6 / repeats; n[e["name"]] += 1
    tot = sum(dur.values())
    print(f"  wall {wall:.3f} s, thunk time summed {tot:.3f} s over {sum(n.values())//repeats} thunks/call")
    for k, v in dur.most_common(top):
        print(f"    {v*1e3:8.1f} ms {n[k]//repeats:6d}x  {k[:110]}")
    return None
pt.kernel_profile = cpu_profile
pt.describe = lambda p: ""
pt.main(sys.argv[1:])

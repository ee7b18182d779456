"""Several processes (and hosts) on JAX's own distributed runtime.

Every process runs the same program on the same host data; JAX joins their devices
into one global device list, the training mesh spans all of them, and each compiled
chunk runs as one SPMD program. What this module adds on top of
``jax.distributed.initialize``:

* ``initialize`` resolves the coordinator, process count and process id from arguments
  or JAX's usual environment variables, validates them with clear errors, does nothing
  for a single process, and selects the gloo collectives on CPU.
* Host/device traffic that keeps every process in step: ``gather`` reads a global
  (possibly non-fully-addressable) array back as numpy on every process, ``broadcast``
  hands process 0's values to all, ``place`` builds global arrays from identical host
  data, ``agree`` makes a host decision process 0's.
* ``is_writer``: only process 0 writes files.

With one process every helper reduces to the ordinary single-process call.
"""
from __future__ import annotations

import json
import os
import re
import sys
from typing import Any, Sequence

import jax
import numpy as np

ENV_COORDINATOR = "JAX_COORDINATOR_ADDRESS"
ENV_NUM_PROCESSES = "JAX_NUM_PROCESSES"
ENV_PROCESS_ID = "JAX_PROCESS_ID"

# HOST:PORT with a DNS name / IPv4 host, or [IPv6]:PORT
_ADDRESS = re.compile(r"^(?:\[(?P<v6>[0-9A-Fa-f:.]+)\]|(?P<host>[A-Za-z0-9_.-]+)):(?P<port>[0-9]+)$")


def _int_from(value: int | str | None, what: str) -> int | None:
    if value is None or value == "":
        return None
    if isinstance(value, bool):
        raise ValueError(f"{what} must be an integer, got {value!r}")
    if isinstance(value, str):
        try:
            return int(value.strip())
        except ValueError:
            raise ValueError(f"{what} must be an integer, got {value!r}") from None
    if isinstance(value, (int, np.integer)):
        return int(value)
    raise ValueError(f"{what} must be an integer, got {value!r}")


def check_address(address: str) -> str:
    """``address`` if it looks like HOST:PORT (or [IPv6]:PORT) with a port in 1..65535."""
    match = _ADDRESS.match(address.strip()) if isinstance(address, str) else None
    if match is None:
        raise ValueError(f"coordinator address must look like HOST:PORT (e.g. 10.0.0.1:1234), "
                         f"got {address!r}")
    port = int(match["port"])
    if not 1 <= port <= 65535:
        raise ValueError(f"coordinator port must be in 1..65535, got {port} in {address!r}")
    return address.strip()


def resolve(coordinator: str | None = None, num_processes: int | None = None,
            process_id: int | None = None) -> tuple[str | None, int | None, int | None]:
    """Explicit values, else JAX's environment variables; validated (None where unset)."""
    coordinator = coordinator or os.environ.get(ENV_COORDINATOR) or None
    num = _int_from(num_processes if num_processes is not None else os.environ.get(ENV_NUM_PROCESSES),
                    f"num_processes ({ENV_NUM_PROCESSES})")
    pid = _int_from(process_id if process_id is not None else os.environ.get(ENV_PROCESS_ID),
                    f"process_id ({ENV_PROCESS_ID})")
    if num is not None and num < 1:
        raise ValueError(f"num_processes must be >= 1, got {num}")
    if pid is not None and pid < 0:
        raise ValueError(f"process_id must be >= 0, got {pid}")
    if num is not None and pid is not None and pid >= num:
        raise ValueError(f"process_id must be in 0..{num - 1} for {num} processes, got {pid}")
    if coordinator is not None:
        coordinator = check_address(coordinator)
    return coordinator, num, pid


def _use_gloo_on_cpu() -> None:
    # Cross-process collectives on XLA:CPU need an implementation, and some jax versions
    # select none by default. Must be set before the CPU backend starts; a user's choice
    # is kept.
    try:
        current = jax.config.jax_cpu_collectives_implementation
    except AttributeError:  # a jax without the option: nothing to select
        return
    if current in (None, "none"):
        jax.config.update("jax_cpu_collectives_implementation", "gloo")


def initialize(coordinator: str | None = None, num_processes: int | None = None,
               process_id: int | None = None, *, local_device_ids: int | Sequence[int] | None = None,
               auto_detect: bool | str = False, initialization_timeout: int = 300) -> bool:
    """Join this process to a multi-process JAX run; True when one was joined.

    Values come from the arguments, else ``JAX_COORDINATOR_ADDRESS``,
    ``JAX_NUM_PROCESSES``, ``JAX_PROCESS_ID``. Without any of them (or with one
    process) nothing happens and False is returned. ``auto_detect=True`` lets JAX read
    unset values from a detected cluster (SLURM, Open MPI, Kubernetes, TPU pods); a
    string picks JAX's detection method by name (e.g. ``"mpi4py"``).
    ``local_device_ids`` restricts the devices this process uses (alternatively run each
    process with its own ``CUDA_VISIBLE_DEVICES``). Call it before any JAX computation.
    """
    if jax.distributed.is_initialized():  # the caller already joined the runtime itself
        return jax.process_count() > 1
    coordinator, num, pid = resolve(coordinator, num_processes, process_id)
    if not auto_detect:
        if coordinator is None and num is None and pid is None:
            return False
        if num == 1:  # (resolve has checked process_id < 1)
            return False
        missing = [name for name, value in (("coordinator", coordinator), ("num_processes", num),
                                            ("process_id", pid)) if value is None]
        if missing:
            raise ValueError(
                f"a multi-process run needs coordinator, num_processes and process_id; missing "
                f"{', '.join(missing)} (set them as arguments / --coordinator --num-processes "
                f"--process-id, or {ENV_COORDINATOR}, {ENV_NUM_PROCESSES}, {ENV_PROCESS_ID}; or "
                f"ask for cluster auto-detection)")
    _use_gloo_on_cpu()
    kwargs: dict[str, Any] = dict(coordinator_address=coordinator, num_processes=num,
                                  process_id=pid, local_device_ids=local_device_ids,
                                  initialization_timeout=initialization_timeout)
    if isinstance(auto_detect, str):
        kwargs["cluster_detection_method"] = auto_detect
    try:
        _initialize_guarded(kwargs)
    except RuntimeError as err:
        if "before" in str(err):
            raise RuntimeError(f"{err} (call smjax.train.distributed.initialize first, before "
                               f"creating any JAX array)") from err
        raise
    return jax.process_count() > 1


class CoordinatorError(ValueError):
    """This process could not join the multi-process run; the message says what to check."""


def _initialize_guarded(kwargs: dict) -> None:
    """``jax.distributed.initialize``, where a failure to join raises ``CoordinatorError``.

    JAX's runtime client aborts the whole process with a C++ stack trace when it cannot
    join (the coordinator or another process did not come within the timeout, or the
    address is another service's): its default error callback is fatal. Here the client
    gets a callback of ours, so the failed connect raises instead, the half-started
    runtime is shut down quietly and the error is one line. A fatal error after joining
    (another process died) still ends this process: the callback exits it (or, where the
    runtime cannot pass it the error, the runtime terminates it), never a silent hang.
    """
    import time

    try:
        import jax._src.distributed as jdist
        make_client = jdist._jax.get_distributed_runtime_client
    except (ImportError, AttributeError):  # another jax layout: its default behaviour
        jax.distributed.initialize(**kwargs)
        return
    joined = [False]

    def on_fatal_error(*_):
        if joined[0]:  # after joining: JAX's own behaviour (end the process), in one line
            print("error: the multi-process run failed: another process stopped or lost its "
                  "connection; see that process's output", file=sys.stderr, flush=True)
            os._exit(1)
        # while joining: returning lets connect() fail with an exception

    def client_with_callback(*args, **kw):
        try:
            return make_client(*args, **kw, missed_heartbeat_callback=on_fatal_error)
        except TypeError:  # a jaxlib without the argument
            return make_client(*args, **kw)

    start = time.monotonic()
    jdist._jax.get_distributed_runtime_client = client_with_callback
    try:
        jax.distributed.initialize(**kwargs)
    except Exception as err:  # noqa: BLE001 - only a failed connect is rewritten below
        if jdist.global_state.client is None:  # failed before connecting: JAX's own error
            raise
        _discard_runtime(jdist.global_state)
        raise CoordinatorError(_join_failure(kwargs, time.monotonic() - start, err)) from None
    finally:
        jdist._jax.get_distributed_runtime_client = make_client
    joined[0] = True


def _join_failure(kwargs: dict, elapsed: float, err: BaseException) -> str:
    address, timeout = kwargs.get("coordinator_address"), kwargs.get("initialization_timeout")
    who = f"process {kwargs.get('process_id')} of {kwargs.get('num_processes')}"
    detail = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    if timeout and elapsed >= 0.9 * timeout:
        why = (f"the run did not form within {timeout} s (the coordinator or another process did "
               f"not answer, or the address is another service's)")
    elif "bad_cast" in detail:  # the runtime could not pass its status on
        why = "the address answered, but not as the run's coordinator (another service's port?)"
    else:
        why = detail[:200]
    return (f"could not join the multi-process run at {address} as {who}: {why}; start every "
            f"process with the same --coordinator and --num-processes (process 0 on the "
            f"coordinator's host), check the address and port, or raise --coordinator-timeout")


def _discard_runtime(state) -> None:
    """Shut a half-started runtime down with its C++ log lines silenced (they would repeat
    the error as many lines), so nothing is left for JAX's exit handler to report."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        for part in ("preemption_sync_manager", "client", "service"):
            obj = getattr(state, part, None)
            if obj is not None:
                try:
                    obj.shutdown()
                except Exception:  # noqa: BLE001 - it is in an error state by definition
                    pass
                setattr(state, part, None)
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def is_multiprocess() -> bool:
    return jax.process_count() > 1


def is_writer() -> bool:
    """Process 0 writes results, checkpoints, plots and logs; the others write nothing."""
    return jax.process_index() == 0


# ---- host <-> device, keeping every process in step ---------------------------------------
def _replicated(x: jax.Array):
    sharding = x.sharding
    if hasattr(sharding, "update"):  # NamedSharding: same mesh, no partitioning
        return sharding.update(spec=jax.sharding.PartitionSpec())
    mesh = jax.sharding.Mesh(np.array(list(sharding.device_set)), ("all",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())


def gather(tree: Any) -> Any:
    """Every leaf as host numpy holding the whole (global) array, on every process.

    Fully addressable leaves are read directly; the others are replicated across their
    devices in one compiled call (a collective: every process must call it together).
    """
    leaves, treedef = jax.tree.flatten(tree)
    remote = [i for i, x in enumerate(leaves)
              if isinstance(x, jax.Array) and not x.is_fully_addressable]
    if remote:
        picked = [leaves[i] for i in remote]
        replicated = jax.jit(lambda xs: xs, out_shardings=[_replicated(x) for x in picked])(picked)
        for i, x in zip(remote, replicated):
            leaves[i] = x.addressable_data(0)
    # one call for every leaf: their copies to the host start together (an accelerator
    # would otherwise wait out one round trip per leaf)
    return jax.tree.unflatten(treedef, [np.asarray(x) for x in jax.device_get(leaves)])


def broadcast(tree: Any) -> Any:
    """Process 0's values of a pytree of host arrays, as numpy on every process (collective)."""
    if not is_multiprocess():
        return jax.tree.map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return multihost_utils.broadcast_one_to_all(jax.tree.map(np.asarray, tree))


def broadcast_json(value: Any) -> Any:
    """Process 0's JSON-able value on every process (two collectives: length, bytes)."""
    if not is_multiprocess():
        return value
    data = np.frombuffer(json.dumps(value).encode(), np.uint8) if is_writer() else np.zeros(0, np.uint8)
    size = int(broadcast(np.asarray([data.size], np.int64))[0])
    buf = np.zeros(size, np.uint8)
    buf[:data.size] = data[:size]
    return json.loads(bytes(broadcast(buf)).decode())


def agree(flag: bool) -> bool:
    """Process 0's decision, on every process (for choices that depend on local clocks)."""
    if not is_multiprocess():
        return bool(flag)
    return bool(broadcast(np.asarray(bool(flag)))[()])


def place(tree: Any, shardings: Any) -> Any:
    """Global arrays with ``shardings`` from values that every process holds identically.

    Single-process this is ``jax.device_put``. With several processes, leaves that are
    already global are resharded in one compiled call; host-local leaves are first made
    process 0's (``broadcast``, so bit-level differences between hosts cannot split the
    run) and each process then fills only its own devices' shards.
    """
    if not is_multiprocess():
        return jax.device_put(tree, shardings)
    leaves, treedef = jax.tree.flatten(tree)
    targets = treedef.flatten_up_to(shardings)
    remote = [i for i, x in enumerate(leaves)
              if isinstance(x, jax.Array) and not x.is_fully_addressable]
    local = [i for i in range(len(leaves)) if i not in set(remote)]
    out: list[Any] = list(leaves)
    if remote:
        moved = jax.jit(lambda xs: xs, out_shardings=[targets[i] for i in remote])(
            [leaves[i] for i in remote])
        for i, x in zip(remote, moved):
            out[i] = x
    if local:
        values = broadcast([np.asarray(leaves[i]) for i in local])
        for i, value in zip(local, values):
            out[i] = jax.make_array_from_callback(value.shape, targets[i],
                                                  lambda index, v=value: v[index])
    return jax.tree.unflatten(treedef, out)

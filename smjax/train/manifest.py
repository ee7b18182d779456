"""What a checkpoint step holds, so a resume can trust it: a manifest inside every step.

``smjax-manifest.json`` in ``step-N/`` records the step's host state (``meta``, as
``latest.json`` holds it) and the sha256 of every other file of the step. A resume
checks both (a flipped byte in an array file, or a host state edited in ``latest.json``,
is refused naming the step instead of resuming to wrong numbers); a step found without
``latest.json`` can still be resumed, from its own manifest; and ``check_host`` refuses
a host state that cannot belong to the run's plan (a stage past the plan, negative
counters).
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

MANIFEST = "smjax-manifest.json"


def _digests(step_dir: Path) -> dict[str, str]:
    out = {}
    for dirpath, _, files in os.walk(step_dir):
        for name in files:
            path = Path(dirpath) / name
            rel = str(path.relative_to(step_dir))
            if rel == MANIFEST:
                continue
            h = hashlib.sha256()
            with open(path, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            out[rel] = h.hexdigest()
    return out


def write_manifest(step_dir: Path, step: int, meta: dict) -> None:
    """Record ``meta`` and the checksums of the finished step (fsynced by the caller)."""
    text = json.dumps({"step": step, "meta": meta, "files": _digests(step_dir)})
    with open(step_dir / MANIFEST, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def read_manifest(step_dir: Path) -> dict | None:
    """The step's manifest, or None where it has none or it is unreadable."""
    try:
        data = json.loads((step_dir / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    ok = (isinstance(data, dict) and isinstance(data.get("files"), dict)
          and isinstance(data.get("meta"), dict) and isinstance(data.get("step"), int))
    return data if ok else None


def damage(step_dir: Path, manifest: dict) -> str | None:
    """What differs between the step's files and its manifest (None: intact)."""
    found = _digests(step_dir)
    for rel, digest in sorted(manifest["files"].items()):
        if rel not in found:
            return f"{rel} is missing"
        if found[rel] != digest:
            return f"{rel} does not match its checksum"
    extra = sorted(set(found) - set(manifest["files"]))
    return f"{extra[0]} is not part of it" if extra else None


def _order(name: str) -> tuple:
    """``step-N`` or ``step-N.k`` as (N, k), for newest-first ordering."""
    number, _, k = name[len("step-"):].partition(".")
    return (int(number), int(k or 0)) if number.isdigit() and (not k or k.isdigit()) else (-1, -1)


def steps_newest_first(root: Path) -> list[Path]:
    """The complete-looking step directories of ``root``, newest first."""
    if not root.is_dir():
        return []
    steps = [p for p in root.iterdir() if p.name.startswith("step-") and p.is_dir()
             and not p.is_symlink() and _order(p.name) >= (0, 0)]
    return sorted(steps, key=lambda p: _order(p.name), reverse=True)


def check_host(host: dict, num_slots: int, num_stages: int) -> str | None:
    """Why a checkpoint's host state cannot belong to this run (None: it can)."""
    stage = host.get("stage")
    if not isinstance(stage, list) or len(stage) != num_slots:
        return f"it holds {len(stage) if isinstance(stage, list) else 'no'} seed stages, not {num_slots}"
    for s, value in enumerate(stage):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= num_stages:
            return f"seed {s}'s stage {value!r} is outside the plan's 0..{num_stages}"
    counters = [("chunks", host.get("chunks"))]
    for key in ("episodes", "env_steps", "gate_attempts", "gate_env_steps", "gate_next", "turn"):
        counters += [(f"{key}[{s}]", v) for s, v in enumerate(host.get(key) or [])]
        ft = host.get("finetune") or {}
        counters += [(f"finetune {key}[{s}]", v) for s, v in enumerate(ft.get(key) or [])]
    for name, value in counters:
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            return f"its counter {name} = {value!r} is not a count"
    return None


_NUMBER = (int, float)
# the fields of a checkpoint's meta that a resume reads, with their types
META_FIELDS = {"run": dict, "host": dict}
RUN_FIELDS = {"task": str, "seeds": list, "env_overrides": dict}
HOST_FIELDS = {"stage": list, "started": list, "levels": list, "curves": list, "finetune": dict,
               "compile_seconds": _NUMBER, "wall_seconds": _NUMBER, "chunks": int}
OPTIONAL = {"settings": dict, "format": int}


def check_meta(meta, complete: bool = True) -> str | None:
    """Which field of a checkpoint's meta has the wrong type, or (``complete``: every field
    a resume reads is needed) is missing; None: none. JSON that parses can still hold a
    string where the seeds' list belongs; the resume would fail on it deep inside, naming
    only the key."""
    if not isinstance(meta, dict):
        return "meta"
    for where, value, fields, required in (
            ("", meta, META_FIELDS, True), ("", meta, OPTIONAL, False),
            ("run.", meta.get("run"), RUN_FIELDS, complete),
            ("host.", meta.get("host"), HOST_FIELDS, complete)):
        for name, kind in fields.items():
            if not isinstance(value, dict):
                return where.rstrip(".")
            if name not in value and not required:
                continue
            if isinstance(value.get(name), bool) or not isinstance(value.get(name), kind):
                return f"{where}{name}"
    seeds = meta["run"].get("seeds", [0])
    if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        return "run.seeds"
    if not all(isinstance(row, list) for row in meta["host"].get("curves", [])):
        return "host.curves"
    if not all(isinstance(level, dict) for level in meta["host"].get("levels", [])):
        return "host.levels"
    return None

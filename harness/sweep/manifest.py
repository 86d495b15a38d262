"""What a sweep's runs depend on (``sweep_manifest.json``), so that ``--resume`` continues
only the same sweep."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
import shutil

from .store import JOURNAL, RUNS
from .worker import scenario_fields

__all__ = ["MANIFEST", "sweep_identity", "read_manifest", "write_manifest", "prepare_folder"]

MANIFEST = "sweep_manifest.json"


def _digest(obj):
    """A short content digest of a JSON-able object."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=repr).encode()).hexdigest()[:16]


def sweep_identity(scs, spreads, n_runs, seed, options, package_digest, bases):
    """What makes a sweep's runs what they are: a sweep is resumed only into the same."""
    return {
        "format": 1,
        "scenarios": [sc.name for sc in scs],
        "scenario_definitions": {sc.name: _digest(scenario_fields(sc)) for sc in scs},
        "runs": int(n_runs),
        "seed": int(seed),
        "spreads": [[s.key, s.distribution, s.width, s.relative] for s in spreads],
        "options": {k: options[k] for k in sorted(options)},
        "fmus": package_digest,
        "base_parameters": {name: _digest(base) for name, base in bases.items()},
    }


def read_manifest(folder):
    try:
        return json.loads((Path(folder) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None


def write_manifest(folder, identity, complete):
    path = Path(folder) / MANIFEST
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"identity": identity, "complete": bool(complete)}, indent=1) + "\n")
    os.replace(tmp, path)


def _identity_difference(old, new):
    names = {"scenarios": "the scenarios", "scenario_definitions": "a scenario's definition",
             "runs": "the number of runs", "seed": "the seed", "spreads": "the spreads",
             "options": "the options", "fmus": "the FMUs", "base_parameters": "the plant parameters",
             "format": "the file format"}
    diff = [names.get(k, k) for k in new if old.get(k) != new[k]]
    if "seed" in [k for k in new if old.get(k) != new[k]]:
        diff[diff.index("the seed")] = f"the seed ({old.get('seed')}, now {new['seed']})"
    if "runs" in [k for k in new if old.get(k) != new[k]]:
        diff[diff.index("the number of runs")] = f"the number of runs ({old.get('runs')}, now {new['runs']})"
    return ", ".join(diff)


def prepare_folder(folder, identity, resume, progress):
    """Check the output folder against ``resume`` and return whether the journal is new."""
    manifest = read_manifest(folder)
    journal, final = folder / JOURNAL, folder / RUNS
    unfinished = manifest is not None and not manifest.get("complete") and journal.exists()
    if not resume:
        if unfinished:
            raise ValueError(f"{folder} holds an unfinished sweep: add --resume to continue it "
                             f"(same scenarios, -n, --seed and --vary), or give another --out")
        return True
    if manifest is None or not (unfinished or (manifest.get("complete") and final.exists())):
        if progress is not None:
            progress.write(f"sweep: --resume: no sweep to continue in {folder}; starting one\n")
        return True
    if manifest.get("identity") != identity:
        raise ValueError(f"--resume: {folder} holds a sweep with other settings "
                         f"({_identity_difference(manifest.get('identity', {}), identity)}): "
                         f"give the same scenarios, -n, --seed, --vary and options, or another --out")
    if not unfinished:                              # complete: its runs table is the journal
        shutil.copyfile(final, journal)
    return False


"""The finished coupling intervals of a loop on disk: saved as they finish, resumed, discarded
when the loop's inputs change.

Each interval folder `interval_NN/` holds `records.npz` (the PBM records and the final state) and
`interval.json` (classes, frequencies, timings, the sample), written last: its presence marks the
interval as finished. `loop_inputs.json` holds the hash of everything the loop's results depend on.
"""

from __future__ import annotations

import hashlib
import json
import logging
import shutil
from dataclasses import asdict
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from pbmdem.atomic import atomic_path, write_json
from pbmdem.readers import read_json

from .sample import DemSample

log = logging.getLogger(__name__)

RECORD_NAMES = ("times", "number", "liquid", "gas", "liquid_added", "refused", "steps")


def discard_stale(outdir: Path, inputs: dict) -> None:
    """Keep the finished intervals in `outdir` only if they were computed from the same `inputs`
    (configuration, speed, sample rule, provider, e.g. the surrogate file's hash); otherwise
    remove them."""
    digest = hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()
    stamp = outdir / "loop_inputs.json"
    if stamp.exists() and json.loads(stamp.read_text()).get("sha256") == digest:
        return
    stale = sorted(outdir.glob("interval_*"))
    if stale:
        log.warning("inputs of %s changed: discarding %d finished intervals", outdir, len(stale))
        for folder in stale:
            shutil.rmtree(folder)
    write_json(stamp, {"sha256": digest, "inputs": inputs}, default=str)


def is_finished(folder: Path) -> bool:
    return (folder / "interval.json").exists()


def save(folder: Path, result, sample: DemSample, matrix: np.ndarray, info: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "records.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, times=result.times, number=result.number, liquid=result.liquid, gas=result.gas,
                     liquid_added=result.liquid_added, refused=result.refused_volume, steps=result.steps,
                     state_t=result.state.t, state_number=result.state.number, state_liquid=result.state.liquid,
                     state_gas=result.state.gas, state_refused=result.state.refused_volume,
                     state_liquid_added=result.state.liquid_added, state_steps=result.state.steps,
                     class_matrix=matrix)
    # interval.json is written last: its presence marks the interval as finished
    write_json(folder / "interval.json", {**info, "sample": asdict(sample)})


def load(folder: Path, grid):
    """(Result, interval info, class matrix) of a finished interval."""
    from pbmdem.pbm.model import State
    from pbmdem.pbm.results import Result

    data = np.load(folder / "records.npz")
    records = SimpleNamespace(**{name: data[name] for name in RECORD_NAMES})
    state = State(float(data["state_t"]), data["state_number"], data["state_liquid"], data["state_gas"],
                  float(data["state_refused"]), float(data["state_liquid_added"]), int(data["state_steps"]))
    info = read_json(folder / "interval.json", "coupling interval record")
    return Result(grid, records, state, {"wall_time_s": info.get("pbm_wall_time_s", 0.0)}), info, data["class_matrix"]

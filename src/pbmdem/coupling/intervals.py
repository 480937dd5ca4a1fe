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
from dataclasses import asdict, fields
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from pbmdem.atomic import atomic_path, write_json
from pbmdem.pbm.results import Result
from pbmdem.pbm.state import FeedGranules, State, State2D
from pbmdem.pbm.stepping import Records
from pbmdem.readers import read_json

from .sample import DemSample

log = logging.getLogger(__name__)

#: the records of a Result (``pbm.stepping.Records``); merged_*: breakage fragments merged at the grid floor (State)
RECORD_NAMES = tuple(f.name for f in fields(Records))


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
    """Whether `folder` holds a finished interval that a loop can resume from: interval.json
    written, and records with every record of RECORD_NAMES (an interval written before the grid
    floor's tally, ``merged_number``, is computed again rather than resumed without it)."""
    if not (folder / "interval.json").exists():
        return False
    with np.load(folder / "records.npz") as data:
        if "state_merged_number" in data.files:
            return True
    log.info("%s was written without the grid floor's tally: computed again", folder)
    return False


def save(folder: Path, result, sample: DemSample, matrix: np.ndarray, info: dict) -> None:
    """Write one finished interval: its PBM records, its final state (with the feed granules not
    yet aggregated, so that a resumed loop continues exactly) and, last, interval.json."""
    folder.mkdir(parents=True, exist_ok=True)
    state = result.state
    feed = {}
    if state.feed is not None:
        feed = {
            "feed_volumes": state.feed.volumes,
            "feed_number": state.feed.number,
            "feed_liquid": state.feed.liquid,
            "feed_gas": state.feed.gas,
        }
    if isinstance(state, State2D):  # the two-dimensional PBM's (size x liquid) classes
        feed.update(state_classes=state.classes, state_class_volumes=state.class_volumes)
    with atomic_path(folder / "records.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(
                fh,
                times=result.times,
                number=result.number,
                liquid=result.liquid,
                gas=result.gas,
                liquid_added=result.liquid_added,
                refused=result.refused_volume,
                steps=result.steps,
                merged_number=result.merged_number,
                merged_volume=result.merged_volume,
                state_t=state.t,
                state_number=state.number,
                state_liquid=state.liquid,
                state_gas=state.gas,
                state_refused=state.refused_volume,
                state_liquid_added=state.liquid_added,
                state_steps=state.steps,
                state_merged_number=state.merged_number,
                state_merged_volume=state.merged_volume,
                class_matrix=matrix,
                **feed,
            )
    # interval.json is written last: its presence marks the interval as finished
    write_json(folder / "interval.json", {**info, "sample": asdict(sample)})


def load(folder: Path, grid):
    """(Result, interval info, class matrix) of a finished interval (the state a State2D if the
    interval was run by the two-dimensional PBM)."""
    data = np.load(folder / "records.npz")
    records = SimpleNamespace(**{name: data[name] for name in RECORD_NAMES})
    feed = None
    if "feed_volumes" in data:
        feed = FeedGranules(data["feed_volumes"], data["feed_number"], data["feed_liquid"], data["feed_gas"])
    two = "state_classes" in data
    kind, extra = (
        (State2D, {"classes": data["state_classes"], "class_volumes": data["state_class_volumes"]})
        if two
        else (State, {})
    )
    state = kind(
        float(data["state_t"]),
        data["state_number"],
        data["state_liquid"],
        data["state_gas"],
        float(data["state_refused"]),
        float(data["state_liquid_added"]),
        int(data["state_steps"]),
        feed,
        float(data["state_merged_number"]),
        float(data["state_merged_volume"]),
        **extra,
    )
    info = read_json(folder / "interval.json", "coupling interval record")
    return Result(grid, records, state, {"wall_time_s": info.get("pbm_wall_time_s", 0.0)}), info, data["class_matrix"]

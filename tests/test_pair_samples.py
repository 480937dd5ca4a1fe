"""The surrogate's pair encounter frequency on the PBM-DEM loops' own samples (validation.pair_samples)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pbmdem.frequency import upper_pairs
from pbmdem.layout import validation_run
from pbmdem.tables import PAIR_SAMPLES
from pbmdem.validation.pair_samples import MAE_TARGET, MEAN_ERROR_TARGET, loop_samples, pair_sample_table


class Law:
    """A stand-in surrogate: c_ij = 1e-3 (d_i + d_j)^2 rpm / n_total (1/s, d in mm)."""

    def frequency_matrix(self, diameters, numbers, rpm):
        d = 1e3 * np.asarray(diameters)
        return 1e-3 * (d[:, None] + d[None, :]) ** 2 * rpm / np.sum(numbers)


def _interval(k, rpm, d, n, c) -> dict:
    return {
        "interval": k,
        "t_start": 60.0 * k,
        "t_end": 60.0 * (k + 1),
        "rpm": rpm,
        "method": "pbm_dem",
        "classes": len(d),
        "class_diameters": json.dumps(list(d)),
        "class_counts": json.dumps(list(n)),
        "sample_particles": int(sum(n)),
        "class_frequencies": json.dumps(list(c)),
        "mean_frequency_per_pair": float(np.mean(c)),
        "provider_wall_time_s": 1.0,
        "pbm_wall_time_s": 0.1,
    }


def _write_loops(root, offsets: dict) -> None:
    """Two replicate loops per speed; interval 0 (the feed) is the same sample in both, interval 1
    differs; the DEM frequencies are the law's times 10^-offset (a model error of +offset), one pair
    of the second sample without DEM encounters."""
    law = Law()
    for rpm, offset in offsets.items():
        for rep in range(2):
            rows = []
            for k, (d, n) in enumerate(
                [([0.002, 0.003, 0.004], [500, 300, 200]), ([0.002, 0.004, 0.006 + 0.001 * rep], [400, 200, 50])]
            ):
                d, n = np.array(d), np.array(n, float)
                iu, ju = upper_pairs(3)
                c = law.frequency_matrix(d, n, float(rpm))[iu, ju] * 10.0**-offset
                if k == 1:
                    c[-1] = 0.0  # the largest class met no other of its own class in the DEM run
                rows.append(_interval(k, float(rpm), d, n, c))
            folder = Path(validation_run("pbm_dem", str(rpm), rep, str(root / "validation")))
            folder.mkdir(parents=True)
            pd.DataFrame(rows).to_csv(folder / "intervals.csv", index=False)


def test_the_table_gives_the_error_on_every_distinct_sample(tmp_path):
    _write_loops(tmp_path, {300: 0.02, 900: -0.005})
    samples = loop_samples(tmp_path / "validation", ["300", "900"], 2)
    # per speed the shared feed once, the second interval of each replicate: 3 samples
    assert len(samples) == 6
    table = PAIR_SAMPLES.check(pair_sample_table(Law(), samples), "")
    assert list(table["rpm"]) == ["300", "900", "all"]
    assert list(table["samples"]) == [3, 3, 6]
    assert list(table["pairs"]) == [6 + 5 + 5, 16, 32]  # the pairs without DEM encounters left out
    np.testing.assert_allclose(table["mean_error_log10"], [0.02, -0.005, 0.0075], atol=1e-12)
    np.testing.assert_allclose(table["mae_log10"], [0.02, 0.005, 0.0125], atol=1e-12)
    assert (table["mean_error_target"] == MEAN_ERROR_TARGET).all() and (table["mae_target"] == MAE_TARGET).all()
    assert list(table["met"]) == [False, True, True]


def test_a_damaged_record_is_refused_with_its_file(tmp_path):
    _write_loops(tmp_path, {300: 0.0})
    path = tmp_path / "validation" / "rpm300" / "pbm_dem" / "rep1" / "intervals.csv"
    frame = pd.read_csv(path)
    frame.loc[1, "class_frequencies"] = json.dumps([1.0, 2.0])
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match=rf"{path}: interval 1: 3 diameters, 3 counts and 2 pair frequencies"):
        loop_samples(tmp_path / "validation", ["300"], 2)
    frame.loc[1, "class_frequencies"] = "[1.0, oops]"
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match=rf"{path}: row 2, column 'class_frequencies' = .*: a JSON list of"):
        loop_samples(tmp_path / "validation", ["300"], 2)

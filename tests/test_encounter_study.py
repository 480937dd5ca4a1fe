"""Whole-bed encounter rates and the flow-development check on hand-made per-replicate tables."""

import numpy as np
import pandas as pd
import pytest

from pbmdem.dem.speed_response import flow_development, speed_response


def replicate_rows(rpm, rep, enc):
    # two classes: 4 and 2 particles; pairs 6, 8, 1; window 0.5 s
    rows = []
    for (i, j), e in zip([(0, 0), (0, 1), (1, 1)], enc):
        rows.append(
            {
                "point_id": f"rpm{rpm}_f",
                "rpm": rpm,
                "distribution": "f",
                "replicate": rep,
                "class_i": i,
                "class_j": j,
                "n_i": [4, 4, 2][i + j],
                "n_j": [4, 2, 2][i + j],
                "sampling_time": 0.5,
                "encounters": e,
                "collisions": 3 * e,
                "impact_velocity_median": 0.1,
            }
        )
    return rows


def test_speed_response_mean_and_se():
    rows = replicate_rows(100, 0, [6, 8, 1]) + replicate_rows(100, 1, [12, 16, 2])
    out = speed_response(pd.DataFrame(rows))
    assert len(out) == 1 and out.n_replicates.iloc[0] == 2
    # 15 and 30 encounters among 6 particles in 0.5 s: 2 x 15 / (6 x 0.5) = 10 and 20 per particle and second
    assert out.encounters_per_particle_per_s.iloc[0] == pytest.approx(15.0)
    assert out.encounters_per_particle_per_s_se.iloc[0] == pytest.approx(np.std([10, 20], ddof=1) / np.sqrt(2))
    # 15 pairs: 15 / (15 x 0.5) = 2 and 4 per pair and second
    assert out.mean_encounter_frequency_per_pair.iloc[0] == pytest.approx(3.0)
    assert out.new_contacts_per_particle_per_s.iloc[0] == pytest.approx(45.0)


def test_flow_development_flags_a_drift():
    runs = pd.DataFrame(
        {
            "point_id": "p",
            "rpm": 100.0,
            "distribution": "f",
            "replicate": [0, 1, 2],
            "encounters_first_half": [100, 104, 98],
            "encounters_second_half": [101, 99, 103],
        }
    )
    flow = flow_development(runs)
    assert flow.within_error.iloc[0]
    # means 100.67 and 101.0; SEs sqrt(var/3) of [100, 104, 98] and [101, 99, 103]
    se1, se2 = np.std([100, 104, 98], ddof=1) / np.sqrt(3), np.std([101, 99, 103], ddof=1) / np.sqrt(3)
    assert flow.half_z.iloc[0] == pytest.approx((101.0 - 302 / 3) / np.hypot(se1, se2))
    runs["encounters_second_half"] = [150, 155, 149]
    assert not flow_development(runs).within_error.iloc[0]
    single = runs.iloc[:1].copy()  # one replicate: the Poisson error of the counts
    assert flow_development(single).half_z.iloc[0] == pytest.approx(50 / np.sqrt(250))

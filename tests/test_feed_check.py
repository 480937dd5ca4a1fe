"""The feed check: which case of the feed study is the most surprising (the stated rule, on
hand-made feed-study tables, SI units), the parents of a case, and the check's table and verdict."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pbmdem.config import SizeDistribution, feed_case_names, feed_case_parents
from pbmdem.coupling.studies import feed_case, feed_cases
from pbmdem.report.findings import feed_check_words
from pbmdem.validation.feed_check import (
    ABOVE,
    BELOW,
    CHECK_COLUMNS,
    OFF,
    check_table,
    confirms,
    most_surprising,
    surprises,
    verdict,
)

FEEDS = ["fine", "fine+medium", "medium", "medium+coarse", "coarse"]
IN_GRID = [True, False, True, False, True]
FEED_D50 = [0.003, 0.004, 0.005, 0.0065, 0.008]  # m


def study(d50_mm, out_of_domain=(0, 0, 0, 0, 0), feeds=FEEDS, feed_d50=FEED_D50, in_grid=IN_GRID) -> pd.DataFrame:
    """A feed-study table as pbmdem.coupling.studies.feed_study writes it (sizes in m), rows reversed:
    the rule orders them by the feed d50 itself."""
    d50 = 1e-3 * np.asarray(d50_mm, float)
    frame = pd.DataFrame(
        {
            "rpm": 300.0,
            "feed": feeds,
            "feed_d50": feed_d50,
            "d10": 0.6 * d50,
            "d50": d50,
            "d90": 1.4 * d50,
            "out_of_domain_intervals": list(out_of_domain),
            "intervals": 4,
            "in_grid": in_grid,
        }
    )
    for s in ("d10", "d50", "d90"):
        frame[f"{s}_member_min"] = 0.9 * frame[s]
        frame[f"{s}_member_max"] = 1.1 * frame[s]
    return frame.iloc[::-1].reset_index(drop=True)


def test_parents_are_the_nearest_grid_feeds_on_either_side():
    parents = feed_case_parents(zip(FEEDS, IN_GRID))
    assert parents == {
        "fine+medium": ("fine", "medium"),
        "medium": ("fine", "coarse"),
        "medium+coarse": ("medium", "coarse"),
    }
    # the feed study's cases by name, ordered by the feeds' mass-median diameter
    fine = SizeDistribution(diameters=(0.002, 0.003, 0.004), number_fractions=(0.5, 0.3, 0.2))
    coarse = SizeDistribution(diameters=(0.0032, 0.005, 0.008), number_fractions=(0.3, 0.4, 0.3))
    assert feed_case_names({"coarse": coarse, "fine": fine}) == [
        ("fine", True),
        ("fine+coarse", False),
        ("coarse", True),
    ]
    assert feed_case_parents(feed_case_names({"coarse": coarse, "fine": fine})) == {"fine+coarse": ("fine", "coarse")}
    assert (
        feed_case({"coarse": coarse, "fine": fine}, "fine+coarse") == feed_cases({"coarse": coarse, "fine": fine})[1][1]
    )
    with pytest.raises(ValueError, match="'fine\\+fine' is not a case of the feed study"):
        feed_case({"coarse": coarse, "fine": fine}, "fine+fine")


def test_the_blend_furthest_outside_its_parents_is_the_most_surprising():
    # fine+medium ends below both parents (7.8 and 10.5 mm): 1.4 mm outside, over its 6.4 mm
    top = most_surprising(study([7.8, 6.4, 10.5, 11.0, 13.0]))
    assert top.feed == "fine+medium" and top.kind == BELOW
    assert (top.parent_finer, top.parent_coarser) == ("fine", "medium")
    assert top.outside == pytest.approx((7.8 - 6.4) / 6.4)
    # a case further outside (relative to its own d50) wins, whatever its kind: medium+coarse above both
    top = most_surprising(study([7.8, 6.4, 10.5, 17.0, 13.0]))
    assert top.feed == "medium+coarse" and top.kind == ABOVE
    assert top.outside == pytest.approx((17.0 - 13.0) / 17.0)
    # a feed between two others counts as well: medium below fine and coarse
    top = most_surprising(study([7.8, 7.0, 6.0, 9.0, 13.0]))
    assert top.feed == "medium" and top.kind == BELOW and top.outside == pytest.approx(1.8 / 6.0)


def test_an_out_of_domain_case_is_no_surprise_and_the_rule_falls_back_to_the_interpolation():
    d50 = [7.8, 6.4, 10.5, 11.0, 13.0]
    # fine+medium extrapolated: nothing in domain lies outside its parents' interval
    s = study(d50, out_of_domain=(0, 2, 0, 0, 0))
    top = most_surprising(s)
    assert top.kind == OFF
    table = surprises(s).set_index("feed")
    assert not table.loc["fine+medium", "in_domain"]

    def off(name, finer, coarser):
        k, a, b = FEEDS.index(name), FEEDS.index(finer), FEEDS.index(coarser)
        w = math.log(FEED_D50[k] / FEED_D50[a]) / math.log(FEED_D50[b] / FEED_D50[a])
        interpolated = math.exp((1 - w) * math.log(d50[a]) + w * math.log(d50[b]))
        return d50[k] / interpolated - 1.0

    deviations = {"medium": off("medium", "fine", "coarse"), "medium+coarse": off("medium+coarse", "medium", "coarse")}
    assert table.loc["medium", "deviation"] == pytest.approx(deviations["medium"])
    assert table.loc["medium+coarse", "deviation"] == pytest.approx(deviations["medium+coarse"])
    assert top.feed == max(deviations, key=lambda k: abs(deviations[k]))
    # a parent without a finite d50 takes its cases out; nothing left in domain: no case
    assert most_surprising(study([7.8, 6.4, 10.5, 11.0, 13.0], out_of_domain=(0, 1, 1, 1, 0))) is None
    gone = study(d50)
    gone.loc[gone.feed == "medium", "d50"] = np.nan
    assert set(surprises(gone).query("in_domain").feed) == set()


def test_a_case_on_its_parents_log_interpolation_deviates_by_nothing():
    feeds, in_grid = ["a", "a+b", "b"], [True, False, True]
    fa, fb, da, db = 0.002, 0.008, 0.005, 0.0125
    s = study([1e3 * da, 1e3 * math.sqrt(da * db), 1e3 * db], (0, 0, 0), feeds, [fa, math.sqrt(fa * fb), fb], in_grid)
    top = most_surprising(s)
    assert top.kind == OFF and top.interpolated_d50 == pytest.approx(math.sqrt(da * db))
    assert abs(top.deviation) < 1e-12


def test_confirmation_counts_the_replicates_on_the_statements_side():
    below = surprises(study([7.8, 6.4, 10.5, 11.0, 13.0])).set_index("feed").loc["fine+medium"]
    assert list(confirms(below, [0.0060, 0.0077, 0.0079])) == [True, True, False]
    assert verdict(confirms(below, [0.0060, 0.0065])) == "yes"
    assert verdict(confirms(below, [0.0060, 0.0080])) == "partly"
    assert verdict(confirms(below, [0.0080, 0.0090])) == "no"
    off = surprises(study([7.8, 9.5, 10.5, 11.0, 13.0])).set_index("feed").loc["fine+medium"]
    assert off.kind == OFF and off.deviation > 0  # 9.5 mm above the interpolation (9.22 mm)
    assert list(confirms(off, [off.interpolated_d50 * 1.01, off.interpolated_d50 * 0.99])) == [True, False]


def _check(dem_d50_mm, study_d50=(7.8, 6.4, 10.5, 11.0, 13.0)):
    ann = study([7.8, 6.4, 10.5, 11.0, 13.0]).query("feed in ['fine', 'fine+medium', 'medium']")
    d50 = 1e-3 * np.asarray(dem_d50_mm)
    dem = pd.DataFrame({"replicate": range(len(d50)), "d10": 0.6 * d50, "d50": d50, "d90": 1.4 * d50})
    return check_table("fine+medium", 300.0, ann, dem, study(list(study_d50)), 300.0).iloc[0]


def test_the_check_table_states_the_verdict_with_its_numbers():
    row = _check([6.1, 6.3, 6.2])
    assert list(row.index) == list(CHECK_COLUMNS)
    assert row.dem_confirms == "yes" and row.dem_replicates == 3 and row.dem_replicates_confirming == 3
    assert row.dem_d50_mean == pytest.approx(6.2e-3)
    assert (row.dem_d50_min, row.dem_d50_max) == pytest.approx((6.1e-3, 6.3e-3))
    assert row.ann_d50 == pytest.approx(6.4e-3)
    assert row.ann_d50_member_min == pytest.approx(0.9 * 6.4e-3)
    # PBM-ANN 6.4 mm lies 0.1 mm above the replicates' 6.1-6.3 mm, over their mean 6.2 mm
    assert row.ann_d50_outside_dem_range == pytest.approx(0.1 / 6.2)
    assert (row.parent_finer, row.parent_coarser) == ("fine", "medium")
    assert (row.parent_finer_ann_d50, row.parent_coarser_ann_d50) == pytest.approx((7.8e-3, 10.5e-3))
    assert row.is_most_surprising and row.most_surprising == "fine+medium"
    assert "``fine+medium`` ends smaller than either parent" in row.statement
    assert _check([6.1, 8.0]).dem_confirms == "partly"
    assert _check([8.0, 8.2]).dem_confirms == "no"
    # the feed study now finds another case more surprising: the table says which
    other = _check([6.1], study_d50=(7.8, 9.0, 10.5, 16.0, 13.0))
    assert not other.is_most_surprising and other.most_surprising == "medium+coarse"
    assert "``medium+coarse`` ends larger than either parent" in other.most_surprising_statement
    with pytest.raises(ValueError, match="no PBM-DEM loop finished"):
        _check([])


def test_the_findings_say_whether_pbm_dem_confirms_it():
    text = feed_check_words(_check([6.1, 6.3, 6.2]).to_dict())
    assert text.startswith("**PBM-DEM check of the feed result.** At 300 rpm PBM-ANN predicts that")
    assert "``fine+medium`` ends smaller than either parent (``fine`` 7.80 mm, ``medium`` 10.50 mm)" in text
    assert "3 PBM-DEM loops" in text and "d50 6.10-6.30 mm (mean 6.20 mm)" in text
    assert "PBM-DEM confirms it: every replicate ends below both parents' PBM-ANN d50." in text
    assert "1.6 % of d50 outside the PBM-DEM replicates' range" in text
    assert "most surprising in-domain result by the stated rule" in text
    assert "training domain in" not in text  # the case and its parents stayed inside it
    partly_outside = _check([6.1, 6.3, 6.2]).to_dict() | {"parent_coarser_out_of_domain_intervals": 1}
    assert (
        "The parent ``medium`` left the training domain in 1 interval of its batch: its d50 is partly an "
        "extrapolation." in feed_check_words(partly_outside)
    )
    text = feed_check_words(_check([8.0, 8.2]).to_dict())
    assert "PBM-DEM does not confirm it: no replicate ends below both parents' PBM-ANN d50." in text
    text = feed_check_words(_check([6.0, 8.0]).to_dict())
    assert "PBM-DEM confirms it in part: 1 of 2 replicates end below both parents' PBM-ANN d50." in text
    text = feed_check_words(_check([6.1], study_d50=(7.8, 9.0, 10.5, 16.0, 13.0)).to_dict())
    assert "1 PBM-DEM loop (" in text and "ends at d50 6.10 mm" in text
    assert "the surrogate's members 5.76-7.04 mm" in text
    assert "set ``validation.feed_check.feed: medium+coarse`` to check that one" in text

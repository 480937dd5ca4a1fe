"""The validation's statistics: replicate bands, the comparison table, the active-learning proposals."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pbmdem.validation import bands, proposals


def summary(times, d50, scale=1.0):
    d50 = np.asarray(d50, float)
    return pd.DataFrame({"time": times, "d10": 0.6 * d50 * scale, "d50": d50 * scale, "d90": 1.4 * d50 * scale})


def test_band_is_the_replicate_envelope_and_outside_is_measured_from_its_edge():
    t = np.array([0.0, 10.0, 20.0])
    dem = [summary(t, [2.0, 3.0, 4.0]), summary(t, [2.0, 3.2, 4.4]), summary(t, [2.0, 2.9, 4.1])]
    ann = summary(t, [2.0, 3.1, 4.8])  # inside, inside, 0.4 above the top edge 4.4
    members = pd.concat([summary(t, [2.0, 3.0, 4.6]).assign(member=0), summary(t, [2.0, 3.3, 5.0]).assign(member=1)])
    table = bands.band_table(dem, ann, members, constant=summary(t, [2.0, 2.5, 3.0]))
    d50 = table[table.statistic == "d50"].reset_index(drop=True)
    np.testing.assert_allclose(d50.dem_min, [2.0, 2.9, 4.0])
    np.testing.assert_allclose(d50.dem_max, [2.0, 3.2, 4.4])
    np.testing.assert_allclose(d50.dem_mean, [2.0, (3.0 + 3.2 + 2.9) / 3, 12.5 / 3])
    np.testing.assert_allclose(d50.dem_sd[1], np.std([3.0, 3.2, 2.9], ddof=1))
    np.testing.assert_allclose(d50.ann_member_min, [2.0, 3.0, 4.6])
    np.testing.assert_allclose(d50.ann_member_max, [2.0, 3.3, 5.0])
    # distance outside: 0 inside the band; (4.8 - 4.4) / mean(4.0, 4.4, 4.1) at the end
    np.testing.assert_allclose(d50.ann_outside, [0.0, 0.0, 0.4 / (12.5 / 3)])
    assert bands.largest_outside(table, "ann", "d50") == pytest.approx(0.4 / (12.5 / 3))
    # below the band counts too: the constant kernel ends 1.0 below the lower edge 4.0
    assert bands.largest_outside(table, "constant", "d50") == pytest.approx((4.0 - 3.0) / (12.5 / 3))
    assert set(table.statistic) == {"d10", "d50", "d90"} and (table.n_dem_replicates == 3).all()


def test_a_single_replicate_has_no_spread_and_replicates_must_share_their_times():
    t = np.array([0.0, 10.0])
    one = bands.band_table([summary(t, [2.0, 3.0])], summary(t, [2.0, 3.0]))
    assert one.dem_sd.isna().all() and (one.ann_outside == 0).all()
    with pytest.raises(ValueError, match="replicate 1 records other times"):
        bands.band_table([summary(t, [2.0, 3.0]), summary(t + 1.0, [2.0, 3.0])], summary(t, [2.0, 3.0]))


def write_run(folder, times, d50, wall, provider_wall, intervals=None, merged=None, **timing):
    folder.mkdir(parents=True, exist_ok=True)
    summary(times, d50, 1e-3).assign(number_mean_diameter=1e-3).to_csv(folder / "summary.csv", index=False)
    pd.DataFrame({"time": [times[-1]], "diameter": [1e-3], "mass_fraction": [1.0]}).to_csv(
        folder / "final_bins.csv", index=False
    )
    timing = {
        "total_wall_time_s": wall,
        "provider_wall_time_s": provider_wall,
        "pbm_wall_time_s": wall - provider_wall,
        **timing,
    }
    if merged is not None:  # the grid floor (pbm.results.grid_floor): the share of the final number merged
        timing["grid_floor"] = {"merged_fraction": merged, "flagged": merged > 0.01}
    (folder / "timing.json").write_text(json.dumps(timing))
    if intervals is not None:
        intervals.to_csv(folder / "intervals.csv", index=False)


def test_comparison_row_follows_the_contract(tmp_path):
    from pbmdem.validation.comparison import compare

    t = np.array([0.0, 10.0, 20.0])
    folder = tmp_path / "rpm300"
    loop = pd.DataFrame({"interval": [0, 1], "out_of_domain_count": [0, 0], "out_of_domain": ["", ""]})
    for k, end in enumerate((4.0, 4.4, 4.1)):
        write_run(
            folder / "pbm_dem" / f"rep{k}",
            t,
            [2.0, 3.0, end],
            wall=120.0 + k,
            provider_wall=119.0,
            intervals=loop,
            merged=0.001 * k,
            dem_cpu_time_s=100.0 + k,  # LIGGGHTS' processes
            pbm_cpu_time_s=0.5,
        )
    write_run(
        folder / "pbm_ann",
        t,
        [2.0, 3.1, 4.8],
        wall=0.04,  # the first batch of its process
        provider_wall=0.01,
        warm_wall_time_s_median=0.012,
        warm_cpu_time_s_median=0.02,  # two threads
        intervals=loop.assign(
            out_of_domain_count=[0, 2], out_of_domain=["", "d_large = 0.011 outside the training range"]
        ),
        merged=0.05,
    )
    write_run(folder / "pbm_constant", t, [2.0, 2.5, 3.0], wall=0.03, provider_wall=0.0)  # an older record
    table = compare(tmp_path, ["300"], [150, 300], replicates=3)
    row = table.iloc[0]
    assert row.rpm == 300 and row.in_training_grid and row.n_dem_replicates == 3
    assert row.d50_end_dem_mm == pytest.approx(12.5 / 3) and row.d50_end_dem_min_mm == 4.0
    assert row.ann_d50_outside_band_max == pytest.approx(0.4 / (12.5 / 3))
    # the tails (d10 = 0.6 d50, d90 = 1.4 d50 here): the same distance outside, in mm at the end
    assert row.ann_d10_outside_band_max == pytest.approx(0.4 / (12.5 / 3))
    assert row.ann_d90_outside_band_max == pytest.approx(0.4 / (12.5 / 3))
    assert row.d10_end_ann_mm == pytest.approx(0.6 * 4.8) and row.d90_end_dem_max_mm == pytest.approx(1.4 * 4.4)
    assert row.d10_end_dem_mm == pytest.approx(0.6 * 12.5 / 3)
    assert row.ann_out_of_domain_intervals == 1 and row.ann_intervals == 2
    # the reference's own spread: replicate 1 (4.4) against the others' mean (4.05) at the end
    assert row.dem_replicate_d50_rel_error_max == pytest.approx(0.35 / 4.05)
    # the speed ratio: warm PBM-ANN batches (median) against a PBM-DEM loop (mean), in CPU and in wall time
    assert row.pbm_dem_wall_s == pytest.approx(121.0) and row.wall_time_ratio_dem_over_ann == pytest.approx(121 / 0.012)
    assert row.pbm_dem_cpu_s == pytest.approx(101.5) and row.pbm_ann_cpu_s == pytest.approx(0.02)
    assert row.cpu_time_ratio_dem_over_ann == pytest.approx(101.5 / 0.02)
    assert row.pbm_ann_first_batch_wall_s == pytest.approx(0.04)
    assert row.dem_calls == 2
    # the grid floor: the replicates' largest share, PBM-ANN's, and n/a for a record without it
    assert row.dem_merged_fraction_max == 0.002 and row.ann_merged_fraction == 0.05
    assert np.isnan(row.constant_merged_fraction)
    from pbmdem.report.tables import comparison_tables

    domain = comparison_tables(table)["domain"].iloc[0]
    assert domain["grid floor: merged fragments per final granule, PBM-DEM / PBM-ANN / PBM-constant (%)"] == (
        "0.2 / 5 FLAGGED / n/a"
    )
    for col in (
        "n_dem_replicates",
        "ann_d50_outside_band_max",
        "ann_out_of_domain_intervals",
        "wall_time_ratio_dem_over_ann",
        "cpu_time_ratio_dem_over_ann",
        "ann_d50_rel_error_max",
        "d50_end_ann_mm",
    ):
        assert col in table.columns


def test_proposals_rank_out_of_domain_samples_and_cap_what_the_bowl_cannot_hold(tiny_config):
    small = tiny_config.distribution("small")  # the tiny grid: 600 and 1200 rpm x small, large
    feed = [round(f * 460) for f in small.number_fractions]
    a_grid = proposals.Assessment(900.0, 0, list(small.diameters), feed, {}, spread=0.04)
    a_fast = proposals.Assessment(1500.0, 0, list(small.diameters), feed, {"tip_speed": 0.25}, spread=0.01)
    a_out = proposals.Assessment(900.0, 1, [0.002, 0.0031, 0.0049], [200, 60, 20], {"d_large": 0.5}, spread=0.02)
    a_big = proposals.Assessment(
        900.0, 2, [0.002, 0.004, 0.03], [150, 40, 12], {"d_large": 4.0, "frac_large": 0.3}, spread=0.05
    )
    table = proposals.propose(
        tiny_config.grid,
        tiny_config.granulator,
        tiny_config.size_distributions,
        [a_grid, a_fast, a_out, a_big],
        max_points=4,
    )
    # by out-of-domain excess, then spread; the feed at 900 rpm is skipped: its bracketing grid
    # points (600 and 1200 rpm) are run already
    assert list(table.interval) == [2, 1, 0] and list(table.rpm) == [900.0, 900.0, 1500.0]
    assert list(table.kind) == ["distribution", "distribution", "point"]
    big = table.iloc[0]
    assert big.capped_at_granulator_limit and max(json.loads(big.diameters)) == pytest.approx(
        proposals.largest_feasible_diameter(tiny_config.granulator)
    )
    assert sum(json.loads(big.number_fractions)) == pytest.approx(1.0, abs=1e-12)
    # between grid speeds: run at the grid speeds on either side; beyond them: at its own speed
    assert json.loads(big.points_rpm) == [600.0, 1200.0]
    assert table.iloc[2]["name"] == "small" and json.loads(table.iloc[2].points_rpm) == [1500.0]
    # names never clash with a defined distribution
    again = proposals.propose(
        tiny_config.grid,
        tiny_config.granulator,
        {**tiny_config.size_distributions, "al_rpm900_i2": tiny_config.distribution("large")},
        [a_big],
        max_points=1,
    )
    assert again["name"].tolist() == ["al_rpm900_i2_2"]
    frag = proposals.fragment(tiny_config.grid, table)
    assert set(frag["size_distributions"]) == {"al_rpm900_i2", "al_rpm900_i1"}
    assert frag["grid"] == {
        "extra_points": [
            {"rpm": 600.0, "distribution": "al_rpm900_i2"},
            {"rpm": 1200.0, "distribution": "al_rpm900_i2"},
            {"rpm": 600.0, "distribution": "al_rpm900_i1"},
            {"rpm": 1200.0, "distribution": "al_rpm900_i1"},
            {"rpm": 1500.0, "distribution": "small"},
        ]
    }


def test_a_sample_like_a_defined_distribution_proposes_that_distribution(tiny_config):
    large = tiny_config.distribution("large")
    d = [x + 4e-5 for x in large.diameters]  # within a rounding step
    n = [round(460 * (f + e)) for f, e in zip(large.number_fractions, (0.005, -0.005, 0.0))]
    args = (tiny_config.grid, tiny_config.granulator, tiny_config.size_distributions)
    beyond = proposals.propose(*args, [proposals.Assessment(1500.0, 3, d, n, {"tip_speed": 0.2})], max_points=2)
    assert beyond[["name", "kind"]].values.tolist() == [["large", "point"]]
    # between grid speeds its bracketing points are the grid's own: nothing to propose
    assert proposals.propose(*args, [proposals.Assessment(900.0, 3, d, n, spread=0.1)], max_points=2).empty


def test_extra_points_join_the_grid_once(tiny_config):
    from conftest import config_of

    from pbmdem.config import ConfigError

    d = tiny_config.to_dict()
    d["grid"]["extra_points"] = [
        {"rpm": 900, "distribution": "small"},
        {"rpm": 600, "distribution": "small"},  # a grid point already
        {"rpm": 900, "distribution": "small"},
    ]
    with pytest.raises(ConfigError, match="extra_points"):
        config_of(d)  # duplicates are refused by the schema
    d["grid"]["extra_points"] = d["grid"]["extra_points"][:2]
    grid = config_of(d).grid
    assert grid.points() == [(600.0, "small"), (600.0, "large"), (1200.0, "small"), (1200.0, "large"), (900.0, "small")]
    assert grid.speeds() == [600.0, 900.0, 1200.0] and grid.distributions() == ["small", "large"]
    d["grid"]["extra_points"] = [{"rpm": 900, "distribution": "nowhere"}]
    with pytest.raises(ConfigError, match=r"grid.extra_points\[0\].distribution: 'nowhere' is not defined"):
        config_of(d)


def test_a_proposal_spans_the_sample_it_comes_from():
    """Rounded outwards at both ends: a class 0.04 % above the training sizes is not rounded back
    into them (which would propose what the surrogate already knows)."""
    a = proposals.Assessment(900.0, 3, [0.002488707, 0.003651743, 0.004583121, 0.008003659], [125, 60, 66, 67])
    d, f, capped = proposals.as_distribution(a, np.inf)
    assert d == pytest.approx([0.0024, 0.0037, 0.0046, 0.0081]) and not capped
    assert min(d) <= min(a.diameters) and max(d) >= max(a.diameters)
    # a class on the step stays where it is (no round-off step outwards)
    d, _, _ = proposals.as_distribution(proposals.Assessment(0.0, 0, [0.002, 0.003, 0.004], [5, 3, 2]), np.inf)
    assert d == pytest.approx([0.002, 0.003, 0.004])


def test_the_fragment_is_a_valid_addition_to_the_config(tiny_config, tmp_path):
    from conftest import config_of

    from pbmdem.config import load_yaml

    a = proposals.Assessment(900.0, 1, [0.002, 0.0031, 0.0049], [200, 60, 20], {"d_large": 0.5}, spread=0.02)
    table = proposals.propose(tiny_config.grid, tiny_config.granulator, tiny_config.size_distributions, [a], 2)
    path = tmp_path / "proposals.yaml"
    proposals.write_fragment(tiny_config.grid, table, path, source="a test")
    text = path.read_text()
    assert text.startswith("# Operating points proposed") and "outside the training domain in d_large" in text
    from snakemake.utils import update_config

    merged = tiny_config.to_dict()
    update_config(merged, load_yaml(path))  # as Snakemake merges a second --configfile
    cfg = config_of(merged)
    assert cfg.grid.size_distributions == tiny_config.grid.size_distributions
    assert cfg.grid.points()[-2:] == [(600.0, "al_rpm900_i1"), (1200.0, "al_rpm900_i1")]
    assert cfg.dem_point("al_rpm900_i1").sizes.diameters == (0.002, 0.0031, 0.0049)


def test_a_failed_ensemble_member_is_reported_not_banded():
    t = np.array([0.0, 10.0])
    ok = summary(t, [2.0, 3.0]).assign(member=0, failed="")
    failed = pd.DataFrame({"member": [1], "time": [np.nan], "failed": ["aggregation beyond the last bin"]})
    members = pd.concat([ok, failed], ignore_index=True)
    table = bands.band_table([summary(t, [2.0, 3.1])], summary(t, [2.0, 3.0]), members)
    d50 = table[table.statistic == "d50"]
    np.testing.assert_allclose(d50.ann_member_min, [2.0, 3.0])  # the failed member is not in the band
    assert bands.finished_members(members).member.unique().tolist() == [0]

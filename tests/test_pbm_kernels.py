"""Collision-frequency sources (DEM table interpolation), success probability, the aggregation
operators, config defaults/schema and the command line."""

from __future__ import annotations

import dem_tables
import numpy as np
import pandas as pd
import pbm_oracle
import pytest

from pbmdem.pbm import (
    SCHEMES,
    CellAverageAggregation,
    FixedPivotAggregation,
    Grid,
    PBMInputError,
    SuccessProbability,
    TableFrequency,
)

D = np.array([0.002, 0.003, 0.004])


def make_table(rpms=(300.0, 900.0)):
    return dem_tables.pair_table(D, lambda rpm, a, b: law(D[a], D[b], rpm), rpms)


def law(d1, d2, rpm):
    return 1e-3 * (rpm / 300.0) * (d1 * d2 / 4e-6) ** 1.2


def test_table_reproduces_nodes_and_power_law_between():
    src = TableFrequency(make_table())
    c = src(D, np.ones(3), 300.0)
    np.testing.assert_allclose(c, law(D[:, None], D[None, :], 300.0), rtol=1e-12)
    # log-log bilinear interpolation is exact for a power law between the nodes
    d = np.array([0.0025, 0.0035])
    np.testing.assert_allclose(src(d, np.ones(2), 900.0), law(d[:, None], d[None, :], 900.0), rtol=1e-12)
    assert np.allclose(c, c.T)


def test_table_rpm_interpolation_and_clamping():
    src = TableFrequency(make_table())
    mid = src(D, np.ones(3), 600.0)
    lo, hi = src(D, np.ones(3), 300.0), src(D, np.ones(3), 900.0)
    # log c linear in rpm: geometric mean half-way
    np.testing.assert_allclose(mid, np.sqrt(lo * hi), rtol=1e-12)
    np.testing.assert_allclose(src(D, np.ones(3), 100.0), lo)
    np.testing.assert_allclose(src(D, np.ones(3), 2000.0), hi)


def test_table_size_clamping_and_linear_extrapolation():
    clamp = TableFrequency(make_table(), extrapolation="clamp")
    lin = TableFrequency(make_table(), extrapolation="linear")
    d = np.array([0.001, 0.002, 0.008])
    c = clamp(d, np.ones(3), 300.0)
    assert c[0, 0] == pytest.approx(law(0.002, 0.002, 300.0))
    assert c[2, 2] == pytest.approx(law(0.004, 0.004, 300.0))
    e = lin(d, np.ones(3), 300.0)
    np.testing.assert_allclose(e, law(d[:, None], d[None, :], 300.0), rtol=1e-10)


def test_table_averages_duplicate_pairs_and_floors_zeros():
    t = make_table(rpms=(300.0,))
    t2 = t.copy()
    t2["distribution"] = "coarse"
    t2["encounter_frequency_per_pair"] *= 3.0
    src = TableFrequency(pd.concat([t, t2]))
    np.testing.assert_allclose(src(D, np.ones(3), 300.0), 2.0 * law(D[:, None], D[None, :], 300.0), rtol=1e-12)
    t3 = t.copy()
    t3.loc[t3.index[-1], "encounter_frequency_per_pair"] = 0.0  # the (4 mm, 4 mm) pair saw no collision
    c = TableFrequency(t3, zero_floor=1e-3)(D, np.ones(3), 300.0)
    assert c[2, 2] == pytest.approx(
        1e-3 * t3["encounter_frequency_per_pair"][t3["encounter_frequency_per_pair"] > 0].min()
    )


def test_table_from_csv_selects_distribution(tmp_path):
    t = make_table()
    t2 = t.copy()
    t2["distribution"] = "coarse"
    t2["encounter_frequency_per_pair"] *= 5.0
    p = tmp_path / "collisions.csv"
    pd.concat([t, t2]).to_csv(p, index=False)
    src = TableFrequency.from_csv(p, distribution="coarse")
    np.testing.assert_allclose(src(D, np.ones(3), 300.0), 5 * law(D[:, None], D[None, :], 300.0), rtol=1e-12)
    with pytest.raises(PBMInputError, match=r"no rows for distribution 'huge'; present: \['coarse', 'fine'\]"):
        TableFrequency.from_csv(p, distribution="huge")


@pytest.mark.parametrize(
    "mutate,match",
    [
        (
            lambda t: t.drop(columns=["encounter_frequency_per_pair"]),
            r"lacks columns \['encounter_frequency_per_pair'\]",
        ),
        (lambda t: t.assign(encounter_frequency_per_pair=-1.0), r"encounter_frequency_per_pair has values \[-1\."),
        (lambda t: t.assign(d_i=0.0), r"column d_i has values \[0\."),
        (lambda t: t.iloc[1:], r"no row for the pair d_i = 0.002, d_j = 0.002"),
    ],
)
def test_bad_tables(mutate, match):
    with pytest.raises(PBMInputError, match=match):
        TableFrequency(mutate(make_table(rpms=(300.0,))))


def test_success_probability_models():
    phi = np.array([0.0, 0.019, 0.02, 0.1])
    step = SuccessProbability("step", threshold=0.02)
    np.testing.assert_array_equal(step.per_particle(phi), [0, 0, 1, 1])
    psi = step(phi)
    assert psi[3, 2] == 1 and psi[3, 1] == 0 and psi[1, 1] == 0
    logi = SuccessProbability("logistic", threshold=0.02, width=0.005)
    p = logi.per_particle(phi)
    assert p[2] == pytest.approx(0.5) and np.all(np.diff(p) > 0)
    np.testing.assert_array_equal(SuccessProbability("always")(phi), np.ones((4, 4)))


def aggregation_rates(op, beta, N, l, g):
    """Per-bin aggregation rates (dN, dL, dG) from per-particle liquid ``l`` and gas ``g``, and the
    refused solid-volume rate (in the unit of the grid), by the compiled totals."""
    N = np.asarray(N, float)
    d, refused = pbm_oracle.compiled_totals(op, beta, np.stack((N, N * l, N * g)))
    return d[0], d[1], d[2], refused * op.x[0]


@pytest.mark.parametrize("scheme", ["cell_average", "fixed_pivot"])
def test_aggregation_targets_and_conservation(scheme):
    g = Grid(12, 2.0, v0=1.0)
    op = SCHEMES[scheme](g.x, g.edges[1:-1])
    # equal pivots double exactly onto the next pivot; the last row/column is beyond the grid
    assert op.target_matrix[3, 3] == 4
    assert op.target_matrix[11, 11] == -1 and op.target_matrix[0, 11] == -1
    rng = np.random.default_rng(1)
    N = rng.random(12) * (np.arange(12) < 10)
    l, gas = rng.random(12), rng.random(12)
    beta = rng.random((12, 12))
    beta = beta + beta.T
    dN, dL, dG, refused = aggregation_rates(op, beta, N, l, gas)
    assert abs(np.sum(dN * g.x)) < 1e-12 * np.sum(N * g.x) * beta.max() * N.sum()
    assert abs(dL.sum()) < 1e-13 and abs(dG.sum()) < 1e-13
    # bins 10 and 11 are empty, so no aggregate leaves the grid; one particle is lost per event
    assert refused == 0.0
    events = 0.5 * (np.outer(N, N) * beta).sum()
    assert dN.sum() == pytest.approx(-events, rel=1e-12)
    # liquid proportional to solid (l = 0.3 x) stays proportional: liquid follows the solid volume
    dN2, dL2, _, _ = aggregation_rates(op, beta, N, 0.3 * g.x, gas)
    np.testing.assert_allclose(dL2, 0.3 * dN2 * g.x, rtol=1e-10, atol=1e-12 * np.abs(dL2).max())


def test_fixed_pivot_splits_each_aggregate_between_its_two_pivots():
    g = Grid(6, 2.0, v0=1.0)  # pivots 1, 2, 4, 8, 16, 32
    fp = FixedPivotAggregation(g.x)
    ca = CellAverageAggregation(g.x)
    beta = np.zeros((6, 6))
    beta[1, 2] = beta[2, 1] = 1.0  # only pairs (2, 4) -> 6, between pivots 4 and 8
    beta[0, 3] = beta[3, 0] = 1.0  # and (1, 8) -> 9, between 8 and 16
    N = np.array([0.0, 1.0, 2.0, 3.0, 0.0, 0.0]) + np.eye(6)[0]
    dN, dL, _, _ = aggregation_rates(fp, beta, N, np.ones(6), np.zeros(6))
    r1, r2 = 1.0 * 2.0, 1.0 * 3.0  # event rates of (2, 4) and (1, 8)
    births = np.array([0.0, 0.0, r1 * 0.5, r1 * 0.5 + r2 * 7 / 8, r2 / 8, 0.0])
    deaths = np.array([r2, r1, r1, r2, 0.0, 0.0])
    np.testing.assert_allclose(dN, births - deaths, rtol=1e-14)
    # liquid (one unit per particle, two per aggregate) follows the solid each pivot receives
    np.testing.assert_allclose(dL[4], 2 * r2 * (1 / 8) * 16 / 9, rtol=1e-14)
    # the cell average pools both aggregates (6 and 9) in the cell of pivot 8 and splits their mean
    # 7.8 between 4 and 8: other births per bin, the same number and solid-volume totals
    dN_ca, _, _, _ = aggregation_rates(ca, beta, N, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(dN_ca, np.array([0.0, 0.0, 5 * 0.2 / 4, 5 - 5 * 0.2 / 4, 0.0, 0.0]) - deaths, rtol=1e-14)
    assert dN_ca.sum() == pytest.approx(dN.sum()) and abs(dN_ca @ g.x) < 1e-13


def test_unknown_aggregation_scheme_is_refused(default_mapping):
    from conftest import config_of

    from pbmdem.config import ConfigError

    default_mapping["pbm"]["aggregation"]["scheme"] = "pivot"
    with pytest.raises(ConfigError, match=r"pbm.aggregation.scheme = 'pivot'"):
        config_of(default_mapping)


def test_main_config_schema_checks_the_pbm_section(default_mapping):
    from conftest import config_of

    from pbmdem.config import ConfigError

    default_mapping["pbm"] = {"grid": {"bins": 1}}
    with pytest.raises(ConfigError, match=r"pbm.grid.bins = 1"):
        config_of(default_mapping)


def test_cli_constant_run(tmp_path, root):
    from pbmdem.cli import main

    out = tmp_path / "rpm600_fine"
    assert (
        main(
            [
                "pbm",
                "--config",
                str(root / "config" / "config.yaml"),
                "--kernel",
                "constant",
                "--rpm",
                "600",
                "--distribution",
                "fine",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    for name in ("summary.csv", "bins.csv", "run.json", "psd.png", "d50.png"):
        assert (out / name).is_file()


def test_cli_table_needs_a_table(tmp_path, root, capsys):
    from pbmdem.cli import main

    assert (
        main(
            [
                "pbm",
                "--config",
                str(root / "config" / "config.yaml"),
                "--kernel",
                "table",
                "--rpm",
                "600",
                "--out",
                str(tmp_path / "t"),
            ]
        )
        == 2
    )
    assert "--kernel table needs --table PATH" in capsys.readouterr().err


def test_cli_table_run(tmp_path, root):
    import yaml

    from pbmdem.cli import main

    table = tmp_path / "collisions.csv"
    make_table().to_csv(table, index=False)
    out = tmp_path / "table"
    cfg = yaml.safe_load((root / "config" / "config.yaml").read_text())
    cfg["pbm"]["breakage"]["enabled"] = False  # no wall tables here: aggregation from the pair table
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(cfg))
    assert (
        main(
            [
                "pbm",
                "--config",
                str(config),
                "--kernel",
                "table",
                "--table",
                str(table),
                "--rpm",
                "600",
                "--distribution",
                "fine",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    s = pd.read_csv(out / "summary.csv")
    assert s["number_mean_diameter"].iloc[-1] > s["number_mean_diameter"].iloc[0]

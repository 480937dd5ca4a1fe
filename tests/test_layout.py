"""The results layout (pbmdem.layout): the paths the rules and the library share."""

from __future__ import annotations

import pytest

from pbmdem import layout


def test_paths_of_one_run_and_their_wildcard_patterns():
    assert layout.dem_run("300", "fine", 1) == "results/dem/rpm300_fine/rep1"
    assert layout.dem_run() == "results/dem/rpm{rpm}_{dist}/rep{rep}"
    assert layout.pbm_run("constant", "600", "coarse", root="out") == "out/pbm/constant/rpm600_coarse"
    assert layout.validation_run("pbm_dem", "450", 2) == "results/validation/rpm450/pbm_dem/rep2"
    assert layout.validation_run("pbm_ann", validation_dir="v") == "v/rpm{rpm}/pbm_ann"
    assert layout.report("tables/settings.csv") == "results/report/tables/settings.csv"
    assert layout.feed_check_run() == "results/validation/feed_check/pbm_dem/rep{rep}"
    assert layout.feed_check_run(2, root="out") == "out/validation/feed_check/pbm_dem/rep2"
    assert layout.feed_check("pbm_ann.csv") == "results/validation/feed_check/pbm_ann.csv"
    assert layout.MODEL == "results/surrogate/model.skops"
    with pytest.raises(
        ValueError, match=r"validation method 'pbm_x'; allowed: \['pbm_dem', 'pbm_ann', 'pbm_constant'\]"
    ):
        layout.validation_run("pbm_x", "300")


@pytest.mark.parametrize("rpm", ["300", "412.5"])
def test_validation_dir_is_found_again_from_any_file_of_a_speed(rpm):
    for folder in (
        layout.validation_run("pbm_dem", rpm, 0, "/data/study/validation"),
        layout.validation_run("pbm_constant", rpm, validation_dir="/data/study/validation"),
        layout.speed(rpm, "/data/study/validation"),
    ):
        assert layout.validation_dir_of(f"{folder}/summary.csv") == "/data/study/validation"
    with pytest.raises(ValueError, match="results/dem/runs.csv is not below a validation speed's folder"):
        layout.validation_dir_of("results/dem/runs.csv")

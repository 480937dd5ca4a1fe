"""Settings (schema, defaults), training entry point, CLI and Snakemake rule of the surrogate."""

import hashlib
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from synthetic_tables import make_synthetic_table, make_synthetic_tables

from pbmdem.cli import build_parser, main
from pbmdem.config import ConfigError, Surrogate, load_config
from pbmdem.config.describe import config_schema
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_EDGES
from pbmdem.surrogate import load_surrogate
from pbmdem.surrogate.features import check_impeller_radius
from pbmdem.surrogate.settings import build_baselines, build_surrogate
from pbmdem.surrogate.train import train_and_report

REPO = Path(__file__).resolve().parents[1]
R = 0.0265  # impeller radius (m) of the synthetic tables
TINY = {
    "hidden_layer_sizes": [[4]],
    "alpha": [0.01, 0.1],
    "ensemble_size": 2,
    "seeds": [3, 4],
    "max_iter": 300,
    "cv": {"strategy": "group_kfold", "n_splits": 3},
    "model": "mlp",
    "kriging": {"n_restarts_optimizer": 1},
}


def tiny_settings() -> dict:
    return Surrogate.from_section(TINY).to_dict()


def test_the_generated_schema_holds_the_defaults():
    schema = config_schema()
    assert schema["$schema"].endswith("draft/2020-12/schema")
    section = schema["$defs"]["Surrogate"]
    assert section["additionalProperties"] is False
    assert set(Surrogate().to_dict()) == set(section["properties"])
    assert section["properties"]["max_iter"]["default"] == Surrogate().max_iter
    # the project config's surrogate section keeps the default seeds
    section = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["surrogate"]
    assert Surrogate.from_section(section).member_seeds == Surrogate.from_section({}).member_seeds


def test_settings_completion_and_validation():
    s = Surrogate.from_section({"cv": {"strategy": "group_kfold"}, "ensemble_size": 3})
    assert s.cv.strategy == "group_kfold" and s.cv.n_splits == 5
    assert s.seeds is None and s.member_seeds == (0, 1, 2)
    with pytest.raises(ConfigError, match="hiden_layer_sizes"):
        Surrogate.from_section({"hiden_layer_sizes": [[4]]})
    with pytest.raises(ConfigError, match=r"surrogate.cv.strategy = 'kfold'"):
        Surrogate.from_section({"cv": {"strategy": "kfold"}})
    with pytest.raises(ConfigError, match=r"surrogate.alpha\[0\] = -1.0"):
        Surrogate.from_section({"alpha": [-1.0]})
    with pytest.raises(ConfigError, match="2 seeds but ensemble_size = 3"):
        Surrogate.from_section({"ensemble_size": 3, "seeds": [1, 2]})


def test_build_surrogate_from_settings():
    cfg = load_config(REPO / "config" / "config.yaml")
    radius = cfg.granulator.impeller.tip_radius
    assert radius == cfg.granulator.impeller.blade_length
    est = build_surrogate(tiny_settings(), radius)
    freq = est.frequency_model
    assert freq.hidden_layer_sizes == ((4,),) and freq.seeds == (3, 4) and est.impeller_radius == radius
    assert freq.cv == "group_kfold" and freq.n_splits == 3
    assert est.velocity_model.get_params() == freq.get_params() and est.velocity_model is not freq
    # every value of the section reaches the estimators (none comes from a constructor default)
    s = cfg.surrogate.to_dict()
    est = build_surrogate(s, radius, n_jobs=2, family="mlp")
    params = est.get_params(deep=False)
    assert sorted(params) == [
        "domain_margin",
        "feature_transform",
        "frequency_model",
        "impeller_radius",
        "physics_offset",
        "speed_law",
        "speed_tail_from",
        "uncertainty_scale",
        "velocity_model",
        "velocity_uncertainty_scale",
    ]
    assert (params["impeller_radius"], params["physics_offset"], params["domain_margin"]) == (
        radius,
        s["physics_offset"],
        s["domain_margin"],
    )
    assert params["feature_transform"] == s["feature_transform"]
    assert params["speed_law"] == s["speed_law"] == "gengamma"
    # the uncertainty scales are set by training from held-out coverage, not by a setting
    assert params["uncertainty_scale"] == params["velocity_uncertainty_scale"] == 1.0
    assert est.frequency_model.get_params() == {
        "hidden_layer_sizes": tuple(tuple(h) for h in s["hidden_layer_sizes"]),
        "alpha": tuple(s["alpha"]),
        "seeds": tuple(s["seeds"]),
        "max_iter": s["max_iter"],
        "activation": s["activation"],
        "solver": s["solver"],
        "cv": s["cv"]["strategy"],
        "n_splits": s["cv"]["n_splits"],
        "n_jobs": 2,
    }
    assert build_baselines(s)["hgb"].random_state == s["random_state"]
    kriging = build_surrogate(s, radius, family="kriging").frequency_model
    assert kriging.get_params() == {
        "n_restarts_optimizer": s["kriging"]["n_restarts_optimizer"],
        "linear_trend": s["kriging"]["linear_trend"],
        "random_state": s["random_state"],
        "n_members": s["ensemble_size"],
    }
    rsm = build_surrogate(s, radius, family="rsm").frequency_model
    assert rsm.get_params() == {
        "degree": tuple(s["rsm"]["degree"]),
        "cv": s["cv"]["strategy"],
        "n_splits": s["cv"]["n_splits"],
        "n_members": s["ensemble_size"],
    }
    with pytest.raises(ValueError, match="surrogate family 'hdmr'"):
        build_surrogate(s, radius, family="hdmr")
    # seeds: null -> random_state, random_state + 1, ...
    assert build_surrogate({**s, "seeds": None, "random_state": 7}, radius).frequency_model.seeds == tuple(
        range(7, 7 + s["ensemble_size"])
    )


def test_the_impeller_radius_comes_only_from_the_granulator():
    with pytest.raises(ValueError, match="impeller_radius"):
        check_impeller_radius(-1.0)
    with pytest.raises(ValueError, match="impeller_radius"):
        build_surrogate(tiny_settings(), None)
    with pytest.raises(TypeError, match="impeller_radius"):
        train_and_report(make_synthetic_table(R, rpms=(300, 600)), "unused/model.skops", settings=tiny_settings())


def test_train_and_report_writes_outputs(tmp_path):
    table, velocity = make_synthetic_tables(R, rpms=(300, 600, 900), seed=7)
    table.loc[3, ["encounters", "encounter_frequency_per_pair"]] = 0.0  # dropped with a warning
    velocity.loc[
        (velocity["point_id"] == table.loc[3, "point_id"])
        & (velocity["class_i"] == table.loc[3, "class_i"])
        & (velocity["class_j"] == table.loc[3, "class_j"]),
        "encounters",
    ] = 0.0
    csv = tmp_path / "collisions.csv"
    vcsv = tmp_path / "impact_velocity.csv"
    table.to_csv(csv, index=False)
    velocity.to_csv(vcsv, index=False)
    out = tmp_path / "surrogate"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(
            csv, out / "model.skops", settings=tiny_settings(), impeller_radius=R, velocity_table=vcsv
        )
    for name in ("model.skops", "model.json", "metrics.csv", "parity.png"):
        assert (out / name).stat().st_size > 0
    metrics = pd.read_csv(out / "metrics.csv", dtype={"fold": str})
    assert list(metrics.columns[:3]) == ["target", "model", "fold"]
    assert {"r2_log10", "mae_log10", "noise_floor_r2_log10", "tv_distance"} <= set(metrics.columns)
    freq = metrics[metrics["target"] == "encounter_frequency"]
    vel = metrics[metrics["target"] == "impact_velocity"]
    families = {"mlp", "kriging", "rsm"}
    assert set(freq["model"]) == families | {"hgb", "physical"} and set(vel["model"]) == families | {"physical"}
    assert len(freq) == 5 * (3 + 2) and len(vel) == 4 * (3 + 2)  # 3 folds + pooled + mean, per model
    # the noise floor stands next to the grouped-CV R2 of every model
    assert freq[freq["fold"] == "pooled"]["noise_floor_r2_log10"].between(0.9, 1.0).all()
    assert meta["n_dropped_rows"] == 1 and meta["params"]["frequency_model"]["params"]["seeds"] == [3, 4]
    assert set(meta["cv_scores"]["outer_summary"]) == families | {"hgb", "physical"}
    # the model setting names the kernel source; every family is cross-validated all the same
    assert meta["family"] == meta["cv_scores"]["selected"] == "mlp"
    pooled = freq[freq["fold"] == "pooled"].set_index("model")
    assert pooled.loc[sorted(families), "coverage_90"].between(0, 1).all()
    assert pooled.loc[["hgb", "physical"], "coverage_90"].isna().all()
    assert meta["cv_scores"]["noise_floor_r2_log10"] == pytest.approx(
        freq[freq["fold"] == "pooled"]["noise_floor_r2_log10"].iloc[0]
    )
    assert set(meta["cv_scores"]["velocity_summary"]) == families | {"physical"}
    assert meta["velocity_table"] == str(vcsv) and meta["n_velocity_rows"] == len(table) - 1
    # the sidecar names the training data by its hash
    assert meta["training_data_sha256"] == {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in (csv, vcsv)}
    assert (out / "parity.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert load_surrogate(out / "model.skops").n_training_rows_ == len(table) - 1


def test_cli_train_and_predict(tmp_path, capsys):
    table, velocity = make_synthetic_tables(R, rpms=(300, 600, 900), seed=8)
    csv = tmp_path / "collisions.csv"
    vcsv = tmp_path / "impact_velocity.csv"
    table.to_csv(csv, index=False)
    velocity.to_csv(vcsv, index=False)
    cfg = yaml.safe_load((REPO / "config" / "test.yaml").read_text())
    cfg["granulator"]["impeller"]["blade_length"] = 0.012
    cfg["surrogate"] = {**TINY, "speed_tail_from": 0.316}  # the tiny tips are 0.4-1.1 m/s
    cfg_path = tmp_path / "config.yaml"
    cfg_path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert (
            main(
                [
                    "surrogate",
                    "train",
                    "--table",
                    str(csv),
                    "--velocity-table",
                    str(vcsv),
                    "--config",
                    str(cfg_path),
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
    printed = capsys.readouterr().out
    assert "replicate noise floor" in printed and "median impact speed" in printed
    meta = json.loads((out / "model.json").read_text())
    assert meta["params"]["impeller_radius"] == 0.012
    tail = meta["speed_tail"]
    assert tail["from_m_s"] == pytest.approx(0.316, rel=1e-3) and tail["a"] > 0 and tail["beta"] > 0
    assert f"pooled fast tail from 0.316 m/s: a {tail['a']:.3g}, beta {tail['beta']:.3g}" in printed
    assert (
        main(
            [
                "surrogate",
                "predict",
                "--model",
                str(out / "model.skops"),
                "--diameters",
                "0.002",
                "0.004",
                "--numbers",
                "1500",
                "500",
                "--rpm",
                "600",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    result = json.loads(printed[printed.index("{") :])
    c = np.array(result["encounter_frequency_per_pair"])
    assert c.shape == (2, 2) and np.allclose(c, c.T) and (c > 0).all()
    v = np.array(result["velocity_fractions"])
    assert v.shape == (2, 2, N_VELOCITY_BINS) and np.allclose(v.sum(axis=-1), 1.0)
    assert len(result["velocity_edges"]) == N_VELOCITY_BINS + 1
    pred_csv = tmp_path / "pred.csv"
    assert (
        main(
            [
                "surrogate",
                "predict",
                "--model",
                str(out / "model.skops"),
                "--table",
                str(csv),
                "--output",
                str(pred_csv),
            ]
        )
        == 0
    )
    pred = pd.read_csv(pred_csv)
    assert (pred["predicted_encounter_frequency_per_pair"] > 0).all()
    assert (pred["predicted_impact_velocity_median"] > 0).all()
    # a config without the granulator has no impeller radius: refused, naming the key
    bare = tmp_path / "bare.yaml"
    bare.write_text(yaml.safe_dump({"surrogate": TINY}))
    assert main(["surrogate", "train", "--table", str(csv), "--config", str(bare), "--out", str(out)]) == 2
    message = f"(?s)pbmdem: error: config file {re.escape(str(bare))}: .*'granulator' is a required property"
    assert re.search(message, capsys.readouterr().err)


def test_pbmdem_registers_the_surrogate_subcommands():
    parser = build_parser()
    args = parser.parse_args(["surrogate", "train", "--table", "t.csv", "--config", "c.yaml", "--out", "o"])
    assert args.surrogate_command == "train" and args.table == Path("t.csv") and args.config == Path("c.yaml")
    args = parser.parse_args(["surrogate", "predict", "--model", "m.skops", "--table", "t.csv"])
    assert args.surrogate_command == "predict"


def test_rule_declares_contract_paths():
    text = (REPO / "rules" / "surrogate.smk").read_text()
    assert "rule train_surrogate" in text
    from pbmdem import layout

    # the paths of docs/architecture.md, named through pbmdem.layout
    for stage, name in (
        ("dem", "collisions.csv"),
        ("dem", "impact_velocity.csv"),
        ("surrogate", "model.json"),
        ("surrogate", "metrics.csv"),
        ("surrogate", "parity.png"),
    ):
        assert f'layout.{stage}("{name}")' in text
        assert getattr(layout, stage)(name) == f"results/{stage}/{name}"
    assert "model=MODEL" in text and layout.MODEL == "results/surrogate/model.skops"
    assert "../workflow/scripts/train_surrogate.py" in text
    script = (REPO / "workflow" / "scripts" / "train_surrogate.py").read_text()
    assert "velocity_table=snakemake.input.velocity" in script


def test_single_run_table_still_trains(tmp_path):
    table = make_synthetic_table(R, rpms=(600,), distributions={"mixed": [0.4, 0.35, 0.25]}, seed=9)
    out = tmp_path / "s"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(table, out / "model.skops", settings=tiny_settings(), impeller_radius=R)
    assert meta["training_point_ids"] == ["rpm600_mixed"]
    assert len(pd.read_csv(out / "metrics.csv")) == 0 and (out / "parity.png").exists()


def test_wall_models_learn_the_wall_impacts_with_the_same_held_out_evaluation(tmp_path):
    from synthetic_tables import make_synthetic_wall_tables, wall_law

    table, velocity = make_synthetic_tables(R, rpms=(300, 600, 900), seed=11)
    walls, wall_velocity = make_synthetic_wall_tables(table, R, seed=12)
    out = tmp_path / "surrogate"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(
            table,
            out / "model.skops",
            settings=tiny_settings(),
            impeller_radius=R,
            velocity_table=velocity,
            wall_table=walls,
            wall_velocity_table=wall_velocity,
        )
    metrics = pd.read_csv(out / "metrics.csv", dtype={"fold": str})
    for wall in ("bowl", "impeller"):
        for target in ("encounter_frequency", "impact_velocity"):
            rows = metrics[(metrics["target"] == f"{wall}_{target}") & (metrics["fold"] == "pooled")]
            # the same candidates on the same folds as the pair model
            assert set(rows["model"]) == set(
                metrics[(metrics["target"] == target) & (metrics["fold"] == "pooled")]["model"]
            )
        assert meta["cv_scores"]["wall_summary"][wall]["frequency"]["mlp"]["pooled_r2_log10"] > 0.8
    model = load_surrogate(out / "model.skops")
    d, n = np.array([0.002, 0.003, 0.004]), np.array([900.0, 600.0, 300.0])
    rates = model.impacts(d, n, 600.0)
    for wall in ("bowl", "impeller"):
        rate, mu, _ = wall_law(wall, d, 600.0, R)
        frequency, fractions = rates.walls.of(wall)
        np.testing.assert_allclose(frequency, rate, rtol=0.3)
        np.testing.assert_allclose(fractions.sum(axis=1), 1.0)
        median = VELOCITY_EDGES[np.argmax(np.cumsum(fractions, axis=1) >= 0.5, axis=1)]
        assert np.all(np.abs(np.log10(median) - mu) < 0.35)  # within about a bin of the law's median
    member = model.member(1).impacts(d, n, 600.0)
    assert member.walls.frequency.shape == (2, 3) and not np.allclose(member.walls.frequency, rates.walls.frequency)


def test_a_wall_frequency_takes_the_family_of_the_walls_best_held_out_score():
    """The wall model's frequency is of the family with that wall's best pooled held-out R2, its speed
    law of the template (the pairs' speed-law family), each with its own calibration factor. The
    template here is a response surface of degree 1 in the untransformed features, which cannot
    follow the synthetic wall laws' power laws as Kriging in log features does: reverting to a clone
    of the template fails."""
    from synthetic_tables import make_synthetic_wall_tables

    from pbmdem.surrogate.persistence import family_name
    from pbmdem.surrogate.walls import train_wall_models

    table, _ = make_synthetic_tables(R, rpms=(300, 600, 900), seed=11)
    walls, wall_velocity = make_synthetic_wall_tables(table, R, seed=12)
    settings = tiny_settings()
    candidates = {name: build_surrogate(settings, R, family=name) for name in ("kriging", "rsm")}
    candidates["rsm"].set_params(feature_transform="none")
    for key in ("frequency_model", "velocity_model"):
        getattr(candidates["rsm"], key).set_params(degree=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        models, _, summaries = train_wall_models(walls, wall_velocity, candidates["rsm"], candidates, settings, R)
    for wall, model in models.items():
        scores = {name: summaries[wall]["frequency"][name]["pooled_r2_log10"] for name in candidates}
        assert scores["kriging"] > scores["rsm"]  # the premise: the template is not the best
        assert family_name(model.frequency_model_) == "kriging"
        assert family_name(model.velocity_model_) == "rsm" and model.velocity_model_.degrees_ == [1, 1, 1]
        assert model.uncertainty_scale == summaries[wall]["frequency"]["kriging"]["uncertainty_scale"]
        assert model.velocity_uncertainty_scale == summaries[wall]["impact_velocity"]["rsm"]["uncertainty_scale"]


def test_auto_chooses_the_frequency_on_the_pbm_samples_and_the_speed_law_apart(tmp_path):
    from pbmdem.surrogate.persistence import FAMILY_CLASSES

    table, velocity = make_synthetic_tables(R, rpms=(300, 600, 900), seed=13)
    samples = sorted(table["point_id"].unique())[:2]
    out = tmp_path / "surrogate"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(
            table,
            out / "model.skops",
            settings={**tiny_settings(), "model": "auto"},
            impeller_radius=R,
            velocity_table=velocity,
            pbm_samples=samples,
        )
    scores = meta["cv_scores"]["pbm_samples"]
    assert scores["point_ids"] == samples
    per = scores["scores"]
    assert set(per) == {"mlp", "kriging", "rsm"} and all(s["n_runs"] == 2 for s in per.values())
    # the frequency: the smallest MAE on the named runs; the speed law: the closest speed bins over all runs
    assert meta["family"] == meta["cv_scores"]["selected"] == min(per, key=lambda n: per[n]["mae_log10"])
    tail = {n: meta["cv_scores"]["pooled_scores"][n]["velocity_tail_log10"] for n in per}
    assert meta["velocity_family"] == meta["cv_scores"]["selected_speed_law"] == min(tail, key=tail.get)
    assert "active-learning runs" in meta["cv_scores"]["selection"]
    model = load_surrogate(out / "model.skops")
    assert type(model.frequency_model_) is FAMILY_CLASSES[meta["family"]]
    assert type(model.velocity_model_) is FAMILY_CLASSES[meta["velocity_family"]]
    # the frequency's uncertainty calibrated on the means of every held-out run (what a member shifts),
    # the speed law's on the named runs' rows
    calibration = meta["cv_scores"]["calibration"]
    assert calibration["frequency"]["rows"] == "means of every held-out run"
    pooled = meta["cv_scores"]["pooled_scores"][meta["family"]]
    assert model.uncertainty_scale == pytest.approx(pooled["run_uncertainty_scale"])
    assert pooled["run_uncertainty_scale"] != pytest.approx(pooled["uncertainty_scale"])
    assert model.velocity_uncertainty_scale == pytest.approx(per[meta["velocity_family"]]["velocity_uncertainty_scale"])
    d, n = np.array([0.002, 0.003, 0.004]), np.array([900.0, 600.0, 300.0])
    for k in range(model.n_members):
        assert model.member(k).encounters(d, n, 600.0, check_domain=False).frequency.shape == (3, 3)

"""Settings (schema, defaults), training entry point, CLI and Snakemake rule of the surrogate."""

import argparse
import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from pbmdem.surrogate import load_surrogate
from pbmdem.surrogate.cli import add_cli, main
from pbmdem.surrogate.settings import (
    DEFAULTS,
    DEFAULTS_PATH,
    SCHEMA_PATH,
    SurrogateConfigError,
    build_surrogate,
    impeller_radius_from,
    resolve_settings,
)
from pbmdem.surrogate.synthetic import make_synthetic_table
from pbmdem.surrogate.train import train_and_report

REPO = Path(__file__).resolve().parents[1]
TINY = {"hidden_layer_sizes": [[4]], "alpha": [0.01, 0.1], "ensemble_size": 2, "seeds": [3, 4],
        "max_iter": 300, "cv": {"strategy": "group_kfold", "n_splits": 3}}


def test_default_file_matches_code_and_schema():
    with open(DEFAULTS_PATH) as fh:
        section = yaml.safe_load(fh)["surrogate"]
    assert section == DEFAULTS
    assert resolve_settings({"surrogate": section}) == DEFAULTS
    schema = yaml.safe_load(SCHEMA_PATH.read_text())
    assert schema["$schema"].endswith("draft/2020-12/schema")
    assert schema["additionalProperties"] is False
    assert set(schema["properties"]) == set(DEFAULTS)


def test_settings_merge_and_validation():
    s = resolve_settings({"surrogate": {"cv": {"strategy": "group_kfold"}, "ensemble_size": 3}})
    assert s["cv"] == {"strategy": "group_kfold", "n_splits": 5}
    assert s["seeds"] is None and s["ensemble_size"] == 3
    assert resolve_settings({"granulator": {}}) == DEFAULTS  # full config without a section
    with pytest.raises(SurrogateConfigError, match="hiden_layer_sizes"):
        resolve_settings({"surrogate": {"hiden_layer_sizes": [[4]]}})
    with pytest.raises(SurrogateConfigError, match="cv.strategy"):
        resolve_settings({"surrogate": {"cv": {"strategy": "kfold"}}})
    with pytest.raises(SurrogateConfigError, match="alpha"):
        resolve_settings({"surrogate": {"alpha": [-1.0]}})
    with pytest.raises(SurrogateConfigError, match="seeds has 2 entries"):
        resolve_settings({"surrogate": {"ensemble_size": 3, "seeds": [1, 2]}})


def test_build_surrogate_from_settings():
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    radius = impeller_radius_from(cfg)
    assert radius == cfg["granulator"]["impeller"]["blade_length"]
    est = build_surrogate(resolve_settings(TINY), radius)
    assert est.hidden_layer_sizes == ((4,),) and est.seeds == (3, 4) and est.impeller_radius == radius
    assert est.cv == "group_kfold" and est.n_splits == 3


def test_train_and_report_writes_outputs(tmp_path):
    table = make_synthetic_table(rpms=(300, 600, 900), seed=7)
    table.loc[3, ["collisions", "frequency", "frequency_per_pair"]] = 0.0  # dropped with a warning
    csv = tmp_path / "collisions.csv"
    table.to_csv(csv, index=False)
    out = tmp_path / "surrogate"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(csv, out / "model.skops", settings={"surrogate": TINY})
    for name in ("model.skops", "model.json", "metrics.csv", "parity.png"):
        assert (out / name).stat().st_size > 0
    metrics = pd.read_csv(out / "metrics.csv", dtype={"fold": str})
    assert list(metrics.columns[:2]) == ["model", "fold"]
    assert {"r2_log10", "mae_log10"} <= set(metrics.columns)
    assert set(metrics["model"]) == {"mlp", "hgb", "physical"}
    assert len(metrics) == 3 * (3 + 2)  # 3 folds + pooled + mean, per model
    assert meta["n_dropped_rows"] == 1 and meta["seeds"] == [3, 4]
    assert set(meta["cv_scores"]["outer_summary"]) == {"mlp", "hgb", "physical"}
    assert (out / "parity.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert load_surrogate(out / "model.skops").n_training_rows_ == len(table) - 1


def test_cli_train_and_predict(tmp_path, capsys):
    table = make_synthetic_table(rpms=(300, 600, 900), seed=8)
    csv = tmp_path / "collisions.csv"
    table.to_csv(csv, index=False)
    cfg = {"granulator": {"impeller": {"blade_length": 0.03}}, "surrogate": TINY}
    cfg_path = tmp_path / "config.yaml"
    cfg_path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["surrogate", "train", "--table", str(csv), "--config", str(cfg_path), "--out", str(out)]) == 0
    assert json.loads((out / "model.json").read_text())["params"]["impeller_radius"] == 0.03
    assert main(["surrogate", "predict", "--model", str(out / "model.skops"), "--diameters", "0.002", "0.004",
                 "--numbers", "1500", "500", "--rpm", "600"]) == 0
    printed = capsys.readouterr().out
    c = np.array(json.loads(printed[printed.index("{"):])["frequency_per_pair"])
    assert c.shape == (2, 2) and np.allclose(c, c.T) and (c > 0).all()
    pred_csv = tmp_path / "pred.csv"
    assert main(["surrogate", "predict", "--model", str(out / "model.skops"), "--table", str(csv),
                 "--output", str(pred_csv)]) == 0
    assert (pd.read_csv(pred_csv)["predicted_frequency_per_pair"] > 0).all()


def test_add_cli_registers_subcommands():
    parser = argparse.ArgumentParser()
    add_cli(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["surrogate", "train", "--table", "t.csv", "--out", "o"])
    assert args.surrogate_command == "train" and args.table == Path("t.csv") and args.config is None
    args = parser.parse_args(["surrogate", "predict", "--model", "m.skops", "--table", "t.csv"])
    assert args.surrogate_command == "predict"


def test_rule_declares_contract_paths():
    text = (REPO / "rules" / "surrogate.smk").read_text()
    assert "rule train_surrogate" in text
    for path in ("results/dem/collisions.csv", "results/surrogate/model.skops", "results/surrogate/model.json",
                 "results/surrogate/metrics.csv", "results/surrogate/parity.png",
                 "../workflow/scripts/train_surrogate.py"):
        assert path in text
    assert (REPO / "workflow" / "scripts" / "train_surrogate.py").exists()


def test_single_run_table_still_trains(tmp_path):
    table = make_synthetic_table(rpms=(600,), distributions={"mixed": [0.4, 0.35, 0.25]}, seed=9)
    out = tmp_path / "s"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = train_and_report(table, out / "model.skops", settings=TINY)
    assert meta["training_point_ids"] == ["rpm600_mixed"]
    assert len(pd.read_csv(out / "metrics.csv")) == 0 and (out / "parity.png").exists()

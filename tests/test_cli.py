"""The `pbmdem` command line as a new user meets it: --version, help with examples for every
command, and the runtime estimate of --plan-only from the measured throughput."""

from __future__ import annotations

import json
import math

import pandas as pd
import pytest

from pbmdem import __version__
from pbmdem.cli import build_parser, main


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"pbmdem {__version__}"


def _commands(parser, prefix=()):
    """(command words, parser) of every command and subcommand."""
    for action in parser._subparsers._group_actions if parser._subparsers else ():
        for name, child in action.choices.items():
            yield (*prefix, name), child
            yield from _commands(child, (*prefix, name))


def test_every_command_has_examples_that_name_itself(capsys):
    """The top-level help says what pbmdem is; each command's help ends with examples of that very
    command (so `pbmdem view --help` shows a call that works)."""
    top = build_parser().format_help()
    assert "high-shear granulator" in top and "examples:" in top
    commands = dict(_commands(build_parser()))
    assert {("dem",), ("pbm",), ("view",), ("surrogate",), ("surrogate", "train"), ("surrogate", "predict")} <= set(
        commands
    )
    for words, parser in commands.items():
        text = parser.format_help()
        assert "examples:" in text, words
        examples = text.split("examples:")[1]
        assert f"pbmdem {' '.join(words)} " in examples, (words, examples)


def test_plan_only_estimates_the_wall_time_from_measured_runs(root, tmp_path, capsys):
    """--plan-only prints the plan with a runtime estimate: its particle-steps over the throughput
    the finished runs in --runs measured (or the reference machine's without them)."""
    config = str(root / "config" / "test.yaml")
    argv = ["dem", "--config", config, "--rpm", "600", "--distribution", "small", "--plan-only"]
    assert main([*argv, "--runs", str(tmp_path / "none.csv")]) == 0
    captured = capsys.readouterr()
    reference = json.loads(captured.out)["runtime_estimate"]
    assert "reference machine" in reference["from"] and reference["wall_time_s"] > 0
    assert "estimated LIGGGHTS wall time" in captured.err
    runs = tmp_path / "runs.csv"
    pd.DataFrame({"n_particles": [100, 100, 5000], "particle_steps_per_s": [1e5, 3e5, 8e5]}).to_csv(runs, index=False)
    assert main([*argv, "--runs", str(runs)]) == 0
    plan = json.loads(capsys.readouterr().out)
    estimate = plan["runtime_estimate"]
    assert str(runs) in estimate["from"] and "3 finished runs" in estimate["from"]
    n = plan["n_particles"]
    assert 100 < n < 5000
    # log-linear in the particle number between the medians 2e5 (100 particles) and 8e5 (5000)
    rate = 2e5 + 6e5 * math.log(n / 100) / math.log(5000 / 100)
    assert estimate["particle_steps_per_s"] == pytest.approx(rate, abs=1)
    steps = n * (plan["settle_steps"] + plan["spinup_steps"] + plan["sampling_steps"])
    assert estimate["particle_steps"] == steps
    assert estimate["wall_time_s"] == pytest.approx(steps / rate, abs=0.06)


def test_pbm_warns_of_fragments_merged_at_the_grid_floor(tiny_mapping, tmp_path, capsys):
    """`pbmdem pbm` with strong breakage (constant rate 0.5 1/s, three bins per doubling of volume):
    the run's run.json holds the grid floor, the printed summary its share of the final number, and a
    warning names it above 1 %."""
    import yaml

    tiny_mapping["pbm"]["grid"].update(ratio=2.0 ** (1 / 3), bins=40)
    tiny_mapping["pbm"]["breakage"].update(enabled=True, constant_rate=0.5)
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(tiny_mapping))
    out = tmp_path / "run"
    assert main(["pbm", "--config", str(config), "--rpm", "600", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    floor = json.loads((out / "run.json").read_text())["grid_floor"]
    assert floor["flagged"] and printed["grid_floor_merged_fraction"] == floor["merged_fraction"] > 0.01
    assert "warning: clipping: " in captured.err
    assert "breakage fragments merged at the grid floor (1.5 mm)" in captured.err and "FLAGGED" in captured.err
    summary = pd.read_csv(out / "summary.csv")
    assert summary.merged_number.iloc[-1] == pytest.approx(floor["merged_number"], rel=1e-12)

"""The Snakemake workflow end to end on the tiny configuration (real LIGGGHTS)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import snakemake_command

pytestmark = [pytest.mark.liggghts, pytest.mark.workflow]


def snakemake(
    root: Path, workdir: Path, configfile: Path, *args: str, env: dict | None = None, check: bool = True
) -> subprocess.CompletedProcess:
    cmd = snakemake_command(workdir, *args, configfile=configfile, project=root)
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=env)
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-6000:]}")
    return proc


@pytest.fixture(scope="module")
def tiny_workflow(tmp_path_factory, root):
    """`snakemake --cores 2` on config/test.yaml, run once for this module."""
    workdir = tmp_path_factory.mktemp("workflow")
    configfile = workdir / "config.yaml"
    shutil.copy(root / "config" / "test.yaml", configfile)
    snakemake(root, workdir, configfile, "--cores", "2")
    return workdir, configfile


def test_grid_tables_have_counts_for_every_class_pair(tiny_workflow):
    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    table = pd.read_csv(workdir / "results" / "dem" / "collisions.csv")
    points = {(float(r), d) for r in cfg["grid"]["impeller_rpm"] for d in cfg["grid"]["size_distributions"]}
    assert set(zip(table.rpm, table.distribution)) == points
    assert (table.collisions > 0).all(), table[table.collisions == 0]
    expected_columns = [
        "point_id",
        "rpm",
        "distribution",
        "class_i",
        "class_j",
        "d_i",
        "d_j",
        "n_i",
        "n_j",
        "n_total",
        "collisions",
        "sampling_time",
        "frequency",
        "frequency_per_pair",
        "encounters",
        "encounter_frequency_per_pair",
        "impact_velocity_median",
        "n_replicates",
        "encounter_frequency_per_pair_se",
        "frequency_per_pair_se",
    ]
    assert list(table.columns) == expected_columns
    runs = pd.read_csv(workdir / "results" / "dem" / "runs.csv")
    assert len(runs) == len(points) * cfg["dem"]["replicates"]
    assert sorted(set(runs.replicate)) == list(range(cfg["dem"]["replicates"]))
    assert (table.n_replicates == cfg["dem"]["replicates"]).all()
    velocities = pd.read_csv(workdir / "results" / "dem" / "impact_velocity.csv")
    assert list(velocities.columns) == [
        "point_id",
        "rpm",
        "distribution",
        "class_i",
        "class_j",
        "v_lo",
        "v_hi",
        "encounters",
        "n_replicates",
    ]
    per_pair = velocities.groupby(["point_id", "class_i", "class_j"])["encounters"].sum()
    np.testing.assert_allclose(
        per_pair.to_numpy(),
        table.set_index(["point_id", "class_i", "class_j"]).loc[per_pair.index, "encounters"].to_numpy(),
    )
    assert (runs.particle_steps_per_s > 0).all()
    walls = pd.read_csv(workdir / "results" / "dem" / "wall_collisions.csv")
    assert set(walls.wall) == {"bowl", "impeller"}


def test_vtk_series_open_in_pyvista(tiny_workflow):
    pyvista = pytest.importorskip("pyvista")
    workdir, _ = tiny_workflow
    for pvd in sorted((workdir / "results" / "dem").glob("*/rep*/post/particles.pvd")):
        reader = pyvista.get_reader(str(pvd))
        assert len(reader.time_values) >= 2
        first = reader.read()  # the reader opens on the first frame: it holds particles (no empty t = 0)
        first = first[0] if isinstance(first, pyvista.MultiBlock) else first
        assert first.n_points > 0 and reader.time_values[0] > 0
        reader.set_active_time_value(reader.time_values[-1])
        mesh = reader.read()
        mesh = mesh[0] if isinstance(mesh, pyvista.MultiBlock) else mesh
        assert mesh.n_points > 100 and "radius" in mesh.point_data


def test_adding_an_operating_point_runs_only_that_point(tiny_workflow, root, tmp_path):
    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    cfg["grid"]["impeller_rpm"].append(900)
    grown = tmp_path / "grown.yaml"
    grown.write_text(yaml.safe_dump(cfg))
    proc = snakemake(root, workdir, grown, "-n", "--cores", "2", "--quiet", "rules")
    out = proc.stdout + proc.stderr
    dem_jobs = [line for line in out.splitlines() if line.strip().startswith("dem_point")]
    assert dem_jobs, out
    # one new rpm x every size distribution, and nothing for the points already computed
    counts = {
        line.split()[0]: int(line.split()[1])
        for line in out.splitlines()
        if len(line.split()) == 2 and line.split()[1].isdigit()
    }
    reps = cfg["dem"]["replicates"]
    assert counts["dem_point"] == len(cfg["grid"]["size_distributions"]) * reps, out
    # the jobs of the detailed dry run are exactly the new speed's points
    detail = snakemake(root, workdir, grown, "-n", "--cores", "2").stdout
    planned, current = set(), None
    for line in detail.splitlines():
        if line.startswith("rule ") or line.startswith("localrule "):
            current = line.split()[1].rstrip(":")
        elif current == "dem_point" and line.strip().startswith("wildcards:"):
            planned.add(line.split("wildcards:")[1].strip())
    assert planned == {f"rpm=900, dist={d}, rep={r}" for d in cfg["grid"]["size_distributions"] for r in range(reps)}, (
        planned
    )


def test_adding_a_replicate_runs_only_that_replicate(tiny_workflow, root, tmp_path):
    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    cfg["dem"]["replicates"] += 1
    grown = tmp_path / "more.yaml"
    grown.write_text(yaml.safe_dump(cfg))
    detail = snakemake(root, workdir, grown, "-n", "--cores", "2").stdout
    planned = set()
    current = None
    for line in detail.splitlines():
        if line.startswith("rule ") or line.startswith("localrule "):
            current = line.split()[1].rstrip(":")
        elif current == "dem_point" and line.strip().startswith("wildcards:"):
            planned.add(line.split("wildcards:")[1].strip())
    new = cfg["dem"]["replicates"] - 1
    assert planned == {
        f"rpm={float(r):g}, dist={d}, rep={new}"
        for r in cfg["grid"]["impeller_rpm"]
        for d in cfg["grid"]["size_distributions"]
    }, planned


def test_execution_settings_rerun_nothing(tiny_workflow, root, tmp_path):
    """MPI ranks, timeouts, threads, resources and the cores given change how jobs run, not their
    results: a finished workflow schedules no job (no DEM point, no coupled loop) when they change."""
    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    cfg["dem"]["mpi_ranks"] = 2
    cfg["dem"]["timeout"] = 1234
    changed = tmp_path / "ranks.yaml"
    changed.write_text(yaml.safe_dump(cfg))
    proc = snakemake(
        root,
        workdir,
        changed,
        "-n",
        "--cores",
        "1",
        "--set-resources",
        "dem_point:tasks=2",
        "dem_point:runtime=90",
        "--set-threads",
        "dem_point=2",
        "pbm_dem_coupled=2",
    )
    out = proc.stdout + proc.stderr
    assert "Nothing to be done" in out, out
    # a change that does alter results is still seen (the check above is not vacuous)
    cfg["dem"]["seed"] = 20143
    reseeded = tmp_path / "seed.yaml"
    reseeded.write_text(yaml.safe_dump(cfg))
    out = snakemake(root, workdir, reseeded, "-n", "--cores", "1", "--quiet", "rules").stdout
    assert "dem_point" in out and "pbm_dem_coupled" in out, out


def rule_jobs(dry_run: str, rule: str) -> list[str]:
    """The job blocks of `rule` in a dry run's output (from its `rule <name>:` line to the next blank one)."""
    return re.findall(rf"^rule {rule}:\n(?:.+\n)+", dry_run + "\n", flags=re.M)


def test_the_pbm_ann_timing_has_both_cores_of_the_default_run(tiny_workflow, root):
    """Rule pbm_ann_coupled times PBM-ANN for the speed ratio: it asks for two threads, so that on
    the default `--cores 2` run no other job runs beside its warm batches (docs/validation.md)."""
    workdir, configfile = tiny_workflow
    proc = snakemake(root, workdir, configfile, "-n", "--cores", "2", "--forcerun", "pbm_ann_coupled")
    jobs = rule_jobs(proc.stdout + proc.stderr, "pbm_ann_coupled")
    assert len(jobs) == 2, proc.stdout + proc.stderr  # the tiny config's two validation speeds
    assert all(re.search(r"^\s+threads: 2$", job, flags=re.M) for job in jobs), jobs
    # a rule without the setting, scheduled in the same dry run, shows no such line (the check
    # above is not vacuous)
    comparison = rule_jobs(proc.stdout + proc.stderr, "comparison")
    assert len(comparison) == 1 and "threads:" not in comparison[0], comparison


PROJECT_FILES = ("Snakefile", "rules", "workflow", "liggghts_templates", "src", "profiles", "envs")


def test_a_copied_project_with_its_results_reruns_nothing(tiny_workflow, root, tmp_path):
    """Moving or copying a finished project (its files, results/ and .snakemake/ in one folder, the
    way a user copies a checkout) reruns nothing: no rule input or param holds an absolute path. A
    real change in the copy (the deck template) is still seen, so the check is not vacuous."""
    workdir, configfile = tiny_workflow
    moved = tmp_path / "elsewhere" / "pbmdem"
    shutil.copytree(workdir, moved, symlinks=True)  # copy2: results keep their time stamps
    for name in PROJECT_FILES:
        src = root / name
        if src.is_dir():
            shutil.copytree(src, moved / name, symlinks=True)  # src/pbmdem/data links stay relative
        else:
            shutil.copy2(src, moved / name)
    dry = snakemake(moved, moved, moved / configfile.name, "-n", "--cores", "2")
    out = dry.stdout + dry.stderr
    assert "Nothing to be done" in out, out[-4000:]
    assert "pbmdem runtime estimate: no DEM run left to do." in out, out[-2000:]
    # provenance records where the project is without being a rerun trigger
    provenance = pd.read_csv(workdir / "results" / "report" / "tables" / "provenance.csv").set_index("quantity")
    assert provenance.loc["working directory", "value"] == str(workdir)
    template = moved / "liggghts_templates" / "granulator.in"
    template.write_text(template.read_text() + "# an edited deck\n")
    dry = snakemake(moved, moved, moved / configfile.name, "-n", "--cores", "2", "--quiet", "rules")
    assert "dem_point" in dry.stdout and "pbm_dem_coupled" in dry.stdout, dry.stdout
    # the dry run's runtime estimate counts the scheduled DEM work, at the throughput measured
    from pbmdem.config import load_config

    cfg = load_config(configfile)
    runs = len(cfg.grid.points()) * cfg.dem_replicates
    intervals = len(cfg.validation.rpm) * cfg.validation.dem_replicates * cfg.validation.coupling_intervals
    intervals += cfg.validation.feed_check.replicates * cfg.validation.coupling_intervals  # the feed check's loops
    assert f"pbmdem runtime estimate: {runs} DEM grid run(s)" in dry.stderr, dry.stderr[-2000:]
    assert f"and {intervals} PBM-DEM coupling interval(s)" in dry.stderr
    assert f"from the throughput of the {runs} finished runs in results/dem/runs.csv" in dry.stderr


def test_a_damaged_run_table_stops_its_rule_with_the_message_alone(tiny_workflow, root, tmp_path):
    """A negative encounter frequency in one DEM run's table (in a copy of the finished workflow):
    the rule that reads it fails, and the terminal and the rule's log show the message naming the
    file, row, column and value, without a Python traceback."""
    workdir, configfile = tiny_workflow
    copy = tmp_path / "wd"
    shutil.copytree(workdir, copy, symlinks=True)  # copy2: results keep their time stamps
    damaged = Path("results/dem/rpm600_small/rep0/collisions.csv")
    table = pd.read_csv(copy / damaged)
    table.loc[1, "encounter_frequency_per_pair"] = -1.0
    table.to_csv(copy / damaged, index=False)  # newer than the grid table: collision_tables reruns
    proc = snakemake(root, copy, copy / configfile.name, "--cores", "1", "results/dem/collisions.csv", check=False)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0, out[-3000:]
    message = f"{damaged}: row 2, column 'encounter_frequency_per_pair' = -1.0"
    log = (copy / "results" / "logs" / "dem" / "collision_tables.log").read_text()
    for text in (out, log):
        assert message in text and "a finite number >= 0 is required" in text, text[-3000:]
        assert "Traceback" not in text, text[-3000:]
    assert "Error in rule collision_tables" in out


def test_lint_is_clean(root, tiny_workflow):
    workdir, configfile = tiny_workflow
    proc = snakemake(root, workdir, configfile, "--lint", check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Congratulations" in proc.stdout + proc.stderr


def test_a_failed_point_keeps_the_finished_ones(root, tmp_path):
    """One operating point's LIGGGHTS fails (a real engine run whose deck is broken mid-sampling):
    the job fails with the log's last lines, leaves crash.json and no table; the other point is kept."""
    from pbmdem.dem import engine as liggghts

    real = liggghts.executable()
    wrapper = tmp_path / "liggghts-fails-for-large"
    wrapper.write_text(
        f"#!{sys.executable}\n"
        "import os, sys\n"
        "args = sys.argv[1:]\n"
        "if 'large' in os.getcwd() and 'beds' not in os.getcwd():\n"
        "    deck = args[args.index('-in') + 1]\n"
        "    lines = open(deck).read().splitlines()\n"
        "    k = max(i for i, l in enumerate(lines) if l.startswith('run '))\n"
        "    lines[k] = 'run 50\\nfix broken all no/such/style'\n"
        "    open('broken.in', 'w').write('\\n'.join(lines) + '\\n')\n"
        "    args[args.index('-in') + 1] = 'broken.in'\n"
        f"os.execv({real!r}, [{real!r}, *args])\n"
    )
    wrapper.chmod(0o755)
    cfg = yaml.safe_load((root / "config" / "test.yaml").read_text())
    cfg["grid"]["impeller_rpm"] = [600]
    configfile = tmp_path / "config.yaml"
    configfile.write_text(yaml.safe_dump(cfg))
    workdir = tmp_path / "wd"
    workdir.mkdir()
    env = dict(__import__("os").environ, PBMDEM_LIGGGHTS=str(wrapper))
    proc = snakemake(
        root,
        workdir,
        configfile,
        "--cores",
        "2",
        "--keep-going",
        "results/dem/rpm600_small/rep0/collisions.csv",
        "results/dem/rpm600_large/rep0/collisions.csv",
        env=env,
        check=False,
    )
    assert proc.returncode != 0
    out = proc.stdout + proc.stderr
    assert "no/such/style" in out  # the log's tail reaches the user
    good, bad = workdir / "results/dem/rpm600_small/rep0", workdir / "results/dem/rpm600_large/rep0"
    assert (good / "collisions.csv").exists() and (good / "summary.json").exists()
    assert not (bad / "collisions.csv").exists()
    assert not (bad / "summary.json").exists()
    crash = json.loads((bad / "crash.json").read_text())
    assert "no/such/style" in crash["log_tail"]


def test_surrogate_pbm_and_report_from_the_real_tables(tiny_workflow):
    """Downstream of the real DEM tables: the surrogate is trained and evaluated on held-out runs,
    the PBM runs per grid point, the coupled loops ran LIGGGHTS, and the report has its numbers."""
    from pbmdem.config import load_config
    from pbmdem.surrogate import load_surrogate

    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    res = workdir / "results"
    metrics = pd.read_csv(res / "surrogate" / "metrics.csv")
    assert set(metrics.model) == {"mlp", "kriging", "rsm", "hgb", "physical"}
    metrics = metrics[metrics.target == "encounter_frequency"]
    pooled = metrics[metrics.fold.astype(str) == "pooled"].set_index("model")
    assert (pooled["n_test"] == len(pd.read_csv(res / "dem" / "collisions.csv"))).all()
    # the families side by side selected the kernel source by their held-out R2 (surrogate.model: auto)
    meta = json.loads((res / "surrogate" / "model.json").read_text())
    families = ["mlp", "kriging", "rsm"]
    assert meta["family"] == meta["cv_scores"]["selected"] == pooled.loc[families, "r2_log10"].idxmax()
    # the frequency's uncertainty calibrated on the held-out runs' means (what a member shifts)
    assert meta["cv_scores"]["calibration"]["frequency"]["rows"] == "means of every held-out run"
    run_scale = meta["cv_scores"]["pooled_scores"][meta["family"]]["run_uncertainty_scale"]
    assert meta["params"]["uncertainty_scale"] == pytest.approx(run_scale, rel=1e-12)
    surrogate = load_surrogate(res / "surrogate" / "model.skops")
    table = pd.read_csv(res / "dem" / "collisions.csv")
    run = table[table.point_id == table.point_id.iloc[0]]
    diag = run[run.class_i == run.class_j]
    c = surrogate.frequency_matrix(diag.d_i.to_numpy(), diag.n_i.to_numpy(float), float(run.rpm.iloc[0]))
    assert c.shape == (len(diag), len(diag)) and (c > 0).all()
    for rpm in cfg["grid"]["impeller_rpm"]:
        for dist in cfg["grid"]["size_distributions"]:
            summary = pd.read_csv(res / "pbm" / "constant" / f"rpm{rpm}_{dist}" / "summary.csv")
            assert summary.d50.iloc[-1] > summary.d50.iloc[0]
    comparison = pd.read_csv(res / "report" / "comparison.csv")
    assert sorted(comparison.rpm) == sorted(float(r) for r in cfg["validation"]["rpm"])
    assert (comparison.dem_calls == cfg["validation"]["coupling_intervals"]).all()
    assert (comparison.wall_time_ratio_dem_over_ann > 1).all()
    # the speed ratio in CPU seconds: LIGGGHTS' processes and the PBM against warm PBM-ANN batches
    assert (comparison.pbm_dem_cpu_s > 0).all() and (comparison.pbm_ann_cpu_s > 0).all()
    assert (comparison.cpu_time_ratio_dem_over_ann > 1).all()
    # d10, d50 and d90 against the PBM-DEM replicate band at every validation speed (two here)
    assert len(comparison) >= 2
    for q in ("d10", "d50", "d90"):
        assert comparison[f"ann_{q}_outside_band_max"].notna().all() and (comparison[f"{q}_end_ann_mm"] > 0).all()
    replicates = [
        sorted((res / "validation" / f"rpm{rpm}" / "pbm_dem").glob("rep*")) for rpm in cfg["validation"]["rpm"]
    ]
    n_replicates = load_config(configfile).validation.dem_replicates
    assert [len(r) for r in replicates] == [n_replicates] * len(cfg["validation"]["rpm"])
    for rep in (r for speed in replicates for r in speed):
        assert (pd.read_csv(rep / "intervals.csv").dem_collisions > 0).all(), rep
    findings = (res / "report" / "findings" / "findings.rst").read_text()
    assert "Findings" in findings
    # the findings first (speed, feed and its PBM-DEM check), then how far to trust them, each figure
    # inside the text
    order = [
        findings.find(p)
        for p in (
            "**Impeller speed.**",
            "**Feed size distribution.**",
            "**PBM-DEM check of the feed result.**",
            "**How far to trust them.**",
        )
    ]
    assert -1 not in order and order == sorted(order), order
    # the four findings figures (speed, feed, with pbm.breakage on the breakage study, and what
    # lumping leaves out)
    assert findings.count(".. image:: data:image/png;base64,") == 4
    assert "**Breakage.**" in findings
    # the PBM in 2-D (issue 37): rule lumping ran PBM-ANN with the lumped and the size x liquid PBM
    from pbmdem.coupling.lumping import CASE_COLUMNS, LIQUID_COLUMNS

    lumping = pd.read_csv(res / "validation" / "lumping.csv", dtype={"failed": str})
    assert list(lumping.columns) == list(CASE_COLUMNS)
    assert set(lumping.study) == {"default", "speed", "binder", "feed"}
    assert len(lumping[lumping.study == "speed"]) == cfg["validation"]["sweep"]["num"]
    assert len(lumping[lumping.study == "binder"]) == cfg["design_space"]["liquid_rate"]["num"]
    assert lumping.failed.isna().all()  # no batch failed (an empty text)
    for m in ("1d", "2d"):
        assert np.isfinite(lumping[f"d50_{m}"]).all() and (lumping[f"d50_{m}"] > 0).all()
    assert np.abs(lumping.solid_rel_change_2d).max() < 1e-12  # solid conserved by the 2-D batches
    assert (lumping.cpu_time_s_2d > 0).all()
    liquid = pd.read_csv(res / "validation" / "lumping_liquid.csv")
    assert list(liquid.columns) == list(LIQUID_COLUMNS) and len(liquid) > 0
    assert liquid.solid_fraction_2d.sum() == pytest.approx(1.0, rel=1e-9)
    assert json.loads((res / "validation" / "lumping.json").read_text())["batches"] > 0
    assert "**What lumping leaves out.**" in findings and "with the two-dimensional one" in findings
    # beside the validation, what the surrogate was trained on (every grid point and replicate of
    # the run) and its accuracy on points it never saw
    grid = cfg["grid"]
    runs = len(grid["impeller_rpm"]) * len(grid["size_distributions"]) * cfg["dem"]["replicates"]
    learned = (
        f"**What the surrogate was trained on.** The surrogate was trained on {runs} DEM runs: "
        f"{len(grid['impeller_rpm']) * len(grid['size_distributions'])} operating points (impeller speeds "
        + " and ".join(f"{r:g}" for r in sorted(grid["impeller_rpm"]))
        + " rpm; feeds "
        + " and ".join(sorted(grid["size_distributions"]))
        + f") with {cfg['dem']['replicates']} replicates each"
    )
    assert learned in findings, findings[findings.find("**How far") :][:3000]
    assert findings.index("**How far to trust them.**") < findings.index(learned)
    assert "cross-validation" in findings and "the noise floor" in findings
    # the feed check: its replicate loops ran LIGGGHTS for the configured case at the feed study's speed
    from pbmdem.validation.feed_check import CHECK_COLUMNS, STUDY_COLUMNS, most_surprising

    check_cfg = load_config(configfile).validation.feed_check
    check = pd.read_csv(res / "validation" / "feed_check.csv")
    assert list(check.columns) == list(CHECK_COLUMNS) and len(check) == 1
    row = check.iloc[0]
    assert (row.feed, row.rpm, row.dem_replicates) == (check_cfg.feed, check_cfg.rpm, check_cfg.replicates)
    loops = sorted((res / "validation" / "feed_check" / "pbm_dem").glob("rep*"))
    assert len(loops) == check_cfg.replicates
    for rep in loops:
        assert (pd.read_csv(rep / "intervals.csv").dem_collisions > 0).all(), rep
        assert json.loads((rep / "timing.json").read_text())["distribution"] == check_cfg.feed
    finals = [pd.read_csv(rep / "summary.csv").d50.iloc[-1] for rep in loops]
    assert (row.dem_d50_min, row.dem_d50_max) == (min(finals), max(finals))
    assert row.dem_d50_mean == pytest.approx(np.mean(finals))
    assert row.dem_confirms in ("yes", "partly", "no")
    assert 0 <= row.dem_replicates_confirming <= row.dem_replicates
    # PBM-ANN of the case at the feed study's speed is the feed study's own row
    study = pd.read_csv(res / "validation" / "feed_study.csv")
    assert row.ann_d50 == pytest.approx(study.set_index("feed").loc[check_cfg.feed, "d50"], rel=1e-12)
    top = most_surprising(study[list(STUDY_COLUMNS)])
    assert row.most_surprising == top.feed and row.is_most_surprising == (top.feed == check_cfg.feed)
    assert f"PBM-ANN predicts that ``{check_cfg.feed}``" in findings
    assert "**Global sensitivity.** Over the stated ranges" in findings
    response = pd.read_csv(res / "dem" / "speed_response.csv")
    assert len(response) == len(cfg["grid"]["impeller_rpm"]) * len(cfg["grid"]["size_distributions"])
    assert (response.n_replicates == cfg["dem"]["replicates"]).all()
    assert (response.encounters_per_particle_per_s > 0).all()
    assert (response.encounters_per_particle_per_s_se > 0).all()
    flow = pd.read_csv(res / "dem" / "flow_development.csv")
    assert set(flow.columns) >= {"half_difference", "half_difference_se", "within_error"}


REPORT_FIGURES = ("size_statistics.png", "psd_evolution.png", "liquid_porosity.png", "collision_frequency.png")
REPORT_TABLES = (
    "settings",
    "speeds",
    "provenance",
    "targets",
    "comparison_d50",
    "comparison_tails",
    "comparison_accuracy",
    "comparison_cost",
    "comparison_domain",
    "design_space_table",
    "calibration_check",
    "lumping",
)


def test_snakemake_report_zip_holds_the_study(tiny_workflow, root, tmp_path):
    """`snakemake --report report.zip` of the finished tiny workflow holds every figure and table of
    the study (each validation speed's figures and out-of-domain table, the settings, provenance,
    targets and comparison tables, the DEM and surrogate results), with their captions rendered."""
    import zipfile
    from collections import Counter

    from pbmdem.config import load_config

    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    archive = tmp_path / "report.zip"
    snakemake(root, workdir, configfile, "--report", str(archive))
    with zipfile.ZipFile(archive) as z:
        raw = {Path(n).name: n for n in z.namelist() if "/data/raw/" in n}
        files = Counter(Path(n).name for n in z.namelist() if "/data/raw/" in n)
        index = z.read("report/report.html").decode()
        settings = z.read(raw["settings.html"]).decode()
        provenance = z.read(raw["provenance.html"]).decode()
    speeds = len(cfg["validation"]["rpm"])
    for name in (*REPORT_FIGURES, "out_of_domain.csv", "out_of_domain.html"):
        assert files[name] == speeds, (name, files)
    for name in REPORT_TABLES:
        assert files[f"{name}.csv"] == 1 and files[f"{name}.html"] == 1, (name, files)
    for name in (
        "comparison.csv",
        "feed_check.csv",
        "proposals.csv",
        "rpm_sweep.png",
        "speed_response.png",
        "impact_velocity.png",
        "parity.png",
        "metrics.csv",
        "runs.csv",
        "design_space.png",
        "calibration_check.png",
        "sensitivity.png",
        "sensitivity.csv",
    ):
        assert files[name] == 1, (name, files)
    assert "surrogate kernel source" in provenance and "Kernel source: " in provenance
    assert "aggregation rate constant beta0" in settings and "<table" in settings
    # the captions, with their wildcards and params filled in, and the workflow description
    flat = re.sub(r"(\\n|\s)+", " ", index)
    replicates = load_config(configfile).validation.dem_replicates
    for rpm in cfg["validation"]["rpm"]:
        assert (
            f"against time (s) at {rpm:g} rpm. Grey: the PBM-DEM band, the envelope (min-max) of {replicates} "
            "coupled PBM-DEM loops" in flat
        ), rpm
        assert f"Where PBM-ANN used the surrogate outside its training domain at {rpm:g} rpm" in flat
    for phrase in (
        "Every impeller speed of the DEM training grid",
        "Where the results come from.",
        "The targets of the validation at every speed",
        "how impeller speed and feed size change granule growth",
        "Granule size against impeller speed.",
        "Granule size against the feed size distribution.",
        "The surrogate on DEM runs it never saw",
        "PBM-ANN design space",
        "Parameter estimation on data of known parameters",
        "Global sensitivity of PBM-ANN",
        "The Sobol' indices of the global sensitivity analysis",
        "What lumping leaves out.",
    ):
        assert phrase in flat, phrase


CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1280,1000",
)


def test_report_in_a_browser_opens_with_the_findings_and_shows_everything(tiny_workflow, root, tmp_path):
    """Snakemake's report (`--report report.html`) in headless Chromium, as a reader opens it: the page
    opens with the findings (speed, feed, then how far to trust them, then the glossary), every image
    of the page and of every result loads, and no table of any HTML result (the display tables) is
    wider than a 1000 px page (tests/browser/check_report.js)."""
    chromium = shutil.which("chromium")
    assert chromium, "Chromium is not installed: run scripts/bootstrap.sh (README command 2)"
    workdir, configfile = tiny_workflow
    report = tmp_path / "report.html"
    snakemake(root, workdir, configfile, "--report", str(report))
    page = report.read_text()
    check = (root / "tests" / "browser" / "check_report.js").read_text()
    end = page.rfind("</body>")
    checked = tmp_path / "checked.html"
    checked.write_text(page[:end] + "<script>" + check + "</script>" + page[end:])
    proc = subprocess.run(
        [
            chromium,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={tmp_path / 'chromium'}",
            "--virtual-time-budget=30000",
            "--dump-dom",
            checked.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    marker = '<pre id="pbmdem-check">{'
    assert marker in proc.stdout, proc.stderr[-3000:]
    found = json.loads(proc.stdout[proc.stdout.rfind(marker) + len(marker) - 1 :].split("</pre>")[0])
    assert found["errors"] == [], found
    # the page starts with its title in view (Snakemake centres a long description above the window)
    assert found["title_top"] is not None and found["title_top"] >= 0, found
    assert found["landing_broken"] == [], found
    findings = [alt for alt in found["landing_alts"] if alt.startswith("final d10, d50, d90 against")]
    assert len(findings) == 2, found["landing_alts"]
    speeds = len(yaml.safe_load(configfile.read_text())["validation"]["rpm"])
    # per speed 4; the sweep, parity, speed response, impact velocities; the four findings figures
    # (speed, feed, with pbm.breakage on the breakage study, and what lumping leaves out); the
    # design-space maps, the calibration check's fits and the Sobol' indices
    assert found["images"] == 4 * speeds + 11 and found["broken"] == [], found
    # the display tables and each speed's out-of-domain table
    assert found["pages"] == len(REPORT_TABLES) + speeds and found["page_broken"] == [] and found["overflow"] == [], (
        found
    )
    # the findings come first: the answers, then how far to trust them, then the rest
    text = re.sub(r"<[^>]+>", " ", proc.stdout[: proc.stdout.rfind(marker)])
    order = [text.find(p) for p in ("Impeller speed.", "Feed size distribution.", "How far to trust them.", "Glossary")]
    assert -1 not in order and order == sorted(order), order
    categories = set(re.findall(r'"(\d\. [^"]+)"', page))  # the menu lists them sorted by name
    assert sorted(categories)[:2] == ["1. Findings", "2. Validation: how far to trust them"], categories


def test_report_provenance_of_the_tiny_workflow(tiny_workflow, root):
    """The provenance table: the config hash is Config.sha256() of the run's config, the settings
    hash that without the execution settings, the git commit of the workflow (or its stated
    absence), and the LIGGGHTS version of the DEM runs' logs."""
    from pbmdem.config import load_config
    from pbmdem.report.provenance import NOT_GIT, settings_mapping, sha256_of

    workdir, configfile = tiny_workflow
    table = pd.read_csv(workdir / "results" / "report" / "tables" / "provenance.csv").set_index("quantity")["value"]
    cfg = load_config(configfile)
    assert table["config sha256"] == cfg.sha256()
    assert table["settings sha256"] == sha256_of(settings_mapping(cfg.to_dict()))
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode == 0:
        assert table["git commit"] == head.stdout.strip()
        assert table["git working tree"] in ("clean", "uncommitted changes to tracked files")
    else:
        assert table["git commit"] == NOT_GIT
    logs = sorted((workdir / "results" / "dem").glob("*/rep*/log.liggghts"))
    header = re.fullmatch(r"LIGGGHTS \(Version (.+)\)", logs[0].read_text().splitlines()[0].strip())
    assert header, logs[0]
    assert table["LIGGGHTS"] == f"{header.group(1)} ({len(logs)} of {len(logs)} runs)"
    assert table["snakemake"] == __import__("importlib.metadata").metadata.version("snakemake")


@pytest.mark.parametrize("kernel", ["constant", "table", "table_stokes", "ann"])
def test_pbm_cli_with_each_kernel(tiny_workflow, tmp_path, kernel, capsys):
    from pbmdem.cli import main

    workdir, configfile = tiny_workflow
    res = workdir / "results"
    if kernel == "table_stokes":
        # the DEM tables with their impact velocities, success by the Stokes criterion
        cfg = yaml.safe_load(Path(configfile).read_text())
        cfg.setdefault("pbm", {}).setdefault("aggregation", {})["success"] = {"velocity_model": "stokes"}
        configfile = tmp_path / "stokes.yaml"
        configfile.write_text(yaml.safe_dump(cfg))
    args = [
        "pbm",
        "--config",
        str(configfile),
        "--kernel",
        kernel.split("_")[0],
        "--rpm",
        "900",
        "--distribution",
        "large",
        "--out",
        str(tmp_path / kernel),
    ]
    if kernel.startswith("table"):
        args += ["--table", str(res / "dem" / "collisions.csv")]
    if kernel == "table_stokes":
        args += ["--velocity-table", str(res / "dem" / "impact_velocity.csv")]
    if kernel == "ann":
        args += ["--model", str(res / "surrogate" / "model.skops")]
    assert main(args) == 0, capsys.readouterr().err
    out = json.loads(capsys.readouterr().out)
    summary = pd.read_csv(tmp_path / kernel / "summary.csv")
    assert out["d50_final_m"] == pytest.approx(summary.d50.iloc[-1])
    solid = summary.total_solid_volume
    assert abs(solid.iloc[-1] - solid.iloc[0]) <= 1e-12 * solid.iloc[0]
    if kernel == "table_stokes":
        # how many encounters the Stokes criterion holds depends on the DEM's impact speeds
        assert summary.d50.iloc[-1] >= summary.d50.iloc[0]
    else:
        assert summary.d50.iloc[-1] > summary.d50.iloc[0]
    assert (tmp_path / kernel / "psd.png").exists()


def test_job_logs_show_progress(tiny_workflow):
    """DEM jobs log LIGGGHTS progress, the surrogate each CV fold, the coupled loops each interval."""
    workdir, _ = tiny_workflow
    logs = workdir / "results" / "logs"
    dem_log = (logs / "dem" / "rpm600_small_rep0.log").read_text()
    assert re.search(
        r"pbmdem.dem.progress: DEM rpm600_small: \w[\w-]*, step \d+ of \d+ \(\d+ %\), \d+ particles", dem_log
    )
    # the run starts from its settled bed and counts its own steps: never past its total
    counts = [(int(a), int(b)) for a, b in re.findall(r"DEM rpm600_small: [\w-]+, step (\d+) of (\d+)", dem_log)]
    assert counts and all(step <= total for step, total in counts), counts
    assert "CV fold 1 of" in (logs / "train_surrogate.log").read_text()
    loop = (logs / "validation" / "pbm_dem_rpm600_rep0.log").read_text()
    assert re.search(
        r"pbm_dem at rpm 600: interval 1 of \d+ .* DEM wall time [\d.]+ s, PBM wall time [\d.]+ s, "
        r"\d+ surrogate out-of-domain",
        loop,
    ), loop[-2000:]
    # the loop's LIGGGHTS calls report progress too (at 600 rpm, a grid speed, the loop borrows the
    # grid's run of its feed and calls none; at 900 rpm it runs its own)
    assert "pbmdem.dem.progress: DEM" in (logs / "validation" / "pbm_dem_rpm900_rep0.log").read_text()
    ann = (logs / "validation" / "pbm_ann_rpm600.log").read_text()
    assert "pbm_ann at rpm 600: interval 1 of" in ann
    assert "rpm sweep: 600 rpm done" in (logs / "validation" / "rpm_sweep.log").read_text()


def test_the_loops_borrow_the_grid_runs_of_their_feed(tiny_workflow):
    """docs/validation.md, "Borrowed grid runs": at a grid speed each PBM-DEM loop's interval 0 (the
    feed) reads the grid's run of its replicate, at another speed it starts from the grid's settled
    bed; a replicate the grid does not run settles its own."""
    workdir, configfile = tiny_workflow
    cfg = yaml.safe_load(configfile.read_text())
    feed, grid_reps = cfg["validation"]["distribution"], cfg["dem"]["replicates"]
    checked = 0
    for rpm in cfg["validation"]["rpm"]:
        for rep in range(cfg["validation"].get("dem_replicates", 3)):
            folder = workdir / "results" / "validation" / f"rpm{rpm}" / "pbm_dem" / f"rep{rep}"
            first = json.loads((folder / "interval_00" / "interval.json").read_text())
            if rep >= grid_reps:
                assert "dem_borrowed_run" not in first and "dem_settled_bed" not in first, first
            elif rpm in cfg["grid"]["impeller_rpm"]:
                assert first["dem_borrowed_run"] == f"results/dem/rpm{rpm}_{feed}/rep{rep}"
                assert not (folder / "interval_00" / "dem").exists()
                assert first["dem_cpu_time_s"] > 0
                assert first["provider_wall_time_s"] >= first["dem_borrowed_wall_time_s"] > 0
                checked += 1
            else:
                assert first["dem_settled_bed"] == f"results/dem/beds/{feed}/rep{rep}"
                assert json.loads((folder / "interval_00" / "dem" / "summary.json").read_text())["from_settled_bed"]
                checked += 1
    assert checked >= 2


def test_a_manual_dem_run_on_a_finished_point_changes_nothing(tiny_workflow, root):
    """The README's `pbmdem dem` on a point the workflow finished is refused without --force, so
    Snakemake still has nothing to redo."""
    workdir, configfile = tiny_workflow
    point = workdir / "results" / "dem" / "rpm600_small" / "rep0"
    before = {p: p.stat().st_mtime_ns for p in point.rglob("*")}
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pbmdem.cli",
            "dem",
            "--config",
            str(configfile),
            "--rpm",
            "600",
            "--distribution",
            "small",
        ],
        cwd=workdir,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 2 and "already holds a finished run" in proc.stderr and "--force" in proc.stderr
    assert {p: p.stat().st_mtime_ns for p in point.rglob("*")} == before
    dry = snakemake(root, workdir, configfile, "-n", "--cores", "2")
    assert "Nothing to be done" in dry.stdout + dry.stderr, dry.stdout[-3000:]


def test_deck_template_edit_reruns_every_dem_job_and_execution_settings_none(root, tmp_path):
    """Rule inputs are complete and params are exact: in a copy of the project, a finished DEM point
    and PBM-DEM loop are redone when the deck template changes, and not when dem.timeout or
    dem.mpi_ranks change."""
    project = tmp_path / "project"
    project.mkdir()
    for name in PROJECT_FILES:
        src = root / name
        if src.is_dir():  # links kept, as in a checkout: the package's deck template is the project's
            shutil.copytree(src, project / name, symlinks=True)
        else:
            shutil.copy2(src, project / name)
    workdir = tmp_path / "wd"
    workdir.mkdir()
    cfg = yaml.safe_load((root / "config" / "test.yaml").read_text())
    cfg["grid"]["impeller_rpm"] = [600]
    cfg["validation"]["rpm"] = [600]
    configfile = workdir / "config.yaml"
    configfile.write_text(yaml.safe_dump(cfg))
    targets = ["results/dem/rpm600_small/rep0/collisions.csv", "results/validation/rpm600/pbm_dem/rep0/summary.csv"]
    snakemake(project, workdir, configfile, "--cores", "2", *targets)

    def planned(config: Path) -> dict[str, int]:
        out = snakemake(project, workdir, config, "-n", "--cores", "2", *targets, "--quiet", "rules")
        text = out.stdout + out.stderr
        return {
            line.split()[0]: int(line.split()[1])
            for line in text.splitlines()
            if len(line.split()) == 2 and line.split()[1].isdigit() and line.split()[0] != "total"
        }

    assert planned(configfile) == {}
    cfg["dem"]["timeout"], cfg["dem"]["mpi_ranks"] = 99.0, 2
    execution = workdir / "execution.yaml"
    execution.write_text(yaml.safe_dump(cfg))
    assert planned(execution) == {}
    template = project / "liggghts_templates" / "granulator.in"
    template.write_text(template.read_text() + "# an edited deck\n")
    # the edited deck settles the bed again and reruns the run from it and the coupled loop
    assert planned(configfile) == {"dem_bed": 1, "dem_point": 1, "pbm_dem_coupled": 1}


def test_adding_the_proposed_points_removes_the_out_of_domain_intervals(tiny_workflow, root, tmp_path):
    """Active learning end to end, on a copy of the finished tiny workflow validated at 1500 rpm,
    beyond the grid's 600-1200 rpm: PBM-ANN is outside the surrogate's training domain (tip speed)
    in every interval; the proposals name that speed; adding them with the fragment the workflow
    wrote runs only the new DEM points and retrains the surrogate, and PBM-ANN at 1500 rpm is then
    inside the domain."""
    import json

    workdir, configfile = tiny_workflow
    copy = tmp_path / "wd"
    shutil.copytree(workdir, copy)  # copy2: the time stamps (Snakemake's view of what is done) are kept
    cfg = yaml.safe_load(configfile.read_text())
    cfg["validation"]["rpm"] = [1500]
    config = copy / "beyond.yaml"
    config.write_text(yaml.safe_dump(cfg))
    targets = ["results/validation/proposals.yaml", "results/validation/rpm1500/pbm_ann/intervals.csv"]
    snakemake(root, copy, config, "--cores", "2", *targets)
    intervals = copy / "results" / "validation" / "rpm1500" / "pbm_ann" / "intervals.csv"
    before = pd.read_csv(intervals)
    assert (before.out_of_domain_count > 0).all() and before.out_of_domain.str.contains("tip_speed").all()
    table = pd.read_csv(copy / "results" / "validation" / "proposals.csv")
    assert all(json.loads(speeds) == [1500.0] for speeds in table.points_rpm)  # beyond the grid: at 1500 rpm
    fragment = copy / "results" / "validation" / "proposals.yaml"
    grid = yaml.safe_load(fragment.read_text())["grid"]
    assert grid.keys() == {"extra_points"} and {p["rpm"] for p in grid["extra_points"]} == {1500.0}
    planned = snakemake(root, copy, config, str(fragment), "-n", "--cores", "2", *targets, "--quiet", "rules")
    counts = {
        line.split()[0]: int(line.split()[1])
        for line in (planned.stdout + planned.stderr).splitlines()
        if len(line.split()) == 2 and line.split()[1].isdigit()
    }
    new_dists = yaml.safe_load(fragment.read_text()).get("size_distributions", {})
    reps = cfg["dem"]["replicates"]
    expected = reps * len(grid["extra_points"])
    assert counts.get("dem_point") == expected, counts  # only the new operating points run
    assert counts.get("pbm_dem_coupled", 0) == 0  # the reference does not depend on the grid
    snakemake(root, copy, config, str(fragment), "--cores", "2", *targets)
    after = pd.read_csv(intervals)
    assert (after.out_of_domain_count == 0).all(), after.out_of_domain.tolist()
    meta = json.loads((copy / "results" / "surrogate" / "model.json").read_text())
    assert any(pid.startswith("rpm1500_") for pid in meta["training_point_ids"])
    print(
        f"active learning: {len(new_dists)} new distribution(s), {len(grid['extra_points'])} new point(s); "
        f"out-of-domain intervals {int((before.out_of_domain_count > 0).sum())} -> "
        f"{int((after.out_of_domain_count > 0).sum())}"
    )


def test_design_space_and_calibration_check_of_the_tiny_workflow(tiny_workflow):
    """The default targets hold the design space (every grid point judged or marked), the
    calibration check (both cases, every parameter, true against estimated with an interval) and
    the Sobol' indices."""
    from pbmdem.config import load_config
    from pbmdem.design.space import STATUSES
    from pbmdem.tables import MEASURED

    workdir, configfile = tiny_workflow
    cfg = load_config(configfile)
    design = pd.read_csv(workdir / "results/design/design_space.csv")
    ds = cfg.design_space
    assert len(design) == ds.impeller_rpm.num * ds.liquid_rate.num * len(ds.third_factor.values)
    assert set(design.spec_status) <= set(STATUSES)
    assert (design.spec_status[design.out_of_domain_intervals > 0] == "out_of_domain").all()
    check = pd.read_csv(workdir / "results/design/calibration_check.csv")
    assert set(check.case) == {"pbm_dem", "pbm_constant_noise"}
    assert set(check.parameter) == set(cfg.calibration.parameters)
    assert (check.ci_low <= check.estimate).all() and (check.estimate <= check.ci_high).all()
    assert (check.recovered == ((check.ci_low <= check.true) & (check.true <= check.ci_high))).all()
    measured = MEASURED.read(workdir / "results/design/measured_pbm_dem.csv")
    assert set(measured.rpm) == {float(r) for r in cfg.validation.rpm}
    # the Sobol' indices of every factor and size statistic, for the mean and each member
    indices = pd.read_csv(workdir / "results/design/sensitivity.csv", dtype={"member": str})
    factors = [f.key for f in cfg.sensitivity.factors()]
    members = {"mean", *(str(k) for k in range(cfg.surrogate.ensemble_size))}
    assert set(indices.parameter) == set(factors) and set(indices.member) == members
    assert len(indices) == len(factors) * 3 * len(members)
    info = json.loads((workdir / "results/design/sensitivity.json").read_text())
    assert info["batches"] == cfg.sensitivity.base_samples * (len(factors) + 2) * len(members)

"""A normal (non-editable) install runs `pbmdem` from any directory: schemas, templates and the
report's word templates are package data, nothing is looked up beside the sources."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path


def test_a_wheel_installed_into_a_fresh_venv_runs_outside_the_checkout(root, tmp_path):
    # build from a copy of the sources, so that the checkout gets no build/ or egg-info
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(root / name, source / name)
    for name in ("src", "workflow", "liggghts_templates"):
        shutil.copytree(
            root / name, source / name, symlinks=True, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info")
        )
    wheels = tmp_path / "wheels"
    build = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(wheels),
            str(source),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert build.returncode == 0, build.stderr[-3000:]
    wheel = next(wheels.glob("pbmdem-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q", str(wheel)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert install.returncode == 0, install.stderr[-3000:]
    # the dependencies come from this test's environment (a path entry, not its editable pbmdem)
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    )
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    config = shutil.copy(root / "config" / "test.yaml", elsewhere / "my.yaml")

    def run(*args):
        return subprocess.run(args, capture_output=True, text=True, cwd=elsewhere, timeout=300)

    where = run(
        str(python),
        "-c",
        "import pbmdem, pbmdem.config, pbmdem.dem.deck as d, pbmdem.report.words as w; "
        "print(pbmdem.__file__); print(d.template_path()); "
        "print(w.ENV.get_template('findings.rst.j2').filename)",
    )
    assert where.returncode == 0, where.stderr
    for line in where.stdout.split():
        assert Path(line).resolve().is_relative_to(venv.resolve()), where.stdout
    helped = run(str(venv / "bin" / "pbmdem"), "--help")
    assert helped.returncode == 0 and "dem" in helped.stdout and "surrogate" in helped.stdout, helped.stderr
    plan = run(
        str(venv / "bin" / "pbmdem"),
        "dem",
        "--config",
        str(config),
        "--rpm",
        "600",
        "--distribution",
        "small",
        "--plan-only",
    )
    assert plan.returncode == 0, plan.stderr
    assert json.loads(plan.stdout)["point_id"] == "rpm600_small"
    bad = run(
        str(venv / "bin" / "pbmdem"),
        "dem",
        "--config",
        str(config),
        "--rpm",
        "600",
        "--distribution",
        "nope",
        "--plan-only",
    )
    assert bad.returncode == 2 and "'nope' is not defined" in bad.stderr and "Traceback" not in bad.stderr

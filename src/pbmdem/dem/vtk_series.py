"""ParaView collection (.pvd) index for the VTK snapshots of a run."""

from __future__ import annotations

import re
from pathlib import Path

from pbmdem.atomic import write_text

SERIES = {"particles": re.compile(r"^particles_(\d+)\.vtk$"), "impeller": re.compile(r"^impeller_(\d+)\.vtk$")}


def snapshots(post_dir: str | Path, kind: str) -> list[tuple[int, Path]]:
    """(step, path) of every snapshot of `kind`, in numeric step order (bounding boxes skipped)."""
    pattern = SERIES[kind]
    found = [(int(m.group(1)), p) for p in Path(post_dir).iterdir() if (m := pattern.match(p.name))]
    return sorted(found)


def point_count(path: str | Path) -> int | None:
    """The number of points of a legacy VTK file (its `POINTS n` header line), None if not found."""
    with open(path, errors="replace") as fh:
        for _, line in zip(range(20), fh, strict=False):
            if line.startswith("POINTS "):
                return int(line.split()[1])
    return None


def write_series(post_dir: str | Path, timestep: float) -> dict[str, Path]:
    """particles.pvd and impeller.pvd: the snapshots with their times in s. Particle snapshots that
    hold no particle (before the insertion, t = 0) are left out, so that a reader of the series
    (ParaView, `pyvista.get_reader`) opens on the first frame with particles."""
    post_dir = Path(post_dir)
    out = {}
    for kind in SERIES:
        snaps = snapshots(post_dir, kind)
        if kind == "particles":
            snaps = [(step, path) for step, path in snaps if point_count(path) != 0]
        if not snaps:
            raise FileNotFoundError(f"no {kind}_<step>.vtk snapshots in {post_dir}")
        entries = "\n".join(
            f'    <DataSet timestep="{step * timestep:.9g}" part="0" file="{path.name}"/>' for step, path in snaps
        )
        text = (
            '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            f"{entries}\n  </Collection>\n</VTKFile>\n"
        )
        out[kind] = write_text(post_dir / f"{kind}.pvd", text)
    return out

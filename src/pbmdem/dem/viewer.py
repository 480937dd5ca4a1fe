"""Look at a DEM run: particles coloured by diameter, the impeller and the bowl, with pyvista.

A run is named by its operating point (impeller speed, size distribution, replicate) or by its
folder, a moment by its time in seconds (the nearest snapshot; by default the first one that holds
particles). The picture's title names the point, the speed, the feed and the time.

The runs' snapshot series are indexed here too: `write_series` writes the ParaView collections
(`particles.pvd`, `impeller.pvd`) that ParaView and this viewer open.
"""

from __future__ import annotations

import argparse
import json
import re
from dataclasses import dataclass
from pathlib import Path

from pbmdem import layout
from pbmdem.atomic import atomic_path, write_text
from pbmdem.config import check_rpm, rpm_text

SERIES = {"particles": re.compile(r"^particles_(\d+)\.vtk$"), "impeller": re.compile(r"^impeller_(\d+)\.vtk$")}


def snapshots(post_dir: str | Path, kind: str) -> list[tuple[int, Path]]:
    """(step, path) of every snapshot of `kind`, in numeric step order (bounding boxes skipped);
    of the particles, those that hold some (none before the insertion, t = 0)."""
    pattern = SERIES[kind]
    found = sorted((int(m.group(1)), p) for p in Path(post_dir).iterdir() if (m := pattern.match(p.name)))
    return [(step, p) for step, p in found if kind != "particles" or point_count(p) != 0]


def point_count(path: str | Path) -> int | None:
    """The number of points of a legacy VTK file (its `POINTS n` header line), None if not found."""
    with open(path, errors="replace") as fh:
        for _, line in zip(range(20), fh, strict=False):
            if line.startswith("POINTS "):
                return int(line.split()[1])
    return None


def write_series(post_dir: str | Path, timestep: float) -> dict[str, Path]:
    """particles.pvd and impeller.pvd: the snapshots with their times in s (a reader of the series,
    ParaView or `pyvista.get_reader`, opens on the first frame with particles)."""
    post_dir = Path(post_dir)
    out = {}
    for kind in SERIES:
        snaps = snapshots(post_dir, kind)
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


EXAMPLES = """examples:
  pbmdem view --rpm 600 --distribution fine                   # first frame with particles, in a window
  pbmdem view --rpm 600 --distribution fine --time 0.5 --screenshot shot.png
  pbmdem view --rpm 600 --distribution fine --replicate 2 --time last
  pbmdem view results/dem/rpm600_fine/rep0 --time 0.25        # a run folder instead of a point
"""


class ViewError(ValueError):
    """The run folder has no such snapshot."""


@dataclass(frozen=True)
class Frame:
    """One snapshot of a run: its step, time (s) and particle file."""

    step: int
    time: float
    path: Path


def run_folder(results: str | Path, rpm: str, distribution: str, replicate: int = 0) -> Path:
    """results/dem/rpm<rpm>_<distribution>/rep<replicate>, the folder of one operating point's run."""
    folder = Path(layout.dem_run(rpm_text(check_rpm(rpm, "--rpm")), distribution, replicate, str(results)))
    if not folder.is_dir():
        runs = sorted(str(p.relative_to(results)) for p in Path(results).glob("dem/rpm*/rep*") if p.is_dir())
        shown = ", ".join(runs[:12]) + (" ..." if len(runs) > 12 else "") if runs else "none"
        raise ViewError(
            f"no DEM run of --rpm {rpm} --distribution {distribution} --replicate {replicate}: {folder} does not "
            f"exist; runs under {results}: {shown}"
        )
    return folder


def _plan(run_dir: Path) -> dict:
    path = run_dir / "plan.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def frames(run_dir: str | Path) -> list[Frame]:
    """Every particle snapshot of a run that holds particles, in time order."""
    run_dir = Path(run_dir)
    post = run_dir / "post"
    if not post.is_dir():
        raise ViewError(f"{run_dir} has no post/ folder with VTK snapshots")
    timestep = _plan(run_dir).get("timestep")
    snaps = snapshots(post, "particles")
    if not snaps:
        raise ViewError(f"no particles snapshots in {post} (is this a finished pbmdem DEM run folder?)")
    if timestep is None:
        raise ViewError(f"{run_dir / 'plan.json'} is missing: the snapshots' times are unknown (use --step)")
    return [Frame(s, s * float(timestep), p) for s, p in snaps]


def pick(run_dir: str | Path, time: float | str | None = None, step: int | None = None) -> Frame:
    """The frame at `time` (s, nearest snapshot; "last" for the last), or at engine `step`, or
    the first frame with particles."""
    found = frames(run_dir)
    if step is not None:
        for frame in found:
            if frame.step == step:
                return frame
        raise ViewError(f"no particles snapshot at step {step}; available steps: {[f.step for f in found]}")
    if time is None:
        return found[0]
    if time == "last":
        return found[-1]
    t = float(time)
    first, last = found[0].time, found[-1].time
    spacing = (last - first) / max(1, len(found) - 1)
    if not first - spacing <= t <= last + spacing:
        raise ViewError(f"--time {time}: allowed {first:.4g} .. {last:.4g} s (the snapshots with particles)")
    return min(found, key=lambda f: abs(f.time - t))


def title(run_dir: Path, frame: Frame) -> str:
    """Point, speed, feed, replicate and time: 'rpm600_fine rep0: 600 rpm, feed fine, t = 0.500 s'."""
    plan = _plan(run_dir)
    point = plan.get("point_id", run_dir.parent.name)
    parts = [f"{point} rep{plan.get('replicate', run_dir.name.removeprefix('rep'))}:"]
    if "rpm" in plan:
        parts.append(f"{float(plan['rpm']):g} rpm,")
    if "distribution" in plan:
        parts.append(f"feed {plan['distribution']},")
    parts.append(f"t = {frame.time:.3f} s (step {frame.step})")
    return " ".join(parts)


def render_run(
    run_dir: str | Path,
    time: float | str | None = None,
    screenshot: str | Path | None = None,
    step: int | None = None,
) -> Path | None:
    """Show the particles of one frame (see `pick`), the impeller and the bowl interactively, or
    render them off-screen to `screenshot` (PNG)."""
    import pyvista as pv  # lazy: pyvista costs ~1.1 s to import (measured), only `pbmdem view` draws

    run_dir = Path(run_dir)
    frame = pick(run_dir, time, step)
    particles = pv.read(frame.path)
    if particles.n_points == 0:
        raise ViewError(f"{frame.path} holds no particles")
    particles["diameter (mm)"] = 2000.0 * particles["radius"]
    spheres = particles.glyph(
        scale="radius", factor=2.0, orient=False, geom=pv.Sphere(radius=0.5, theta_resolution=12, phi_resolution=12)
    )
    plotter = pv.Plotter(off_screen=screenshot is not None, window_size=(900, 700))
    plotter.add_mesh(spheres, scalars="diameter (mm)", cmap="viridis", scalar_bar_args={"title": "diameter (mm)"})
    impellers = dict(snapshots(run_dir / "post", "impeller"))
    if frame.step in impellers:
        plotter.add_mesh(pv.read(impellers[frame.step]), color="lightgrey")
    bowl = run_dir / "bowl.stl"
    if bowl.exists():
        plotter.add_mesh(pv.read(bowl), style="wireframe", color="black", opacity=0.25)
    plotter.add_text(title(run_dir, frame), font_size=11)
    plotter.camera_position = "iso"
    if screenshot is None:
        plotter.show()
        return None
    screenshot = Path(screenshot)
    with atomic_path(screenshot) as tmp:
        plotter.screenshot(str(tmp))
    plotter.close()
    return screenshot


def _time(text: str) -> float | str:
    if text == "last":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: allowed a time in s (e.g. 0.5) or 'last'") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: allowed a time >= 0 s or 'last'")
    return value


def _view(args: argparse.Namespace) -> int:
    if args.run_dir is not None and (args.rpm is not None or args.distribution is not None):
        raise ViewError("give a run folder or --rpm/--distribution, not both")
    if args.run_dir is None:
        if args.rpm is None or args.distribution is None:
            raise ViewError("name the run: --rpm RPM --distribution NAME [--replicate K], or a run folder")
        run_dir = run_folder(args.results, args.rpm, args.distribution, args.replicate)
    else:
        run_dir = Path(args.run_dir)
    out = render_run(run_dir, args.time, args.screenshot, step=args.step)
    if out is not None:
        print(f"wrote {out}")
    return 0


def add_options(view: argparse.ArgumentParser) -> None:
    """The description (this module's second paragraph), examples and options of `pbmdem view`."""
    view.description = __doc__.split("\n\n")[1].strip()
    view.epilog = EXAMPLES
    view.add_argument("run_dir", nargs="?", default=None, help="a run folder, e.g. results/dem/rpm600_fine/rep0")
    view.add_argument("--rpm", default=None, help="impeller speed (1/min) of the operating point")
    view.add_argument("--distribution", default=None, help="size distribution (feed) name of the operating point")
    view.add_argument("--replicate", type=int, default=0, help="replicate of the point (default 0)")
    view.add_argument("--results", default="results", help="the workflow's results folder (default: results)")
    when = view.add_mutually_exclusive_group()
    when.add_argument(
        "--time",
        type=_time,
        default=None,
        help="time in s (nearest snapshot), or 'last' (default: the first snapshot with particles)",
    )
    when.add_argument("--step", type=int, default=None, help="an engine step instead of --time (expert use)")
    view.add_argument("--screenshot", default=None, help="render off-screen to this PNG instead of a window")
    view.set_defaults(func=_view)

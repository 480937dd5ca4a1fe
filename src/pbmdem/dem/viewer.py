"""Look at a DEM run: particles coloured by diameter, the impeller and the bowl, with pyvista.

pbmdem view results/dem/rpm600_fine                 # interactive window
pbmdem view results/dem/rpm600_fine --step 40000 --screenshot shot.png   # off-screen PNG
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pbmdem.atomic import atomic_path

from .vtk_series import snapshots


class ViewError(ValueError):
    """The run folder has no such snapshot."""


def _pick(post: Path, kind: str, step: int | None) -> tuple[int, Path]:
    snaps = snapshots(post, kind)
    if not snaps:
        raise ViewError(f"no {kind} snapshots in {post} (is this a finished pbmdem DEM run folder?)")
    if step is None:
        return snaps[-1]
    for s, path in snaps:
        if s == step:
            return s, path
    raise ViewError(f"no {kind} snapshot at step {step} in {post}; available steps: {[s for s, _ in snaps]}")


def build_scene(run_dir: str | Path, step: int | None = None, off_screen: bool = False):
    """A pyvista Plotter with the particles at `step` (default: last) and the impeller."""
    import pyvista as pv

    run_dir = Path(run_dir)
    post = run_dir / "post"
    if not post.is_dir():
        raise ViewError(f"{run_dir} has no post/ folder with VTK snapshots")
    step, particle_file = _pick(post, "particles", step)
    particles = pv.read(particle_file)
    if particles.n_points == 0:
        raise ViewError(f"{particle_file} holds no particles")
    particles["diameter (mm)"] = 2000.0 * particles["radius"]
    spheres = particles.glyph(
        scale="radius", factor=2.0, orient=False, geom=pv.Sphere(radius=0.5, theta_resolution=12, phi_resolution=12)
    )
    plotter = pv.Plotter(off_screen=off_screen, window_size=(900, 700))
    plotter.add_mesh(spheres, scalars="diameter (mm)", cmap="viridis", scalar_bar_args={"title": "diameter (mm)"})
    impellers = dict(snapshots(post, "impeller"))
    if step in impellers:
        plotter.add_mesh(pv.read(impellers[step]), color="lightgrey")
    bowl = run_dir / "bowl.stl"
    if bowl.exists():
        plotter.add_mesh(pv.read(bowl), style="wireframe", color="black", opacity=0.25)
    plotter.add_text(f"{run_dir.name}  step {step}", font_size=10)
    plotter.camera_position = "iso"
    return plotter, step


def render_run(run_dir: str | Path, step: int | None = None, screenshot: str | Path | None = None) -> Path | None:
    """Show the run interactively, or render it off-screen to `screenshot` (PNG)."""
    plotter, _ = build_scene(run_dir, step, off_screen=screenshot is not None)
    if screenshot is None:
        plotter.show()
        return None
    screenshot = Path(screenshot)
    with atomic_path(screenshot) as tmp:
        plotter.screenshot(str(tmp))
    plotter.close()
    return screenshot


def _view(args: argparse.Namespace) -> int:
    out = render_run(args.run_dir, args.step, args.screenshot)
    if out is not None:
        print(f"wrote {out}")
    return 0


def add_cli(subparsers) -> None:
    view = subparsers.add_parser("view", help="show a DEM run (particles coloured by size, impeller)")
    view.add_argument("run_dir", help="a run folder, e.g. results/dem/rpm600_fine")
    view.add_argument("--step", type=int, default=None, help="time step of the snapshot (default: last)")
    view.add_argument("--screenshot", default=None, help="render off-screen to this PNG instead of a window")
    view.set_defaults(func=_view)

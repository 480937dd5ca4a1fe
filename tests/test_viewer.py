"""VTK series and viewer on a real (tiny) LIGGGHTS run: pyvista reads the series, and
`pbmdem view --screenshot` renders a picture of particles coloured by size."""

from pathlib import Path
from xml.etree import ElementTree

import pytest

from pbmdem.cli import main
from pbmdem.dem import viewer

pytestmark = pytest.mark.liggghts


def read_series(pvd_path: Path) -> list[tuple[float, Path]]:
    """(time, snapshot path) of every DataSet of a ParaView series file."""
    root = ElementTree.parse(pvd_path).getroot()
    return [(float(d.get("timestep")), pvd_path.parent / d.get("file")) for d in root.iter("DataSet")]


def test_series_index_is_in_numeric_step_order(tiny_run):
    post = tiny_run["dir"] / "post"
    series = read_series(post / "particles.pvd")
    times = [t for t, _ in series]
    assert times == sorted(times) and len(times) >= 3
    steps = [int(p.stem.split("_")[1]) for _, p in series]
    assert steps == sorted(steps)
    assert times[1] == pytest.approx(steps[1] * tiny_run["plan"].timestep)
    assert all("boundingBox" not in p.name for _, p in series)
    assert all(p.exists() for _, p in series)


def test_series_opens_on_a_frame_with_particles(tiny_run):
    """The t = 0 snapshot precedes the insertion (no points): the series leaves it out, so that
    ParaView and pyvista's reader open on particles ("No points read!" otherwise)."""
    import pyvista

    post = tiny_run["dir"] / "post"
    assert viewer.point_count(post / "particles_0.vtk") == 0
    series = read_series(post / "particles.pvd")
    assert series[0][0] > 0 and all(viewer.point_count(p) > 0 for _, p in series)
    reader = pyvista.get_reader(str(post / "particles.pvd"))
    mesh = reader.read()
    mesh = mesh[0] if isinstance(mesh, pyvista.MultiBlock) else mesh
    assert reader.time_values[0] == pytest.approx(series[0][0]) and mesh.n_points > 0


def test_view_picks_a_time_in_seconds_and_names_it(tiny_run):
    """--time in s: the nearest snapshot with particles; by default the first with particles; the
    title names the point, speed, feed and time."""
    run = tiny_run["dir"]
    first = viewer.pick(run)
    assert first.step > 0 and viewer.point_count(first.path) > 0
    assert first.time == pytest.approx(first.step * tiny_run["plan"].timestep)
    last = viewer.pick(run, "last")
    assert viewer.pick(run, last.time * 0.999) == last and last.time > first.time
    title = viewer.title(run, last)
    assert title.startswith(f"{tiny_run['plan'].point_id} rep0: 600 rpm, feed small, t = {last.time:.3f} s"), title
    with pytest.raises(viewer.ViewError, match=r"--time 99: allowed .* s"):
        viewer.pick(run, 99)


def test_view_by_operating_point(tiny_run, tmp_path, capsys):
    """`pbmdem view --rpm R --distribution D` finds results/dem/<point>/rep<k>; an unknown point
    is an error naming the flags and listing the runs there."""
    results = tmp_path / "results"
    (results / "dem" / "rpm600_small").mkdir(parents=True)
    (results / "dem" / "rpm600_small" / "rep0").symlink_to(tiny_run["dir"])
    out = tmp_path / "shot.png"
    argv = ["view", "--results", str(results), "--rpm", "600", "--distribution", "small", "--time", "0.05"]
    assert main([*argv, "--screenshot", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["view", "--results", str(results), "--rpm", "900", "--distribution", "small"]) == 2
    err = capsys.readouterr().err
    assert "--rpm 900 --distribution small --replicate 0" in err and "dem/rpm600_small/rep0" in err, err


def test_screenshot_shows_particles_coloured_by_size(tiny_run, tmp_path):
    import matplotlib.image

    out = tmp_path / "shot.png"
    assert main(["view", str(tiny_run["dir"]), "--time", "last", "--screenshot", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = matplotlib.image.imread(out)[..., :3]
    assert img.shape[0] > 200 and img.shape[1] > 200
    assert img.std() > 0.05  # not a blank picture
    # the viridis colours of the smallest (dark purple) and largest (yellow) classes are present
    purple = (img[..., 0] < 0.4) & (img[..., 1] < 0.2) & (img[..., 2] > 0.25)
    yellow = (img[..., 0] > 0.75) & (img[..., 1] > 0.75) & (img[..., 2] < 0.35)
    assert purple.sum() > 50 and yellow.sum() > 50


def test_unknown_step_lists_the_available_ones(tiny_run, capsys):
    with pytest.raises(viewer.ViewError, match="available steps"):
        viewer.render_run(tiny_run["dir"], step=1, screenshot=tiny_run["dir"] / "x.png")
    assert not (tiny_run["dir"] / "x.png").exists()


def test_not_a_run_folder(tmp_path):
    with pytest.raises(viewer.ViewError, match="no post/ folder"):
        viewer.render_run(tmp_path, screenshot=tmp_path / "x.png")
    with pytest.raises(FileNotFoundError, match="no particles"):
        (tmp_path / "post").mkdir()
        viewer.write_series(tmp_path / "post", 1e-5)

"""VTK series and viewer on a real (tiny) LIGGGHTS run: pyvista reads the series, and
`pbmdem view --screenshot` renders a picture of particles coloured by size."""

import pytest

from pbmdem.cli import main
from pbmdem.dem import viewer, vtk_series

pytestmark = pytest.mark.liggghts


def test_series_index_is_in_numeric_step_order(tiny_run):
    post = tiny_run["dir"] / "post"
    series = vtk_series.read_series(post / "particles.pvd")
    times = [t for t, _ in series]
    assert times == sorted(times) and len(times) >= 3
    steps = [int(p.stem.split("_")[1]) for _, p in series]
    assert steps == sorted(steps)
    assert times[1] == pytest.approx(steps[1] * tiny_run["plan"].timestep)
    assert all("boundingBox" not in p.name for _, p in series)
    assert all(p.exists() for _, p in series)


def test_screenshot_shows_particles_coloured_by_size(tiny_run, tmp_path):
    import matplotlib.image

    out = tmp_path / "shot.png"
    assert main(["view", str(tiny_run["dir"]), "--screenshot", str(out)]) == 0
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
        vtk_series.write_series(tmp_path / "post", 1e-5)

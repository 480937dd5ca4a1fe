"""Config validation: every bad input names the key and what is allowed."""

import copy
import subprocess

import pytest
import yaml
from conftest import snakemake_command

from pbmdem.config import Config, ConfigError, load_config


def bad(cfg: Config, edit):
    mapping = copy.deepcopy(cfg.to_dict())
    edit(mapping)
    with pytest.raises(ConfigError) as info:
        Config.from_mapping(mapping)
    return str(info.value)


def test_default_and_tiny_configs_are_valid(default_config, tiny_config):
    assert len(default_config.grid.impeller_rpm) >= 3
    assert len(default_config.grid.size_distributions) >= 3
    for name in default_config.grid.size_distributions:
        assert len(default_config.size_distributions[name].diameters) >= 3


def test_wrong_type(default_config):
    msg = bad(default_config, lambda c: c["material"].__setitem__("density", "heavy"))
    assert "material.density" in msg and "'heavy'" in msg and "number" in msg


def test_missing_key(default_config):
    msg = bad(default_config, lambda c: c["dem"].pop("sampling_time"))
    assert "sampling_time" in msg and "required" in msg


def test_negative_size(default_config):
    msg = bad(default_config, lambda c: c["size_distributions"]["fine"]["diameters"].__setitem__(0, -0.002))
    assert "size_distributions.fine.diameters[0]" in msg and "-0.002" in msg and ">= 1e-05" in msg


def test_fractions_must_sum_to_one(default_config):
    msg = bad(
        default_config, lambda c: c["size_distributions"]["fine"].__setitem__("number_fractions", [0.5, 0.3, 0.1])
    )
    assert "size_distributions.fine.number_fractions" in msg and "sum to 0.9" in msg and "must sum to 1" in msg


def test_particles_must_fit_the_bowl(default_config):
    msg = bad(default_config, lambda c: c["size_distributions"]["fine"].__setitem__("diameters", [0.002, 0.003, 0.02]))
    assert "size_distributions.fine.diameters" in msg and "does not fit the bowl" in msg


def test_blade_must_stay_inside_the_bowl(default_config):
    radius = default_config.granulator.bowl.radius
    msg = bad(default_config, lambda c: c["granulator"]["impeller"].__setitem__("blade_length", radius))
    assert "granulator.impeller.blade_length" in msg and "must be smaller than the bowl radius" in msg


def test_unknown_distribution_in_grid(default_config):
    msg = bad(default_config, lambda c: c["grid"]["size_distributions"].append("huge"))
    assert "'huge' is not defined" in msg and "fine" in msg


def test_bed_must_cover_impeller(default_config):
    msg = bad(default_config, lambda c: c["dem"].__setitem__("bed_height", 0.005))
    assert "dem.bed_height" in msg and "cover the impeller" in msg


def test_unknown_key_lists_allowed(default_config):
    msg = bad(default_config, lambda c: c["material"].__setitem__("colour", "red"))
    assert "colour" in msg and "allowed keys" in msg


def test_injection_in_a_distribution_name_is_rejected(default_config):
    evil = "fine\nshell touch /tmp/pwned"

    def edit(c):
        c["size_distributions"][evil] = c["size_distributions"]["fine"]
        c["grid"]["size_distributions"] = [evil]

    msg = bad(default_config, edit)
    assert "does not match" in msg


def test_snakemake_rejects_a_bad_config_before_running(tmp_path, root, default_mapping):
    cfg = default_mapping
    cfg["size_distributions"]["fine"]["diameters"][0] = -0.002
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg))
    proc = subprocess.run(
        snakemake_command(tmp_path, "-n", "--cores", "1", configfile=path),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode != 0
    assert "diameters" in proc.stdout + proc.stderr and "minimum" in proc.stdout + proc.stderr
    assert not (tmp_path / "results").exists()


def test_load_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "none.yaml")
    p = tmp_path / "list.yaml"
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_config(p)


@pytest.mark.parametrize(
    "key, value, allowed",
    [
        ("strength_size_exponent", -0.5, "allowed: number >= 0 and <= 3"),
        ("strength_size_exponent", 3.5, "allowed: number >= 0 and <= 3"),
        ("strength_porosity_exponent", -1.0, "allowed: number >= 0 and <= 4"),
        ("yield_strength", 0.0, "allowed: number > 0 and <= 1000000000.0"),
        ("yield_strength", -1.0e4, "allowed: number > 0 and <= 1000000000.0"),
        ("critical_stokes", 0.0, "allowed: number > 0 and <= 1000.0"),
        ("strength_spread", -0.1, "allowed: number >= 0 and <= 5"),
        ("reference_porosity", 0.0, "allowed: number > 0 and < 1"),
        ("reference_porosity", 1.0, "allowed: number > 0 and < 1"),
        ("reference_diameter", -0.002, "allowed: number > 0 and <= 1"),
        ("constant_rate", -0.002, "allowed: number >= 0 and <= 1000.0"),
    ],
)
def test_breakage_settings_out_of_their_physical_range_are_refused_where_they_enter(
    tmp_path, root, key, value, allowed
):
    """A breakage setting out of its range is refused when the file is loaded, with the key, the
    value and the allowed range, before any computation (no numpy warning first)."""
    import warnings

    cfg = yaml.safe_load((root / "config" / "config.yaml").read_text())
    cfg["pbm"].setdefault("breakage", {}).update({"enabled": True, key: value})
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(cfg))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning before the error fails the test
        with pytest.raises(ConfigError) as info:
            load_config(path)
    message = str(info.value)
    assert f"pbm.breakage.{key} = {value!r}" in message and allowed in message, message
    assert "Traceback" not in message


def test_feed_check_names_a_case_of_the_feed_study(default_config, tiny_config):
    check = default_config.validation.feed_check
    assert (check.feed, check.replicates) == ("fine+medium", 3)
    # rpm null: the feed study's speed, the grid's middle speed (150, 300, 600, 1200 -> 300)
    assert check.rpm == default_config.grid.middle_speed() == 300.0
    assert tiny_config.validation.feed_check.rpm == 600.0  # of 600 and 1200, the lower
    mapping = copy.deepcopy(default_config.to_dict())
    mapping["validation"]["feed_check"] = {"feed": "medium", "rpm": 450}
    chosen = Config.from_mapping(mapping).validation.feed_check
    assert (chosen.feed, chosen.rpm, chosen.replicates) == ("medium", 450.0, 3)
    mapping["validation"]["feed_check"] = {}
    assert Config.from_mapping(mapping).validation.feed_check.feed is None  # no feed check
    # a blend of feeds that are not neighbours, an end of the order, an unknown name: refused
    for feed in ("fine+coarse", "fine", "coarse", "huge"):
        msg = bad(default_config, lambda c, f=feed: c["validation"]["feed_check"].__setitem__("feed", f))
        assert f"validation.feed_check.feed = {feed!r}" in msg, msg
        assert "allowed: ['fine+medium', 'medium', 'medium+coarse']" in msg, msg
    msg = bad(default_config, lambda c: c["validation"]["feed_check"].__setitem__("replicates", 0))
    assert "validation.feed_check.replicates = 0" in msg and ">= 1" in msg
    msg = bad(default_config, lambda c: c["validation"]["feed_check"].__setitem__("rpm", -300))
    assert "validation.feed_check.rpm = -300" in msg
    msg = bad(default_config, lambda c: c["validation"]["feed_check"].__setitem__("seeds", 2))
    assert "seeds" in msg and "allowed keys" in msg


def test_the_feed_check_jobs_follow_the_config(tmp_path, tiny_mapping):
    """validation.feed_check: one PBM-DEM job per replicate, PBM-ANN and the table; none with
    feed null; an unknown feed stops Snakemake before any job with the key, value and what is allowed."""

    def jobs(edit) -> tuple[int, dict, str]:
        cfg = copy.deepcopy(tiny_mapping)
        edit(cfg["validation"]["feed_check"])
        path = tmp_path / "check.yaml"
        path.write_text(yaml.safe_dump(cfg))
        proc = subprocess.run(
            snakemake_command(tmp_path, "-n", "--cores", "2", "--quiet", "rules", configfile=path),
            capture_output=True,
            text=True,
            timeout=300,
        )
        counts = {
            line.split()[0]: int(line.split()[1])
            for line in proc.stdout.splitlines()
            if len(line.split()) == 2 and line.split()[1].isdigit()
        }
        return proc.returncode, counts, proc.stdout + proc.stderr

    code, counts, out = jobs(lambda c: c.update(replicates=3))
    assert code == 0, out
    assert (counts["feed_check_dem"], counts["feed_check_ann"], counts["feed_check"]) == (3, 1, 1), out
    code, counts, out = jobs(lambda c: c.update(feed=None))
    assert code == 0 and "pbm_dem_coupled" in counts, out
    assert not {"feed_check_dem", "feed_check_ann", "feed_check"} & set(counts), out
    code, counts, out = jobs(lambda c: c.update(feed="large+small"))
    assert code != 0 and "validation.feed_check.feed = 'large+small'" in out and "allowed: ['small+large']" in out
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("key", ["speed_law_from", "speed_tail_from"])
def test_speeds_the_surrogate_fits_from_are_velocity_bin_edges_checked_where_they_enter(tmp_path, root, key):
    """A fitting speed between two velocity-bin edges is refused when the file is loaded (not when
    the surrogate is trained, minutes into a run), naming the key, the value and the edges."""
    cfg = yaml.safe_load((root / "config" / "config.yaml").read_text())
    cfg["surrogate"][key] = 1.5
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert f"surrogate.{key} = 1.5 m/s; allowed: null or an inner edge" in message and "1.778" in message, message
    cfg["surrogate"][key] = 1.778  # an edge to 3 digits
    path.write_text(yaml.safe_dump(cfg))
    assert getattr(load_config(path).surrogate, key) == 1.778

"""Configuration validation: every site file passes; bad files fail with one clear line."""

from pathlib import Path

import pytest
import yaml

from kitegully import InputError
from kitegully.config import checked_choice, checked_number, load_yaml, validate_config
from kitegully.tether.config import check_tether_config

from snakemake_utils import REPO, run_snakemake

SITES = sorted((REPO / "config" / "sites").glob("*.yaml"))


def _merged(site: Path) -> dict:
    cfg = load_yaml(REPO / "config" / "config.yaml")
    cfg.update(load_yaml(site))
    return cfg


@pytest.mark.parametrize("site", SITES, ids=lambda p: p.stem)
def test_every_shipped_site_is_valid(site):
    cfg = validate_config(_merged(site), [REPO / "config" / "config.yaml", site])
    if "tether" in cfg:
        check_tether_config(cfg["tether"])


def _write_variant(tmp_path, edit) -> Path:
    cfg = load_yaml(REPO / "config" / "sites" / "kamech_twin.yaml")
    edit(cfg)
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_unknown_key_names_key_and_file(tmp_path):
    path = _write_variant(tmp_path, lambda c: c["tether"]["kites"]["delta10"].update(wing_area=10))
    with pytest.raises(InputError) as err:
        validate_config(_merged(path), [path])
    msg = str(err.value)
    assert str(path) in msg and "unknown key 'tether.kites.delta10.wing_area'" in msg
    assert "\n" not in msg


def test_wrong_type_names_key_and_file(tmp_path):
    path = _write_variant(tmp_path, lambda c: c["tether"]["atmosphere"].update(air_density_kg_m3="dense"))
    with pytest.raises(InputError, match=r"tether\.atmosphere\.air_density_kg_m3: 'dense' is not of type 'number'") as err:
        validate_config(_merged(path), [path])
    assert str(path) in str(err.value)


def test_missing_required_key(tmp_path):
    path = _write_variant(tmp_path, lambda c: c["tether"].pop("sweep"))
    with pytest.raises(InputError, match="'sweep' is a required property"):
        validate_config(_merged(path), [path])


def test_broken_yaml_names_the_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("site:\n  name: [unclosed\n")
    with pytest.raises(InputError, match=r"bad\.yaml: not valid YAML \(line"):
        load_yaml(path)


def test_dangling_reference_in_tether_config(tmp_path):
    cfg = load_yaml(REPO / "config" / "sites" / "kamech_twin.yaml")
    cfg["tether"]["observed"]["flights"][0]["kite"] = "parafoil"
    with pytest.raises(InputError, match=r"observed\.flights\[0\]\.kite: unknown kite 'parafoil'"):
        check_tether_config(cfg["tether"])


def test_snakemake_refuses_a_bad_config_before_running(tmp_path):
    path = _write_variant(tmp_path, lambda c: c["site"].update(colour="red"))
    proc = run_snakemake(path, tmp_path / "results", extra=["--dry-run"], check=False)
    assert proc.returncode != 0
    assert f"Invalid configuration: {path}: unknown key 'site.colour'" in proc.stdout + proc.stderr
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("value, low, strict, message", [
    (0, 0.0, True, r"^dense\.cell_m: must be positive, got 0$"),
    (-1, 0.0, False, r"^dense\.cell_m: must be at least 0, got -1$"),
    (2, 3, False, r"^dense\.cell_m: must be at least 3, got 2$"),
    ("1.0", 0.0, True, r"^dense\.cell_m: must be positive, got '1\.0'$"),
    (True, 0.0, True, r"^dense\.cell_m: must be positive, got True$"),
])
def test_checked_number_names_the_key_and_the_bound(value, low, strict, message):
    with pytest.raises(InputError, match=message):
        checked_number({"cell_m": value}, "cell_m", "dense", low, strict=strict)


def test_checked_number_and_choice_return_good_values():
    assert checked_number({"k": 3}, "k", "s", 3, strict=False) == 3
    assert checked_number({"k": 0.5}, "k", "s") == 0.5
    assert checked_choice({"m": "laz"}, "m", "georef", ("laz", "las")) == "laz"
    with pytest.raises(InputError, match=r"^georef\.m: must be one of laz, las, got 'tif'$"):
        checked_choice({"m": "tif"}, "m", "georef", ("laz", "las"))

"""Rules pass only the config values they use: changing one sub-section reruns only its readers.

Snakemake's default rerun triggers include ``params``: a rule whose ``params:`` held the
whole ``gully:`` section reran the expensive ``gully_map`` when a validation tolerance
changed. Here the gully rules' outputs are made to exist with their metadata recorded
(``--summary`` lists them, empty files are created, ``--touch --forcerun`` records the
params of every gully job without running it), then a dry run with a changed site config
lists the jobs Snakemake would rerun.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from snakemake_utils import run_snakemake
from .test_gully import GULLY_RULES, SITE, fabricate_twin

TARGETS = ("gully_summary.csv", "network_validation.csv", "gully_sensitivity.csv", "gully_section.png")


@pytest.fixture(scope="module")
def touched(tmp_path_factory):
    results = tmp_path_factory.mktemp("params_rerun")
    fabricate_twin(results / "tiny_twin" / "twin")
    targets = [str(results / "tiny_twin" / "gully" / n) for n in TARGETS]
    allowed = ["--allowed-rules", *GULLY_RULES, "--nocolor"]
    summary = run_snakemake(SITE, results, targets, extra=[*allowed, "--summary"]).stdout
    outputs = [line.split("\t")[0] for line in summary.splitlines()[1:] if "\t" in line]
    assert outputs, summary
    for f in outputs:
        Path(f).parent.mkdir(parents=True, exist_ok=True)
        Path(f).touch()
    # tiny_twin maps the dense DSM (gully.dem: dense): the stand-in rule does not exist there
    mapping_rules = [r for r in GULLY_RULES if r != "gully_standin_dem"]
    run_snakemake(SITE, results, targets, extra=[*allowed, "--touch", "--forcerun", *mapping_rules, "--nocolor"])

    def planned(change=None) -> set[str]:
        site = SITE
        if change is not None:
            cfg = yaml.safe_load(SITE.read_text())
            change(cfg)
            site = results / "changed_site.yaml"
            site.write_text(yaml.safe_dump(cfg, sort_keys=False))  # key order kept: params compare by value
        out = run_snakemake(site, results, targets, extra=[*allowed, "-n"]).stdout
        return set(re.findall(r"^(?:local)?rule (\w+):", out, re.M))

    return planned


def test_nothing_to_do_after_touch(touched):
    assert touched() == set()


def test_validation_change_does_not_rerun_the_mapping(touched):
    def change(cfg):
        cfg["gully"]["validation"]["tolerance_m"] = 7.0
        cfg["gully"]["validation"]["reference_join_m"] = 2.0

    rerun = touched(change)
    assert "gully_map" not in rerun and "gully_section" not in rerun
    assert rerun == {"gully_validate", "gully_sensitivity"}  # the sensitivity table scores at tolerance_m


def test_sensitivity_change_reruns_only_the_sensitivity(touched):
    def change(cfg):
        cfg["gully"]["sensitivity"]["sigmas_m"] = [5.0, 10.0]

    assert touched(change) == {"gully_sensitivity"}


def test_mapping_change_reruns_the_mapping(touched):
    def change(cfg):
        cfg["gully"]["depth_threshold_m"] = 0.3

    assert {"gully_map", "gully_section", "gully_sensitivity"} <= touched(change)

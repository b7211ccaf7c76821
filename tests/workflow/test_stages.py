"""STAGES in workflow/rules/common.smk and the rule files agree (the Snakefile stops otherwise)."""

from __future__ import annotations

import ast
import re

from snakemake_utils import REPO


def _stages() -> list[str]:
    text = (REPO / "workflow/rules/common.smk").read_text(encoding="utf-8")
    m = re.search(r"^STAGES = (\[.*?\])", text, re.S | re.M)
    assert m, "STAGES list not found in common.smk"
    return ast.literal_eval(m.group(1))


def test_every_listed_stage_has_a_rule_file():
    missing = [s for s in _stages() if not (REPO / "workflow/rules" / f"{s}.smk").is_file()]
    assert not missing, f"STAGES lists stages without a rule file: {missing}"


def test_every_rule_file_is_a_listed_stage():
    files = {p.stem for p in (REPO / "workflow/rules").glob("*.smk")} - {"common"}
    assert files == set(_stages())


def test_snakefile_raises_for_a_stage_without_rule_file():
    text = (REPO / "Snakefile").read_text(encoding="utf-8")
    assert "without a rule file" in text and "raise WorkflowError" in text

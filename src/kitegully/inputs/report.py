"""The input report: report.json (machine-readable) and report.md (for people)."""

from __future__ import annotations

import json
from pathlib import Path

from kitegully.inputs.findings import Findings


def write_report(found: Findings, json_path: str | Path, md_path: str | Path, site: str) -> None:
    """Write the findings as ``report.json`` and ``report.md``.

    Parameters
    ----------
    found : Findings
        The findings and facts of the input checks.
    json_path : str or Path
        Output ``report.json``: :meth:`Findings.as_dict` plus ``site``.
    md_path : str or Path
        Output ``report.md``: verdict, findings by level and a table of the facts.
    site : str
        Site name.
    """
    d = found.as_dict()
    Path(json_path).write_text(json.dumps(d | {"site": site}, indent=2, default=str) + "\n", encoding="utf-8")
    lines = [f"# Input check: {site}", "", f"**Verdict: {d['verdict']}** "
             f"({len(d['errors'])} error(s), {len(d['warnings'])} warning(s), {len(d['notes'])} note(s))", ""]
    for title, key in (("Errors (the run is refused)", "errors"), ("Warnings", "warnings"), ("Notes", "notes")):
        if d[key]:
            lines += [f"## {title}", ""] + [f"- `{f['source']}`: {f['message']}" for f in d[key]] + [""]
    lines += ["## What was read", "", "| item | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in d["facts"].items()]
    Path(md_path).write_text("\n".join(lines) + "\n", encoding="utf-8")

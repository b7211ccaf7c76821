"""Tables: CSV with units in column names, plus a Markdown copy for the report."""

from __future__ import annotations

from pathlib import Path

import pandas as pd


def write_table(df: pd.DataFrame, csv_path: str | Path, markdown: bool = True, floatfmt: str = ".4g") -> None:
    """Write ``df`` to ``csv_path`` and, if ``markdown``, the same table to ``.md`` beside it.

    Parameters
    ----------
    df : DataFrame
        The table; its index is not written.
    csv_path : str or Path
        Output CSV file; its folder is created.
    markdown : bool
        Also write the Markdown copy.
    floatfmt : str
        Number format of the Markdown copy.
    """
    csv_path = Path(csv_path)
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(csv_path, index=False)
    if markdown:
        csv_path.with_suffix(".md").write_text(df.to_markdown(index=False, floatfmt=floatfmt) + "\n", encoding="utf-8")

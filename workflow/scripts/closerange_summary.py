"""Rule closerange_summary: 001 Table 1 and the OBIA accuracy on photogrammetric vs direct orthophotos."""

import json

from kitegully.closerange import closerange_tables
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
inp, out = snakemake.input, snakemake.output


def _load(paths):
    records = []
    for p in paths:
        with open(p, encoding="utf-8") as fh:
            records.append(json.load(fh))
    return records


tables = closerange_tables(_load(inp.records), _load(inp.confusion_sfm), _load(inp.confusion_direct),
                           list(zip(inp.class_direct, inp.class_sfm, inp.truth)))
write_table(tables.table1, out.table1)
write_table(tables.accuracy, out.accuracy)

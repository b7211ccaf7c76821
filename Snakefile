# kitegully: kite/drone photogrammetry for soil-erosion mapping.
#
#   snakemake --cores 2                                         # default site (kamech_twin)
#   snakemake --cores 2 --configfile config/sites/<site>.yaml   # another site
#   snakemake --report report.html                              # HTML report
#
# config/config.yaml names the default site file; a site file given with --configfile
# replaces it. Every loaded file is validated against config/schema before any job runs.

import sys
from pathlib import Path

from kitegully import InputError
from kitegully.config import validate_config


configfile: "config/config.yaml"


if not workflow.overwrite_configfiles:

    configfile: config["default_site"]


try:
    config = validate_config(config, sources=workflow.configfiles)
except InputError as _err:
    # one line, no Snakefile traceback: the message names the file and the key
    import sys

    print(f"Invalid configuration: {_err}", file=sys.stderr)
    sys.exit(1)

SITE = config["site"]["name"]
IS_TWIN = config["site"]["kind"] == "twin"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"


# One rule file per stage, in data-flow order. Each file registers its final outputs with
# add_targets() and decides itself whether it applies to the site (e.g. twin-only stages).
_missing = [s for s in STAGES if not Path(workflow.basedir, "workflow", "rules", f"{s}.smk").exists()]
if _missing:
    raise WorkflowError(f"STAGES in workflow/rules/common.smk lists {', '.join(_missing)} without a rule file workflow/rules/<stage>.smk")

for _stage in STAGES:

    include: f"workflow/rules/{_stage}.smk"


rule all:
    input:
        all_targets(),
    default_target: True


onerror:
    # Snakemake ends a failed run with its own "Error in rule" blocks: end the console with
    # each failed job's last log line (for bad input, the one sentence saying what is wrong).
    from kitegully.logs import failed_job_lines

    for _line in failed_job_lines(log):
        print(_line, file=sys.stderr)

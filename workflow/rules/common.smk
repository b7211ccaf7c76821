# Shared helpers for all rule files: paths, logs and the list of final targets.

# The stages in data-flow order; each has workflow/rules/<stage>.smk (the Snakefile stops
# with an error naming a listed stage whose rule file is missing). A new stage is added here
# together with its rule file (docs/architecture.md, "Adding a stage").
STAGES = [
    "inputs",
    "tether",
    "twin",
    "flight",
    "sfm",
    "georef",
    "dense",
    "validate",
    "gully",
    "polygons",
    "obia",
    "change",
]

RESULTS = Path(config["results_dir"]) / SITE
TARGETS = []


def result(stage, name):
    """Path of an output of a stage: <results_dir>/<site>/<stage>/<name>."""
    return str(RESULTS / stage / name)


def logfile(stage, name):
    """Log file of a rule: <results_dir>/<site>/logs/<stage>/<name>.log."""
    return str(RESULTS / "logs" / stage / f"{name}.log")


def benchfile(stage, name):
    """Benchmark file of a heavy rule: <results_dir>/<site>/benchmarks/<stage>/<name>.tsv."""
    return str(RESULTS / "benchmarks" / stage / f"{name}.tsv")


def add_targets(*paths):
    """Register final outputs of a stage for rule `all`.

    Accepts paths and (nested) lists of paths such as a rule's ``output`` Namedlist.
    """
    for p in paths:
        if isinstance(p, (str, Path)):
            TARGETS.append(str(p))
        else:
            add_targets(*p)


def all_targets():
    return TARGETS


def config_keys(section, keys):
    """The named keys of config[section]: what a rule passes in ``params:`` when it uses only
    part of a section (a change to a key it ignores then does not rerun it)."""
    return {k: config[section][k] for k in keys if k in config[section]}


def caption(name):
    """Report caption file, relative to workflow/rules/ (where report() is called)."""
    return f"../report/{name}.rst"

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
    "closerange",
    "change",
    "stereo",
    "lowcost",
    "report",
]

RESULTS = Path(config["results_dir"]) / SITE
TARGETS = []


def result(stage, name):
    """Path of an output of a stage: <results_dir>/<site>/<stage>/<name>."""
    return str(RESULTS / stage / name)


# Survey epochs (issue 17). A twin is surveyed twice; the chain flight -> inputs -> sfm -> georef
# -> dense -> validate runs once per epoch as the wildcard {epoch} of the same rules. Epoch 1
# keeps the paths it had before epochs existed (results/<site>/<stage>/<name>: every consumer,
# table and test stays as it is) and epoch 2 lives one folder down
# (results/<site>/<stage>/epoch2/<name>), the layout the twin stage already writes. So {epoch}
# is the folder prefix: "" for epoch 1, "epoch2/" for epoch 2 (an empty wildcard value is fine
# with an explicit constraint).
EPOCHS = {1: "", 2: "epoch2/"}


wildcard_constraints:
    epoch="(epoch2/)?",


def epoch_dir(n):
    """Folder prefix of survey epoch ``n`` (1 or 2): "" or "epoch2/"."""
    return EPOCHS[int(n)]


def epoch_number(wildcards):
    """Survey epoch (1 or 2) of a job with the {epoch} wildcard."""
    return {v: k for k, v in EPOCHS.items()}[wildcards.epoch]


def eresult(stage, name):
    """Path pattern of a per-epoch output: <results_dir>/<site>/<stage>/{epoch}<name>."""
    return str(RESULTS / stage) + "/{epoch}" + name


def epoch_result(stage, name, n):
    """Path of a per-epoch output for epoch ``n`` (no wildcard): eresult() filled in."""
    return str(RESULTS / stage) + "/" + epoch_dir(n) + name


def elogfile(stage, name):
    """Log file of a per-epoch rule: <results_dir>/<site>/logs/<stage>/{epoch}<name>.log."""
    return str(RESULTS / "logs" / stage) + "/{epoch}" + f"{name}.log"


def ebenchfile(stage, name):
    """Benchmark file of a per-epoch rule: <results_dir>/<site>/benchmarks/<stage>/{epoch}<name>.tsv."""
    return str(RESULTS / "benchmarks" / stage) + "/{epoch}" + f"{name}.tsv"


# Epochs this run surveys: twins with a second epoch and a change stage fly both; other sites 1.
SURVEY_EPOCHS = [1, 2] if IS_TWIN and "epoch2" in config.get("twin", {}) and "change" in config else [1]


def epoch_results(stage, name):
    """Paths of a per-epoch output for every epoch this run surveys (for add_targets)."""
    return [epoch_result(stage, name, n) for n in SURVEY_EPOCHS]


def _overlay(base, over):
    out = dict(base)
    for k, v in over.items():
        out[k] = _overlay(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def epoch_section(section, keys=None, exclude=()):
    """Params function: config[section] for the job's epoch, i.e. the section with its
    ``epochs.epoch<n>`` overlay merged in (nested keys merged, not replaced) and without the
    ``epochs`` key itself; only ``keys`` (in that order) if given, without ``exclude``.
    Epoch 1 without an overlay gets exactly what the rule got before epochs existed."""

    def params(wildcards):
        cfg = config.get(section, {})
        over = (cfg.get("epochs") or {}).get(f"epoch{epoch_number(wildcards)}") or {}
        merged = _overlay({k: v for k, v in cfg.items() if k != "epochs"}, over)
        if keys is not None:
            merged = {k: merged[k] for k in keys if k in merged}
        return {k: v for k, v in merged.items() if k not in exclude}

    return params


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

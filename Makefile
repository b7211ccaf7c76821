# kitegully: the two commands are `make run` and `make test`.
# Both create .venv from the pinned lock file when it is missing or stale.
PYTHON ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed
BIN := $(VENV)/bin
CORES ?= 2
SITE ?=
SNAKE_ARGS ?=

ifeq ($(SITE),)
CONFIG_ARG :=
else
CONFIG_ARG := --configfile config/sites/$(SITE).yaml
endif
# one line naming file and line for a YAML error (Snakemake's own loader names neither)
CONFIG_CHECK = $(BIN)/python -m kitegully.config $(if $(SITE),config/sites/$(SITE).yaml,)

.PHONY: run test report venv clean-venv dryrun benchmark slurm-test ensemble holdout ensemble-change holdout-change gully-ensemble-analysis change-vs-xdem stereo kamech-full kamech-full-estimate tiles-check lowcost lowcost-5mm lowcost-5mm-cost closerange polygons-benchmarks speed-benchmarks polygons-tiles-check dense-view-cap georef-tie-density bundle-speed dense-final-window gsd-experiment gsd-experiment-base

$(STAMP): pyproject.toml requirements.lock
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "kitegully needs $(PYTHON) on PATH (set PYTHON=...)"; exit 1; }
	rm -rf $(VENV)
	$(PYTHON) -m venv $(VENV)
	@echo "installing pinned dependencies into $(VENV) (log: $(VENV)/install.log)"
	$(BIN)/python -m pip install -r requirements.lock > $(VENV)/install.log 2>&1 || { tail -30 $(VENV)/install.log; exit 1; }
	$(BIN)/python -m pip install --no-deps --no-build-isolation -e . >> $(VENV)/install.log 2>&1 || { tail -30 $(VENV)/install.log; exit 1; }
	touch $(STAMP)

venv: $(STAMP)

run: $(STAMP)
	@$(CONFIG_CHECK)
	$(BIN)/snakemake --cores $(CORES) $(CONFIG_ARG) $(SNAKE_ARGS)

dryrun: $(STAMP)
	@$(CONFIG_CHECK)
	$(BIN)/snakemake --cores $(CORES) $(CONFIG_ARG) --dry-run

report: $(STAMP)
	$(BIN)/snakemake --cores $(CORES) $(CONFIG_ARG) --report report.html

test: $(STAMP)
	$(BIN)/python -m pytest -n $(CORES) --dist loadgroup $(PYTEST_ARGS)

# Whole chain on the default twin and the 5 twins of config/sites/ensemble/ (issue 15):
# results/ensemble/summary.csv and summary.md (about 6 x 10 min on 2 idle cores).
ensemble: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/twin_ensemble.py --cores $(CORES) $(ENSEMBLE_ARGS)

# The same chain on the held-out twins of config/sites/holdout/ (never looked at while a method was
# written or chosen; h3-h26 drawn at random by benchmarks/draw_holdout_twins.py; h27-h32 declared stress draws in
# one corner of the range, session 43): results/holdout/summary.csv and summary.md (32 twins, about 32 x 8 min =
# 4.3 h on 2 cores; one set: ENSEMBLE_ARGS="--members h23,h24,h25,h26"; with `make holdout-change`, about 12 min per
# twin in all).
holdout: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/twin_ensemble.py --cores $(CORES) --member-dir config/sites/holdout --out results/holdout $(ENSEMBLE_ARGS)

# Epoch 2 and the change stage (issue 17) on every ensemble / held-out twin, on top of the chain that
# `make ensemble` / `make holdout` ran (epoch-1 products reused; about 4.5 min per twin on 2 idle
# cores), then the headcut measurement on the photogrammetric DSMs, the true DSMs and the true DTMs
# (evaluation only): results/ensemble_change/, results/holdout_change/, results/benchmarks/headcut_ceilings*/.
ensemble-change: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/twin_ensemble.py --cores $(CORES) --change --out results/ensemble_change $(ENSEMBLE_ARGS)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/headcut_ceilings.py --members kamech_twin,ens1,ens2,ens3,ens4,ens5

holdout-change: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/twin_ensemble.py --cores $(CORES) --change --member-dir config/sites/holdout --out results/holdout_change $(ENSEMBLE_ARGS)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/headcut_ceilings.py --members h1,h2,h3,h4,h5,h6 --out results/benchmarks/headcut_ceilings_holdout

# Where the gully network misses reference length and which automatic heads are false, on every
# ensemble member's DSM that `make ensemble` has written (evaluation only, reads the twins' truth;
# ~1 min per member and script): results/ensemble_misses/, results/ensemble_auto_fp/.
gully-ensemble-analysis: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/gully_ensemble_misses.py --results results
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/gully_auto_fp_analysis.py --results results

# Plot-scale stereo lab (issue 19, Moritani et al. 2010): its own site, not part of `make run`;
# results/stereo_lab/stereo/ (README "Plot-scale stereo (Moritani et al. 2010)").
stereo: $(STAMP)
	@$(BIN)/python -m kitegully.config config/sites/stereo_lab.yaml
	$(BIN)/snakemake --cores $(CORES) --configfile config/sites/stereo_lab.yaml $(SNAKE_ARGS)

# The whole Kamech survey at full size (issue 21): config/sites/kamech_full.yaml on $(CORES) cores,
# then results/kamech_full/benchmark.csv (per-rule wall/CPU/memory, total wall, accuracies next to
# the paper, 1- vs 2-core speed-up of the tiled stages). Hours on 2 cores; KAMECH_FULL_ARGS="--cut 600x400
# --tile-m 200" runs a corner instead (its table says NOT the full site).
kamech-full: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/kamech_full.py --cores $(CORES) $(KAMECH_FULL_ARGS)

# An ESTIMATE of the full site's wall time on $(CORES) cores, in a minute: the job graph of make
# kamech-full (a dry run on an empty results folder) replayed with the job times a finished run
# measured (KAMECH_TIMES, a benchmark.csv; default the sessions 15-16 run).
KAMECH_TIMES ?= docs/benchmarks/kamech_full_sessions15-16.csv
kamech-full-estimate: $(STAMP)
	rm -rf /tmp/kitegully_kamech_dry
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/kamech_full.py --cores $(CORES) --dry-run --results-dir /tmp/kitegully_kamech_dry
	$(BIN)/python benchmarks/schedule_estimate.py /tmp/kitegully_kamech_dry/kamech_full/benchmark_dryrun.log $(KAMECH_TIMES) --cores $(CORES)

# Dense matching with and without dense.matching.max_views (issue 21) in one run: a 1024 x 1024-cell
# window of the full site's tile r002_c002 (needs a full-size run's georef/sfm under FULL_RESULTS, read
# only; ~10 min) -> benchmarks/out/dense_view_cap_full.md; then the default twin's whole DSM -> _twin.md.
FULL_RESULTS ?= results/kamech_full
TWIN_RESULTS ?= results/kamech_twin
# Evaluation only, on a finished default run (results/kamech_twin): the last dense pass with a
# 3 x 3 window against the site's 5 x 5, in boxes around the 32 true gully heads, scored against
# the twin's true DSM (docs/stages/05_dense_validate.md). About 2 min on 2 idle cores.
dense-final-window: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/dense_final_window.py --results results/kamech_twin \
		--variant "site:" --variant "w3:final_window_half_cells=1"

dense-view-cap: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/dense_view_cap.py --site config/sites/kamech_full.yaml \
		--results $(FULL_RESULTS) --rows 5888:6912 --cols 4864:5888 --caps none,20,none@64 --repeats 2 \
		--out benchmarks/out/dense_view_cap_full.md
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/dense_view_cap.py --site config/sites/kamech_twin.yaml \
		--results $(TWIN_RESULTS) --caps none,20 --out benchmarks/out/dense_view_cap_twin.md

# The GCP bundle's tie-point budget against the block's shape (issue 21; evaluation only): one epoch
# of a finished full-size run's SfM model adjusted with 10 000, ~4 a tie-grid cell and every tie point,
# each also with f fixed at the true value; camera errors, the tie points' dome against the true DSM and
# at the checkpoints (~15 min) -> results/benchmarks/georef_tie_density_<epoch>.csv.
TIE_EPOCH ?= epoch2/
georef-tie-density: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/georef_tie_density.py --site config/sites/kamech_full.yaml \
		--results $(FULL_RESULTS) --epoch "$(TIE_EPOCH)" --ties 10000,99072,0 --f-true \
		--out results/benchmarks/georef_tie_density_$(subst /,,$(TIE_EPOCH)).csv

# GCP bundle at the full site's size (528 synthetic photos, 247 000 points): the compiled
# normal-equation kernels against the NumPy + SciPy sparse formulation, one run (~1 min, 3 GB).
bundle-speed: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/bundle_speed.py --out results/benchmarks/bundle_speed.csv

# Tiny twin's gully map untiled and with the tiled fill rules: products must be identical (~1-5 min).
tiles-check: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/tiled_rules_check.py --cores $(CORES)

# The default site's polygons untiled and with the tiled morphometry rules: identical products
# (~2-4 min; on the DSM of a default run, or POLY_DSM=path).
POLY_DSM ?= results/kamech_twin/dense/dsm.tif
polygons-tiles-check: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/polygons_tiles_check.py --dsm $(POLY_DSM) --cores $(CORES)

# The low-cost RGB + NIR kite survey of paper 004 (issue 18) on its own twin; not part of
# the default run (about 10 min on 2 idle cores).
lowcost: $(STAMP)
	@$(BIN)/python -m kitegully.config config/sites/lowcost_twin.yaml
	$(BIN)/snakemake --cores $(CORES) --configfile config/sites/lowcost_twin.yaml $(SNAKE_ARGS)

# The same survey at the paper's ~5 mm pixels (16 MP photos, 2.5 cm DSM, 5 mm mosaics):
# config/sites/variants/lowcost_twin_5mm.yaml over lowcost_twin.yaml, results/lowcost_twin_5mm/. At most about
# 1 h of CPU and 5 GB, extrapolated (README "Low-cost NIR survey"); lowcost-5mm-cost measures the steps
# on 6 full-size photos and writes the extrapolation (results/benchmarks/lowcost_5mm_cost.md).
LOWCOST_5MM := config/sites/lowcost_twin.yaml config/sites/variants/lowcost_twin_5mm.yaml
lowcost-5mm: $(STAMP)
	@$(BIN)/python -m kitegully.config $(LOWCOST_5MM)
	$(BIN)/snakemake --cores $(CORES) --configfile $(LOWCOST_5MM) $(SNAKE_ARGS)

lowcost-5mm-cost: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/lowcost_5mm_cost.py --site config/sites/lowcost_twin.yaml \
		--override config/sites/variants/lowcost_twin_5mm.yaml --photos 6

# Survey design (issues 16, 17): the default twin photographed at ~0.07 m GSD (4000 px photos, 0.1 m DSM,
# a 0.5 m matching window), everything else the default twin's: config/sites/variants/kamech_twin_gsd7cm.yaml,
# results/kamech_twin_gsd7cm/. Epochs 1 and 2 to the polygons' and the change stage's scores against the truth
# (18 jobs, 25 min 52 s on 2 cores beside other work, peak 5.1 GB, session 33; ens1 32 min). GSD_MEMBER=ens1 does the same for an ensemble member
# (results/ens1_gsd7cm/; `make gsd-experiment-base GSD_MEMBER=ens1` runs its default-GSD epoch 2 and change for
# the comparison). Copying results/<twin>/twin there first (cp -a) reuses the same truth (regenerated otherwise,
# identically). Then benchmarks/gsd_experiment.py puts the two runs side by side.
GSD_MEMBER ?=
GSD_BASE := config/sites/kamech_twin.yaml $(if $(GSD_MEMBER),config/sites/ensemble/$(GSD_MEMBER).yaml)
GSD_SITE := $(if $(GSD_MEMBER),$(GSD_MEMBER),kamech_twin)
GSD_TARGETS = results/$(1)/change/evaluation_summary.csv results/$(1)/polygons/morphometry_errors.csv \
	results/$(1)/validate/checkpoint_summary.csv results/$(1)/validate/epoch2/checkpoint_summary.csv \
	results/$(1)/validate/dsm_error_by_landcover.csv
gsd-experiment: $(STAMP)
	@$(BIN)/python -m kitegully.config $(GSD_BASE) config/sites/variants/kamech_twin_gsd7cm.yaml
	$(BIN)/snakemake --cores $(CORES) --configfile $(GSD_BASE) config/sites/variants/kamech_twin_gsd7cm.yaml \
		--config 'site={name: $(GSD_SITE)_gsd7cm}' $(SNAKE_ARGS) -- $(call GSD_TARGETS,$(GSD_SITE)_gsd7cm)

gsd-experiment-base: $(STAMP)
	$(BIN)/snakemake --cores $(CORES) --configfile $(GSD_BASE) $(SNAKE_ARGS) -- $(call GSD_TARGETS,$(GSD_SITE))

# Close-range SfM of all OBIA scenes (issue 20; the default run builds closerange.scenes, one
# scene): pole photos -> SfM -> 2 cm orthophotos -> OBIA, results/<site>/obia/closerange_sfm.csv
# and closerange_accuracy.csv (all 10: 19 min 59 s wall on 2 idle cores, session 11; 17-20 min in session 9).
# on_scene_failure: record: a scene that cannot be georeferenced (none since session 8: 08 now registers
# with closerange.sfm_affine_features: fallback, ~26 min of its own on the loaded machine) is a `failed`
# row with its one sentence, and the overall accuracy is over the scenes that succeeded ("9 of 10").
# --forcerun closerange_classify (about 5 s a scene): Snakemake 9.27 does not rerun a scene's
# classification when the SfM checkpoint's orthophoto is newer (the classify job is only found
# after the checkpoint; measured: a rerun SfM left the old classification in the summary).
closerange: $(STAMP)
	@$(CONFIG_CHECK)
	$(BIN)/snakemake --cores $(CORES) $(CONFIG_ARG) --config 'closerange={scenes: all, on_scene_failure: record}' --forcerun closerange_classify $(SNAKE_ARGS) -- closerange_summary

# Gully polygons (issue 16): the paper's settings against ours on the peat valley (~4 min), and the
# stage on every ensemble member's DSM that `make ensemble` has written (~1 min per member):
# results/benchmarks/polygons_paper_settings.md, polygons_ensemble.md, and the depth error by section
# kind with the bounds of a bias correction (polygons_depth_bounds.md; evaluation only).
polygons-benchmarks: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/polygons_paper_settings.py
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/polygons_ensemble.py --sections $(POLYGONS_ENSEMBLE_ARGS)
	$(BIN)/python benchmarks/polygons_depth_bounds.py results/benchmarks/polygons_ensemble_sections.csv --out results/benchmarks/polygons_depth_bounds
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/polygons_dsm_diagnosis.py $(POLYGONS_ENSEMBLE_ARGS)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/polygons_rules_off.py $(POLYGONS_ENSEMBLE_ARGS)

# Speed of the heavy stages (issue 21), each beside its reference in one run: the dense kernels
# against the former revision's (benchmarks/out/dense_kernels_speed.md, ~6 min on a loaded machine),
# the gully stage at 80 M cells with the full site's settings (no former revision since session 23: the
# old one cannot run head_snap posterior or edge_inlets; --against REV in gully_benchmark.py) and the fill against GRASS r.fill.dir
# and pysheds (results/benchmarks/gully_benchmark.md, ~30 min loaded, 7-9 min near idle; installs grass-core with apt
# and pysheds in its own venv on first use).
speed-benchmarks: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/dense_kernels_speed.py
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/gully_benchmark.py --skip-scipy

clean-venv:
	rm -rf $(VENV)

# Our change stage against xDEM (pinned, in its own .venv-xdem built with pip: xDEM would downgrade
# pandas in .venv) on the DEM-site example's pair: shift, volume, speed -> benchmarks/out/change_vs_xdem.md.
# Needs the site's change stage run first (snakemake --configfile config/sites/kamech_dem_change.yaml).
change-vs-xdem: $(STAMP)
	PYTHONPATH=$(CURDIR)/src $(BIN)/python benchmarks/change_vs_xdem.py --site kamech_dem_change

# One-node SLURM cluster on this machine (needs root): tiny twin through workflow/profiles/slurm,
# jobs checked in sacct, tables compared with a local run. Not part of `make test`.
slurm-test: $(STAMP)
	bash tests/cluster/run_slurm.sh

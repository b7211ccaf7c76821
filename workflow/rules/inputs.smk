# Input checks (issue 14): one cheap rule reads every input the site hands in (photographs,
# GCP file, checkpoints, rasters) and refuses the run with one sentence before structure
# from motion. It writes inputs/report.md and .json, and the checked GCP and checkpoint
# files (heights in metres, inputs.z_units) that georef and validate read.

INPUTS_GCP = None  # checked copies, set below when the site has photographs
INPUTS_CHECKPOINTS = None

if "sfm" in config:

    def inputs_sources():
        """Files to check: config inputs for real sites, the flight and twin stages' observed files for twins."""
        if IS_TWIN:
            src = dict(images=eresult("flight", "observed/images"), gcp=eresult("flight", "observed/gcp_list.txt"))
            if "twin" in config:
                src["checkpoints"] = eresult("twin", "observed/checkpoints.csv")
            return src
        ins = config["inputs"]
        src = dict(images=ins["images_dir"], gcp=ins["gcp_file"])
        if ins["checkpoints"]:
            src["checkpoints"] = ins["checkpoints"]
        if ins.get("rasters"):
            src["rasters"] = [r["path"] for r in ins["rasters"]]
        if INPUTS_VECTORS:
            src["vectors"] = list(INPUTS_VECTORS.values())
        return src

    # vector files a real site hands in (twins make their own), by the config key naming them
    INPUTS_VECTORS = {} if IS_TWIN or "gully" not in config else {
        k: v for k, v in {
            "gully.heads_file": config["gully"]["heads_file"],
            "gully.reference_network_file": config["gully"]["reference_network_file"],
            "gully.validation.catchment_file": config["gully"]["validation"]["catchment_file"],
        }.items() if v
    }

    INPUTS_SRC = inputs_sources()
    INPUTS_GCP = eresult("inputs", "gcp_file" + Path(INPUTS_SRC["gcp"]).suffix)  # per epoch (issue 17)
    INPUTS_CHECKPOINTS = eresult("inputs", "checkpoints.csv") if "checkpoints" in INPUTS_SRC else None

    rule check_inputs:
        input:
            **INPUTS_SRC,
        output:
            report=report(eresult("inputs", "report.md"), caption=caption("inputs_report"), category="Inputs"),
            json=eresult("inputs", "report.json"),
            gcp=INPUTS_GCP,
            **({"checkpoints": INPUTS_CHECKPOINTS} if INPUTS_CHECKPOINTS else {}),
        params:
            cfg={
                "crs": config["site"]["crs"],
                "inputs": {k: v for k, v in config.get("inputs", {}).items() if k in ("z_units", "rasters")},
                "georef": {k: v for k, v in config.get("georef", {}).items()
                           if k in ("gcp_format", "csv_crs", "gcp_pixel_frame", "gcp_pixel_scale")},
                "vectors": INPUTS_VECTORS,
            },
            site=SITE,
        log:
            elogfile("inputs", "check_inputs"),
        script:
            "../scripts/inputs_check.py"

    add_targets(epoch_results("inputs", "report.json"))


# DEM files a site hands to the DEM stages instead of (or besides) photographs (issue 17: a LiDAR
# or TLS DTM, another software's DSM): gully.dem_file (with gully.dem: file) and polygons.dem_file.
# One cheap rule per file checks it (CRS, grid, undeclared nodata sentinels) and writes the copy the
# stage reads (float32, NaN = nodata), so every rule of the stage sees the same checked elevations.
DEM_FILES = {
    s: config[s]["dem_file"] for s in ("gully", "polygons")
    if s in config and config[s].get("dem_file") and (s != "gully" or config[s]["dem"] == "file")
}


def checked_dem(stage):
    """Path of the checked copy of ``<stage>.dem_file``."""
    return result("inputs", f"dem/{stage}.tif")


if DEM_FILES:

    rule check_dem_file:
        input:
            dem=lambda wc: DEM_FILES[wc.stage],
        output:
            dem=result("inputs", "dem/{stage}.tif"),
        wildcard_constraints:
            stage="|".join(DEM_FILES),
        params:
            crs=config["site"]["crs"],
            nodata=lambda wc: config[wc.stage].get("dem_nodata"),
            key=lambda wc: f"{wc.stage}.dem_file",
        log:
            logfile("inputs", "dem_{stage}"),
        script:
            "../scripts/inputs_dem_file.py"

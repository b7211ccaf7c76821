# Dense matching (issue 6): object-space multi-view matching of the georeferenced model into
# a DSM, a correlation raster, a true orthophoto and relief shading (MicMac Malt/Tawny-like).

if "dense" in config and "georef" in config and "sfm" in config:
    # issue 17: the DSM's vertical datum checked at the GCP targets (kitegully.dense.datum)
    DENSE_DATUM = bool((config["dense"].get("datum") or {}).get("enabled", False))

    rule dense_match:
        input:
            model=eresult("georef", "model"),
            transform=eresult("georef", "transform.json"),
            sfm_work=eresult("sfm", "work"),  # images/ holds the prepared copies the model names
            **({"site": result("twin", "site.json")} if config["dense"]["extent"] == "site" else {}),
            **({"gcp": INPUTS_GCP, "gcp_residuals": eresult("georef", "gcp_residuals.csv")} if DENSE_DATUM else {}),
        output:
            dsm=eresult("dense", "dsm.tif"),
            correlation=eresult("dense", "correlation.tif"),
            orthophoto=eresult("dense", "orthophoto.tif"),
            hillshade=report(eresult("dense", "hillshade.png"), caption=caption("dense_hillshade"), category="Dense matching"),
            openness=report(eresult("dense", "openness.png"), caption=caption("dense_openness"), category="Dense matching"),
            summary=report(eresult("dense", "dense_summary.csv"), caption=caption("dense_summary"), category="Dense matching"),
            **({"datum": eresult("dense", "datum_check.csv")} if DENSE_DATUM else {}),
        params:
            dense=config["dense"],
            crs=config["site"]["crs"],
            gcp_format=config["georef"]["gcp_format"],
            csv_crs=config["georef"]["csv_crs"],
        threads: config["dense"]["threads"]
        log:
            elogfile("dense", "dense_match"),
        benchmark:
            ebenchfile("dense", "dense_match")
        script:
            "../scripts/dense_match.py"

    add_targets(
        epoch_results("dense", "dsm.tif"),
        epoch_results("dense", "orthophoto.tif"),
        epoch_results("dense", "hillshade.png"),
        epoch_results("dense", "openness.png"),
        epoch_results("dense", "dense_summary.csv"),
    )

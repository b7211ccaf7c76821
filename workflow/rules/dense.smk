# Dense matching (issue 6): object-space multi-view matching of the georeferenced model into
# a DSM, a correlation raster, a true orthophoto and relief shading (MicMac Malt/Tawny-like).

if "dense" in config and "georef" in config and "sfm" in config:

    rule dense_match:
        input:
            model=result("georef", "model"),
            transform=result("georef", "transform.json"),
            sfm_work=result("sfm", "work"),  # images/ holds the prepared copies the model names
            **({"site": result("twin", "site.json")} if config["dense"]["extent"] == "site" else {}),
        output:
            dsm=result("dense", "dsm.tif"),
            correlation=result("dense", "correlation.tif"),
            orthophoto=result("dense", "orthophoto.tif"),
            hillshade=report(result("dense", "hillshade.png"), caption=caption("dense_hillshade"), category="Dense matching"),
            openness=report(result("dense", "openness.png"), caption=caption("dense_openness"), category="Dense matching"),
            summary=report(result("dense", "dense_summary.csv"), caption=caption("dense_summary"), category="Dense matching"),
        params:
            dense=config["dense"],
            crs=config["site"]["crs"],
        threads: config["dense"]["threads"]
        log:
            logfile("dense", "dense_match"),
        benchmark:
            benchfile("dense", "dense_match")
        script:
            "../scripts/dense_match.py"

    add_targets(
        result("dense", "dsm.tif"),
        result("dense", "orthophoto.tif"),
        result("dense", "hillshade.png"),
        result("dense", "openness.png"),
        result("dense", "dense_summary.csv"),
    )

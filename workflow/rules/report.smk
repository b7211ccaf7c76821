# Products that open everywhere (issue 14): a QGIS project of the site's products,
# results/<site>/<site>.qgs, written as plain XML (no QGIS needed). Its inputs are only the
# products the site's other rules make (a rule file that does not apply leaves its layer out).
# Rules of the survey chain run per epoch ({epoch}); the project shows epoch 1, the site's
# first survey (its paths are those of a one-epoch site).

_DEFINED_RULES = {r.name for r in workflow.rules}
_QGIS_PRODUCTS = {
    key: expand(getattr(getattr(rules, rule).output, name), epoch=epoch_dir(1))[0]
    for key, rule, name in (
        ("dsm", "dense_match", "dsm"),
        ("orthophoto", "dense_match", "orthophoto"),
        ("gully_network", "gully_map", "network"),
        ("gully_polygons", "gully_map", "polygons"),
        ("bare_soil", "obia_kite_scale", "bare_soil"),
        ("checkpoint_errors", "validate_checkpoints", "errors"),
    )
    if rule in _DEFINED_RULES and (rule != "obia_kite_scale" or config["obia"]["kite_scale"]["enabled"])
}

if _QGIS_PRODUCTS:

    rule report_qgis:
        """QGIS project of the site's products (DSM + hillshade, orthophoto, gullies, bare soil, checkpoint errors)."""
        input:
            **_QGIS_PRODUCTS,
        output:
            project=str(RESULTS / f"{SITE}.qgs"),
            **({"checkpoints": result("report", "checkpoint_errors.gpkg")} if "checkpoint_errors" in _QGIS_PRODUCTS else {}),
        params:
            site=SITE,
            crs=config["site"]["crs"],
            error_limit_m=config["validate"]["error_limit_m"] if "validate" in config else 0.5,
            shading=config["dense"]["shading"] if "dense" in config else {"azimuth_deg": 315.0, "altitude_deg": 45.0},
        log:
            logfile("report", "qgis"),
        script:
            "../scripts/report_qgis.py"

    add_targets(str(RESULTS / f"{SITE}.qgs"))
